// WideTop: the 8-wide traversal form of an instance kd-tree (WideTop.h), derived and refreshed.
//
// A derivation has two steps. The first computes, bottom-up, each kd node's tight box: the union
// of the boxes of the references below it, each clipped to its leaf's cell. The second groups the
// tree into wide nodes top-down: starting from a kd subtree, it repeatedly opens the candidate of
// largest area (an inner kd node into its two children, a leaf into its references) while the node
// has room for the result, so that large boxes are split and small ones stay whole. Leaves of more
// than 8 references are halved at the median along their widest axis before they are opened.
//
// Refreshes: what a derivation computes per kd node (the tight box, the wide node of a subtree,
// which wide node opened it) is kept by node index. A commit's edits change the references of the
// leaves their boxes meet and the tight boxes of those leaves' ancestors (the nodes whose cells
// meet an edited box). A wide node that opened such a leaf, or a node rebuilt in place since, is
// derived afresh; one that only holds such an ancestor as a subtree child keeps its children and
// gets that child's new box (a refit: its grouping was chosen for the old boxes, which the
// trace-after-many-commits figure watches). Nodes appended since (local rebuilds) have nothing
// kept. Cells of kept subtrees may have moved with the root since: a kept box is still a valid
// cover, because every box below lay inside the old root.

#include "WideTop.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <limits>
#include <utility>

namespace duplex::toplevel_detail {

// A candidate child of a wide node under construction (plain data: derivations allocate nothing
// per node but the output).
struct WideTop::Item {
  enum Kind : std::uint8_t { Kd, Refs, Ref } kind;
  std::uint32_t index = 0;           // Kd: the kd node (jumps resolved); Ref: the slot
  std::uint32_t begin = 0, end = 0;  // Refs: the range of refs_
  Box cell;                          // Kd: its cell
  Box box;                           // the tight box
};

struct WideTop::Deriver {
  WideTop& top;
  const KdTree& tree;
  const std::vector<Box>& boxes;
  int max_depth = 0;

  // The tight box of kd node `index` with cell `cell` (jumps stand for their target's subtree).
  Box tight(std::uint32_t index, const Box& cell) {
    Cached& c = top.cache_[index];
    if (c.tight_ok) return c.tight;
    const KdNode& n = tree.nodes[index];
    Box b;
    if (n.isJump()) {
      b = tight(n.jumpTarget(), cell);
    } else if (n.isLeaf()) {
      for (std::uint32_t k = 0; k < n.primCount(); ++k) {
        const Box clipped = intersection(boxes[tree.prim_indices[n.primOffset() + k]], cell);
        if (!clipped.empty()) b.extend(clipped);
      }
    } else {
      const auto [lower, upper] = childCells(n, cell);
      b = tight(index + 1, lower);
      b.extend(tight(n.upperChild(), upper));
    }
    Cached& out = top.cache_[index];  // (the recursion does not resize the cache)
    out.tight = b;
    out.tight_ok = true;
    return b;
  }

  Item kdItem(std::uint32_t index, const Box& cell) const {
    while (tree.nodes[index].isJump()) index = tree.nodes[index].jumpTarget();
    return Item{Item::Kd, index, 0, 0, cell, top.cache_[index].tight};
  }

  // How many items opening `it` gives at most (0: it cannot be opened).
  std::size_t openedCount(const Item& it) const {
    switch (it.kind) {
      case Item::Ref: return 0;
      case Item::Refs: return it.end - it.begin > 8 ? 2 : it.end - it.begin;
      case Item::Kd: break;
    }
    const KdNode& n = tree.nodes[it.index];
    if (!n.isLeaf()) return 2;  // an empty child is dropped when opened
    return n.primCount() > 8 ? 2 : n.primCount();
  }

  // Records kd node `index` as opened (or dropped as empty) by wide node `owner`: an edit that
  // touches it makes `owner` be derived afresh. A node opened inside a wide node roots no wide
  // subtree: a wide node kept for it from an earlier grouping is unreachable, and would be out of
  // date if a later grouping returned to it.
  void claim(std::uint32_t index, std::uint32_t owner, bool dropped) {
    if (top.cache_[index].wide != kWideNone) top.forget(top.cache_[index].wide);
    Cached& k = top.cache_[index];
    k.owner = owner;
    k.owner_gen = top.side_[owner].gen;
    k.word = tree.nodes[index];
    k.dropped = dropped;
  }

