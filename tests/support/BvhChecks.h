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
inline ::testing::AssertionResult checkBvhStructure(const WideBvh& bvh, std::span<const Box> prim_bounds,
                                                    const std::vector<char>& usable, const BvhCheckOptions& opt) {
  using namespace bvhcheck_detail;
  Failures f;
  const std::size_t prim_count = prim_bounds.size();
  const bool tight = opt.tight && !opt.spatial_splits;
  std::size_t usable_count = 0;
  Box expected;
  for (std::size_t i = 0; i < prim_count; ++i)
    if (usable[i]) {
      ++usable_count;
      expected.extend(prim_bounds[i]);
    }
  if (bvh.leaf_block != opt.leaf_block)
    f.add([&](auto& os) { os << "leaf_block " << bvh.leaf_block << ", expected " << opt.leaf_block; });
  if (f.any()) return f.result("BVH structure");
  if (bvh.root == BvhRef::kEmpty) {
    if (usable_count != 0) f.add([&](auto& os) { os << "empty root but " << usable_count << " usable primitives"; });
    if (!bvh.nodes.empty() || !bvh.prim_indices.empty())
      f.add([&](auto& os) {
        os << "empty root with " << bvh.nodes.size() << " nodes and " << bvh.prim_indices.size() << " indices";
      });
    if (!bvh.bounds.empty()) f.add([&](auto& os) { os << "empty root with bounds " << bvh.bounds; });
    return f.result("BVH structure");
  }
  if (usable_count == 0) {
    f.add([&](auto& os) { os << "no usable primitive, but the root is " << bvh.root; });
    return f.result("BVH structure");
  }
  if (!(bvh.bounds == expected))
    f.add([&](auto& os) { os << "bounds " << bvh.bounds << " != union of usable bounds " << expected; });
  if (BvhRef::isLeaf(bvh.root) && !bvh.nodes.empty())
    f.add([&](auto& os) { os << "leaf root with " << bvh.nodes.size() << " nodes"; });
  if (BvhRef::isInner(bvh.root) && bvh.root != 0) f.add([&](auto& os) { os << "inner root " << bvh.root << " != 0"; });
  if (f.any()) return f.result("BVH structure");

  std::vector<std::uint32_t> references(prim_count, 0);
  std::vector<char> block_owned(bvh.prim_indices.size() / std::max<std::uint32_t>(1, bvh.leaf_block), 0);
  if (bvh.prim_indices.size() % bvh.leaf_block != 0)
    f.add([&](auto& os) { os << "prim_indices size " << bvh.prim_indices.size() << " not a multiple of leaf_block"; });
  std::size_t total_refs = 0;
  std::vector<std::uint32_t> ids;
  auto checkLeaf = [&](std::uint32_t ref, const Box& box, const std::string& where) {
    const std::uint32_t count = BvhRef::leafCount(ref);
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    const std::size_t blocks = (count + bvh.leaf_block - 1) / bvh.leaf_block;
    if (count > opt.max_leaf_size)
      f.add([&](auto& os) { os << where << ": leaf of " << count << " > max_leaf_size " << opt.max_leaf_size; });
    if (first + blocks * bvh.leaf_block > bvh.prim_indices.size()) {
      f.add([&](auto& os) {
        os << where << ": leaf range [" << first << ", " << first + blocks * bvh.leaf_block
           << ") beyond prim_indices size " << bvh.prim_indices.size();
      });
      return;
    }
    for (std::size_t b = BvhRef::leafBlock(ref); b < BvhRef::leafBlock(ref) + blocks; ++b)
      if (block_owned[b]++) f.add([&](auto& os) { os << where << ": block " << b << " belongs to two leaves"; });
    for (std::size_t i = first + count; i < first + blocks * bvh.leaf_block; ++i)
      if (bvh.prim_indices[i] != WideBvh::kPadding)
        f.add([&](auto& os) { os << where << ": prim_indices[" << i << "] after the leaf is not padding"; });
    ids.assign(bvh.prim_indices.begin() + static_cast<std::ptrdiff_t>(first),
               bvh.prim_indices.begin() + static_cast<std::ptrdiff_t>(first + count));
    Box held;
    for (const std::uint32_t id : ids) {
      if (id >= prim_count || !usable[id]) {
        f.add([&](auto& os) {
          os << where << ": references primitive " << id
             << (id == WideBvh::kPadding ? " (padding inside the leaf)"
                                         : (id >= prim_count ? " (out of range)" : " (not usable)"));
        });
        continue;
      }
      ++references[id];
      ++total_refs;
      held.extend(prim_bounds[id]);
      if (!opt.spatial_splits && !inside(prim_bounds[id], box))
        f.add([&](auto& os) {
          os << where << ": box " << box << " does not contain primitive " << id << " " << prim_bounds[id];
        });
      if (opt.spatial_splits && intersection(box, prim_bounds[id]).empty())
        f.add([&](auto& os) {
          os << where << ": box " << box << " does not overlap primitive " << id << " " << prim_bounds[id];
        });
    }
    if (tight && !(held == box))
      f.add([&](auto& os) { os << where << ": box " << box << " != union of its primitives " << held; });
    std::sort(ids.begin(), ids.end());
    if (std::adjacent_find(ids.begin(), ids.end()) != ids.end())
      f.add([&](auto& os) { os << where << ": a primitive twice in one leaf"; });
  };

  if (BvhRef::isLeaf(bvh.root)) {
    checkLeaf(bvh.root, bvh.bounds, "root leaf");
  } else {
    struct Item {
      std::uint32_t node;
      std::uint32_t parent;
      Box box;  // the parent's slot box (bvh.bounds for the root)
      int depth;
    };
    std::vector<Item> stack{{0, BvhRef::kEmpty, bvh.bounds, 1}};
    std::vector<char> visited(bvh.nodes.size(), 0);
    std::uint32_t order = 0;
    while (!stack.empty()) {
      const Item it = stack.back();
      stack.pop_back();
      const std::string at = "node " + std::to_string(it.node);
      if (it.node >= bvh.nodes.size()) {
        f.add([&](auto& os) { os << at << " out of range (" << bvh.nodes.size() << " nodes)"; });
        continue;
      }
      if (visited[it.node]++) {
        f.add([&](auto& os) { os << at << " reached twice"; });
        continue;
      }
      if (it.parent != BvhRef::kEmpty && it.node <= it.parent)
        f.add([&](auto& os) { os << at << " is a child of node " << it.parent << ": children come after parents"; });
      if (it.node != order)
        f.add([&](auto& os) { os << at << " visited at depth-first position " << order << ": not depth-first"; });
      ++order;
      if (it.depth > WideBvh::kMaxDepth)
        f.add([&](auto& os) { os << at << " at depth " << it.depth << " > kMaxDepth " << WideBvh::kMaxDepth; });
      const BvhNode8& node = bvh.nodes[it.node];
      int used = 0;
      while (used < BvhNode8::kWidth && node.child[used] != BvhRef::kEmpty) ++used;
      if (used < 2) f.add([&](auto& os) { os << at << " has " << used << " children (at least 2)"; });
      if (!node.orderValid()) {
        f.add([&](auto& os) { os << at << ": child order is not a permutation of the slots per octant"; });
      } else if (opt.tight) {
        BvhNode8 sorted = node;
        sorted.computeOrder();
        if (!std::equal(std::begin(node.order), std::end(node.order), std::begin(sorted.order)))
          f.add([&](auto& os) { os << at << ": child order differs from the boxes' (computeOrder)"; });
      }
      Box all;
      for (int k = 0; k < BvhNode8::kWidth; ++k) {
        const Box b = node.childBox(k);
        const std::string slot = at + " slot " + std::to_string(k);
        if (k >= used) {
          if (node.child[k] != BvhRef::kEmpty)
            f.add([&](auto& os) { os << slot << ": used slot " << node.child[k] << " after an empty one"; });
          if (!isEmptySlotBox(b))
            f.add([&](auto& os) { os << slot << ": empty slot with box " << b << " (not [+inf, -inf])"; });
          continue;
        }
        if (!b.finite() || b.empty()) {
          f.add([&](auto& os) { os << slot << ": box " << b << " not finite and non-empty"; });
          continue;
        }
        if (!inside(b, it.box))
          f.add([&](auto& os) { os << slot << ": box " << b << " outside the parent's box " << it.box; });
        all.extend(b);
        if (BvhRef::isLeaf(node.child[k])) checkLeaf(node.child[k], b, slot);
      }
      if (tight && !(all == it.box))
        f.add([&](auto& os) { os << at << ": parent's box " << it.box << " != union of the children " << all; });
      // Reverse slot order, so that slot 0 is visited next (depth-first in slot order).
      for (int k = used - 1; k >= 0; --k)
        if (BvhRef::isInner(node.child[k])) stack.push_back({node.child[k], it.node, node.childBox(k), it.depth + 1});
    }
    if (order != bvh.nodes.size())
      f.add([&](auto& os) { os << "only " << order << " of " << bvh.nodes.size() << " nodes reached from the root"; });
  }
  const auto owned = static_cast<std::size_t>(std::count(block_owned.begin(), block_owned.end(), 1));
  if (owned != block_owned.size())
    f.add([&](auto& os) { os << block_owned.size() - owned << " blocks of prim_indices belong to no leaf"; });
  for (std::size_t i = 0; i < prim_count; ++i) {
    if (!usable[i]) continue;
    if (references[i] == 0) f.add([&](auto& os) { os << "usable primitive " << i << " is in no leaf"; });
    else if (references[i] > 1 && !opt.spatial_splits)
      f.add([&](auto& os) { os << "primitive " << i << " in " << references[i] << " leaves without spatial splits"; });
  }
  if (opt.spatial_splits && double(total_refs) > (1.0 + double(opt.spatial_split_budget)) * double(usable_count) + 1.0)
    f.add([&](auto& os) {
      os << total_refs << " references for " << usable_count << " primitives exceed the budget "
         << opt.spatial_split_budget;
    });
  return f.result("BVH structure");
}

