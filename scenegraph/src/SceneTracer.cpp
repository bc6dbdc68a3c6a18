#include "duplex/scenegraph/SceneTracer.h"

#include "FeatureEdges.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/accel/WriterPreferringMutex.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <glm/vec2.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numbers>
#include <shared_mutex>  // std::shared_lock
#include <string>
#include <type_traits>

namespace duplex {

struct SceneTracer::Impl {
  TopLevel top;
  // Queries share it; the commit observer takes it alone, and once it waits no new query starts.
  mutable WriterPreferringMutex mutex;
  SceneGraph::ObserverId observer = 0;
  double last_update_ms = 0.0;
  std::atomic<bool> packets{true};  // batch queries trace packets (setBatchPackets)
  // The object of each instance in the top level, by node id (written under `mutex` alone): what
  // tolerance picks look up feature edges for.
  std::vector<std::shared_ptr<const Object>> object_of;
  // Feature edges per object and feature angle, built on first use. An entry keeps only a weak
  // reference, so that a replaced or deformed object is freed; its address may then be reused,
  // which the weak reference tells apart.
  struct FeatureEntry {
    const Object* object;
    std::weak_ptr<const Object> alive;
    double feature_angle_deg;
    std::shared_ptr<const FeatureEdges> edges;
  };
  std::mutex feature_mutex;
  std::vector<FeatureEntry> features;

  explicit Impl(const TopLevelConfig& config) : top(config) {}

