// InstanceTree: a kd-tree over instance world boxes, kept up to date incrementally.
//
// Incremental update (commit): an edited instance is routed through the split planes with its old
// and new world boxes; it leaves the leaves only the old box touches and joins the leaves only the
// new box touches. A leaf that gains references is re-split by a small SAH build over its own
// references (clipped to its cell) when it overflows or when it now holds empty space worth cutting
// off; the subtree is appended to the node array and the leaf becomes a jump node to it, so no
// other node moves. Local builds are redone when their boxes change: a small jump subtree that lost
// a quarter of its references is rebuilt over the rest, and a frontier subtree of the last full
// build (max(1,024, 1/64) of the references, at most 1/8) is rebuilt once edits changed 5% of its
// references, one per commit as the edits pay for it (InstanceTreeRefine.cpp); replaced nodes are
// garbage until the tree is compacted depth first. The SAH cost of the tree is tracked per edit
// and per refinement, and made exact (with the root shrunk to its boxes) every 32 commits or
// before a rebuild decision; when it exceeds the cost of the last full build by
// TopLevelConfig::rebuild_ratio, the instance count drifted far from that build's, or the tree
// grew to 4 times its nodes or references, the whole tree is rebuilt. A leaf that grows is moved to the end of the
// index list (its old range becomes garbage, compacted when garbage outweighs live references), so an edit costs
// O(leaves touched), independent of the scene size, apart from the amortised exact recomputations.

#include "duplex/accel/InstanceTree.h"

#include "duplex/accel/Check.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/TopLevelMemory.h"

#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>

#include "InstanceTreeState.h"
#include "InstanceTreeWide.h"
#include "KdBuildRefs.h"

