#pragma once
/// \file KdTree.h
/// A built kd-tree: flat node array, leaf primitive index list, bounds. Data-agnostic: it knows
/// primitives only by index.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdNode.h"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace duplex {

/// Summary figures of a tree (for benchmarks and tests).
struct KdTreeStats {
  std::uint32_t nodes = 0;         ///< all nodes, inner and leaves
  std::uint32_t inner_nodes = 0;   ///< nodes with a split plane
  std::uint32_t leaves = 0;        ///< leaves, empty ones included
  std::uint32_t empty_leaves = 0;  ///< leaves with no primitive
  std::uint32_t references = 0;    ///< sum of leaf sizes
  std::uint32_t max_depth = 0;     ///< depth of the deepest leaf (root: 0)
  double avg_leaf_size = 0.0;      ///< references / non-empty leaves
  double sah_cost = 0.0;           ///< expected cost of a ray through the root box (build costs)
  std::size_t bytes = 0;           ///< nodes + index list
};

/// Immutable after build; safe to traverse from any number of threads.
struct KdTree {
  Box bounds;                               ///< box of all primitives, in the primitives' space
  std::vector<KdNode> nodes;                ///< depth-first; node 0 is the root
  std::vector<std::uint32_t> prim_indices;  ///< leaf ranges index into this list

  /// Whether the tree has no node (built over no primitive).
  [[nodiscard]] bool empty() const { return nodes.empty(); }
  /// Statistics; `traversal_cost` / `intersection_cost` weigh the SAH cost.
  [[nodiscard]] KdTreeStats stats(float traversal_cost, float intersection_cost) const;
  /// Box of node `index` (walks from the root; for tests and tools, not for traversal).
  [[nodiscard]] Box nodeBox(std::uint32_t index) const;
};

/// The cells of an inner node's two children: `cell` cut at the node's split plane. Clamped,
/// because in an incrementally updated tree whose root shrank a plane may lie outside its node.
struct KdChildCells {
  Box lower;  ///< the cell of the lower child (index + 1)
  Box upper;  ///< the cell of the upper child (upperChild())
};

/// The children's cells of inner node `n` whose cell is `cell`.
[[nodiscard]] inline KdChildCells childCells(const KdNode& n, const Box& cell) {
  KdChildCells c{cell, cell};
  const int axis = n.axis();
  c.lower.hi[axis] = std::min(n.split(), cell.hi[axis]);
  c.upper.lo[axis] = std::max(n.split(), cell.lo[axis]);
  return c;
}

}  // namespace duplex
