#pragma once
/// \file WideBvh.h
/// An 8-wide bounding volume hierarchy over primitive boxes, data-agnostic (the mesh type adds its
/// triangle blocks and traversal), and its binned-SAH builder.
///
/// Layout, chosen for SIMD traversal and for a later refit that keeps the topology:
/// - every node holds the boxes of its (up to) 8 children as structure of arrays, one row of 8
///   floats per plane, so that one vector load gives a plane of all children;
/// - nodes are in depth-first order, each parent before its children, so that a refit is one pass
///   over the nodes in reverse order;
/// - a child is an inner node's index, a leaf (a range of prim_indices), or empty (the box is
///   [+inf, -inf], which no ray enters).

#include "duplex/accel/Box.h"
#include "duplex/accel/BvhBuildConfig.h"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <iterator>
#include <span>
#include <vector>

namespace duplex {

/// A child reference of a wide node (or the root reference of a WideBvh).
///
/// Encoding: kEmpty; an inner node index (bit 31 clear); or a leaf, bit 31 set, bits 27..30 the
/// primitive count minus one (1 to 16) and bits 0..26 the leaf's first entry in prim_indices
/// divided by the leaf block (leaf ranges start at multiples of it).
struct BvhRef {
  static constexpr std::uint32_t kEmpty = 0xFFFFFFFFu;            ///< no child
  static constexpr std::uint32_t kLeafBit = 0x80000000u;          ///< set for a leaf
  static constexpr std::uint32_t kMaxLeafSize = 16;               ///< primitives per leaf at most
  static constexpr std::uint32_t kMaxLeafBlock = (1u << 27) - 1;  ///< largest encodable block index
  static constexpr std::uint32_t kMaxNodes = 0x7FFFFFFFu;         ///< inner node indices are below this

  /// Whether `r` is no child.
  [[nodiscard]] static constexpr bool isEmpty(std::uint32_t r) { return r == kEmpty; }
  /// Whether `r` is a leaf.
  [[nodiscard]] static constexpr bool isLeaf(std::uint32_t r) { return (r & kLeafBit) != 0 && r != kEmpty; }
  /// Whether `r` is an inner node index.
  [[nodiscard]] static constexpr bool isInner(std::uint32_t r) { return (r & kLeafBit) == 0; }
  /// A leaf of `count` (1..16) primitives starting at block `block` (its first entry / leaf_block).
  [[nodiscard]] static constexpr std::uint32_t leaf(std::uint32_t block, std::uint32_t count) {
    return kLeafBit | (count - 1) << 27 | block;
  }
  /// The leaf's first block (first prim_indices entry / leaf_block).
  [[nodiscard]] static constexpr std::uint32_t leafBlock(std::uint32_t r) { return r & kMaxLeafBlock; }
  /// The leaf's primitive count (1 to 16).
  [[nodiscard]] static constexpr std::uint32_t leafCount(std::uint32_t r) { return ((r >> 27) & 15u) + 1; }
};

/// One node: the boxes (in the space of the primitives) and references of up to 8 children, and
/// for each ray octant an order of the children. Unused slots are empty references with box
/// [+inf, -inf] and follow the used ones. 256 bytes, four cache lines.
///
/// The orders let a traversal visit children front to back without sorting them per ray: a ray
/// whose direction has signs `octant` (bit a set: negative on axis a) meets the children roughly in
/// the order of their box centres along that octant's diagonal. `(order[i] >> 3 * octant) & 7` is
/// the slot at rank i, rank 0 the farthest, so that pushing ranks 0..7 on a stack leaves the nearest
/// on top. Every octant's 8 entries are a permutation of the slots (then any order is correct; this
/// one is a heuristic for speed); bits 24..31 are zero.
struct alignas(64) BvhNode8 {
  static constexpr int kWidth = 8;  ///< children per node
  /// lo[axis][child], hi[axis][child]: the child boxes, plane by plane.
  float lo[3][kWidth];
  float hi[3][kWidth];          ///< upper planes, as lo
  std::uint32_t child[kWidth];  ///< BvhRef encoding
  std::uint32_t order[kWidth];  ///< per-octant child order, 3 bits per octant (see above)