  // Appends the non-empty items `it` opens into; a kd node opened is recorded as opened by wide
  // node `owner`.
  void open(Item it, std::array<Item, 8>& items, std::size_t& count, std::uint32_t owner) {
    auto add = [&](const Item& c) {
      if (c.box.empty()) return;
      // An instance that several opened leaves reference becomes one child with the union of
      // its clipped boxes: one box test and one visit instead of several.
      if (c.kind == Item::Ref)
        for (std::size_t i = 0; i < count; ++i)
          if (items[i].kind == Item::Ref && items[i].index == c.index) {
            items[i].box.extend(c.box);
            return;
          }
      items[count++] = c;
    };
    if (it.kind == Item::Kd) {
      const KdNode& n = tree.nodes[it.index];
      claim(it.index, owner, false);
      if (!n.isLeaf()) {
        const auto [lower, upper] = childCells(n, it.cell);
        for (const auto& [child, cell] : {std::pair{it.index + 1, lower}, std::pair{n.upperChild(), upper}}) {
          // Jumps on the way to a child are this wide node's too: one that changes its target (or
          // becomes a leaf) changes what the child is.
          for (std::uint32_t j = child; tree.nodes[j].isJump(); j = tree.nodes[j].jumpTarget()) claim(j, owner, false);
          const Item c = kdItem(child, cell);
          // An empty child is dropped, but an edit that fills it changes this wide node.
          if (c.box.empty()) claim(c.index, owner, true);
          add(c);
        }
        return;
      }
      it.kind = Item::Refs;
      it.begin = static_cast<std::uint32_t>(top.refs_.size());
      for (std::uint32_t k = 0; k < n.primCount(); ++k) {
        const std::uint32_t slot = tree.prim_indices[n.primOffset() + k];
        const Box c = intersection(boxes[slot], it.cell);
        if (!c.empty()) top.refs_.emplace_back(slot, c);
      }
      it.end = static_cast<std::uint32_t>(top.refs_.size());
    }
    auto* refs = top.refs_.data();
    if (it.end - it.begin <= 8) {
      for (std::uint32_t r = it.begin; r < it.end; ++r)
        add(Item{Item::Ref, refs[r].first, 0, 0, Box{}, refs[r].second});
      return;
    }
    const glm::vec3 e = it.box.extent();
    const int axis = e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
    const std::uint32_t mid = it.begin + (it.end - it.begin) / 2;
    std::nth_element(refs + it.begin, refs + mid, refs + it.end, [axis](const auto& a, const auto& b) {
      return a.second.lo[axis] + a.second.hi[axis] < b.second.lo[axis] + b.second.hi[axis];
    });
    for (const auto& [b, e2] : {std::pair{it.begin, mid}, std::pair{mid, it.end}}) {
      Item part{Item::Refs, 0, b, e2, Box{}, Box{}};
      for (std::uint32_t r = b; r < e2; ++r) part.box.extend(refs[r].second);
      add(part);
    }
  }

  // The wide node of kd subtree `it` (kept from an earlier derivation, refitted when its cell met
  // an edit, or derived now), its node count and depth added to `nodes` and `depth`.
  std::uint32_t kdSubtree(const Item& it, std::uint32_t& nodes, int& depth) {
    const Cached& c = top.cache_[it.index];
    if (c.wide != kWideNone && c.touched && !refit(c.wide)) top.forget(c.wide);
    if (top.cache_[it.index].wide == kWideNone) {
      std::uint32_t n = 0;
      int d = 0;
      const std::uint32_t w = emit({it}, 1, n, d, it.index, c.last_wide, c.last_gen);
      Cached& out = top.cache_[it.index];
      out.wide = w;
      out.wide_nodes = n;
      out.wide_depth = static_cast<std::uint16_t>(std::min(d, 0xFFFF));
    }
    const Cached& k = top.cache_[it.index];
    nodes += k.wide_nodes;
    depth = std::max(depth, static_cast<int>(k.wide_depth));
    return k.wide;
  }

