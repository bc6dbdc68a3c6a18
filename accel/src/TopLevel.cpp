// The top level: two instance trees (InstanceTree.cpp), one over the instances that block or
// attenuate rays and one over the non-blocking ones (ObjectRole::Crossing), so that closest-hit,
// occlusion and transmittance queries never traverse the second. This file routes edits to the
// tree an instance belongs to (moving it when its object changes role) and merges the answers of
// the queries that see both; the crossing query is in TopLevelCrossings.cpp.

#include "duplex/accel/TopLevel.h"

#include "duplex/accel/Error.h"

#include <algorithm>
#include <exception>
#include <string>
#include <unordered_set>
#include <utility>

#include "InstanceTreeState.h"

namespace duplex {

using namespace toplevel_detail;

namespace {

bool isCrossing(const InstanceDesc& d) { return d.object && d.object->role() == ObjectRole::Crossing; }

}  // namespace

TopLevel::TopLevel(const TopLevelConfig& config) : blocking_(config) { validateConfig(config); }

InstanceTree& TopLevel::crossingLevelForEdit() {
  if (!crossing_) crossing_ = std::make_unique<InstanceTree>(config(), InstanceTree::Kind::Crossing);
  return *crossing_;
}

void TopLevel::setConfig(const TopLevelConfig& config) {
  validateConfig(config);
  blocking_.setConfig(config);
  if (crossing_) crossing_->setConfig(config);
}

void TopLevel::build(std::span<const InstanceDesc> instances, const KdBuildConfig& config) {
  const bool any_crossing = std::any_of(instances.begin(), instances.end(), isCrossing);
  if (!any_crossing && !crossing_) {
    blocking_.build(instances, config);
    return;
  }
  // Ids are unique over both trees; the sensors' tree is built aside first, so that a failure of
  // either build leaves everything as it was.
  std::vector<InstanceDesc> others, sensors;
  std::unordered_set<std::uint32_t> ids;
  ids.reserve(instances.size());
  for (const InstanceDesc& d : instances) {
    if (!ids.insert(d.id).second) throw InvalidArgument(describeInstance(d) + ": duplicate instance id");
    (isCrossing(d) ? sensors : others).push_back(d);
  }
  TopLevelConfig c = this->config();
  c.build = config;
  validateConfig(c);
  auto level = std::make_unique<InstanceTree>(c, InstanceTree::Kind::Crossing);
  level->build(sensors, c.crossing_build);
  blocking_.build(others, config);
  crossing_ = std::move(level);
}

void TopLevel::build(std::span<const InstanceDesc> instances) { build(instances, config().build); }

void TopLevel::set(const InstanceDesc& instance) {
  // Set in the tree the instance belongs to first (it validates and throws before recording
  // anything), then take it out of the other one (an object that changed role moves).
  if (isCrossing(instance)) {
    blocking_.ensureState();  // queries read the (empty) records of the blocking tree
    crossingLevelForEdit().set(instance);
    if (blocking_.contains(instance.id)) blocking_.remove(instance.id);
    return;
  }
  blocking_.set(instance);
  if (crossing_ && crossing_->contains(instance.id)) crossing_->remove(instance.id);
}

void TopLevel::remove(std::uint32_t id) {
  if (blocking_.contains(id)) {
    blocking_.remove(id);
  } else if (crossing_ && crossing_->contains(id)) {
    crossing_->remove(id);
  } else {
    throw InvalidArgument("top level: remove of instance " + std::to_string(id) + ", which is not present");
  }
}

bool TopLevel::contains(std::uint32_t id) const {
  return blocking_.contains(id) || (crossing_ && crossing_->contains(id));
}

void TopLevel::commit() {
  // Both trees commit even when one throws (each then keeps its own promise, InstanceTree::commit).
  std::exception_ptr failure;
  if (crossing_) {
    try {
      crossing_->commit();
    } catch (...) {
      failure = std::current_exception();
    }
  }
  blocking_.commit();
  if (failure) std::rethrow_exception(failure);
}

void TopLevel::rebuild() {
  if (crossing_) crossing_->rebuild();
  blocking_.rebuild();
}

Hit TopLevel::intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return blocking_.intersect(ray_ws, ctx, mask);
}

Hit TopLevel::intersect(const RayD& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return blocking_.intersect(ray_ws, ctx, mask);
}