  void setObject(NodeId id, std::shared_ptr<const Object> object) {
    if (id >= object_of.size()) object_of.resize(id + 1);
    object_of[id] = std::move(object);
  }
  // The feature edges of instance id's object (nullptr: none to pick). The caller holds `mutex`.
  std::shared_ptr<const FeatureEdges> featureEdges(NodeId id, double feature_angle_deg) {
    if (id >= object_of.size() || !object_of[id]) return nullptr;
    return featureEdgesOf(object_of[id], feature_angle_deg);
  }
  std::shared_ptr<const FeatureEdges> featureEdgesOf(const std::shared_ptr<const Object>& object,
                                                     double feature_angle_deg) {
    {
      std::lock_guard lock(feature_mutex);
      for (const FeatureEntry& e : features)
        if (e.object == object.get() && e.feature_angle_deg == feature_angle_deg && e.alive.lock() == object)
          return e.edges;
    }
    // Built outside the cache's lock (a large mesh takes a while; other objects' picks go on). Two
    // picks may build the same one at once: both results are equal, the first stored wins.
    std::shared_ptr<const FeatureEdges> built = FeatureEdges::build(*object, feature_angle_deg);
    std::lock_guard lock(feature_mutex);
    std::erase_if(features, [](const FeatureEntry& e) { return e.alive.expired(); });
    for (const FeatureEntry& e : features)
      if (e.object == object.get() && e.feature_angle_deg == feature_angle_deg) return e.edges;
    features.push_back({object.get(), object, feature_angle_deg, built});
    return built;
  }
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
  for (const InstanceDesc& d : instances) impl_->setObject(d.id, d.object);
  Impl* impl = impl_.get();
  SceneGraph* g = &graph_;
  impl_->observer = graph_.subscribe([impl, g](const ChangeSet& changes) {
    const auto start = std::chrono::steady_clock::now();
    std::unique_lock lock(impl->mutex);
    std::string failures;
    // Disappeared first, so that nothing is both removed and set.
    // (An instance left out earlier, see below, is not in the top level.)
    for (const NodeId id : changes.disappeared) {
      if (impl->top.contains(id)) impl->top.remove(id);
      impl->setObject(id, nullptr);
    }
    auto set = [&](NodeId id) {
      try {
        const InstanceDesc d = describeInstance(*g, id);
        impl->top.set(d);
        impl->setObject(id, d.object);
      } catch (const Error& e) {
        // A world transform can turn non-finite or singular as a product of valid local ones.
        failures += std::string(failures.empty() ? "" : "; ") + g->path(id) + ": " + e.what();
        if (impl->top.contains(id)) impl->top.remove(id);
        impl->setObject(id, nullptr);
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
// body(range, ctx) over [0, count) in parallel chunks of at most about `grain`, one QueryContext
// per chunk, with progress after each chunk and cancellation between chunks (then Cancelled).
// Isolated: the caller holds the shared lock while it waits here, and a thread that waits in a TBB
// loop may otherwise pick up an unrelated outer task, which could be another batch query taking
// the same lock again on this thread (a deadlock when a commit waits between the two).
template <class Body>
void forEachChunk(const char* what, std::size_t count, std::size_t grain, const WorkControl& control, Body&& body) {
  ProgressCounter counter(control, count);
  std::atomic<bool> stopped{false};
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        if (stopped.load(std::memory_order_relaxed) || control.cancelled()) {
                          stopped.store(true, std::memory_order_relaxed);
                          return;
                        }
                        QueryContext ctx;
                        body(range, ctx);
                        counter.add(range.size());
                      });
  });
  if (stopped.load()) throw Cancelled(std::string(what) + ": cancelled; the results are incomplete");
}

template <class In, class Out, class Query>
void forEachRay(const char* what, std::span<const In> rays, std::span<Out> out, const WorkControl& control,
                Query&& query) {
  if (out.size() != rays.size())
    throw InvalidArgument(std::string(what) + ": " + std::to_string(rays.size()) +
                          (std::is_same_v<In, Ray> ? " rays" : " requests") + " but room for " +
                          std::to_string(out.size()) + " results");
  forEachChunk(what, rays.size(), kBatchGrain, control,
               [&](const tbb::blocked_range<std::size_t>& range, QueryContext& ctx) {
                 for (std::size_t i = range.begin(); i != range.end(); ++i) out[i] = query(rays[i], ctx);
               });
}

// The batch closest-hit and any-hit queries over rays [0, n) of `rays` into `out`, in packets of
// kMaxPacketRays consecutive rays (TopLevel::intersectPacket / occludedPacket) or ray by ray.
void intersectRange(const TopLevel& top, bool packets, std::span<const Ray> rays, Hit* out, QueryContext& ctx,
                    std::uint32_t mask) {
  if (!packets) {
    top.intersectBatch(rays, {out, rays.size()}, ctx, mask);
    return;
  }
  constexpr auto kPacket = static_cast<std::size_t>(kMaxPacketRays);
  for (std::size_t first = 0; first < rays.size(); first += kPacket) {
    const std::size_t n = std::min(kPacket, rays.size() - first);
    (void)top.intersectPacket(rays.subspan(first, n), std::span<Hit>(out + first, n), ctx, mask);
  }
}

void occludedRange(const TopLevel& top, bool packets, std::span<const Ray> rays, std::uint8_t* out, QueryContext& ctx,
                   std::uint32_t mask) {
  if (!packets) {
    top.occludedBatch(rays, {out, rays.size()}, ctx, mask);
    return;
  }
  constexpr auto kPacket = static_cast<std::size_t>(kMaxPacketRays);
  for (std::size_t first = 0; first < rays.size(); first += kPacket) {
    const std::size_t n = std::min(kPacket, rays.size() - first);
    const std::uint32_t blocked = top.occludedPacket(rays.subspan(first, n), ctx, mask);
    for (std::size_t j = 0; j < n; ++j) out[first + j] = (blocked >> j & 1u) != 0 ? 1 : 0;
  }
}

// Checks the sizes as forEachRay, then runs range(rays of a chunk, first result, ctx) per chunk.
template <class Out, class Range>
void forEachRayRange(const char* what, std::span<const Ray> rays, std::span<Out> out, const WorkControl& control,
                     Range&& range) {
  if (out.size() != rays.size())
    throw InvalidArgument(std::string(what) + ": " + std::to_string(rays.size()) + " rays but room for " +
                          std::to_string(out.size()) + " results");
  forEachChunk(what, rays.size(), kBatchGrain, control,
               [&](const tbb::blocked_range<std::size_t>& r, QueryContext& ctx) {
                 range(rays.subspan(r.begin(), r.size()), out.data() + r.begin(), ctx);
               });
}

// The batch over rays that `load` supplies and results that `store` takes, kStreamBlock at a time:
// range(rays of a block, results of the block, ctx).
template <class Out, class Range>
void forEachBlock(const char* what, std::size_t count, const SceneTracer::RayBlockLoader& load,
                  const std::function<void(std::size_t, std::span<const Out>)>& store, const WorkControl& control,
                  Range&& range) {
  if (!load || !store) throw InvalidArgument(std::string(what) + ": the loader and the store must not be empty");
  constexpr std::size_t kBlock = SceneTracer::kStreamBlock;
  forEachChunk(what, count, kBlock, control, [&](const tbb::blocked_range<std::size_t>& r, QueryContext& ctx) {
    std::array<Ray, kBlock> rays;
    std::array<Out, kBlock> out;
    for (std::size_t first = r.begin(); first < r.end(); first += kBlock) {
      const std::size_t n = std::min(kBlock, r.end() - first);
      load(first, std::span<Ray>(rays.data(), n));
      range(std::span<const Ray>(rays.data(), n), out.data(), ctx);
      store(first, std::span<const Out>(out.data(), n));
    }
  });
}

}  // namespace

void SceneTracer::setBatchPackets(bool on) { impl_->packets.store(on, std::memory_order_relaxed); }

bool SceneTracer::batchPackets() const { return impl_->packets.load(std::memory_order_relaxed); }

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
  const bool packets = batchPackets();
  forEachRayRange(
      "SceneTracer::intersect", rays, hits, control,
      [&](std::span<const Ray> r, Hit* out, QueryContext& ctx) { intersectRange(top, packets, r, out, ctx, mask); });
}

