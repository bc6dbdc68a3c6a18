// Local rebuilds of an incremental instance tree (called by InstanceTree::commit, see InstanceTree.cpp).
//
// - A leaf that grew is re-split by a small SAH build over its references clipped to its cell,
//   rooted at the cell (so empty space between the cell and its content is cut off where it pays);
//   the subtree is appended to the node array and the leaf becomes a jump node to it.
// - A jump subtree (an earlier local build) of at most kMaxJumpRebuild references that lost a
//   quarter of its references since it was built is rebuilt over its current ones: a local build
//   is optimal only for the boxes it was built over, and left alone it keeps the planes of boxes
//   that are gone (an added then removed instance leaves a subtree of empty leaves behind). Its
//   old nodes become garbage.
// - Frontier subtrees of the last full build are rebuilt once edits changed 5% of their
//   references, one per commit as the edits pay for it (rebuildEditedFrontiers).
// - Compaction rewrites the tree depth first without garbage, jumps flattened: the layout of a
//   fresh build, at O(nodes + references), when garbage outweighs a quarter of the nodes or half
//   of the references.

#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/InstanceTree.h"

#include <algorithm>
#include <span>
#include <tuple>
#include <cmath>
#include <vector>

#include "InstanceTreeState.h"

namespace duplex {

using namespace toplevel_detail;

namespace {

// Jump subtrees up to this many references are rebuilt when their references change; a local
// build over them costs a few microseconds.
constexpr std::size_t kMaxJumpRebuild = 64;

// Frontier subtrees (InstanceTreeState.h) hold at most max(kMinFrontierRefs, references /
// kFrontiersPerTree) references.
constexpr std::uint32_t kMinFrontierRefs = 1024;  // smaller frontiers: no better tree, more commits with a rebuild
constexpr std::uint32_t kFrontiersPerTree = 64;
// A frontier is due for a rebuild when the references added to or removed from it since its last
// build exceed this share of its references (plus 4). Larger shares let a frontier drift further
// from a fresh build before it comes due (docs/design/two-level.md, "The incremental top level").
constexpr double kFrontierEditShare = 0.05;
// References of rebuild work each reference edit pays for (see rebuildEditedFrontiers); less
// credit leaves frontiers waiting longer, and the tree's cost drifts up.
constexpr double kCreditPerEdit = 16.0;
// Frontier rebuilds run in commits that edit at most this share of the instances (at least one).
constexpr double kFrontierBatchShare = 1.0 / 256.0;

double boxArea(const Box& b) { return static_cast<double>(b.area()); }

// What a subtree holds: its distinct slots, its nodes, its SAH cost in area units (the sum of
// cell area times node cost, not yet divided by the root's area), and the jump nodes inside it.
struct SubtreeScan {
  std::vector<std::uint32_t> slots;
  std::size_t nodes = 0, refs = 0;
  double area_cost = 0.0;
  std::vector<std::uint32_t> jumps;
  bool complete = true;
};

// Stops early (with `complete` false) once more than `max_refs` references were seen.
SubtreeScan scanSubtree(const KdTree& tree, std::uint32_t root, const Box& cell, const KdBuildConfig& cfg,
                        std::size_t max_refs = static_cast<std::size_t>(-1)) {
  SubtreeScan out;
  std::vector<std::pair<std::uint32_t, Box>> stack{{root, cell}};
  while (!stack.empty()) {
    if (out.refs > max_refs) {
      out.complete = false;
      return out;
    }
    auto [i, box] = stack.back();
    stack.pop_back();
    const KdNode n = tree.nodes[i];
    ++out.nodes;
    if (n.isJump()) {
      out.jumps.push_back(i);
      stack.emplace_back(n.jumpTarget(), box);
      continue;
    }
    if (n.isLeaf()) {
      out.area_cost += boxArea(box) * cfg.intersection_cost * n.primCount();
      out.refs += n.primCount();
      for (std::uint32_t k = 0; k < n.primCount(); ++k) out.slots.push_back(tree.prim_indices[n.primOffset() + k]);
      continue;
    }
    out.area_cost += boxArea(box) * cfg.traversal_cost;
    const auto [lower, upper] = childCells(n, box);
    stack.emplace_back(n.upperChild(), upper);
    stack.emplace_back(i + 1, lower);
  }
  std::sort(out.slots.begin(), out.slots.end());
  out.slots.erase(std::unique(out.slots.begin(), out.slots.end()), out.slots.end());
  return out;
}

// A cell on the root's boundary grew with the root since the visit that found it.
void growWithRoot(Box& cell, const Box& root_then, const Box& root_now) {
  for (int a = 0; a < 3; ++a) {
    if (cell.lo[a] <= root_then.lo[a]) cell.lo[a] = root_now.lo[a];
    if (cell.hi[a] >= root_then.hi[a]) cell.hi[a] = root_now.hi[a];
  }
}

// A local SAH build over `clipped` (boxes inside `cell`) rooted at `cell`, at `depth` inner nodes
// below the root; an empty tree when the traversal stack leaves no room.
KdTree localBuild(const KdBuildConfig& build, std::span<const Box> clipped, const Box& cell, std::uint32_t depth) {
  const int depth_left = kKdStackSize - 4 - static_cast<int>(depth);
  if (depth_left < 2 || clipped.empty()) return {};
  KdBuildConfig cfg = build;
  cfg.parallel_threshold = 0;  // a handful of boxes: task overhead would dominate
  const int auto_depth = 8 + static_cast<int>(1.3 * std::log2(static_cast<double>(clipped.size())));
  cfg.max_depth = std::min(cfg.max_depth > 0 ? cfg.max_depth : auto_depth, depth_left);
  return buildKdTreeOverBoxes(clipped, cfg, cell);
}

// Appends `sub` (its child and leaf offsets shifted; its indices mapped through `slots`) to `tree`;
// returns the index of its root.
std::uint32_t appendSubtree(KdTree& tree, const KdTree& sub, const std::vector<std::uint32_t>& slots) {
  const auto node_base = static_cast<std::uint32_t>(tree.nodes.size());
  const auto prim_base = static_cast<std::uint32_t>(tree.prim_indices.size());
  for (KdNode m : sub.nodes) {
    if (m.isLeaf()) m = KdNode::leaf(m.primCount() ? m.primOffset() + prim_base : 0, m.primCount());
    else m.setUpperChild(m.upperChild() + node_base);
    tree.nodes.push_back(m);
  }
  for (const std::uint32_t p : sub.prim_indices) tree.prim_indices.push_back(slots[p]);
  return node_base;
}

// Whether the boxes `clipped` (with bounds `content`) are worth splitting in `cell`: more than
// `leaf_size` of them, or much empty space around them.
bool worthSplitting(std::size_t count, const Box& content, const Box& cell, std::uint32_t leaf_size) {
  return count > leaf_size || boxArea(content) < 0.5 * boxArea(cell);
}

// Replaces the subtree at `node` (its cell `cell`, `depth` inner nodes above it; `old` its scan) by
// a local build over its references' boxes clipped to the cell: `node` becomes a jump to the new
// subtree, or a leaf when no split pays. The old subtree's other nodes and references become
// garbage. Returns the new subtree's cost in area units; `new_refs` its references.
double rebuildInPlace(KdTree& tree, std::uint32_t node, const Box& cell, std::uint32_t depth, const SubtreeScan& old,
                      std::span<const Box> boxes, const TopLevelConfig& config, std::uint32_t& new_refs) {
  std::vector<Box> clipped;
  std::vector<std::uint32_t> slots;
  Box content;
  for (const std::uint32_t slot : old.slots) {
    const Box c = intersection(boxes[slot], cell);
    if (c.empty()) continue;
    clipped.push_back(c);
    slots.push_back(slot);
    content.extend(c);
  }
  KdTree sub;
  if (worthSplitting(clipped.size(), content, cell, config.leaf_split_size))
    sub = localBuild(config.build, clipped, cell, depth);
  if (sub.nodes.size() > 1) {
    tree.nodes[node] = KdNode::jump(appendSubtree(tree, sub, slots));
    new_refs = static_cast<std::uint32_t>(sub.prim_indices.size());
    return sub.stats(config.build.traversal_cost, config.build.intersection_cost).sah_cost * boxArea(cell);
  }
  const auto off = static_cast<std::uint32_t>(tree.prim_indices.size());
  tree.prim_indices.insert(tree.prim_indices.end(), slots.begin(), slots.end());
  tree.nodes[node] = KdNode::leaf(slots.empty() ? 0 : off, static_cast<std::uint32_t>(slots.size()));
  new_refs = static_cast<std::uint32_t>(slots.size());
  return boxArea(cell) * config.build.intersection_cost * static_cast<double>(slots.size());
}

// Sorts visits by `key` and keeps one per value.
void uniqueBy(std::vector<LeafVisit>& visits, std::uint32_t LeafVisit::*key) {
  std::sort(visits.begin(), visits.end(), [&](const LeafVisit& a, const LeafVisit& b) { return a.*key < b.*key; });
  const auto same = [&](const LeafVisit& a, const LeafVisit& b) { return a.*key == b.*key; };
  visits.erase(std::unique(visits.begin(), visits.end(), same), visits.end());
}

// Whether the visit's leaf lies in a frontier subtree that was rebuilt (and is garbage now).
bool inRebuilt(const LeafVisit& v, const std::vector<std::uint32_t>& rebuilt_frontiers) {
  return v.frontier != kNoJump &&
         std::find(rebuilt_frontiers.begin(), rebuilt_frontiers.end(), v.frontier) != rebuilt_frontiers.end();
}

}  // namespace

void InstanceTree::State::markFrontiers(const KdTree& tree) {
  frontiers.clear();
  frontier_of.assign(tree.nodes.size(), kNoJump);
  touched_frontiers.clear();
  if (tree.nodes.empty()) return;
  // References per subtree: children follow their parent in a fresh build, so one backward pass.
  std::vector<std::uint32_t> refs(tree.nodes.size(), 0);
  for (std::size_t i = tree.nodes.size(); i-- > 0;) {
    const KdNode& n = tree.nodes[i];
    refs[i] = n.isLeaf() ? n.primCount() : refs[i + 1] + refs[n.upperChild()];
  }
  // At most an eighth of the tree: a small tree has no frontiers (a full rebuild costs microseconds,
  // and the SAH check in InstanceTree.cpp orders it).
  const auto total = static_cast<std::uint32_t>(tree.prim_indices.size());
  const std::uint32_t max_refs = std::min(std::max(kMinFrontierRefs, total / kFrontiersPerTree), total / 8);
  std::vector<std::tuple<std::uint32_t, Box, std::uint32_t>> stack{{0u, tree.bounds, 0u}};
  while (!stack.empty()) {
    const auto [i, cell, depth] = stack.back();
    stack.pop_back();
    const KdNode& n = tree.nodes[i];
    if (refs[i] <= max_refs || n.isLeaf()) {
      if (i != 0) {  // never the whole tree
        frontier_of[i] = static_cast<std::uint32_t>(frontiers.size());
        frontiers.push_back({i, cell, tree.bounds, depth, refs[i], 0});
      }
      continue;
    }
    Box lower = cell, upper = cell;
    lower.hi[n.axis()] = n.split();
    upper.lo[n.axis()] = n.split();
    stack.emplace_back(n.upperChild(), upper, depth + 1);
    stack.emplace_back(i + 1, lower, depth + 1);
  }
}

std::vector<std::uint32_t> InstanceTree::State::rebuildEditedFrontiers(InstanceTree& top) {
  KdTree& tree = top.tree_;
  const TopLevelConfig& config = top.config_;
  std::vector<std::uint32_t> rebuilt;
  const double root_area = std::max(1e-30, boxArea(tree.bounds));
  // Credit: every reference edit earns kCreditPerEdit references of rebuild work, so that the
  // upkeep stays proportional to the edits (on paper-3, a frontier of ~2,400 references every ~11
  // commits of one moved instance); at most one frontier per commit.
  frontier_credit += kCreditPerEdit * static_cast<double>(touched_frontiers.size());
  std::sort(touched_frontiers.begin(), touched_frontiers.end());
  touched_frontiers.erase(std::unique(touched_frontiers.begin(), touched_frontiers.end()), touched_frontiers.end());
  // The most edited frontier (relative to its size) over the threshold.
  std::uint32_t pick = kNoJump;
  double pick_share = 0.0;
  for (const std::uint32_t fi : touched_frontiers) {
    const Frontier& f = frontiers[fi];
    const double share = static_cast<double>(f.edits) / (static_cast<double>(f.refs) + 1.0);
    if (static_cast<double>(f.edits) > kFrontierEditShare * static_cast<double>(f.refs) + 4.0 && share > pick_share)
      pick = fi, pick_share = share;
  }
  std::size_t max_refs = 0;
  for (const std::uint32_t fi : touched_frontiers) max_refs = std::max<std::size_t>(max_refs, frontiers[fi].refs);
  frontier_credit =
      std::min(frontier_credit, 2.0 * static_cast<double>(std::max<std::size_t>(max_refs, kMinFrontierRefs)));
  touched_frontiers.clear();
  if (pick != kNoJump && frontier_credit >= static_cast<double>(frontiers[pick].refs))
    touched_frontiers.push_back(pick);
  // Large batches drift the tree faster than one frontier per commit repairs; their quality is left
  // to the SAH check and full rebuilds (InstanceTree.cpp), and their commits stay as cheap as before.
  if (static_cast<double>(last_edits) >
      std::max(1.0, kFrontierBatchShare * static_cast<double>(boxes.size() - free_slots.size())))
    touched_frontiers.clear();
  for (const std::uint32_t fi : touched_frontiers) {
    Frontier& f = frontiers[fi];
    frontier_credit -= static_cast<double>(f.refs);
    growWithRoot(f.cell, f.root, tree.bounds);
    f.root = tree.bounds;
    const SubtreeScan old = scanSubtree(tree, f.node, f.cell, config.build);
    const double new_area_cost = rebuildInPlace(tree, f.node, f.cell, f.depth, old, boxes, config, f.refs);
    // The frontier node itself stays (as the jump or leaf); the rest of its old subtree is garbage.
    garbage += old.refs;
    garbage_nodes += old.nodes - 1;
    sah_cost += (new_area_cost - old.area_cost) / root_area;
    cost_stale = true;
    ++subtree_rebuilds;
    f.edits = 0;
    rebuilt.push_back(fi);
  }
  touched_frontiers.clear();  // frontiers below the threshold keep their counts
  return rebuilt;
}

std::vector<std::uint32_t> InstanceTree::State::rebuildTouchedJumps(
    InstanceTree& top, const std::vector<std::uint32_t>& rebuilt_frontiers) {
  KdTree& tree = top.tree_;
  const TopLevelConfig& config = top.config_;
  std::vector<std::uint32_t> gone;
  if (touched_jumps.empty()) return gone;
  for (const LeafVisit& v : touched_jumps) ++jump_losses[v.jump];
  uniqueBy(touched_jumps, &LeafVisit::jump);
  const double root_area = std::max(1e-30, boxArea(tree.bounds));
  for (LeafVisit& v : touched_jumps) {
    if (std::find(gone.begin(), gone.end(), v.jump) != gone.end() || inRebuilt(v, rebuilt_frontiers)) continue;
    Box cell = v.jump_cell;
    growWithRoot(cell, v.root, tree.bounds);
    // Rebuilt once it lost a quarter of its references (a rebuild at every loss would put a local
    // build into most commits of scenes with many jumps).
    // A frontier that a frontier rebuild turned into a jump is left to the frontier rules.
    if (v.jump < frontier_of.size() && frontier_of[v.jump] != kNoJump) continue;
    // The jump and its subtree (a subtree that holds more than 4 references per allowed instance is
    // too large: the scan stops).
    const SubtreeScan old = scanSubtree(tree, v.jump, cell, config.build, 4 * kMaxJumpRebuild);
    if (!old.complete || old.slots.size() > kMaxJumpRebuild || 4 * jump_losses[v.jump] < old.refs) continue;
    jump_losses.erase(v.jump);
    std::uint32_t new_refs = 0;
    const double new_area_cost = rebuildInPlace(tree, v.jump, cell, v.jump_depth, old, boxes, config, new_refs);
    garbage += old.refs;
    garbage_nodes += old.nodes - 1;  // the jump node stays (as a jump or a leaf)
    sah_cost += (new_area_cost - old.area_cost) / root_area;
    cost_stale = true;
    ++subtree_rebuilds;
    gone.push_back(v.jump);
    gone.insert(gone.end(), old.jumps.begin(), old.jumps.end());
  }
  return gone;
}

bool InstanceTree::State::refineLeaves(InstanceTree& top, std::vector<LeafVisit>& grown_leaves) {
  KdTree& tree = top.tree_;
  const TopLevelConfig& config = top.config_;
  const std::vector<std::uint32_t> rebuilt = rebuildEditedFrontiers(top);
  const std::vector<std::uint32_t> gone = rebuildTouchedJumps(top, rebuilt);
  bool changed = !gone.empty() || !rebuilt.empty();
  if (grown_leaves.empty()) return changed;
  uniqueBy(grown_leaves, &LeafVisit::node);
  const double root_area = std::max(1e-30, boxArea(tree.bounds));
  std::vector<Box> clipped;
  std::vector<std::uint32_t> slots;
  for (LeafVisit& v : grown_leaves) {
    // A leaf of a rebuilt jump subtree is garbage now (the rebuild took its references).
    if ((v.jump != kNoJump && std::find(gone.begin(), gone.end(), v.jump) != gone.end()) || inRebuilt(v, rebuilt))
      continue;
    const KdNode n = tree.nodes[v.node];
    const std::uint32_t cnt = n.primCount();
    if (cnt < 2) continue;
    growWithRoot(v.cell, v.root, tree.bounds);
    clipped.clear();
    slots.clear();
    Box content;
    for (std::uint32_t i = 0; i < cnt; ++i) {
      const std::uint32_t slot = tree.prim_indices[n.primOffset() + i];
      const Box c = intersection(boxes[slot], v.cell);
      clipped.push_back(c);
      slots.push_back(slot);
      content.extend(c);
    }
    // Worth a local build: an overflowing leaf, or one whose references cover much less than its
    // cell (empty space an SAH split would cut off).
    if (!worthSplitting(cnt, content, v.cell, config.leaf_split_size)) continue;
    const KdTree sub = localBuild(config.build, clipped, v.cell, v.depth);
    if (sub.nodes.size() <= 1) continue;
    tree.nodes[v.node] = KdNode::jump(appendSubtree(tree, sub, slots));
    garbage += cnt;
    // The tracked cost: the leaf's term out, the subtree's (rooted at the cell) in.
    const double sub_cost = sub.stats(config.build.traversal_cost, config.build.intersection_cost).sah_cost;
    sah_cost += (sub_cost - config.build.intersection_cost * static_cast<double>(cnt)) * boxArea(v.cell) / root_area;
    cost_stale = true;
    ++subtree_rebuilds;
    changed = true;
  }
  return changed;
}

void InstanceTree::compact() {
  state_->wide_full = true;  // the kd nodes are renumbered: derive the wide form afresh
  State& s = *state_;
  const KdTree& in = tree_;
  if (in.nodes.empty()) return;
  KdTree out;
  out.bounds = in.bounds;
  out.nodes.reserve(in.nodes.size() - std::min(in.nodes.size(), s.garbage_nodes));
  out.prim_indices.reserve(in.prim_indices.size() - std::min(in.prim_indices.size(), s.garbage));
  // Depth first from the root (depth <= kKdStackSize: recursion is fine), jumps followed in place.
  auto emit = [&](auto&& self, std::uint32_t i) -> void {
    if (i < s.frontier_of.size() && s.frontier_of[i] != kNoJump)
      s.frontiers[s.frontier_of[i]].node = static_cast<std::uint32_t>(out.nodes.size());
    while (in.nodes[i].isJump()) i = in.nodes[i].jumpTarget();
    const KdNode n = in.nodes[i];
    if (n.isLeaf()) {
      const auto off = static_cast<std::uint32_t>(out.prim_indices.size());
      out.prim_indices.insert(out.prim_indices.end(), in.prim_indices.begin() + n.primOffset(),
                              in.prim_indices.begin() + n.primOffset() + n.primCount());
      out.nodes.push_back(KdNode::leaf(n.primCount() ? off : 0, n.primCount()));
      return;
    }
    const std::size_t at = out.nodes.size();
    out.nodes.push_back(n);
    self(self, i + 1);
    out.nodes[at].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
    self(self, n.upperChild());
  };
  emit(emit, 0);
  tree_ = std::move(out);
  s.jump_losses.clear();  // no jumps left
  s.frontier_of.assign(tree_.nodes.size(), kNoJump);
  for (std::size_t f = 0; f < s.frontiers.size(); ++f)
    s.frontier_of[s.frontiers[f].node] = static_cast<std::uint32_t>(f);
  s.garbage = 0;
  s.garbage_nodes = 0;
}

}  // namespace duplex