void TopLevel::intersectBatch(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                              std::uint32_t mask) const {
  blocking_.intersectBatch(rays_ws, hits, ctx, mask);
}

void TopLevel::occludedBatch(std::span<const Ray> rays_ws, std::span<std::uint8_t> occluded, QueryContext& ctx,
                             std::uint32_t mask) const {
  blocking_.occludedBatch(rays_ws, occluded, ctx, mask);
}

bool TopLevel::occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return blocking_.occluded(ray_ws, ctx, mask);
}

float TopLevel::transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  return blocking_.transmittance(ray_ws, ctx, mask);
}

void TopLevel::intersectAll(const Ray& ray_ws, std::vector<Hit>& hits, QueryContext& ctx, std::uint32_t mask) const {
  blocking_.intersectAllImpl(ray_ws, nullptr, hits, ctx, mask, crossing_.get());
}

void TopLevel::intersectAll(const RayD& ray_ws, std::vector<Hit>& hits, QueryContext& ctx, std::uint32_t mask) const {
  blocking_.intersectAllImpl(fromDouble(ray_ws).f, &ray_ws, hits, ctx, mask, crossing_.get());
}

const Affine& TopLevel::objectFromWorld(std::uint32_t id) const {
  if (const Affine* a = blocking_.findObjectFromWorld(id)) return *a;
  if (crossing_)
    if (const Affine* a = crossing_->findObjectFromWorld(id)) return *a;
  throw InvalidArgument("top level: unknown instance " + std::to_string(id));
}

Box TopLevel::instanceBounds(std::uint32_t id) const {
  if (const Box* b = blocking_.findBounds(id)) return *b;
  if (crossing_)
    if (const Box* b = crossing_->findBounds(id)) return *b;
  throw InvalidArgument("top level: unknown instance " + std::to_string(id));
}

std::uint32_t TopLevel::idAt(std::uint32_t slot) const { return blocking_.idAt(slot); }

TopLevelStats TopLevel::stats() const {
  TopLevelStats st;
  const TopLevelConfig& config = this->config();
  st.instances = blocking_.size();
  st.tree = blocking_.tree().stats(config.build.traversal_cost, config.build.intersection_cost);
  if (const InstanceTree::State* s = blocking_.state_.get()) {
    st.sah_cost = s->sah_cost;
    st.fresh_sah_cost = s->fresh_cost;
    st.commits = s->commits;
    st.full_rebuilds = s->full_rebuilds;
    st.subtree_rebuilds = s->subtree_rebuilds;
    st.last_commit_edits = s->last_edits;
    st.last_commit_full_rebuild = s->last_full;
    st.garbage_nodes = s->garbage_nodes;
    if (s->wide.usable) {
      st.wide_nodes = s->wide.liveNodes();
      st.wide_garbage_nodes = s->wide.garbage();
    }
    st.wide_bytes = s->wide.bytes();
  }
  if (crossing_) {
    st.crossing_instances = crossing_->size();
    const KdBuildConfig& b = crossing_->config().build;
    st.crossing_tree = crossing_->tree().stats(b.traversal_cost, b.intersection_cost);
    if (const InstanceTree::State* s = crossing_->state_.get()) {
      st.crossing_box_lanes = s->leaf_boxes.lanes;
      if (config.crossing_grid && s->grid.usable()) {
        st.crossing_grid_cells = std::size_t{s->grid.dims[0]} * s->grid.dims[1] * s->grid.dims[2];
        st.crossing_grid_entries = s->grid.slots.size();
      }
    }
  }
  return st;
}

Box TopLevel::bounds() const {
  Box b = blocking_.tree().bounds;
  if (crossing_ && !crossing_->tree().empty()) {
    const Box& o = crossing_->tree().bounds;
    b = blocking_.tree().empty() ? o : Box{glm::min(b.lo, o.lo), glm::max(b.hi, o.hi)};
  }
  return b;
}

std::size_t TopLevel::bytesPerInstance() {
  // Record, query filter, owner pointer, world box, and the id map's node (key, value, next
  // pointer, hash).
  return sizeof(Record) + sizeof(SlotFilter) + sizeof(std::shared_ptr<const Object>) + sizeof(Box) + 4 * sizeof(void*);
}

}  // namespace duplex