void SceneTracer::intersectBlocks(std::size_t count, const RayBlockLoader& load, const HitBlockStore& store,
                                  std::uint32_t mask, const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  const bool packets = batchPackets();
  forEachBlock<Hit>(
      "SceneTracer::intersectBlocks", count, load, store, control,
      [&](std::span<const Ray> r, Hit* out, QueryContext& ctx) { intersectRange(top, packets, r, out, ctx, mask); });
}

void SceneTracer::occludedBlocks(std::size_t count, const RayBlockLoader& load, const OccludedBlockStore& store,
                                 std::uint32_t mask, const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  const bool packets = batchPackets();
  forEachBlock<std::uint8_t>("SceneTracer::occludedBlocks", count, load, store, control,
                             [&](std::span<const Ray> r, std::uint8_t* out, QueryContext& ctx) {
                               occludedRange(top, packets, r, out, ctx, mask);
                             });
}

void SceneTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded, std::uint32_t mask,
                           const WorkControl& control) const {
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  const bool packets = batchPackets();
  forEachRayRange("SceneTracer::occluded", rays, occluded, control,
                  [&](std::span<const Ray> r, std::uint8_t* out, QueryContext& ctx) {
                    occludedRange(top, packets, r, out, ctx, mask);
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

namespace {

// The nearest thing under a picking ray. Sensors never block, so intersect() looks through them;
// a pick whose mask selects sensors wants the nearest thing under the cursor, sensor or surface
// (a tie goes to the surface). The caller holds the tracer's lock.
Hit nearestUnderCursor(const TopLevel& top, const RayD& ray, QueryContext& ctx, std::uint32_t mask) {
  Hit nearest = top.intersect(ray, ctx, mask);
  if (const InstanceTree* sensors = top.crossingLevel()) {
    RayD up_to = ray;
    if (nearest.valid()) up_to.tfar = nearest.t;
    std::vector<Hit> crossings;
    sensors->intersectAll(up_to, crossings, ctx, mask);
    if (!crossings.empty() && (!nearest.valid() || crossings.front().t < nearest.t)) nearest = crossings.front();
  }
  return nearest;
}

// The side planes of the frustum through the pixel rectangle [x0, x1] x [y0, y1] (x0 <= x1,
// y0 <= y1) and the plane through the eye facing forward (nothing behind the camera), world space.
std::vector<glm::dvec4> frustumPlanes(const PinholeCamera& camera, double x0, double y0, double x1, double y1,
                                      std::uint32_t width, std::uint32_t height) {
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
  planes.emplace_back(-camera.forward, -glm::dot(camera.forward, camera.eye));
  return planes;
}

// World points to continuous pixel coordinates: the inverse of PinholeCamera::directionAt for any
// independent camera axes (the offset from the eye is solved in the camera's own basis).
class ScreenProjection {
 public:
  ScreenProjection(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height)
      : eye_(camera.eye), width_(width), height_(height) {
    const glm::dmat3 basis(camera.forward, camera.right, camera.up);
    if (!(std::abs(glm::determinant(basis)) > 0.0))
      throw InvalidArgument("SceneTracer::pickElement: camera forward lies in the plane of right and up");
    to_camera_ = glm::inverse(basis);
    half_h_ = std::tan(0.5 * camera.vertical_fov_deg * std::numbers::pi / 180.0);
    half_w_ = half_h_ * static_cast<double>(width) / static_cast<double>(height);
  }
  // Depth along forward (in units of forward's length); > 0 in front of the eye.
  [[nodiscard]] double depth(const glm::dvec3& p) const { return (to_camera_ * (p - eye_)).x; }
  // Pixel coordinates of a point in front of the eye.
  [[nodiscard]] glm::dvec2 pixel(const glm::dvec3& p) const {
    const glm::dvec3 c = to_camera_ * (p - eye_);
    return {(c.y / c.x / half_w_ + 1.0) * 0.5 * width_, (1.0 - c.z / c.x / half_h_) * 0.5 * height_};
  }

 private:
  glm::dvec3 eye_;
  glm::dmat3 to_camera_{1.0};
  double half_w_ = 1.0, half_h_ = 1.0;
  double width_, height_;
};

// A vertex or an edge near the cursor, before its visibility is known.
struct ElementCandidate {
  std::uint32_t instance = kInvalidId;
  std::uint32_t prim_id = kInvalidId;
  std::array<std::uint32_t, 2> vertices{kInvalidId, kInvalidId};  // a vertex: [0] only
  glm::dvec3 point_ws{0.0};
  double distance_px = 0.0;
  double depth = 0.0;  // distance from the eye, world units
};

bool closerOnScreen(const ElementCandidate& a, const ElementCandidate& b) {
  if (a.distance_px != b.distance_px) return a.distance_px < b.distance_px;
  if (a.depth != b.depth) return a.depth < b.depth;
  if (a.instance != b.instance) return a.instance < b.instance;
  if (a.vertices != b.vertices) return a.vertices < b.vertices;
  return a.prim_id < b.prim_id;
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
    SceneHit h = detail(graph_, impl_->top, ray, nearestUnderCursor(impl_->top, ray, ctx, mask));
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

ElementPick SceneTracer::pickElement(const PinholeCamera& camera, double px, double py, std::uint32_t width,
                                     std::uint32_t height, const PickOptions& options) const {
  requireImage("SceneTracer::pickElement", width, height);
  requireCamera("SceneTracer::pickElement", camera);
  if (!std::isfinite(px) || !std::isfinite(py))
    throw InvalidArgument("SceneTracer::pickElement: pixel coordinates must be finite");
  if (!(options.radius_px >= 0.0) || !std::isfinite(options.radius_px))
    throw InvalidArgument("SceneTracer::pickElement: radius_px " + std::to_string(options.radius_px) +
                          " (must be finite and >= 0)");
  if (!(options.feature_angle_deg >= 0.0 && options.feature_angle_deg < 180.0))
    throw InvalidArgument("SceneTracer::pickElement: feature_angle_deg " + std::to_string(options.feature_angle_deg) +
                          " (must lie in [0, 180))");
  const ScreenProjection screen(camera, width, height);
  const glm::dvec2 cursor(px, py);
  const double r = options.radius_px;
  QueryContext ctx;
  std::shared_lock lock(impl_->mutex);
  const TopLevel& top = impl_->top;
  // Nothing that the mask selects lies on the segment from the eye to p (its own faces, met at the
  // far end, do not count).
  const auto visible = [&](const glm::dvec3& p) {
    RayD ray;
    ray.origin = camera.eye;
    ray.dir = p - camera.eye;
    ray.tfar = 1.0 - 1e-4;
    return !top.intersect(ray, ctx, options.mask).valid();
  };
  const auto finish = [&](PickElement kind, const ElementCandidate& c) {
    ElementPick pick;
    pick.kind = kind;
    pick.instance = c.instance;
    pick.path = graph_.committedPathIds(c.instance);
    pick.prim_id = c.prim_id;
    if (kind == PickElement::Vertex) pick.vertex = c.vertices[0];
    if (kind == PickElement::Edge) pick.edge = c.vertices;
    pick.point_ws = c.point_ws;
    pick.distance_px = c.distance_px;
    pick.depth = c.depth;
    return pick;
  };

  if (r > 0.0 && (options.vertices || options.edges)) {
    // The instances whose boxes meet the pick frustum, and in each the feature edges that meet it
    // (the object's edge index, object space): the only edges that can come within r of the cursor.
    const std::vector<glm::dvec4> planes = frustumPlanes(camera, px - r, py - r, px + r, py + r, width, height);
    const ConvexRegion region(planes);
    // A near edge: its projection comes within r of the cursor. Ends as the object gives them
    // (a: the lower vertex index), their depths along forward, their pixels where in front of the eye.
    struct NearEdge {
      std::uint32_t instance, low, high, prim;
      glm::dvec3 a, b;
      double za, zb;
      glm::dvec2 sa{0.0}, sb{0.0};
      double s = 0.0;  // where along the projected (clipped) edge it is nearest the cursor
      double d = 0.0;  // the distance there, pixels
    };
    // The part of [a, b] in front of the eye with its depths and pixels; false when none is.
    struct Segment {
      glm::dvec3 a, b;
      double za, zb;
      glm::dvec2 sa, sb;
    };
    const auto segment = [&](const NearEdge& e, Segment& out) {
      out = {e.a, e.b, e.za, e.zb, e.sa, e.sb};
      if (out.za > 0.0 && out.zb > 0.0) return true;
      // Only the part in front of the eye projects; cut a little in front of the eye plane.
      const double z_min = 1e-9 * std::max(std::abs(out.za), std::abs(out.zb));
      if (out.za <= z_min && out.zb <= z_min) return false;
      if (out.za < z_min) {
        out.a += (z_min - out.za) / (out.zb - out.za) * (out.b - out.a);
        out.za = z_min;
      } else if (out.zb < z_min) {
        out.b += (z_min - out.zb) / (out.za - out.zb) * (out.a - out.b);
        out.zb = z_min;
      }
      out.sa = screen.pixel(out.a);
      out.sb = screen.pixel(out.b);
      return true;
    };
    std::vector<NearEdge> near;
    std::vector<std::uint32_t> found_edges;
    for (const std::uint32_t id : top.instancesInRegion(planes, options.mask, RegionMode::Boxes)) {
      const std::shared_ptr<const FeatureEdges> features = impl_->featureEdges(id, options.feature_angle_deg);
      if (!features || features->size() == 0) continue;
      const Affine world_from_object = top.objectFromWorld(id).inverse();
      found_edges.clear();
      features->query(region.transformed(world_from_object), found_edges);
      for (const std::uint32_t i : found_edges) {
        const FeatureEdges::Edge& edge = features->edge(i);
        NearEdge e{id,
                   edge.low,
                   edge.high,
                   edge.prim,
                   world_from_object.point(glm::dvec3(edge.p[0])),
                   world_from_object.point(glm::dvec3(edge.p[1])),
                   0.0,
                   0.0};
        e.za = screen.depth(e.a);
        e.zb = screen.depth(e.b);
        if (e.za > 0.0) e.sa = screen.pixel(e.a);
        if (e.zb > 0.0) e.sb = screen.pixel(e.b);
        Segment g;
        if (!segment(e, g)) continue;
        const glm::dvec2 ab = g.sb - g.sa;
        const double len2 = glm::dot(ab, ab);
        e.s = len2 > 0.0 ? std::clamp(glm::dot(cursor - g.sa, ab) / len2, 0.0, 1.0) : 0.0;
        e.d = glm::length(g.sa + e.s * ab - cursor);
        if (e.d <= r) near.push_back(e);
      }
    }
    // Candidates in screen-distance order, built as a heap: the first visible one is usually among
    // the first few, so a full sort would be wasted.
    const auto later = [](const ElementCandidate& x, const ElementCandidate& y) { return closerOnScreen(y, x); };
    const auto firstVisible = [&](std::vector<ElementCandidate>& found) -> const ElementCandidate* {
      std::make_heap(found.begin(), found.end(), later);
      const ElementCandidate* last = nullptr;
      for (auto end = found.end(); end != found.begin(); --end) {
        std::pop_heap(found.begin(), end, later);
        const ElementCandidate& c = *(end - 1);
        // The same element again (from another edge at it): already tested.
        if (last && c.instance == last->instance && c.vertices == last->vertices) continue;
        if (visible(c.point_ws)) return &c;
        last = &c;
      }
      return nullptr;
    };

    if (options.vertices) {
      // A vertex within r of the cursor makes every edge at it a near edge: the ends of the
      // (feature) near edges are all the vertices that can count.
      std::vector<ElementCandidate> found;
      for (const NearEdge& e : near)
        for (int k = 0; k < 2; ++k) {
          const double z = k == 0 ? e.za : e.zb;
          if (!(z > 0.0)) continue;
          const double d = glm::length((k == 0 ? e.sa : e.sb) - cursor);
          if (!(d <= r)) continue;
          const glm::dvec3& p = k == 0 ? e.a : e.b;
          found.push_back(
              {e.instance, e.prim, {k == 0 ? e.low : e.high, kInvalidId}, p, d, glm::length(p - camera.eye)});
        }
      if (const ElementCandidate* c = firstVisible(found)) return finish(PickElement::Vertex, *c);
    }

    if (options.edges) {
      // Each near edge's point nearest the cursor on screen (perspective: 1/depth is linear along
      // the projected segment).
      std::vector<ElementCandidate> found;
      found.reserve(near.size());
      for (const NearEdge& e : near) {
        Segment g;
        (void)segment(e, g);
        const double u = e.s * g.za / ((1.0 - e.s) * g.zb + e.s * g.za);
        const glm::dvec3 p = g.a + u * (g.b - g.a);
        found.push_back({e.instance, e.prim, {e.low, e.high}, p, e.d, glm::length(p - camera.eye)});
      }
      if (const ElementCandidate* c = firstVisible(found)) return finish(PickElement::Edge, *c);
    }
  }

  ElementPick pick;
  if (!options.faces) return pick;
  RayD ray;
  ray.origin = camera.eye;
  ray.dir = camera.directionAt(px, py, width, height);
  const SceneHit h = detail(graph_, top, ray, nearestUnderCursor(top, ray, ctx, options.mask));
  if (!h.valid()) return pick;
  pick.kind = PickElement::Face;
  pick.instance = h.instance;
  pick.path = h.path;
  pick.prim_id = h.hit.prim_id;
  pick.point_ws = h.position_ws;
  pick.depth = glm::length(h.position_ws - camera.eye);
  return pick;
}

void SceneTracer::preparePicking(double feature_angle_deg) const {
  if (!(feature_angle_deg >= 0.0 && feature_angle_deg < 180.0))
    throw InvalidArgument("SceneTracer::preparePicking: feature_angle_deg " + std::to_string(feature_angle_deg) +
                          " (must lie in [0, 180))");
  std::shared_lock lock(impl_->mutex);
  std::vector<std::shared_ptr<const Object>> objects;
  for (const std::shared_ptr<const Object>& o : impl_->object_of)
    if (o) objects.push_back(o);
  std::sort(objects.begin(), objects.end());
  objects.erase(std::unique(objects.begin(), objects.end()), objects.end());
  tbb::parallel_for(std::size_t{0}, objects.size(),
                    [&](std::size_t i) { (void)impl_->featureEdgesOf(objects[i], feature_angle_deg); });
}

std::vector<NodeId> SceneTracer::selectRectangle(const PinholeCamera& camera, double x0, double y0, double x1,
                                                 double y1, std::uint32_t width, std::uint32_t height,
                                                 std::uint32_t mask, RegionMode mode) const {
  requireImage("SceneTracer::selectRectangle", width, height);
  requireCamera("SceneTracer::selectRectangle", camera);
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1))
    throw InvalidArgument("SceneTracer::selectRectangle: rectangle coordinates must be finite");
  if (x0 > x1) std::swap(x0, x1);
  if (y0 > y1) std::swap(y0, y1);
  const std::vector<glm::dvec4> planes = frustumPlanes(camera, x0, y0, x1, y1, width, height);
  std::shared_lock lock(impl_->mutex);
  return impl_->top.instancesInRegion(planes, mask, mode);
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
