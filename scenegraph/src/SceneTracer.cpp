#include "duplex/scenegraph/SceneTracer.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"

#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <type_traits>

namespace duplex {

struct SceneTracer::Impl {
  TopLevel top;
  mutable std::shared_mutex mutex;  // queries share it; the commit observer takes it alone
  SceneGraph::ObserverId observer = 0;
  double last_update_ms = 0.0;

  explicit Impl(const TopLevelConfig& config) : top(config) {}
};

namespace {

InstanceDesc describeInstance(const SceneGraph& graph, NodeId id) {
  const NodeInfo info = graph.node(id);
  return {graph.library().get(info.object), graph.worldTransform(id), id, info.mask};
}

// Batches are split into chunks of this many rays: one QueryContext per chunk.
constexpr std::size_t kBatchGrain = 256;

}  // namespace

SceneTracer::SceneTracer(SceneGraph& graph, const TopLevelConfig& config)
    : graph_(graph), impl_(std::make_unique<Impl>(config)) {
  // The tracer starts from the committed scene; pending edits would leak into it.
  if (graph.hasPendingEdits())
    throw InvalidArgument("SceneTracer: the scene graph has uncommitted edits (commit or roll back first)");
  std::vector<InstanceDesc> instances;
  for (const NodeId id : graph.visibleInstances()) instances.push_back(describeInstance(graph, id));
  impl_->top.build(instances);
  Impl* impl = impl_.get();
  SceneGraph* g = &graph_;
  impl_->observer = graph_.subscribe([impl, g](const ChangeSet& changes) {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock lock(impl->mutex);
    std::string failures;
    // Disappeared first, so that nothing is both removed and set.
    // (An instance left out earlier, see below, is not in the top level.)
    for (const NodeId id : changes.disappeared)
      if (impl->top.contains(id)) impl->top.remove(id);
    auto set = [&](NodeId id) {
      try {
        impl->top.set(describeInstance(*g, id));
      } catch (const Error& e) {
        // A world transform can turn non-finite or singular as a product of valid local ones.
        failures += std::string(failures.empty() ? "" : "; ") + g->path(id) + ": " + e.what();
        if (impl->top.contains(id)) impl->top.remove(id);
      }
    };
    for (const NodeId id : changes.appeared) set(id);
    // moved, object_changed and mask_changed may share ids: set each once.
    std::vector<NodeId> changed;
    changed.reserve(changes.moved.size() + changes.object_changed.size() + changes.mask_changed.size());
    changed.insert(changed.end(), changes.moved.begin(), changes.moved.end());
    changed.insert(changed.end(), changes.object_changed.begin(), changes.object_changed.end());
    changed.insert(changed.end(), changes.mask_changed.begin(), changes.mask_changed.end());
    if (!changes.object_changed.empty() || !changes.mask_changed.empty()) {
      std::sort(changed.begin(), changed.end());
      changed.erase(std::unique(changed.begin(), changed.end()), changed.end());
    }
    for (const NodeId id : changed) set(id);
    impl->top.commit();
    impl->last_update_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!failures.empty()) throw InvalidArgument("scene tracer: instances left out of the top level: " + failures);
  });
}

SceneTracer::~SceneTracer() { graph_.unsubscribe(impl_->observer); }

Hit SceneTracer::intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  return impl_->top.intersect(ray_ws, ctx, mask);
}

bool SceneTracer::occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  return impl_->top.occluded(ray_ws, ctx, mask);
}

float SceneTracer::transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  return impl_->top.transmittance(ray_ws, ctx, mask);
}

std::vector<Hit> SceneTracer::intersectAll(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  std::vector<Hit> hits;
  impl_->top.intersectAll(ray_ws, hits, ctx, mask);
  return hits;
}

namespace {

// Position recomputed in double from the object-space hit: the object-space ray is formed in
// double, the point found on it, and mapped back with world_from_object.
SceneHit detail(const SceneGraph& graph, const TopLevel& top, const RayD& ray_ws, const Hit& hit) {
  SceneHit out;
  out.hit = hit;
  if (!hit.valid()) return out;
  out.instance = hit.instance_id;
  const Affine& object_from_world = top.objectFromWorld(hit.instance_id);
  const glm::dvec3 o_os = object_from_world.point(ray_ws.origin);
  const glm::dvec3 d_os = object_from_world.vector(ray_ws.dir);
  const glm::dvec3 p_os = o_os + static_cast<double>(hit.t) * d_os;
  // world_from_object from the top level's record (as of the commit the hit comes from), not from
  // the graph, which a concurrent commit may be rewriting.
  out.position_ws = object_from_world.inverse().point(p_os);
  const glm::dvec3 n(hit.ng);
  const double len = glm::length(n);
  out.normal_ws = len > 0.0 ? n / len : n;
  // The path as of the commit the hit comes from: pending edits of this thread are not seen.
  out.path = graph.committedPathIds(hit.instance_id);
  return out;
}

}  // namespace

SceneHit SceneTracer::intersectDetailed(const RayD& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  return detail(graph_, impl_->top, ray_ws, impl_->top.intersect(ray_ws, ctx, mask));
}

