#pragma once
/// \file KdNode.h
/// The 8-byte kd-tree node (after pbrt's KdAccelNode, without type punning through a union).

#include <bit>
#include <cstdint>

namespace duplex {

/// Inner node: split plane position (float, in the tree's space) on one axis; its lower child is
/// the next node in the array (depth-first layout), its upper child is at `upperChild()`.
/// Leaf: a range [primOffset(), primOffset() + primCount()) of the tree's primitive index list.
/// Jump (only in incrementally updated trees, never from the builder): a leaf-tagged node with all
/// bits set in the count field, standing for the subtree rooted at jumpTarget(). It lets an update
/// replace a leaf by a subtree appended at the end of the array without moving any other node.
class KdNode {
 public:
  static constexpr std::uint32_t kLeafTag = 3;  ///< value of the two low bits that marks a leaf (or a jump)
  /// Largest child index or primitive count a node can hold (30 bits; all ones marks a jump).
  static constexpr std::uint32_t kMaxIndex = (1u << 30) - 2;  // all ones marks a jump

  /// Inner node splitting `axis` (0 x, 1 y, 2 z) at `split` (tree space); upper child at index `upper_child` (<=
  /// kMaxIndex).
  static KdNode inner(int axis, float split, std::uint32_t upper_child) {
    KdNode n;
    n.payload_ = std::bit_cast<std::uint32_t>(split);
    n.bits_ = (upper_child << 2) | static_cast<std::uint32_t>(axis);
    return n;
  }
  /// Jump node standing for the subtree rooted at node index `target`.
  static KdNode jump(std::uint32_t target) {
    KdNode n;
    n.payload_ = target;
    n.bits_ = 0xFFFFFFFFu;
    return n;
  }
  /// Leaf of `prim_count` (<= kMaxIndex) entries of the index list from `prim_offset` on.
  static KdNode leaf(std::uint32_t prim_offset, std::uint32_t prim_count) {
    KdNode n;
    n.payload_ = prim_offset;
    n.bits_ = (prim_count << 2) | kLeafTag;
    return n;
  }

  /// True for leaves and jumps (test isJump() in a leaf's branch, where it costs nothing on trees
  /// without jumps).
  [[nodiscard]] bool isLeaf() const { return (bits_ & 3u) == kLeafTag; }
  /// Whether this is a jump node (see jumpTarget()).
  [[nodiscard]] bool isJump() const { return bits_ == 0xFFFFFFFFu; }
  /// A leaf with no primitives (one compare: the traversal tests it on both children of a step).
  [[nodiscard]] bool isEmptyLeaf() const { return bits_ == kLeafTag; }
  /// Jump: index of the node that roots the subtree it stands for.
  [[nodiscard]] std::uint32_t jumpTarget() const { return payload_; }
  /// Inner node: split axis, 0 x, 1 y, 2 z.
  [[nodiscard]] int axis() const { return static_cast<int>(bits_ & 3u); }
  /// Inner node: split plane position on axis(), in the tree's space.
  [[nodiscard]] float split() const { return std::bit_cast<float>(payload_); }
  /// Inner node: index of the upper child (the lower one is the next node).
  [[nodiscard]] std::uint32_t upperChild() const { return bits_ >> 2; }
  /// Leaf: first position of its range in the tree's primitive index list.
  [[nodiscard]] std::uint32_t primOffset() const { return payload_; }
  /// Leaf: number of primitives in its range.
  [[nodiscard]] std::uint32_t primCount() const { return bits_ >> 2; }
  /// Inner node: moves the upper child to index `upper_child`, keeping the axis.
  void setUpperChild(std::uint32_t upper_child) { bits_ = (upper_child << 2) | (bits_ & 3u); }
  /// Leaf: moves its range to start at `offset`, keeping the count.
  void setPrimOffset(std::uint32_t offset) { payload_ = offset; }

 private:
  std::uint32_t payload_ = 0;  // split position bits (inner) or primitive offset (leaf)
  std::uint32_t bits_ = 0;     // 2 low bits: axis or leaf tag; 30 high bits: upper child or count
};
static_assert(sizeof(KdNode) == 8);

}  // namespace duplex