namespace duplex {

using namespace toplevel_detail;

namespace {

Prepared prepare(const InstanceDesc& d) {
  if (!d.object) throw InvalidArgument(describeInstance(d) + ": no object");
  if (!d.world_from_object.isFinite())
    throw InvalidArgument(describeInstance(d) + ": transform has NaN or infinite entries");
  if (d.world_from_object.isSingular()) throw InvalidArgument(describeInstance(d) + ": transform is singular");
  if (d.id == kInvalidId) throw InvalidArgument(describeInstance(d) + ": id 0xFFFFFFFF is reserved for misses");
  Prepared p;
  const glm::dmat3& l = d.world_from_object.linear;
  p.record.object = d.object.get();
  p.record.object_from_world = d.world_from_object.inverse();
  p.record.id = d.id;
  p.record.mask = d.mask;
  p.record.role = d.object->role();
  p.record.identity = l == glm::dmat3(1.0) && d.world_from_object.translation == glm::dvec3(0.0);
  p.record.entry = d.object->rayEntry();
  p.owner = d.object;
  p.box = d.world_from_object.apply(d.object->bounds());
  // A finite double transform can still carry the box beyond float range (a scale of 1e30 on an
  // object of size 1e10): the builder would drop such a box and an incremental commit would grow the
  // root to infinity, so the instance is refused here, on both paths alike.
  if (!p.box.empty() && !p.box.finite())
    throw InvalidArgument(describeInstance(d) + ": world box exceeds float range (transform too large for the object)");
  return p;
}

double boxArea(const Box& b) { return static_cast<double>(b.area()); }

// Calls f(LeafVisit) for every leaf whose closed cell meets `box` (a superset of the leaves the
// builder put the box in: touching counts on both sides of a plane).
// `frontier_of` maps node indices to frontier indices (InstanceTree::State::frontiers).
template <class F>
void forEachLeaf(const KdTree& tree, const std::vector<std::uint32_t>& frontier_of, const Box& box, F&& f) {
  if (tree.nodes.empty()) return;
  LeafVisit stack[kKdStackSize + 1];
  int top = 0;
  stack[top++] = {0, tree.bounds, 0, tree.bounds, kNoJump, {}, 0, kNoJump};
  while (top > 0) {
    LeafVisit v = stack[--top];
    if (v.node < frontier_of.size() && frontier_of[v.node] != kNoJump) v.frontier = frontier_of[v.node];
    KdNode n = tree.nodes[v.node];
    while (n.isJump()) {
      v.jump = v.node;
      v.jump_cell = v.cell;
      v.jump_depth = v.depth;
      v.node = n.jumpTarget();
      n = tree.nodes[v.node];
    }
    if (n.isLeaf()) {
      f(v);
      continue;
    }
    const int a = n.axis();
    const float s = n.split();
    // Cells are clamped to their parent: after the root shrank, a plane may lie outside it.
    if (box.hi[a] >= s) {
      LeafVisit u = v;
      u.node = n.upperChild();
      ++u.depth;
      u.cell.lo[a] = std::max(s, v.cell.lo[a]);
      stack[top++] = u;
    }
    if (box.lo[a] <= s) {
      LeafVisit l = v;
      ++l.node;
      ++l.depth;
      l.cell.hi[a] = std::min(s, v.cell.hi[a]);
      stack[top++] = l;
    }
  }
}

void validateBuild(const KdBuildConfig& b, const std::string& which) {
  auto bad = [&](const std::string& what) { throw InvalidArgument("top level configuration: " + which + what); };
  if (!(std::isfinite(b.traversal_cost) && b.traversal_cost > 0.0f)) bad("traversal_cost must be finite and positive");
  if (!(std::isfinite(b.intersection_cost) && b.intersection_cost > 0.0f))
    bad("intersection_cost must be finite and positive");
  if (!(b.empty_bonus >= 0.0f && b.empty_bonus < 1.0f)) bad("empty_bonus must be in [0, 1)");
  if (b.max_depth < 0) bad("max_depth must not be negative (0 = automatic)");
}

}  // namespace

namespace toplevel_detail {

void validateConfig(const TopLevelConfig& c) {
  auto bad = [](const std::string& what) { throw InvalidArgument("top level configuration: " + what); };
  validateBuild(c.build, "");
  validateBuild(c.crossing_build, "crossing_build.");
  if (!(c.rebuild_ratio >= 1.0)) bad("rebuild_ratio must be at least 1");
  if (!(c.max_incremental_fraction >= 0.0)) bad("max_incremental_fraction must not be negative");
  if (c.leaf_split_size < 1) bad("leaf_split_size must be at least 1");
}

}  // namespace toplevel_detail

// ---------------------------------------------------------------------------------------------
// Edits

// A crossing tree builds with the non-blocking instances' configuration (TopLevelConfig::crossing_build).
InstanceTree::InstanceTree(const TopLevelConfig& config, Kind kind) : config_(config), kind_(kind) {
  if (kind_ == Kind::Crossing) config_.build = config.crossing_build;
}

void InstanceTree::setConfig(const TopLevelConfig& config) {
  config_ = config;
  if (kind_ == Kind::Crossing) config_.build = config.crossing_build;
  // The traversal form follows at once (it depends on nothing a commit changes).
  if (kind_ == Kind::Blocking && state_ && config_.wide_traversal != state_->wide.usable && !tree_.empty()) {
    if (config_.wide_traversal) state_->wide.build(tree_, state_->boxes);
    else state_->wide = {};
  }
}

void InstanceTree::ensureState() {
  if (!state_) state_ = std::make_shared<State>();
}

void InstanceTree::build(std::span<const InstanceDesc> instances, const KdBuildConfig& build) {
  TopLevelConfig c = config_;
  c.build = build;
  validateConfig(c);
  // Validate everything before touching the current state.
  std::vector<Prepared> prepared;
  prepared.reserve(instances.size());
  std::unordered_map<std::uint32_t, std::uint32_t> slot_of_id;
  slot_of_id.reserve(instances.size());
  for (const InstanceDesc& d : instances) {
    prepared.push_back(prepare(d));
    if (!slot_of_id.emplace(d.id, static_cast<std::uint32_t>(prepared.size() - 1)).second)
      throw InvalidArgument(describeInstance(d) + ": duplicate instance id");
  }
  auto state = std::make_shared<State>();
  state->records.reserve(prepared.size());
  for (Prepared& p : prepared) {
    state->records.push_back(p.record);
    state->filters.push_back(filterOf(p.record));
    state->owners.push_back(std::move(p.owner));
    state->boxes.push_back(p.box);
  }
  state->slot_of_id = std::move(slot_of_id);
  if (state_) {
    state->commits = state_->commits;
    state->full_rebuilds = state_->full_rebuilds;
    state->subtree_rebuilds = state_->subtree_rebuilds;
  }
  // The tree first: if the build throws, nothing has changed.
  KdTree tree = buildKdTreeOverBoxes(state->boxes, c.build);
  config_ = c;
  state_ = std::move(state);
  live_count_ = prepared.size();
  install(std::move(tree));
}

void InstanceTree::set(const InstanceDesc& instance) {
  ensureState();
  Prepared p = prepare(instance);
  State& s = *state_;
  const auto it = s.pending_index.find(instance.id);
  if (it != s.pending_index.end()) {
    s.pending[it->second].second = std::move(p);
  } else {
    s.pending_index.emplace(instance.id, s.pending.size());
    s.pending.emplace_back(instance.id, std::move(p));
  }
}

void InstanceTree::remove(std::uint32_t id) {
  State& s = *state_;
  const auto it = s.pending_index.find(id);
  if (it != s.pending_index.end()) {
    s.pending[it->second].second.reset();
  } else {
    s.pending_index.emplace(id, s.pending.size());
    s.pending.emplace_back(id, std::nullopt);
  }
}

bool InstanceTree::contains(std::uint32_t id) const {
  if (!state_) return false;
  const auto it = state_->pending_index.find(id);
  if (it != state_->pending_index.end()) return state_->pending[it->second].second.has_value();
  return state_->slot_of_id.count(id) != 0;
}

// ---------------------------------------------------------------------------------------------
// Commit

void InstanceTree::install(KdTree&& tree) {
  State& s = *state_;
  tree_ = std::move(tree);
  s.garbage = 0;
  s.garbage_nodes = 0;
  s.touched_jumps.clear();
  s.jump_losses.clear();
  s.markFrontiers(tree_);
  const KdTreeStats st = tree_.stats(config_.build.traversal_cost, config_.build.intersection_cost);
  s.sah_cost = st.sah_cost;
  s.fresh_cost = st.sah_cost;
  s.fresh_count = live_count_;
  s.fresh_nodes = tree_.nodes.size();
  s.fresh_refs = tree_.prim_indices.size();
  s.cost_stale = false;
  s.boundary_left = false;
  s.needs_rebuild = false;
  ++s.full_rebuilds;
  s.last_full = true;
  refreshTraversalForms();
}

void InstanceTree::fullRebuild() {
  // Free slots hold empty boxes, which the builder leaves out.
  install(buildKdTreeOverBoxes(state_->boxes, config_.build));
}

void InstanceTree::rebuild() {
  if (!state_) return;
  fullRebuild();
}

// The forms derived from the tree for traversal: a crossing tree's leaf boxes and grid, a blocking
// tree's wide form (all of it after a full build or a compaction, else what lies on the paths of
// the boxes the commit edited).
void InstanceTree::refreshTraversalForms() {
  State& s = *state_;
  if (kind_ == Kind::Crossing) {
    s.refreshLeafBoxes(tree_);
  } else if (!config_.wide_traversal) {
    s.wide = {};
  } else if (s.last_full || s.wide_full) {
    s.wide.build(tree_, s.boxes);
  } else {
    s.wide.refresh(tree_, s.boxes, s.wide_edited);
  }
  s.wide_edited.clear();
  s.wide_full = false;
}

void InstanceTree::commit() {
  if (!state_ || (state_->pending.empty() && !state_->needs_rebuild)) return;
  try {
    commitEdits();
    if (!state_->last_full) refreshTraversalForms();  // a full rebuild refreshed them
  } catch (...) {
    // The records already describe the new scene; a tree that no longer matches them must not be
    // traversed. Rebuild from the records, or (when even that fails) answer nothing until the next
    // commit rebuilds.
    State& s = *state_;
    try {
      fullRebuild();
    } catch (...) {
      tree_ = KdTree{};
      s.wide = {};
      s.needs_rebuild = true;
    }
    throw;
  }
}

// What the steps of one commit share.
struct InstanceTree::CommitPass {
  bool incremental = false;  // re-insert the edited instances (else one full rebuild at the end)
  // The root's area before the commit: the tracked SAH cost weighs the leaves edited in this
  // commit by their area over it (a root grown meanwhile is rescaled in growRoot).
  double root_area_before = 1e-30;
  std::vector<LeafVisit> grown;  // leaves that gained references
};

void InstanceTree::commitEdits() {
  State& s = *state_;  // with needs_rebuild set, the edits go to the records and the tree is rebuilt
  auto pending = std::move(s.pending);
  s.pending.clear();
  s.pending_index.clear();
  ++s.commits;
  s.last_edits = pending.size();
  s.last_full = false;
  s.touched_jumps.clear();
  s.touched_frontiers.clear();
  s.wide_edited.clear();

  // A batch that edits a large part of the scene is cheaper, and gives a better tree, as one
  // full rebuild than as as many re-insertions (the same holds for scenes of a few instances).
  const bool large_batch =
      static_cast<double>(pending.size()) > config_.max_incremental_fraction * static_cast<double>(live_count_);
  CommitPass pass;
  pass.incremental =
      config_.update == TopLevelUpdate::Incremental && !tree_.empty() && !large_batch && !s.needs_rebuild;
  pass.root_area_before = std::max(1e-30, boxArea(tree_.bounds));

  // The per-slot arrays grow together: reserve them all first, so that a bad_alloc cannot leave
  // one longer than another (queries index all of them by the tree's slots).
  const std::size_t max_slots = s.records.size() + pending.size();
  s.records.reserve(max_slots);
  s.filters.reserve(max_slots);
  s.owners.reserve(max_slots);
  s.boxes.reserve(max_slots);
  for (auto& [id, edit] : pending) {
    if (edit) applySet(pass, id, std::move(*edit));
    else applyRemoval(pass, id);
  }
  if (!pass.incremental) {
    fullRebuild();
    return;
  }
  finishIncrementalCommit(pass);
}

void InstanceTree::removeFromLeaf(CommitPass& pass, const LeafVisit& v, std::uint32_t slot) {
  State& s = *state_;
  KdNode& n = tree_.nodes[v.node];
  const std::uint32_t off = n.primOffset(), cnt = n.primCount();
  std::uint32_t* refs = tree_.prim_indices.data() + off;
  for (std::uint32_t i = 0; i < cnt; ++i) {
    if (refs[i] != slot) continue;
    refs[i] = refs[cnt - 1];
    n = KdNode::leaf(off, cnt - 1);
    ++s.garbage;
    s.sah_cost -= config_.build.intersection_cost * boxArea(v.cell) / pass.root_area_before;
    if (v.jump != kNoJump) s.touched_jumps.push_back(v);  // its local build no longer fits
    s.countEdit(v);
    return;
  }
  // Not there: the builder placed a box that only touches a plane on one side only.
}

void InstanceTree::appendToLeaf(CommitPass& pass, const LeafVisit& v, std::uint32_t slot) {
  State& s = *state_;
  KdNode& n = tree_.nodes[v.node];
  const std::uint32_t off = n.primOffset(), cnt = n.primCount();
  auto& idx = tree_.prim_indices;
  if (cnt == 0 || off + cnt == idx.size()) {
    if (cnt == 0) n = KdNode::leaf(static_cast<std::uint32_t>(idx.size()), 0);
    idx.push_back(slot);
  } else {
    // Move the leaf's range to the end; the old range becomes garbage.
    const std::size_t new_off = idx.size();
    idx.resize(new_off + cnt + 1);
    std::copy_n(idx.begin() + off, cnt, idx.begin() + static_cast<std::ptrdiff_t>(new_off));
    idx.back() = slot;
    s.garbage += cnt;
    n = KdNode::leaf(static_cast<std::uint32_t>(new_off), cnt);
  }
  n = KdNode::leaf(n.primOffset(), cnt + 1);
  s.sah_cost += config_.build.intersection_cost * boxArea(v.cell) / pass.root_area_before;
  pass.grown.push_back(v);
  s.countEdit(v);
}

void InstanceTree::growRoot(const Box& box) {
  if (box.empty()) return;
  if (tree_.bounds.lo.x <= box.lo.x && tree_.bounds.lo.y <= box.lo.y && tree_.bounds.lo.z <= box.lo.z &&
      tree_.bounds.hi.x >= box.hi.x && tree_.bounds.hi.y >= box.hi.y && tree_.bounds.hi.z >= box.hi.z)
    return;
  // Boundary cells grow with the root. Every node's weight is its area over the root's: rescale
  // the tracked cost now (the boundary cells' growth is left to the next exact recomputation).
  const double before = std::max(1e-30, boxArea(tree_.bounds));
  tree_.bounds.extend(box);
  State& s = *state_;
  s.sah_cost *= before / std::max(1e-30, boxArea(tree_.bounds));
  s.cost_stale = true;
}

// Whether a box holds up a face of the root bounds: when it moves or vanishes the bounds may
// shrink (rays that miss everything stop traversing the emptied margin).
bool InstanceTree::onRootFace(const Box& b) const {
  const Box& r = tree_.bounds;
  return !b.empty() && (b.lo.x <= r.lo.x || b.lo.y <= r.lo.y || b.lo.z <= r.lo.z || b.hi.x >= r.hi.x ||
                        b.hi.y >= r.hi.y || b.hi.z >= r.hi.z);
}

void InstanceTree::applyRemoval(CommitPass& pass, std::uint32_t id) {
  State& s = *state_;
  const auto it = s.slot_of_id.find(id);
  if (it == s.slot_of_id.end()) return;  // added and removed within this batch
  const std::uint32_t slot = it->second;
  s.boundary_left |= onRootFace(s.boxes[slot]);
  if (pass.incremental) s.wide_edited.push_back(s.boxes[slot]);
  if (pass.incremental)
    forEachLeaf(tree_, s.frontier_of, s.boxes[slot], [&](const LeafVisit& v) { removeFromLeaf(pass, v, slot); });
  s.boxes[slot] = Box();
  s.records[slot] = Record{};
  s.filters[slot] = SlotFilter{};
  s.owners[slot].reset();
  s.free_slots.push_back(slot);
  s.slot_of_id.erase(it);
  DUPLEX_CHECK(live_count_ > 0);
  --live_count_;
}

void InstanceTree::applySet(CommitPass& pass, std::uint32_t id, Prepared&& edit) {
  State& s = *state_;
  const auto it = s.slot_of_id.find(id);
  std::uint32_t slot;
  Box old_box;
  if (it != s.slot_of_id.end()) {
    slot = it->second;
    old_box = s.boxes[slot];
  } else {
    if (!s.free_slots.empty()) {
      slot = s.free_slots.back();
      s.free_slots.pop_back();
    } else {
      slot = static_cast<std::uint32_t>(s.records.size());
      s.records.emplace_back();
      s.filters.emplace_back();
      s.owners.emplace_back();
      s.boxes.emplace_back();
    }
    s.slot_of_id.emplace(id, slot);
    ++live_count_;
  }
  s.records[slot] = edit.record;
  s.filters[slot] = filterOf(edit.record);
  s.owners[slot] = std::move(edit.owner);
  s.boxes[slot] = edit.box;
  if (!pass.incremental || old_box == edit.box) return;
  s.boundary_left |= onRootFace(old_box);
  s.wide_edited.push_back(old_box);
  s.wide_edited.push_back(edit.box);
  // Leave the leaves only the old box touches, join those only the new box touches.
  s.scratch_old.clear();
  s.scratch_new.clear();
  if (!old_box.empty())
    forEachLeaf(tree_, s.frontier_of, old_box, [&](const LeafVisit& v) { s.scratch_old.push_back(v); });
  growRoot(edit.box);
  if (!edit.box.empty())
    forEachLeaf(tree_, s.frontier_of, edit.box, [&](const LeafVisit& v) { s.scratch_new.push_back(v); });
  auto in = [](const std::vector<LeafVisit>& list, std::uint32_t node) {
    return std::any_of(list.begin(), list.end(), [&](const LeafVisit& v) { return v.node == node; });
  };
  for (const LeafVisit& v : s.scratch_old)
    if (!in(s.scratch_new, v.node)) removeFromLeaf(pass, v, slot);
  for (const LeafVisit& v : s.scratch_new) {
    if (in(s.scratch_old, v.node)) {
      // The builder may have left the old box out of a leaf it only touched.
      const KdNode& n = tree_.nodes[v.node];
      const std::uint32_t* refs = tree_.prim_indices.data() + n.primOffset();
      if (std::find(refs, refs + n.primCount(), slot) != refs + n.primCount()) continue;
    }
    appendToLeaf(pass, v, slot);
  }
}

// After the edits of an incremental commit: local refinement, then the decisions to rebuild the
// whole tree (too few instances, drift, growth, cost) or to compact it.
void InstanceTree::finishIncrementalCommit(CommitPass& pass) {
  State& s = *state_;
  // Too few instances to bother, or the count drifted far from the last full build's: rebuild.
  const double drift = std::abs(static_cast<double>(live_count_) - static_cast<double>(s.fresh_count));
  if (live_count_ < config_.min_incremental_instances ||
      drift > 0.25 * static_cast<double>(std::max<std::size_t>(s.fresh_count, 1))) {
    fullRebuild();
    return;
  }
  s.refineLeaves(*this, pass.grown);
  // Refinement without bound fragments cells (each local build is optimal only locally): a tree
  // grown far beyond the last full build is rebuilt whatever its estimated cost.
  DUPLEX_CHECK(s.garbage <= tree_.prim_indices.size() && s.garbage_nodes <= tree_.nodes.size());
  const std::size_t live_refs = tree_.prim_indices.size() - s.garbage;
  const std::size_t live_nodes = tree_.nodes.size() - s.garbage_nodes;
  if (live_nodes > 4 * s.fresh_nodes + 4096 || live_refs > 4 * s.fresh_refs + 4096) {
    fullRebuild();
    return;
  }
  // O(instances) and O(nodes) work, amortised: shrinking the root and recomputing the exact cost
  // happen every kExactEvery commits at most (and before a rebuild decision rests on an estimate).
  constexpr std::uint64_t kExactEvery = 32;
  const bool periodic = s.commits % kExactEvery == 0;
  shrinkRootIfDue(periodic);
  const bool over = s.sah_cost > config_.rebuild_ratio * s.fresh_cost;
  if (s.cost_stale && (periodic || over)) {
    s.sah_cost = tree_.stats(config_.build.traversal_cost, config_.build.intersection_cost).sah_cost;
    s.cost_stale = false;
  }
  if (s.sah_cost > config_.rebuild_ratio * s.fresh_cost) {
    fullRebuild();
    return;
  }
  if ((s.garbage > 1024 && s.garbage > tree_.prim_indices.size() / 2) ||
      (s.garbage_nodes > 4096 && s.garbage_nodes > tree_.nodes.size() / 4))
    compact();
}

// Shrinks the root to the boxes after a box on its face moved or vanished: on periodic commits,
// and on every commit of a small tree (the loop costs less than the rest of the commit there: a
// root left loose for up to 32 commits made rays that miss everything walk the margin).
void InstanceTree::shrinkRootIfDue(bool periodic) {
  State& s = *state_;
  constexpr std::size_t kShrinkAlwaysBelow = 256;
  if (!s.boundary_left || !(periodic || s.boxes.size() <= kShrinkAlwaysBelow)) return;
  // Shrinking the root is always valid: every box stays inside, and a split plane outside the
  // smaller root just leaves one child empty (cells are clamped to the root when walked).
  Box tight;
  for (const Box& b : s.boxes) tight.extend(b);
  if (!(tight == tree_.bounds)) {
    tree_.bounds = tight;
    s.cost_stale = true;
  }
  s.boundary_left = false;
}

// ---------------------------------------------------------------------------------------------
// Queries (the per-ray helpers are in InstanceTreeState.h)

// The closest-hit and any-hit walks: the ray is set up once with SSE (validity, inverse direction,
// the clip to the root box), a leaf tests each box's three slabs at once, and the closest-hit walk
// visits a leaf's instances nearest first (InstanceTreeState.h).
Hit InstanceTree::intersectImpl(const Ray& ray_f, const RayD* ray_d, QueryContext& ctx, std::uint32_t mask) const {
  ++ctx.stats.rays;
  if (tree_.empty()) return Hit{};
  const State& s = *state_;
  if (s.wide.usable) {
    Hit out;
    wideKernels().closest({&s.wide, s.records.data(), s.filters.data(), mask}, ray_f, ray_d, out, ctx);
    return out;
  }
  const WorldRay w{ray_f, ray_d};
  Hit best;
  const Record* winner = nullptr;
  {
    KdRay kray;
    BoxTestRay box_ray;
    float tmin, tmax;
    if (!setupWorldRay(ray_f, tree_.bounds, kray, box_ray, tmin, tmax)) return Hit{};
    const Record* records = s.records.data();
    const SlotFilter* filters = s.filters.data();
    const Box* boxes = s.boxes.data();
    const std::uint32_t* prims = tree_.prim_indices.data();
    std::uint32_t best_id = kInvalidId;
    Mailbox mailbox;
    float t_best = ray_f.tfar;
    const auto pass = [mask](SlotFilter f) { return (f.mask & mask) != 0 && f.role == ObjectRole::Surface; };
    traverseKdTreeClipped<false>(tree_, kray, tmin, tmax, t_best,
                                 [&](std::uint32_t begin, std::uint32_t count, float& t) {
                                   return closestInLeaf(box_ray, prims + begin, count, filters, boxes, t, mailbox, pass,
                                                        [&](std::uint32_t slot) {
                                                          const Record& rec = records[slot];
                                                          ++ctx.stats.instance_visits;
                                                          if (!closerHit(rec, toObject(rec, w), best, t, best_id, ctx))
                                                            return false;
                                                          winner = &rec;
                                                          return true;
                                                        });
                                 });
  }
  if (!winner) return Hit{};
  best.instance_id = winner->id;
  best.ng = normalToWorld(*winner, best.ng);
  return best;
}

Hit InstanceTree::intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return intersectImpl(ray_ws, nullptr, ctx, mask);
}