/// Usable as the builder defines it: a non-empty, finite box.
inline std::vector<char> usableBoxes(std::span<const Box> boxes) {
  std::vector<char> usable(boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) usable[i] = !boxes[i].empty() && boxes[i].finite();
  return usable;
}

/// Full check of a BVH over boxes (buildWideBvh directly, or after refitWideBvh).
inline ::testing::AssertionResult checkBoxBvh(const WideBvh& bvh, std::span<const Box> boxes,
                                              const BvhCheckOptions& opt = {}) {
  using namespace bvhcheck_detail;
  const std::vector<char> usable = usableBoxes(boxes);
  auto structure = checkBvhStructure(bvh, boxes, usable, opt);
  if (!structure || !opt.spatial_splits) return structure;
  Failures f;
  const auto leaves = leafBoxesByPrimitive(bvh, boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (!usable[i]) continue;
    const glm::dvec3 lo(boxes[i].lo), hi(boxes[i].hi);
    for (int corner = 0; corner < 9; ++corner) {
      const glm::dvec3 p =
          corner == 8 ? 0.5 * (lo + hi)
                      : glm::dvec3(corner & 1 ? hi.x : lo.x, corner & 2 ? hi.y : lo.y, corner & 4 ? hi.z : lo.z);
      if (!coveredByLeaves(p, leaves[i])) {
        f.add([&](auto& os) { os << "a point of box " << i << " " << boxes[i] << " is in no leaf referencing it"; });
        break;
      }
    }
  }
  return f.result("BVH box coverage");
}

