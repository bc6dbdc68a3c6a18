#pragma once
/// \file KdTreeChecks.h
/// One reusable checker of kd-tree invariants, run on every tree the tests build:
///  - structure: node indices in range (upper child after the lower subtree), every node reached
///    exactly once, leaf ranges inside prim_indices and disjoint, referenced ids in range and usable
///    (no degenerate / NaN primitive), no duplicate id in a leaf, every usable primitive referenced;
///  - geometry: bounds = union of the usable primitives' bounds; every split strictly inside its
///    node's box; child boxes are the two halves (also checked against KdTree::nodeBox);
///  - depth <= round(8 + 1.3 log2 N) (the builder's automatic bound) + 1;
///  - coverage: a primitive that overlaps a leaf box with positive area (triangles, clipped in double
///    to the leaf box shrunk by 1e-6 of its extent on each axis of positive extent) or non-empty
///    intersection (boxes, same shrunk box) is referenced by that leaf;
///  - point coverage (catches primitives lying in a split plane, which the shrunk boxes exclude):
///    for the vertices, edge midpoints and centroid of each triangle (corners and centre of each box)
///    some leaf whose closed box contains the point references the primitive.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <span>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::test {

namespace kdcheck_detail {

/// Collects the first few failures of a check into one readable message.
class Failures {
 public:
  template <class F>
  void add(F&& describe) {
    if (count_++ < 12) {
      std::ostringstream os;
      describe(os);
      text_ += "\n  " + os.str();
    }
  }
  [[nodiscard]] bool any() const { return count_ > 0; }
  [[nodiscard]] ::testing::AssertionResult result(const char* what) const {
    if (count_ == 0) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << what << ": " << count_ << " violation(s):" << text_;
  }

 private:
  std::size_t count_ = 0;
  std::string text_;
};

/// Convex polygon in double with its bounds, clipped by axis planes (Sutherland-Hodgman, closed
/// half-spaces). A triangle clipped to a box has at most 9 corners; the capacity leaves room for
/// repeated points from rounding, and running out is reported as a checker failure.
struct Polygon {
  static constexpr int kCap = 24;
  glm::dvec3 p[kCap];
  int n = 0;
  bool overflow = false;
  glm::dvec3 lo{0.0}, hi{0.0};

  void push(const glm::dvec3& q) {
    if (n > 0 && p[n - 1] == q) return;  // drop exact repeats (a vertex on the plane)
    if (n == kCap) {
      overflow = true;
      return;
    }
    p[n++] = q;
  }
  void finish() {
    if (n > 1 && p[0] == p[n - 1]) --n;
    if (n == 0) return;
    lo = hi = p[0];
    for (int i = 1; i < n; ++i) {
      lo = glm::min(lo, p[i]);
      hi = glm::max(hi, p[i]);
    }
  }
  /// Keeps the part with coordinate `axis` >= value (keep_above) or <= value.
  void clip(int axis, double value, bool keep_above, Polygon& out) const {
    out.n = 0;
    out.overflow = overflow;
    for (int i = 0; i < n; ++i) {
      const glm::dvec3& a = p[i];
      const glm::dvec3& b = p[i + 1 == n ? 0 : i + 1];
      const bool ain = keep_above ? a[axis] >= value : a[axis] <= value;
      const bool bin = keep_above ? b[axis] >= value : b[axis] <= value;
      if (ain) out.push(a);
      if (ain != bin) {
        const double t = (value - a[axis]) / (b[axis] - a[axis]);
        glm::dvec3 x = a + t * (b - a);
        x[axis] = value;
        out.push(x);
      }
    }
    out.finish();
  }
  [[nodiscard]] double area() const {
    if (n < 3) return 0.0;
    glm::dvec3 s(0.0);
    for (int i = 1; i + 1 < n; ++i) s += glm::cross(p[i] - p[0], p[i + 1] - p[0]);
    return 0.5 * glm::length(s);
  }
};

/// The leaf box shrunk by 1e-6 of its extent on each axis where the extent is positive.
inline void shrunk(const Box& b, glm::dvec3& lo, glm::dvec3& hi) {
  lo = glm::dvec3(b.lo);
  hi = glm::dvec3(b.hi);
  for (int k = 0; k < 3; ++k) {
    const double e = hi[k] - lo[k];
    if (e > 0.0) {
      lo[k] += 1e-6 * e;
      hi[k] -= 1e-6 * e;
    }
  }
}

inline bool leafReferences(const KdTree& tree, const KdNode& leaf, std::uint32_t prim) {
  const std::uint32_t* b = tree.prim_indices.data() + leaf.primOffset();
  return std::find(b, b + leaf.primCount(), prim) != b + leaf.primCount();
}

/// Whether some leaf whose closed box contains `p` references `prim`.
inline bool pointCovered(const KdTree& tree, const glm::dvec3& p, std::uint32_t prim) {
  std::uint32_t stack[256];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const std::uint32_t i = stack[--top];
    const KdNode& n = tree.nodes[i];
    if (n.isLeaf()) {
      if (leafReferences(tree, n, prim)) return true;
      continue;
    }
    const double s = n.split();
    const double x = p[n.axis()];
    if (top + 2 > 256) return false;
    if (x <= s) stack[top++] = i + 1;
    if (x >= s) stack[top++] = n.upperChild();
  }
  return false;
}