  /// The box of child slot `k`.
  [[nodiscard]] Box childBox(int k) const {
    return Box({lo[0][k], lo[1][k], lo[2][k]}, {hi[0][k], hi[1][k], hi[2][k]});
  }
  /// Sets slot `k` to `ref` with box `b` (the orders are not updated: call computeOrder()).
  void setChild(int k, std::uint32_t ref, const Box& b) {
    for (int a = 0; a < 3; ++a) {
      lo[a][k] = b.lo[a];
      hi[a][k] = b.hi[a];
    }
    child[k] = ref;
  }
  /// Number of used slots (the used slots come first).
  [[nodiscard]] int childCount() const {
    int n = 0;
    while (n < kWidth && child[n] != BvhRef::kEmpty) ++n;
    return n;
  }
  /// Sets `order` from the current child boxes: per octant, used slots by decreasing centre
  /// coordinate along the octant's diagonal (ties by slot in octants 0-3, reversed in their
  /// opposites 7-0 .. 4, which are computed as the reverse), empty slots first.
  void computeOrder();
  /// computeOrder() for a node whose `order` may still fit its boxes (a refit's, from the boxes
  /// before the move): checks it against the boxes first (linear in the slots) and sorts only
  /// when it no longer fits. The result equals computeOrder()'s whatever `order` held before.
  void updateOrder();
  /// Whether `order` is a valid encoding: per octant a permutation of the 8 slots, high bits zero.
  [[nodiscard]] bool orderValid() const;
  /// The slot at rank `rank` (0: farthest) for rays of `octant`.
  [[nodiscard]] int orderedSlot(int octant, int rank) const {
    return static_cast<int>((order[rank] >> (3 * octant)) & 7u);
  }
};
static_assert(sizeof(BvhNode8) == 256);

/// The hierarchy. Space and units are those of the primitive boxes it was built from.
struct WideBvh {
  Box bounds;  ///< bounds of every referenced primitive (empty when none)
  /// The root: inner node 0, a single leaf (few primitives), or kEmpty (no valid primitive).
  std::uint32_t root = BvhRef::kEmpty;
  std::vector<BvhNode8> nodes;  ///< depth-first, parents before children
  /// Leaf ranges: a leaf's primitives are prim_indices[leaf_block * leafBlock(r) + i] for i below
  /// leafCount(r). Each range is padded to a multiple of leaf_block with kPadding entries.
  std::vector<std::uint32_t> prim_indices;
  std::uint32_t leaf_block = 4;                           ///< see BvhBuildConfig::leaf_block
  static constexpr std::uint32_t kPadding = 0xFFFFFFFFu;  ///< a padding entry of prim_indices
  /// Inner nodes on a path from the root at most (the builder keeps within it; traversal stacks
  /// are sized by it: 7 pending children per level).
  static constexpr int kMaxDepth = 64;

