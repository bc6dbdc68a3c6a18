#include "duplex/scenegraph/SceneTracer.h"

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
    for (std::size_t i = 0; i < rays.size(); ++i) out[i] = top.intersect(rays[i], ctx, mask);
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
    for (std::size_t i = 0; i < rays.size(); ++i) out[i] = top.occluded(rays[i], ctx, mask) ? 1 : 0;
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
  return a.vertices < b.vertices;
}

glm::dvec3 unitNormal(const InstanceTriangle& t) {
  const glm::dvec3 n = glm::cross(t.position_ws[1] - t.position_ws[0], t.position_ws[2] - t.position_ws[0]);
  const double len = glm::length(n);
  return len > 0.0 ? n / len : n;
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
    const std::vector<InstanceTriangle> tris =
        top.trianglesInRegion(frustumPlanes(camera, px - r, py - r, px + r, py + r, width, height), options.mask);
    // Each candidate triangle's corners on screen, once (CAD parts give thousands of long slivers
    // through a small pick frustum, each with all three edges near the cursor).
    struct Corner {
      glm::dvec2 px{0.0};
      double z = 0.0;  // depth along forward; the pixel is valid only for z > 0
    };
    std::vector<std::array<Corner, 3>> corners(tris.size());
    for (std::size_t i = 0; i < tris.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        Corner& c = corners[i][k];
        c.z = screen.depth(tris[i].position_ws[k]);
        if (c.z > 0.0) c.px = screen.pixel(tris[i].position_ws[k]);
      }
    // The near edges: those whose projection comes within r of the cursor, each with its point
    // nearest the cursor on screen. An edge is listed once per triangle around it; a triangle with
    // an edge meeting the pick frustum meets it too, so all of an edge's triangles are here.
    struct NearEdge {
      std::uint64_t instance_and_low;  // instance id << 32 | the lower vertex index: the sort key
      std::uint32_t high;              // the higher vertex index
      std::uint32_t triangle;          // index into tris
      double s;                        // where along the projected edge (from its lower vertex) it is nearest
      double d;                        // the distance there, pixels
      [[nodiscard]] bool sameEdge(const NearEdge& o) const {
        return instance_and_low == o.instance_and_low && high == o.high;
      }
    };
    // The segment of triangle t's edge from vertex `from` to vertex `to` (corner indices) that lies
    // in front of the eye, with its depths and pixels; false when none does.
    struct Segment {
      glm::dvec3 a, b;
      double za, zb;
      glm::dvec2 sa, sb;
    };
    const auto segment = [&](std::uint32_t t, int from, int to, Segment& out) {
      out = {tris[t].position_ws[from], tris[t].position_ws[to], corners[t][from].z,
             corners[t][to].z,          corners[t][from].px,     corners[t][to].px};
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
    near.reserve(3 * tris.size());
    for (std::uint32_t i = 0; i < tris.size(); ++i) {
      const InstanceTriangle& t = tris[i];
      for (int k = 0; k < 3; ++k) {
        // Oriented from the lower vertex index, so that both triangles of an edge measure alike.
        int from = k, to = (k + 1) % 3;
        if (t.vertex[from] > t.vertex[to]) std::swap(from, to);
        Segment g;
        if (!segment(i, from, to, g)) continue;
        const glm::dvec2 ab = g.sb - g.sa;
        const double len2 = glm::dot(ab, ab);
        const double s = len2 > 0.0 ? std::clamp(glm::dot(cursor - g.sa, ab) / len2, 0.0, 1.0) : 0.0;
        const double d = glm::length(g.sa + s * ab - cursor);
        if (!(d <= r)) continue;
        near.push_back({(std::uint64_t{t.instance_id} << 32) | t.vertex[from], t.vertex[to], i, s, d});
      }
    }
    // The 3D point a near edge shows at its nearest screen point (perspective: 1/depth is linear
    // along the projected segment).
    const auto edgeCandidate = [&](const NearEdge& e) {
      const InstanceTriangle& t = tris[e.triangle];
      const int from = t.vertex[0] == static_cast<std::uint32_t>(e.instance_and_low)   ? 0
                       : t.vertex[1] == static_cast<std::uint32_t>(e.instance_and_low) ? 1
                                                                                       : 2;
      const int to = t.vertex[0] == e.high ? 0 : (t.vertex[1] == e.high ? 1 : 2);
      Segment g;
      (void)segment(e.triangle, from, to, g);
      const double u = e.s * g.za / ((1.0 - e.s) * g.zb + e.s * g.za);
      const glm::dvec3 p = g.a + u * (g.b - g.a);
      return ElementCandidate{
          t.instance_id, t.prim_id, {t.vertex[from], t.vertex[to]}, p, e.d, glm::length(p - camera.eye)};
    };
    // The feature filter: an edge's triangles side by side, one entry kept per feature edge.
    if (options.feature_angle_deg > 0.0) {
      std::sort(near.begin(), near.end(), [](const NearEdge& x, const NearEdge& y) {
        if (x.instance_and_low != y.instance_and_low) return x.instance_and_low < y.instance_and_low;
        return x.high != y.high ? x.high < y.high : x.triangle < y.triangle;
      });
      const double cos_feature = std::cos(options.feature_angle_deg * std::numbers::pi / 180.0);
      std::size_t kept = 0;
      for (std::size_t i = 0; i < near.size();) {
        std::size_t j = i + 1;
        while (j < near.size() && near[j].sameEdge(near[i])) ++j;
        const bool feature = j - i != 2 || glm::dot(unitNormal(tris[near[i].triangle]),
                                                    unitNormal(tris[near[i + 1].triangle])) < cos_feature;
        if (feature) near[kept++] = near[i];
        i = j;
      }
      near.resize(kept);
    }
    // Candidates in screen-distance order, built as a heap: the first visible one is usually among
    // the first few, so a full sort of thousands would be wasted.
    const auto later = [](const ElementCandidate& x, const ElementCandidate& y) { return closerOnScreen(y, x); };
    const auto firstVisible = [&](std::vector<ElementCandidate>& found) -> const ElementCandidate* {
      std::make_heap(found.begin(), found.end(), later);
      const ElementCandidate* last = nullptr;
      for (auto end = found.end(); end != found.begin(); --end) {
        std::pop_heap(found.begin(), end, later);
        const ElementCandidate& c = *(end - 1);
        // The same element again (from another triangle around it): already tested.
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
      for (const NearEdge& e : near) {
        const InstanceTriangle& t = tris[e.triangle];
        for (int k = 0; k < 3; ++k) {
          if (t.vertex[k] != static_cast<std::uint32_t>(e.instance_and_low) && t.vertex[k] != e.high) continue;
          const Corner& c = corners[e.triangle][k];
          if (!(c.z > 0.0)) continue;
          const double d = glm::length(c.px - cursor);
          if (!(d <= r)) continue;
          const glm::dvec3& p = t.position_ws[k];
          found.push_back({t.instance_id, t.prim_id, {t.vertex[k], kInvalidId}, p, d, glm::length(p - camera.eye)});
        }
      }
      if (const ElementCandidate* c = firstVisible(found)) return finish(PickElement::Vertex, *c);
    }

    if (options.edges) {
      std::vector<ElementCandidate> found;
      found.reserve(near.size());
      for (const NearEdge& e : near) found.push_back(edgeCandidate(e));
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