namespace {

// Runs query(ray, ctx) over `rays` (or other requests) in parallel (one QueryContext per chunk)
// into `out`.
template <class In, class Out, class Query>
void forEachRay(const char* what, std::span<const In> rays, std::span<Out> out, const WorkControl& control,
                Query&& query) {
  if (out.size() != rays.size())
    throw InvalidArgument(std::string(what) + ": " + std::to_string(rays.size()) +
                          (std::is_same_v<In, Ray> ? " rays" : " requests") + " but room for " +
                          std::to_string(out.size()) + " results");
  // Isolated: the caller holds the shared lock while it waits here, and a thread that waits in a
  // TBB loop may otherwise pick up an unrelated outer task, which could be another batch query
  // taking the same lock again on this thread (undefined for std::shared_mutex; a deadlock when a
  // commit waits between the two).
  ProgressCounter counter(control, rays.size());
  std::atomic<bool> stopped{false};
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), kBatchGrain), [&](const auto& range) {
      if (stopped.load(std::memory_order_relaxed) || control.cancelled()) {
        stopped.store(true, std::memory_order_relaxed);
        return;
      }
      QueryContext ctx;
      for (std::size_t i = range.begin(); i != range.end(); ++i) out[i] = query(rays[i], ctx);
      counter.add(range.size());
    });
  });
  if (stopped.load()) throw Cancelled(std::string(what) + ": cancelled; the results are incomplete");
}

}  // namespace

SceneClosestPoint SceneTracer::closestPoint(const glm::dvec3& point_ws, double max_distance, std::uint32_t mask) const {
  std::shared_lock lock(impl_->mutex);
  QueryContext ctx;
  SceneClosestPoint out;
  out.point = impl_->top.closestPoint(point_ws, max_distance, ctx, mask);
  if (out.valid()) {
    out.instance = out.point.instance_id;
    out.path = graph_.committedPathIds(out.instance);
  }
  return out;
}

void SceneTracer::closestPoints(std::span<const ClosestPointRequest> requests, std::span<ClosestPoint> out,
                                std::uint32_t mask, const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  forEachRay("SceneTracer::closestPoints", requests, out, control,
             [&](const ClosestPointRequest& r, QueryContext& ctx) {
               return top.closestPoint(r.point_ws, r.max_distance, ctx, mask);
             });
}

void SceneTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits, std::uint32_t mask,
                            const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  forEachRay("SceneTracer::intersect", rays, hits, control,
             [&](const Ray& r, QueryContext& ctx) { return top.intersect(r, ctx, mask); });
}

void SceneTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded, std::uint32_t mask,
                           const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  forEachRay("SceneTracer::occluded", rays, occluded, control, [&](const Ray& r, QueryContext& ctx) {
    return static_cast<std::uint8_t>(top.occluded(r, ctx, mask) ? 1 : 0);
  });
}

void SceneTracer::transmittance(std::span<const Ray> rays, std::span<float> transmittance, std::uint32_t mask,
                                const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  forEachRay("SceneTracer::transmittance", rays, transmittance, control,
             [&](const Ray& r, QueryContext& ctx) { return top.transmittance(r, ctx, mask); });
}

void SceneTracer::intersectAll(std::span<const Ray> rays, std::vector<Hit>& hits, std::vector<std::size_t>& offsets,
                               std::uint32_t mask, const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  // Each ray's hits in its own list first (their counts are unknown until traced), then one
  // prefix sum and a parallel copy into the flat result.
  std::vector<std::vector<Hit>> per_ray(rays.size());
  forEachRay("SceneTracer::intersectAll", rays, std::span<std::vector<Hit>>(per_ray), control,
             [&](const Ray& r, QueryContext& ctx) {
               std::vector<Hit> layer;
               top.intersectAll(r, layer, ctx, mask);
               return layer;
             });
  offsets.assign(rays.size() + 1, 0);
  for (std::size_t i = 0; i < rays.size(); ++i) offsets[i + 1] = offsets[i] + per_ray[i].size();
  hits.resize(offsets.back());
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), kBatchGrain), [&](const auto& range) {
      for (std::size_t i = range.begin(); i != range.end(); ++i)
        std::copy(per_ray[i].begin(), per_ray[i].end(), hits.begin() + static_cast<std::ptrdiff_t>(offsets[i]));
    });
  });
}

