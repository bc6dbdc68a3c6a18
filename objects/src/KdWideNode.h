#pragma once
// The query-side wide kd-tree node: two levels of the binary kd-tree (KdNode) collapsed into one
// 32-byte node with three planes and four children. Private to the objects library: the binary tree
// stays what the builder, saved files, tests and the top level use; MeshObject derives this form
// from it for its queries (KdWideTree.h).

#include <cstdint>

namespace duplex::detail {

/// Planes (object space): plane[0] splits the cell on axis0 into a lower and an upper half;
/// plane[1] splits the lower half on axis1, plane[2] the upper half on axis2. The children, in
/// memory order, are the cells (lower0, lower1), (lower0, upper1), (upper0, lower2), (upper0, upper2).
/// A half that is a leaf in the binary tree gets the plane -inf (its lower side is empty, never
/// visited) and the leaf as its upper child.
///
/// A child word is the index of a wide node, or, with kLeafBit set, a leaf: bits 0-24 the offset of
/// its first triangle block, bits 25-30 its number of blocks (1-63); a block count of 0 marks a leaf
/// too large for the fields, whose offset field then indexes KdWideTree::big_leaves. Empty children
/// have their bit clear in the visit mask and are never read.
struct alignas(32) KdWideNode {
  static constexpr std::uint32_t kLeafBit = 0x80000000u;
  static constexpr std::uint32_t kOffsetBits = 25;
  static constexpr std::uint32_t kOffsetMask = (1u << kOffsetBits) - 1;
  static constexpr std::uint32_t kMaxCount = 63;

  float plane[3];
  /// 16 x the axis of plane k (the byte offset of the axis' entry in the traversal's per-ray table).
  std::uint8_t axis16[3];
  /// Bit i set: child i is not empty.
  std::uint8_t child_mask;
  std::uint32_t child[4];

  [[nodiscard]] int axis(int k) const { return axis16[k] >> 4; }
};
static_assert(sizeof(KdWideNode) == 32);

}  // namespace duplex::detail