  // Keeps the children of wide node `w` (nothing it opened changed) and derives again only its
  // subtree children whose cells met an edit, refitting their boxes. False (nothing changed yet):
  // such a child's subtree is empty now, and `w` must be derived afresh.
  bool refit(std::uint32_t w) {
    // `kd[c]` stays what the child was derived from: a subtree rebuilt in place there since turned
    // it into a jump, which is followed afresh at every refit.
    std::array<Item, 8> items;
    for (int c = 0; c < 8; ++c) {
      const std::uint32_t k = top.side_[w].kd[c];
      if (k >= kSideRefs) continue;
      items[c] = kdItem(k, top.cache_[k].cell);
      if (top.cache_[k].touched && items[c].box.empty()) return false;
    }
    std::uint32_t below = 0;
    int below_depth = 0;
    for (int c = 0; c < 8; ++c) {
      const std::uint32_t k = top.side_[w].kd[c];
      if (k >= kSideRefs) continue;
      const Item& it = items[c];
      if (!top.cache_[k].touched) {
        below += top.cache_[it.index].wide_nodes;
        below_depth = std::max(below_depth, static_cast<int>(top.cache_[it.index].wide_depth));
        continue;
      }
      const std::uint32_t child = kdSubtree(it, below, below_depth);  // (may grow `nodes`)
      WideNode& node = top.nodes[w];
      setBounds(node, c, it.box);
      node.child[c] = child;
    }
    const Side& sd = top.side_[w];
    Cached& out = top.cache_[sd.kd_root];
    out.wide_nodes = sd.own_nodes + below;
    out.wide_depth = static_cast<std::uint16_t>(std::min(std::max<int>(sd.own_depth, 1 + below_depth), 0xFFFF));
    return true;
  }

  static void setBounds(WideNode& node, std::size_t c, const Box& b) {
    node.bounds[0][c] = b.lo.x;
    node.bounds[1][c] = b.hi.x;
    node.bounds[2][c] = b.lo.y;
    node.bounds[3][c] = b.hi.y;
    node.bounds[4][c] = b.lo.z;
    node.bounds[5][c] = b.hi.z;
  }