Hit InstanceTree::intersect(const RayD& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return intersectImpl(fromDouble(ray_ws).f, &ray_ws, ctx, mask);
}

void InstanceTree::intersectBatch(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                  std::uint32_t mask) const {
  if (hits.size() < rays_ws.size())
    throw InvalidArgument("InstanceTree::intersectBatch: " + std::to_string(hits.size()) + " hits for " +
                          std::to_string(rays_ws.size()) + " rays");
  // An empty tree may have no state yet (intersectImpl answers it without reading any).
  if (tree_.empty() || !state_->wide.usable) {
    for (std::size_t i = 0; i < rays_ws.size(); ++i) hits[i] = intersectImpl(rays_ws[i], nullptr, ctx, mask);
    return;
  }
  const State& s = *state_;
  ctx.stats.rays += rays_ws.size();
  wideKernels().closestBatch({&s.wide, s.records.data(), s.filters.data(), mask}, rays_ws.data(), rays_ws.size(),
                             hits.data(), ctx);
}

void InstanceTree::occludedBatch(std::span<const Ray> rays_ws, std::span<std::uint8_t> occluded_out, QueryContext& ctx,
                                 std::uint32_t mask) const {
  if (occluded_out.size() < rays_ws.size())
    throw InvalidArgument("InstanceTree::occludedBatch: " + std::to_string(occluded_out.size()) + " results for " +
                          std::to_string(rays_ws.size()) + " rays");
  if (tree_.empty() || !state_->wide.usable) {
    for (std::size_t i = 0; i < rays_ws.size(); ++i) occluded_out[i] = occluded(rays_ws[i], ctx, mask) ? 1 : 0;
    return;
  }
  const State& s = *state_;
  ctx.stats.rays += rays_ws.size();
  wideKernels().occludedBatch({&s.wide, s.records.data(), s.filters.data(), mask}, rays_ws.data(), rays_ws.size(),
                              occluded_out.data(), ctx);
}