  /// The SAH cost of the tree with `config`'s costs: sum over nodes of area / root area times the
  /// traversal cost, plus over leaves of area / root area times intersection_cost * blocks.
  [[nodiscard]] double sahCost(const BvhBuildConfig& config) const;
  /// Bytes of nodes and prim_indices.
  [[nodiscard]] std::size_t memoryBytes() const {
    return nodes.size() * sizeof(BvhNode8) + prim_indices.size() * sizeof(std::uint32_t);
  }
};

/// Splits a primitive at an axis-aligned plane within `box`: fills the bounds of its parts below
/// and above `pos` on `axis` (either may be empty). The spatial splits of the High preset need it;
/// without one they are off.
using BvhClipFunction =
    std::function<void(std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper)>;

/// Builds a BVH over `prim_bounds` (one box per primitive; empty or non-finite boxes are left out:
/// those primitives are never referenced). With a clip function and spatial_split_alpha > 0 a
/// primitive may be referenced by several leaves (spatial splits); otherwise by exactly one.
/// Throws InvalidArgument for an invalid config or more primitives than the encoding holds; the
/// build runs on TBB's threads and the result does not depend on their number.
[[nodiscard]] WideBvh buildWideBvh(std::span<const Box> prim_bounds, const BvhBuildConfig& config = {},
                                   const BvhClipFunction& clip = {});

/// Recomputes every node's child boxes from `prim_bounds` for the same topology (a refit: the
/// primitives moved, the tree did not change), and `bvh.bounds`. Every referenced primitive's box
/// must be non-empty; the SAH quality decays as the primitives move away from the built layout.
void refitWideBvh(WideBvh& bvh, std::span<const Box> prim_bounds);

namespace detail {
/// Runs fn(context, i) for i in [0, count), in parallel on TBB's threads (refit's top levels).
void bvhParallelFor(int count, void* context, void (*fn)(void* context, int i));
}  // namespace detail

/// The refit pass itself: fills `nodes` (as many as from.nodes; every field is overwritten, so
/// their old content does not matter, and `nodes` may be from.nodes itself) with `from`'s topology,
/// each child box from `leaf_box(ref)` for a leaf reference `ref` (a callable inlined into the
/// pass, called once per leaf) or from the refitted child node, and the orders those of
/// computeOrder() for the new boxes (through updateOrder(), from `from`'s orders). Returns the new bounds
/// (leaf_box(from.root) for a leaf root, empty for an empty one). The subtrees below the root's children are refitted
/// in parallel (TBB), so leaf_box may run on several threads at once; the result does not depend on the thread count.
template <class LeafBox>
Box refitWideBvhNodes(const WideBvh& from, std::span<BvhNode8> nodes, const LeafBox& leaf_box) {
  struct Refit {
    const WideBvh& from;
    std::span<BvhNode8> nodes;
    const LeafBox& leaf_box;
    // Node n's children first, then its own slots and orders; returns its box.
    Box node(std::uint32_t n, int depth) const {
      BvhNode8& node = nodes[n];
      std::uint32_t child[BvhNode8::kWidth];
      std::copy(std::begin(from.nodes[n].child), std::end(from.nodes[n].child), child);
      if (&node != &from.nodes[n])
        std::copy(std::begin(from.nodes[n].order), std::end(from.nodes[n].order), node.order);
      Box child_box[BvhNode8::kWidth];
      auto one = [&](int k) {
        const std::uint32_t c = child[k];
        if (c != BvhRef::kEmpty) child_box[k] = BvhRef::isLeaf(c) ? leaf_box(c) : this->node(c, depth + 1);
      };
      if (depth < 2) {
        struct Context {
          decltype(one)* f;
        } context{&one};
        detail::bvhParallelFor(BvhNode8::kWidth, &context, [](void* c, int k) { (*static_cast<Context*>(c)->f)(k); });
      } else {
        for (int k = 0; k < BvhNode8::kWidth; ++k) one(k);
      }
      Box all;
      for (int k = 0; k < BvhNode8::kWidth; ++k) {
        node.setChild(k, child[k], child_box[k]);  // empty slots keep [+inf, -inf]
        all.extend(child_box[k]);
      }
      node.updateOrder();  // smooth motion seldom changes an order
      return all;
    }
  };
  if (from.root == BvhRef::kEmpty) return Box();
  if (BvhRef::isLeaf(from.root)) return leaf_box(from.root);
  return Refit{from, nodes, leaf_box}.node(from.root, 0);
}

/// refitWideBvh with each referenced primitive's box from `prim_box(prim)` (a callable inlined
/// into the pass, so that no array of boxes is needed), in place; see refitWideBvhNodes.
template <class PrimBox>
void refitWideBvhWith(WideBvh& bvh, const PrimBox& prim_box) {
  bvh.bounds = refitWideBvhNodes(bvh, bvh.nodes, [&](std::uint32_t ref) {
    Box b;
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    for (std::uint32_t i = 0; i < BvhRef::leafCount(ref); ++i) b.extend(prim_box(bvh.prim_indices[first + i]));
    return b;
  });
}

}  // namespace duplex
