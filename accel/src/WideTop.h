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
  // derives again the wide nodes that opened those leaves (or nodes rebuilt since), refits the
  // boxes on their paths and keeps the rest. The kd nodes must have kept their
  // indices since the last derivation (new nodes appended): after a compaction, call build().
  void refresh(const KdTree& tree, const std::vector<Box>& boxes, const std::vector<Box>& edited);

  // Nodes reachable from the root, and nodes no walk reaches (replaced by refreshes).
  [[nodiscard]] std::size_t liveNodes() const { return live_; }
  [[nodiscard]] std::size_t garbage() const { return nodes.size() - live_; }  // free slots included
  // Bytes held: the nodes and what is kept per kd node (capacities).
  [[nodiscard]] std::size_t bytes() const {
    return nodes.capacity() * sizeof(WideNode) + cache_.capacity() * sizeof(Cached) +
           refs_.capacity() * sizeof(refs_[0]) + side_.capacity() * sizeof(Side);
  }

 private:
  struct Item;
  struct Deriver;
  // What a derivation leaves for the next one, by kd node. The tight box and the wide node of a
  // subtree hold until an edit's box meets the node's cell (`touched`); what a wide node opened
  // (owner, word) tells a refresh whether that node can keep its children and only refit their
  // boxes.
  struct Cached {
    Box tight;                            // the tight box of the node's subtree
    Box cell;                             // touched nodes: the cell, as of this refresh
    KdNode word;                          // the node as the wide node `owner` opened it
    std::uint32_t wide = kWideNone;       // the wide node derived for the subtree, if any
    std::uint32_t owner = kWideNone;      // the wide node that opened this node, if any
    std::uint32_t owner_gen = 0;          // Side::gen of `owner` then (a slot reused since is not it)
    std::uint32_t last_wide = kWideNone;  // the wide node a refresh forgot for the subtree, and
    std::uint32_t last_gen = 0;           // its Side::gen: derived again along the same lines
    std::uint32_t wide_nodes = 0;         // wide nodes under it (itself included)
    std::uint16_t wide_depth = 0;         // wide levels under it (itself included)
    bool tight_ok = false;
    bool touched = false;  // its cell met an edited box since the last derivation
    bool dropped = false;  // `owner` left it out as empty (an edit that fills it changes `owner`)
  };
  // Per wide node: what its children are made of, so that a refresh can refit it in place.
  struct Side {
    std::uint32_t kd[8];                // a subtree child: its kd node; else kSideRef or kSideRefs
    std::uint32_t kd_root = kWideNone;  // the kd node whose subtree it was derived for, if any
    std::uint32_t own_nodes = 1;        // itself and its reference-group nodes
    std::uint16_t own_depth = 1;        // levels of itself and its reference-group nodes
    std::uint32_t gen = 0;              // counts the slot's uses
  };
  static constexpr std::uint32_t kSideRef = 0xFFFFFFFFu;   // an instance reference (or unused)
  static constexpr std::uint32_t kSideRefs = 0xFFFFFFFEu;  // a node of references of opened leaves
  void forget(std::uint32_t wide);                         // returns a node and its reference-group nodes to free_
  void derive(const KdTree& tree, const std::vector<Box>& boxes);

  std::vector<Cached> cache_;           // by kd node
  std::vector<Side> side_;              // by wide node
  std::vector<std::uint32_t> free_;     // node slots a refresh freed, reused by its derivation
  std::vector<std::uint32_t> touched_;  // scratch: the kd nodes a refresh marked
  std::size_t live_ = 0;
  std::vector<std::pair<std::uint32_t, Box>> refs_;  // scratch: clipped references of opened leaves
};

// Maximal depth of a wide form (a deeper one is left unusable) and the stack a walk needs for it:
// each node on the path keeps at most 7 entries waiting.
inline constexpr int kWideMaxDepth = kKdStackSize + 32;
inline constexpr int kWideStackSize = 7 * kWideMaxDepth;

}  // namespace duplex::toplevel_detail