bool InstanceTree::occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  ++ctx.stats.rays;
  if (tree_.empty()) return false;
  const WorldRay w = fromFloat(ray_ws);
  const State& s = *state_;
  if (s.wide.usable) return wideKernels().occluded({&s.wide, s.records.data(), s.filters.data(), mask}, ray_ws, ctx);
  KdRay kray;
  BoxTestRay box_ray;
  float tmin, tmax;
  if (!setupWorldRay(ray_ws, tree_.bounds, kray, box_ray, tmin, tmax)) return false;
  const Record* records = s.records.data();
  const SlotFilter* filters = s.filters.data();
  const Box* boxes = s.boxes.data();
  const std::uint32_t* prims = tree_.prim_indices.data();
  Mailbox mailbox;
  float t_best = ray_ws.tfar;
  const auto pass = [mask](SlotFilter f) { return (f.mask & mask) != 0 && f.role == ObjectRole::Surface; };
  return traverseKdTreeClipped<true>(
      tree_, kray, tmin, tmax, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
        for (std::uint32_t i = begin; i < begin + count; ++i) {
          const std::uint32_t slot = prims[i];
          float t_enter;
          if (!pass(filters[slot]) || !meetsBoxAt(box_ray, boxes[slot], ray_ws.tfar, t_enter) || mailbox.seen(slot))
            continue;
          ++ctx.stats.instance_visits;
          if (occludes(records[slot], toObject(records[slot], w), ctx)) return true;
        }
        return false;
      });
}