/// Full check of a BVH over triangles `tris[i]`; `usable[i]` false for degenerate triangles.
inline ::testing::AssertionResult checkTriangleBvh(const WideBvh& bvh, std::span<const std::array<glm::vec3, 3>> tris,
                                                   const std::vector<char>& usable, const BvhCheckOptions& opt) {
  using namespace bvhcheck_detail;
  std::vector<Box> bounds(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i)
    if (usable[i])
      for (const auto& v : tris[i]) bounds[i].extend(v);
  // Without spatial splits, leaf boxes containing the triangle boxes contain all three vertices.
  auto structure = checkBvhStructure(bvh, bounds, usable, opt);
  if (!structure || !opt.spatial_splits) return structure;
  Failures f;
  const auto leaves = leafBoxesByPrimitive(bvh, tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i) {
    if (!usable[i]) continue;
    const glm::dvec3 a(tris[i][0]), b(tris[i][1]), c(tris[i][2]);
    // Every referencing leaf box meets the triangle itself, not only its bounding box.
    for (const Box& box : leaves[i]) {
      glm::dvec3 lo, hi;
      grown(box, lo, hi);
      kdcheck_detail::Polygon cur, tmp;
      cur.push(a);
      cur.push(b);
      cur.push(c);
      cur.finish();
      for (int k = 0; k < 3 && cur.n > 0; ++k) {
        cur.clip(k, lo[k], true, tmp);
        cur = tmp;
        if (cur.n == 0) break;
        cur.clip(k, hi[k], false, tmp);
        cur = tmp;
      }
      if (cur.n == 0)
        f.add([&](auto& os) { os << "triangle " << i << " referenced by leaf " << box << " which it does not meet"; });
    }
    // The referencing leaves together cover the triangle.
    const glm::dvec3 samples[10] = {a,
                                    b,
                                    c,
                                    0.5 * (a + b),
                                    0.5 * (b + c),
                                    0.5 * (c + a),
                                    (a + b + c) / 3.0,
                                    0.7 * a + 0.2 * b + 0.1 * c,
                                    0.1 * a + 0.7 * b + 0.2 * c,
                                    0.2 * a + 0.1 * b + 0.7 * c};
    for (const auto& p : samples)
      if (!coveredByLeaves(p, leaves[i])) {
        f.add([&](auto& os) {
          os << "point (" << p.x << ", " << p.y << ", " << p.z << ") of triangle " << i
             << " lies in no leaf that references it";
        });
        break;
      }
  }
  return f.result("BVH triangle coverage");
}

/// The BVH of a mesh object over its triangles (degenerate ones must not be referenced).
inline ::testing::AssertionResult checkMeshBvh(const MeshObject& object, const BvhCheckOptions& opt) {
  if (object.structure() != MeshStructure::Bvh)
    return ::testing::AssertionFailure() << "mesh '" << object.mesh().name() << "' has no BVH";
  const CheckedTriangles t(object.mesh());
  return checkTriangleBvh(object.bvh(), t.tris, t.usable, opt);
}

}  // namespace duplex::test
