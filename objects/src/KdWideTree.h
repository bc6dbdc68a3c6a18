#pragma once
// The wide form of a mesh's kd-tree that queries traverse (KdWideNode.h, KdWideTraversal.h).
// Private to the objects library.

#include "KdWideNode.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTree.h"

#include <cstdint>
#include <utility>
#include <vector>

namespace duplex::detail {

struct KdWideTree {
  /// The binary tree's bounds (object space).
  Box bounds;
  /// Nodes in depth-first order; nodes[0] is the root when root_word names a node.
  std::vector<KdWideNode> nodes;
  /// Leaves whose block offset or count does not fit a child word: {first block, blocks}.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> big_leaves;
  /// The root as a child word (a node index or a leaf word); kEmptyRoot for a tree with no
  /// primitives.
  std::uint32_t root_word = kEmptyRoot;
  static constexpr std::uint32_t kEmptyRoot = 0xFFFFFFFFu;
};

/// Collapses pairs of levels of `block_tree` (a mesh's binary tree whose leaf offsets index
/// 4-triangle blocks and whose leaf counts are triangles; no jump nodes) into wide nodes. The cells,
/// and so every query's result, are those of the binary tree.
[[nodiscard]] KdWideTree buildKdWideTree(const KdTree& block_tree);

}  // namespace duplex::detail