void InstanceTree::intersectAll(const Ray& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                                std::uint32_t mask) const {
  intersectAllImpl(ray_ws, nullptr, hits, ctx, mask);
}

void InstanceTree::intersectAll(const RayD& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                                std::uint32_t mask) const {
  intersectAllImpl(fromDouble(ray_ws).f, &ray_ws, hits, ctx, mask);
}

void InstanceTree::collectAll(const toplevel_detail::WorldRay& w, std::vector<Hit>& hits, QueryContext& ctx,
                              std::uint32_t mask) const {
  const Ray& ray_ws = w.f;
  const Record* records = state_->records.data();
  const SlotFilter* filters = state_->filters.data();
  std::vector<std::uint32_t> visited;  // every instance once, however many leaves hold it
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;  // never lowered: all leaves along the ray
  traverseKdTree<false>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
    for (std::uint32_t i = begin; i < begin + count; ++i) {
      const std::uint32_t slot = tree_.prim_indices[i];
      if ((filters[slot].mask & mask) == 0 || std::find(visited.begin(), visited.end(), slot) != visited.end())
        continue;
      const Record& rec = records[slot];
      visited.push_back(slot);
      ++ctx.stats.instance_visits;
      const std::size_t first = hits.size();
      rec.object->intersectAll(toObject(rec, w), hits, ctx);
      for (std::size_t k = first; k < hits.size(); ++k) {
        hits[k].instance_id = rec.id;
        hits[k].ng = normalToWorld(rec, hits[k].ng);
      }
    }
    return false;
  });
}