namespace {

void requireImage(const char* what, std::uint32_t width, std::uint32_t height) {
  if (width == 0 || height == 0)
    throw InvalidArgument(std::string(what) + ": image size " + std::to_string(width) + " x " + std::to_string(height) +
                          " (both must be positive)");
}

/// A camera that makes finite, distinct corner rays: finite vectors, non-zero axes, a field of
/// view strictly between 0 and 180 degrees. Anything else would give NaN planes (select everything)
/// or coincident rays (select everything in front).
void requireCamera(const char* what, const PinholeCamera& c) {
  const auto finite = [](const glm::dvec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  if (!finite(c.eye) || !finite(c.forward) || !finite(c.right) || !finite(c.up))
    throw InvalidArgument(std::string(what) + ": camera has non-finite eye or axes");
  if (!(glm::length(c.forward) > 0.0) || !(glm::length(c.right) > 0.0) || !(glm::length(c.up) > 0.0) ||
      !(glm::length(glm::cross(c.right, c.up)) > 0.0))
    throw InvalidArgument(std::string(what) + ": camera axes are zero or right and up are parallel");
  if (!(c.vertical_fov_deg > 0.0 && c.vertical_fov_deg < 180.0))
    throw InvalidArgument(std::string(what) + ": camera vertical_fov_deg " + std::to_string(c.vertical_fov_deg) +
                          " (must lie strictly between 0 and 180)");
}

}  // namespace

std::vector<SceneHit> SceneTracer::pick(const PinholeCamera& camera, double px, double py, std::uint32_t width,
                                        std::uint32_t height, PickMode mode, std::uint32_t mask) const {
  requireImage("SceneTracer::pick", width, height);
  requireCamera("SceneTracer::pick", camera);
  if (!std::isfinite(px) || !std::isfinite(py))
    throw InvalidArgument("SceneTracer::pick: pixel coordinates must be finite");
  RayD ray;
  ray.origin = camera.eye;
  ray.dir = camera.directionAt(px, py, width, height);
  QueryContext ctx;
  std::shared_lock lock(impl_->mutex);
  std::vector<SceneHit> out;
  if (mode == PickMode::Nearest) {
    Hit nearest = impl_->top.intersect(ray, ctx, mask);
    // Sensors never block, so intersect() looks through them; a pick whose mask selects sensors
    // wants the nearest thing under the cursor, sensor or surface (a tie goes to the surface).
    if (const InstanceTree* sensors = impl_->top.crossingLevel()) {
      RayD up_to = ray;
      if (nearest.valid()) up_to.tfar = nearest.t;
      std::vector<Hit> crossings;
      sensors->intersectAll(up_to, crossings, ctx, mask);
      if (!crossings.empty() && (!nearest.valid() || crossings.front().t < nearest.t)) nearest = crossings.front();
    }
    SceneHit h = detail(graph_, impl_->top, ray, nearest);
    if (h.valid()) out.push_back(std::move(h));
    return out;
  }
  std::vector<Hit> hits;
  impl_->top.intersectAll(ray, hits, ctx, mask);
  std::vector<NodeId> seen;
  for (const Hit& h : hits) {
    if (mode == PickMode::PerInstance) {
      if (std::find(seen.begin(), seen.end(), h.instance_id) != seen.end()) continue;
      seen.push_back(h.instance_id);
    }
    out.push_back(detail(graph_, impl_->top, ray, h));
  }
  return out;
}

std::vector<NodeId> SceneTracer::selectRectangle(const PinholeCamera& camera, double x0, double y0, double x1,
                                                 double y1, std::uint32_t width, std::uint32_t height,
                                                 std::uint32_t mask) const {
  requireImage("SceneTracer::selectRectangle", width, height);
  requireCamera("SceneTracer::selectRectangle", camera);
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1))
    throw InvalidArgument("SceneTracer::selectRectangle: rectangle coordinates must be finite");
  if (x0 > x1) std::swap(x0, x1);
  if (y0 > y1) std::swap(y0, y1);
  // Corner directions in the order top-left, top-right, bottom-right, bottom-left (clockwise on
  // screen); each side plane contains the eye and two neighbouring corner rays, normal outward.
  const glm::dvec3 c[4] = {camera.directionAt(x0, y0, width, height), camera.directionAt(x1, y0, width, height),
                           camera.directionAt(x1, y1, width, height), camera.directionAt(x0, y1, width, height)};
  std::vector<glm::dvec4> planes;
  const glm::dvec3 inside = glm::normalize(c[0] + c[1] + c[2] + c[3]);
  for (int k = 0; k < 4; ++k) {
    glm::dvec3 n = glm::cross(c[k], c[(k + 1) % 4]);
    const double len = glm::length(n);
    if (!(len > 0.0)) continue;  // a zero-width rectangle: its side planes coincide; keep the others
    n /= len;
    if (glm::dot(n, inside) > 0.0) n = -n;
    planes.emplace_back(n, glm::dot(n, camera.eye));
  }
  // Nothing behind the camera.
  planes.emplace_back(-camera.forward, -glm::dot(camera.forward, camera.eye));
  std::shared_lock lock(impl_->mutex);
  return impl_->top.instancesInRegion(planes, mask);
}

Box SceneTracer::bounds() const {
  std::shared_lock lock(impl_->mutex);
  return impl_->top.bounds();
}

TopLevelStats SceneTracer::stats() const {
  std::shared_lock lock(impl_->mutex);
  return impl_->top.stats();
}

double SceneTracer::lastUpdateMs() const {
  std::shared_lock lock(impl_->mutex);
  return impl_->last_update_ms;
}

void SceneTracer::rebuild() {
  std::unique_lock lock(impl_->mutex);
  impl_->top.rebuild();
}

const TopLevel& SceneTracer::topLevel() const { return impl_->top; }

}  // namespace duplex
