#pragma once
// Private to accel/src: the 8-wide traversal form of a blocking instance tree, derived from its
// kd-tree after every build and commit.
//
// The kd-tree stays the structure that edits update (locally, without a rebuild). Walking it costs
// a split-plane step per inner node with a data-dependent branch, and its cells are far larger than
// what they hold. The wide form re-groups the same tree: each node holds up to 8 children, each
// with a tight box (the instance boxes below it, each clipped to its kd leaf's cell), tested 8 at a
// time; children are either nodes or single instance references. An instance is still referenced
// by every leaf its box overlaps, but each reference's box is clipped to its leaf's cell, so that
// a ray meets only the references whose part of the box it crosses.
//
// Why clipping is safe: a hit point p of instance i lies in i's world box and in the cell of some
// leaf; every leaf whose cell overlaps i's box references i, so p lies in that reference's clipped
// box, and a ray through p meets it at an entry no later than p's distance.
//
// A commit derives again only what lies on the paths of its edits (WideTop::refresh).

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTree.h"

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace duplex::toplevel_detail {

// A node of 8 children: their boxes as rows of 8 floats (the near and far planes of an axis are
// picked per ray by the direction's sign), and what each child is.
struct alignas(64) WideNode {
  // bounds[2 * axis + 0]: lower planes, bounds[2 * axis + 1]: upper planes, per child.
  float bounds[6][8];
  // kRef | slot: an instance reference; otherwise the index of a child node. Unused children
  // hold kNone and a box no ray meets (see valid).
  std::uint32_t child[8];
  std::uint32_t valid = 0;  // bit c: child c is used
};

inline constexpr std::uint32_t kWideRef = 0x80000000u;
inline constexpr std::uint32_t kWideNone = 0xFFFFFFFFu;

struct WideTop {
  std::vector<WideNode> nodes;     // reachable from `root`, with garbage between them
  std::uint32_t root = kWideNone;  // the root node
  bool usable = false;             // false: walk the kd-tree instead (no tree, or too deep a form)

  // Derives the form afresh from `tree`, whose references index `boxes` (world boxes by slot).
  void build(const KdTree& tree, const std::vector<Box>& boxes);
  // After an incremental commit of `tree` whose edits changed the references of the leaves meeting
  // the world boxes `edited` (the old and new boxes of moved, added and removed instances):
  // derives again what lies on their paths and keeps the rest. The kd nodes must have kept their
  // indices since the last derivation (new nodes appended): after a compaction, call build().
  void refresh(const KdTree& tree, const std::vector<Box>& boxes, const std::vector<Box>& edited);

  // Nodes reachable from the root, and nodes no walk reaches (replaced by refreshes).
  [[nodiscard]] std::size_t liveNodes() const { return live_; }
  [[nodiscard]] std::size_t garbage() const { return nodes.size() - live_; }  // free slots included
  // Bytes held: the nodes and what is kept per kd node (capacities).
  [[nodiscard]] std::size_t bytes() const {
    return nodes.capacity() * sizeof(WideNode) + cache_.capacity() * sizeof(Cached) +
           refs_.capacity() * sizeof(refs_[0]);
  }

 private:
  struct Item;
  struct Deriver;
  // What a derivation leaves for the next one, by kd node: valid until an edit's box meets the
  // node's cell (the node's references, or those below it, may have changed).
  struct Cached {
    Box tight;                       // the tight box of the node's subtree
    std::uint32_t wide = kWideNone;  // the wide node derived for the subtree, if any
    std::uint32_t wide_nodes = 0;    // wide nodes under it (itself included)
    std::uint16_t wide_depth = 0;    // wide levels under it (itself included)
    bool tight_ok = false;
  };
  void derive(const KdTree& tree, const std::vector<Box>& boxes);

  std::vector<Cached> cache_;        // by kd node
  std::vector<std::uint32_t> free_;  // node slots a refresh freed, reused by its derivation
  std::size_t live_ = 0;
  std::vector<std::pair<std::uint32_t, Box>> refs_;  // scratch: clipped references of opened leaves
};

// Maximal depth of a wide form (a deeper one is left unusable) and the stack a walk needs for it:
// each node on the path keeps at most 7 entries waiting.
inline constexpr int kWideMaxDepth = kKdStackSize + 32;
inline constexpr int kWideStackSize = 7 * kWideMaxDepth;

}  // namespace duplex::toplevel_detail