void InstanceTree::intersectAllImpl(const Ray& ray_ws, const RayD* ray_d, std::vector<Hit>& hits, QueryContext& ctx,
                                    std::uint32_t mask, const InstanceTree* also) const {
  ++ctx.stats.rays;  // one ray in the statistics, however many trees answer it
  hits.clear();
  if (!isQueryable(ray_ws)) return;
  const WorldRay w = ray_d ? fromDouble(*ray_d) : fromFloat(ray_ws);
  if (!tree_.empty()) collectAll(w, hits, ctx, mask);
  if (also && !also->tree_.empty()) also->collectAll(w, hits, ctx, mask);
  sortHits(hits);
}

const Affine* InstanceTree::findObjectFromWorld(std::uint32_t id) const {
  if (!state_) return nullptr;
  const auto it = state_->slot_of_id.find(id);
  return it == state_->slot_of_id.end() ? nullptr : &state_->records[it->second].object_from_world;
}

const Box* InstanceTree::findBounds(std::uint32_t id) const {
  if (!state_) return nullptr;
  const auto it = state_->slot_of_id.find(id);
  return it == state_->slot_of_id.end() ? nullptr : &state_->boxes[it->second];
}

std::uint32_t InstanceTree::idAt(std::uint32_t slot) const {
  if (!state_ || slot >= state_->records.size()) return kInvalidId;
  return state_->records[slot].id;
}

std::uint64_t topLevelBytesPerInstance() {
  using toplevel_detail::Prepared;
  using toplevel_detail::Record;
  using toplevel_detail::SlotFilter;
  // A node of an unordered_map<uint32_t, T>: the next pointer, the pair and its cached slot in a
  // bucket list of about one pointer per element.
  constexpr std::uint64_t kMapEntry = 3 * sizeof(void*) + sizeof(std::uint64_t);
  return sizeof(InstanceDesc) + sizeof(Record) + sizeof(SlotFilter) + sizeof(std::shared_ptr<const Object>) +
         sizeof(Box) + sizeof(std::pair<std::uint32_t, std::optional<Prepared>>) + 2 * kMapEntry +
         2 * sizeof(std::uint32_t) + 2 * sizeof(kd_detail::PrimRef);
}

}  // namespace duplex