  // Writes the wide node for `items` (opened while they fit in 8) and its subtree; returns its
  // index, with the nodes written or reused under it (itself included) and its depth in levels.
  // `kd_root`: the kd node whose subtree it stands for (kWideNone: a node of references).
  // `last`, `last_gen`: the wide node this one replaces (kWideNone: none). Its grouping is
  // followed first (the kd nodes it opened are opened again), and subtrees that keep a wide node
  // stay whole: regrouping by the new boxes would derive their subtrees again, and those of their
  // children, for the same edit.
  std::uint32_t emit(std::array<Item, 8> items, std::size_t count, std::uint32_t& nodes, int& depth,
                     std::uint32_t kd_root, std::uint32_t last = kWideNone, std::uint32_t last_gen = 0) {
    // A node slot freed by the refresh (its subtree's paths were edited), else a new one.
    std::uint32_t index;
    if (!top.free_.empty()) {
      index = top.free_.back();
      top.free_.pop_back();
    } else {
      index = static_cast<std::uint32_t>(top.nodes.size());
      top.nodes.emplace_back();
      top.side_.emplace_back();
    }
    const std::uint32_t gen = ++top.side_[index].gen;
    while (true) {
      std::size_t best = count;
      float best_area = -1.0f;
      for (std::size_t i = 0; i < count; ++i) {
        const std::size_t n = openedCount(items[i]);
        if (n == 0 || count - 1 + n > 8) continue;
        float a = items[i].box.area();
        if (last != kWideNone && items[i].kind == Item::Kd) {
          const Cached& k = top.cache_[items[i].index];
          if (k.owner == last && k.owner_gen == last_gen) a = std::numeric_limits<float>::infinity();
          else if (k.wide != kWideNone) continue;
        }
        if (a > best_area) {
          best_area = a;
          best = i;
        }
      }
      if (best == count) break;
      const Item it = items[best];
      items[best] = items[--count];
      open(it, items, count, index);
    }
    WideNode node;
    Side side;
    side.kd_root = kd_root;
    side.gen = gen;
    for (std::size_t c = 0; c < 8; ++c) {
      node.child[c] = kWideNone;
      side.kd[c] = kSideRef;
      for (int row = 0; row < 6; ++row) node.bounds[row][c] = 0.0f;
    }
    node.valid = 0;
    std::uint32_t own = 1, below = 0;
    int own_depth = 1, below_depth = 0;
    for (std::size_t c = 0; c < count; ++c) {
      const Item& it = items[c];
      setBounds(node, c, it.box);
      node.valid |= 1u << c;
      if (it.kind == Item::Ref) {
        node.child[c] = kWideRef | it.index;
      } else if (it.kind == Item::Kd) {
        node.child[c] = kdSubtree(it, below, below_depth);
        side.kd[c] = it.index;
      } else {
        std::uint32_t n = 0;
        int d = 0;
        node.child[c] = emit({it}, 1, n, d, kWideNone);
        side.kd[c] = kSideRefs;
        own += n;
        own_depth = std::max(own_depth, 1 + d);
      }
    }
    side.own_nodes = own;
    side.own_depth = static_cast<std::uint16_t>(std::min(own_depth, 0xFFFF));
    top.nodes[index] = node;
    top.side_[index] = side;
    nodes += own + below;
    depth = std::max({depth, own_depth, 1 + below_depth});
    return index;
  }
};

// Returns wide node `w` and the reference-group nodes below it to the free list, and forgets it
// as its kd subtree's node.
void WideTop::forget(std::uint32_t w) {
  const Side& sd = side_[w];
  if (sd.kd_root != kWideNone) {
    Cached& c = cache_[sd.kd_root];
    c.wide = kWideNone;
    c.last_wide = w;
    c.last_gen = sd.gen;
  }
  free_.push_back(w);
  for (int c = 0; c < 8; ++c)
    if (side_[w].kd[c] == kSideRefs) {
      forget(nodes[w].child[c]);
    }
}

void WideTop::derive(const KdTree& tree, const std::vector<Box>& boxes) {
  usable = false;
  root = kWideNone;
  live_ = 0;
  if (tree.empty()) return;
  cache_.resize(tree.nodes.size());
  Deriver d{*this, tree, boxes};
  if (d.tight(0, tree.bounds).empty()) return;
  refs_.clear();
  std::uint32_t count = 0;
  int depth = 0;
  root = d.kdSubtree(d.kdItem(0, tree.bounds), count, depth);
  refs_.clear();
  live_ = count;
  usable = depth <= kWideMaxDepth;
}

void WideTop::build(const KdTree& tree, const std::vector<Box>& boxes) {
  nodes.clear();
  side_.clear();
  free_.clear();
  cache_.assign(tree.nodes.size(), Cached{});
  derive(tree, boxes);
  // A full derivation's slack (vector growth) and scratch are dropped: refreshes append little.
  nodes.shrink_to_fit();
  side_.shrink_to_fit();
  refs_ = {};
}

void WideTop::refresh(const KdTree& tree, const std::vector<Box>& boxes, const std::vector<Box>& edited) {
  if (tree.empty() || nodes.empty() || cache_.size() > tree.nodes.size()) {
    build(tree, boxes);
    return;
  }
  cache_.resize(tree.nodes.size());  // appended nodes: nothing kept
  // Mark every node whose (closed) cell meets an edited box: its tight box is recomputed, and the
  // subtree's wide node refitted. A wide node that opened a marked leaf (whose references changed)
  // or a node that changed since (a leaf or subtree rebuilt in place) is derived afresh.
  struct Entry {
    std::uint32_t node;
    Box cell;
  };
  std::vector<Entry> stack;
  touched_.clear();
  for (const Box& box : edited) {
    if (box.empty()) continue;
    stack.push_back({0, tree.bounds});
    while (!stack.empty()) {
      const Entry e = stack.back();
      stack.pop_back();
      Cached& c = cache_[e.node];
      if (!c.touched) {
        c.touched = true;
        touched_.push_back(e.node);
      }
      c.cell = e.cell;
      c.tight_ok = false;
      const KdNode& n = tree.nodes[e.node];
      // A stale owner (a slot since reused) only costs a needless derivation.
      if (c.owner != kWideNone && ((n.isLeaf() && !n.isJump()) || c.dropped ||
                                   std::bit_cast<std::uint64_t>(n) != std::bit_cast<std::uint64_t>(c.word))) {
        const std::uint32_t w = c.owner;
        c.owner = kWideNone;
        // A stale owner (its slot reused since) is not this node's: forgetting it would drop a
        // wide node that a kept parent still points to.
        const std::uint32_t root = side_[w].gen == c.owner_gen ? side_[w].kd_root : kWideNone;
        if (root != kWideNone && cache_[root].wide == w) forget(w);
      }
      if (n.isJump()) {
        stack.push_back({n.jumpTarget(), e.cell});
        continue;
      }
      if (n.isLeaf()) continue;
      const auto [lower, upper] = childCells(n, e.cell);
      const int a = n.axis();
      if (box.hi[a] >= n.split()) stack.push_back({n.upperChild(), upper});
      if (box.lo[a] <= n.split()) stack.push_back({e.node + 1, lower});
    }
  }
  derive(tree, boxes);
  for (const std::uint32_t k : touched_) cache_[k].touched = false;
  // A form that is mostly garbage is derived afresh (compacted).
  if (garbage() > 1024 && garbage() > live_) build(tree, boxes);
}

}  // namespace duplex::toplevel_detail
