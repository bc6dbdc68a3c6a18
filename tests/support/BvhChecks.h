#pragma once
/// \file BvhChecks.h
/// One reusable checker of wide-BVH invariants (WideBvh.h), run on every BVH the tests build. It is
/// written from the definitions in WideBvh.h, independently of the loader's check:
///  - encoding: leaf_block as configured; an empty root has no nodes, indices or bounds; a leaf root
///    has no nodes; an inner root is node 0;
///  - layout: nodes in depth-first (pre-)order, children visited in slot order, so every child index
///    exceeds its parent's and every node is reached exactly once; used slots first, each with a
///    finite non-empty box; unused slots kEmpty with box exactly [+inf, -inf]; no inner node with
///    fewer than 2 children; at most WideBvh::kMaxDepth inner nodes on a path;
///  - leaves: 1 to max_leaf_size primitives, the range starting at its block inside prim_indices and
///    padded with kPadding to a multiple of leaf_block, every block owned by exactly one leaf, no
///    index out of range, unusable (empty, non-finite, degenerate) or repeated within a leaf;
///  - geometry: bvh.bounds the union of the usable primitives' bounds; every child box inside its
///    parent's slot box; a leaf box contains its primitives' boxes (triangles: all three vertices)
///    and, for trees from the builder or a refit, equals their union, as an inner slot box equals
///    its children's union ("tight");
///  - references: without spatial splits every usable primitive exactly once. With spatial splits a
///    primitive may be in several leaves, whose boxes need only overlap it (triangles: the triangle
///    clipped to the box is not empty), within the reference budget, and points spread over each
///    primitive (triangles: vertices, edge points, interior points; boxes: corners and centre) each
///    lie in a leaf box that references it.

#include "KdTreeChecks.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/BvhBuildConfig.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <sstream>
#include <vector>

namespace duplex::test {

/// What a checked BVH promises beyond the encoding.
struct BvhCheckOptions {
  std::uint32_t max_leaf_size = BvhRef::kMaxLeafSize;  ///< primitives per leaf at most
  std::uint32_t leaf_block = 4;                        ///< expected WideBvh::leaf_block
  /// Built with spatial splits: references may repeat and leaf boxes may clip their primitives.
  bool spatial_splits = false;
  /// With spatial splits: references at most (1 + budget) times the usable primitives.
  float spatial_split_budget = 4.0f;
  /// Slot boxes equal the union of what they hold (builder and refit output; ignored with spatial
  /// splits, whose leaf boxes hold clipped parts).
  bool tight = true;

  /// The promises of a tree built with `c` (spatial splits when alpha > 0).
  static BvhCheckOptions of(const BvhBuildConfig& c) {
    BvhCheckOptions o;
    o.max_leaf_size = c.max_leaf_size;
    o.leaf_block = c.leaf_block;
    o.spatial_splits = c.spatial_split_alpha > 0.0f;
    o.spatial_split_budget = c.spatial_split_budget;
    return o;
  }
};

namespace bvhcheck_detail {

using kdcheck_detail::Failures;

inline bool inside(const Box& inner, const Box& outer) {
  for (int k = 0; k < 3; ++k)
    if (!(inner.lo[k] >= outer.lo[k] && inner.hi[k] <= outer.hi[k])) return false;
  return true;
}

inline bool isEmptySlotBox(const Box& b) {
  constexpr float inf = std::numeric_limits<float>::infinity();
  for (int k = 0; k < 3; ++k)
    if (!(b.lo[k] == inf && b.hi[k] == -inf)) return false;
  return true;
}

/// `b` grown on every side by a rounding allowance relative to its coordinates (double).
inline void grown(const Box& b, glm::dvec3& lo, glm::dvec3& hi) {
  lo = glm::dvec3(b.lo);
  hi = glm::dvec3(b.hi);
  double m = 0.0;
  for (int k = 0; k < 3; ++k) m = std::max({m, std::abs(lo[k]), std::abs(hi[k])});
  const double pad = 1e-6 * m + 1e-30;
  lo -= pad;
  hi += pad;
}

inline bool pointIn(const glm::dvec3& p, const glm::dvec3& lo, const glm::dvec3& hi) {
  return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
}

/// Calls f(leaf ref, leaf box) for every leaf; only on a tree that passed the structure check.
template <class F>
void forEachLeaf(const WideBvh& bvh, F&& f) {
  if (bvh.root == BvhRef::kEmpty) return;
  if (BvhRef::isLeaf(bvh.root)) {
    f(bvh.root, bvh.bounds);
    return;
  }
  for (const BvhNode8& node : bvh.nodes)
    for (int k = 0; k < node.childCount(); ++k)
      if (BvhRef::isLeaf(node.child[k])) f(node.child[k], node.childBox(k));
}

/// The leaf boxes that reference each primitive.
inline std::vector<std::vector<Box>> leafBoxesByPrimitive(const WideBvh& bvh, std::size_t prim_count) {
  std::vector<std::vector<Box>> out(prim_count);
  forEachLeaf(bvh, [&](std::uint32_t ref, const Box& box) {
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    for (std::uint32_t i = 0; i < BvhRef::leafCount(ref); ++i) out[bvh.prim_indices[first + i]].push_back(box);
  });
  return out;
}

inline bool coveredByLeaves(const glm::dvec3& p, const std::vector<Box>& boxes) {
  for (const Box& b : boxes) {
    glm::dvec3 lo, hi;
    grown(b, lo, hi);
    if (pointIn(p, lo, hi)) return true;
  }
  return false;
}

}  // namespace bvhcheck_detail

/// Encoding, layout, leaves, box geometry and references of `bvh` over primitives with bounds
/// `prim_bounds[i]`; `usable[i]` whether the builder may reference primitive i.
::testing::AssertionResult checkBvhStructure(const WideBvh& bvh, std::span<const Box> prim_bounds,
                                             const std::vector<char>& usable, const BvhCheckOptions& opt);

/// Usable as the builder defines it: a non-empty, finite box.
std::vector<char> usableBoxes(std::span<const Box> boxes);

/// Full check of a BVH over boxes (buildWideBvh directly, or after refitWideBvh).
::testing::AssertionResult checkBoxBvh(const WideBvh& bvh, std::span<const Box> boxes, const BvhCheckOptions& opt = {});

/// Full check of a BVH over triangles `tris[i]`; `usable[i]` false for degenerate triangles.
::testing::AssertionResult checkTriangleBvh(const WideBvh& bvh, std::span<const std::array<glm::vec3, 3>> tris,
                                            const std::vector<char>& usable, const BvhCheckOptions& opt);

/// The BVH of a mesh object over its triangles (degenerate ones must not be referenced).
::testing::AssertionResult checkMeshBvh(const MeshObject& object, const BvhCheckOptions& opt);

}  // namespace duplex::test