inline int depthBound(std::size_t usable, int max_depth) {
  if (max_depth > 0) return std::min(max_depth, 60);
  const int automatic = static_cast<int>(std::lround(8.0 + 1.3 * std::log2(static_cast<double>(usable))));
  return std::min(automatic, 60) + 1;  // +1: slack for the rounding of the bound
}

/// The boxes of `tris` (model space), empty for those not `usable`: what a structure over them
/// bounds.
std::vector<Box> triangleBounds(std::span<const std::array<glm::vec3, 3>> tris, const std::vector<char>& usable);

/// Sample point `k` (0-8) of the box [lo, hi]: its corners (bit 0, 1, 2 of `k`: x, y, z at hi) and,
/// for 8, its centre: the points a structure must cover where it references the box.
inline glm::dvec3 boxSamplePoint(const glm::dvec3& lo, const glm::dvec3& hi, int k) {
  return k == 8 ? 0.5 * (lo + hi) : glm::dvec3(k & 1 ? hi.x : lo.x, k & 2 ? hi.y : lo.y, k & 4 ? hi.z : lo.z);
}

}  // namespace kdcheck_detail

/// Structural and geometric checks shared by triangle and box trees. `prim_bounds[i]` is the
/// bound of primitive i; `usable[i]` whether the builder may reference it (its bounds are
/// non-empty and finite). `max_depth` is the configured bound (0: automatic). `root_bounds`: the
/// bounds the tree was built for when the caller gave them (buildKdTreeOverBoxes with root bounds),
/// else the tree's bounds must be the union of the usable bounds.
::testing::AssertionResult checkKdStructure(const KdTree& tree, std::span<const Box> prim_bounds,
                                            const std::vector<char>& usable, int max_depth = 0,
                                            const Box* root_bounds = nullptr);

/// Full check of a tree over triangles `tris[i]`; `usable[i]` false for degenerate triangles.
::testing::AssertionResult checkTriangleKdTree(const KdTree& tree, std::span<const std::array<glm::vec3, 3>> tris,
                                               const std::vector<char>& usable, int max_depth = 0);

/// Full check of a tree over boxes (top level, or buildKdTreeOverBoxes; `root_bounds` as for
/// checkKdStructure).
::testing::AssertionResult checkBoxKdTree(const KdTree& tree, std::span<const Box> boxes, int max_depth = 0,
                                          const Box* root_bounds = nullptr);

/// A mesh's triangles (object space) and whether each is valid (non-degenerate, finite): what the
/// structure checkers take.
struct CheckedTriangles {
  std::vector<std::array<glm::vec3, 3>> tris;
  std::vector<char> usable;
  explicit CheckedTriangles(const TriangleMesh& m) : tris(m.triangleCount()), usable(m.triangleCount()) {
    for (std::size_t i = 0; i < m.triangleCount(); ++i) {
      tris[i] = m.vertices(i);
      usable[i] = m.isValid(i);
    }
  }
};

/// The tree of a mesh object, over its triangles (degenerate ones must not be referenced).
::testing::AssertionResult checkMeshTree(const MeshObject& object, int max_depth = 0);

/// A named build configuration for parameterised tests.
struct ConfigCase {
  std::string name;
  KdBuildConfig config;
};

/// Test names print the case's name, not its bytes.
inline void PrintTo(const ConfigCase& c, std::ostream* os) { *os << c.name; }

/// Every heuristic with and without clipping, plus the knobs that change the tree's shape or the
/// build path (TBB subtrees, serial, depth limit, small leaves, cheap traversal).
std::vector<ConfigCase> allConfigCases();

}  // namespace duplex::test
