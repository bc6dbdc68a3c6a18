#include "BenchFrameCommand.h"

#include "LoadScene.h"
#include "WorkerThreads.h"

#include "BenchBuild.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/MemoryLimit.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeTwoLevel.h"
#endif

#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <iostream>
#include <memory>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

namespace duplex::cli {
namespace {

using bench::median;
using bench::Stopwatch;

struct Move {
  std::uint32_t instance;  ///< index into the benchmark's instance list
  glm::dvec3 delta_ws;
};
using Frame = std::vector<Move>;

double unitInterval(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// The frames described in BenchFrameCommand.h.
std::vector<Frame> makeFrames(std::size_t n, std::size_t moves, int frames, std::uint64_t seed, double side) {
  std::mt19937_64 rng(seed);
  std::vector<Frame> plan;
  std::vector<std::uint32_t> ids(n);
  for (int f = 0; f < frames; ++f) {
    std::iota(ids.begin(), ids.end(), 0u);
    for (std::size_t j = 0; j < moves; ++j) std::swap(ids[j], ids[j + rng() % (n - j)]);
    Frame frame;
    for (std::size_t j = 0; j < moves; ++j) {
      const double x = (unitInterval(rng) - 0.5) * side;
      const double y = (unitInterval(rng) - 0.5) * side;
      const double z = (unitInterval(rng) - 0.5) * side;
      frame.push_back({ids[j], {x, y, z}});
    }
    plan.push_back(std::move(frame));
  }
  return plan;
}

// "1", "0" or "1%" (of the instances, at least 1).
std::size_t parseMoves(const std::string& text, std::size_t instances) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw InvalidArgument("--moves '" + text + "': expected a count or a percentage such as 1%");
  }
  const bool percent = used < text.size() && text.substr(used) == "%";
  if ((used != text.size() && !percent) || !(value >= 0.0) || (percent && !(value > 0.0)) ||
      (!percent && value != std::floor(value)))
    throw InvalidArgument("--moves '" + text + "': expected a count (0 or more) or a percentage such as 1%");
  const std::size_t m =
      percent ? std::max<std::size_t>(
                    1, static_cast<std::size_t>(std::round(value * static_cast<double>(instances) / 100.0)))
              : static_cast<std::size_t>(value);
  if (m > instances)
    throw InvalidArgument("--moves " + text + " exceeds the scene's " + std::to_string(instances) +
                          " visible instances");
  return m;
}

/// The pixels of `duplex rays --primary W H` in tiles of 4 x 4 (see BenchFrameCommand.h): neighbouring
/// rays go in the same packets.
std::vector<Ray> tiledPrimaryRays(const Box& bounds, std::uint32_t width, std::uint32_t height) {
  const PinholeCamera cam = PinholeCamera::looking_at_box(bounds);
  std::vector<Ray> rays;
  rays.reserve(static_cast<std::size_t>(width) * height);
  for (std::uint32_t ty = 0; ty < height; ty += 4)
    for (std::uint32_t tx = 0; tx < width; tx += 4)
      for (std::uint32_t y = ty; y < std::min(ty + 4, height); ++y)
        for (std::uint32_t x = tx; x < std::min(tx + 4, width); ++x) {
          Ray r;
          r.origin = glm::vec3(cam.eye);
          r.dir = cam.direction(x, y, width, height);
          rays.push_back(r);
        }
  return rays;
}

glm::vec3 lightOf(const Box& bounds) {
  const glm::vec3 c = bounds.center(), ext = bounds.hi - bounds.lo;
  return c + glm::vec3(0.3f * ext.x, 1.5f * ext.y, 0.9f * ext.z);
}

/// Rays per block of the shadow-ray set-up (and of Embree's trace loops): a multiple of 16 rays.
constexpr std::size_t kBlock = bench::kTraceChunk;

/// Writes the shadow ray of every primary hit to `out` in ray order and returns how many; runs in
/// parallel in the caller's arena (a count per block, then the rays), as a renderer would.
std::size_t makeShadowRays(std::span<const Ray> rays, std::span<const Hit> hits, const glm::vec3& light,
                           std::span<Ray> out, std::vector<std::size_t>& offsets) {
  const std::size_t blocks = (rays.size() + kBlock - 1) / kBlock;
  offsets.assign(blocks + 1, 0);
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t b) {
    std::size_t n = 0;
    for (std::size_t i = b * kBlock; i < std::min(rays.size(), (b + 1) * kBlock); ++i) n += hits[i].valid() ? 1 : 0;
    offsets[b + 1] = n;
  });
  std::partial_sum(offsets.begin(), offsets.end(), offsets.begin());
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t b) {
    std::size_t k = offsets[b];
    for (std::size_t i = b * kBlock; i < std::min(rays.size(), (b + 1) * kBlock); ++i) {
      if (!hits[i].valid()) continue;
      Ray s;
      s.origin = rays[i].origin + hits[i].t * rays[i].dir;
      s.dir = light - s.origin;
      s.tnear = 1e-4f;
      s.tfar = 1.0f - 1e-4f;
      out[k++] = s;
    }
  });
  return offsets.back();
}

/// One tracer with its frame buffers. Edits, commits and queries run inside the run's arena.
class Side {
 public:
  Side(std::string name, std::size_t rays, std::vector<Affine> initial)
      : name_(std::move(name)), current_(std::move(initial)), hits_(rays), shadow_(rays), blocked_(rays) {}
  virtual ~Side() = default;
  Side(const Side&) = delete;
  Side& operator=(const Side&) = delete;
  [[nodiscard]] const std::string& name() const { return name_; }

  struct Result {
    double edit_ms = 0.0, trace_ms = 0.0, primary_ms = 0.0;
    std::uint64_t primary_hits = 0, shadow_rays = 0, shadow_blocked = 0;
  };
  /// One frame: the moves, the commit, the primary rays, the shadow rays. Times everything from the
  /// first edit to the last answer; counts the hits afterwards.
  Result frame(const Frame& moves, std::span<const Ray> rays, const glm::vec3& light) {
    Result r;
    const Stopwatch watch;
    for (const Move& m : moves) {
      current_[m.instance].translation += m.delta_ws;
      setTransform(m.instance, current_[m.instance]);
    }
    commit();
    r.edit_ms = watch.ms();
    intersect(rays, hits_);
    r.primary_ms = watch.ms() - r.edit_ms;
    const std::size_t shadows = makeShadowRays(rays, hits_, light, shadow_, offsets_);
    occluded(std::span<const Ray>(shadow_).first(shadows), std::span<std::uint8_t>(blocked_).first(shadows));
    r.trace_ms = watch.ms() - r.edit_ms;
    for (const Hit& h : hits_) r.primary_hits += h.valid() ? 1u : 0u;
    r.shadow_rays = shadows;
    for (std::size_t i = 0; i < shadows; ++i) r.shadow_blocked += blocked_[i] != 0 ? 1u : 0u;
    return r;
  }

 protected:
  virtual void setTransform(std::uint32_t instance, const Affine& world_from_object) = 0;
  virtual void commit() = 0;
  virtual void intersect(std::span<const Ray> rays, std::span<Hit> hits) = 0;
  virtual void occluded(std::span<const Ray> rays, std::span<std::uint8_t> blocked) = 0;

 private:
  std::string name_;
  std::vector<Affine> current_;  ///< world_from_object by instance index
  std::vector<Hit> hits_;
  std::vector<Ray> shadow_;
  std::vector<std::uint8_t> blocked_;
  std::vector<std::size_t> offsets_;
};

/// Ours: the document's graph with a SceneTracer, edited and queried as an application would.
class Ours final : public Side {
 public:
  Ours(SceneGraph& graph, std::span<const NodeId> nodes, std::span<const std::optional<Affine>> parent_from_world,
       std::size_t rays, std::vector<Affine> initial)
      : Side("ours", rays, std::move(initial)),
        graph_(graph),
        nodes_(nodes),
        parent_from_world_(parent_from_world),
        tracer_(graph) {}

 protected:
  void setTransform(std::uint32_t instance, const Affine& world_from_object) override {
    const std::optional<Affine>& parent_from_world = parent_from_world_[instance];
    graph_.setTransform(nodes_[instance],
                        parent_from_world ? *parent_from_world * world_from_object : world_from_object);
  }
  void commit() override { (void)graph_.commit(); }
  void intersect(std::span<const Ray> rays, std::span<Hit> hits) override { tracer_.intersect(rays, hits); }
  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> blocked) override {
    tracer_.occluded(rays, blocked);
  }

 private:
  SceneGraph& graph_;
  std::span<const NodeId> nodes_;
  std::span<const std::optional<Affine>> parent_from_world_;
  SceneTracer tracer_;
};

#if DUPLEX_BENCH_HAVE_EMBREE
/// Embree's two-level scene, traced one ray per call or in packets of 16 consecutive rays (primary
/// rays with the coherent flag, Embree's fastest form for camera rays), over blocks of rays in parallel.
class EmbreeSide final : public Side {
 public:
  EmbreeSide(bench::EmbreeDevice& device, std::span<const TriangleMesh* const> meshes,
             std::span<const bench::EmbreeInstanceDesc> instances, bench::EmbreeTopLevelMode mode, bool packets,
             std::size_t rays, std::vector<Affine> initial)
      : Side(std::string("embree_") + bench::toString(mode) + (packets ? "_16" : "_1"), rays, std::move(initial)),
        scene_(device, meshes, instances, mode),
        packets_(packets) {}

 protected:
  void setTransform(std::uint32_t instance, const Affine& world_from_object) override {
    scene_.setTransform(instance, world_from_object);
  }
  void commit() override { scene_.commit(); }

  void intersect(std::span<const Ray> rays, std::span<Hit> hits) override {
    const RTCScene scene = scene_.scene();
    forBlocks(rays.size(), [&](std::size_t begin, std::size_t end) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      if (!packets_) {
        for (std::size_t i = begin; i < end; ++i) {
          RTCRayHit rh = bench::toRayHit(rays[i], rays[i].tfar);
          rtcIntersect1(scene, &ctx, &rh);
          hits[i] = Hit{};
          if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
          hits[i].t = rh.ray.tfar;
          hits[i].prim_id = rh.hit.primID;
          hits[i].instance_id = rh.hit.instID[0];
        }
        return;
      }
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      for (std::size_t i = begin; i < end; i += 16) {
        alignas(64) RTCRayHit16 rh;
        alignas(64) int valid[16];
        const std::size_t m = std::min<std::size_t>(16, end - i);
        fill(rh.ray, rays.subspan(i, m), valid);
        for (int j = 0; j < 16; ++j) {
          rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
          rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid, scene, &ctx, &rh);
        for (std::size_t j = 0; j < m; ++j) {
          Hit& h = hits[i + j];
          h = Hit{};
          if (rh.hit.geomID[j] == RTC_INVALID_GEOMETRY_ID) continue;
          h.t = rh.ray.tfar[j];
          h.prim_id = rh.hit.primID[j];
          h.instance_id = rh.hit.instID[0][j];
        }
      }
    });
  }

  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> blocked) override {
    const RTCScene scene = scene_.scene();
    forBlocks(rays.size(), [&](std::size_t begin, std::size_t end) {
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      if (!packets_) {
        for (std::size_t i = begin; i < end; ++i) {
          RTCRayHit rh = bench::toRayHit(rays[i], rays[i].tfar);
          rtcOccluded1(scene, &ctx, &rh.ray);
          blocked[i] = rh.ray.tfar < 0.0f ? 1 : 0;  // Embree sets tfar to -inf on an occlusion
        }
        return;
      }
      // No coherent flag: with it, Embree 3.13.5's rtcOccluded16 does not return on shadow rays
      // through instances of the paper's scenes; rtcIntersect16 is not affected.
      for (std::size_t i = begin; i < end; i += 16) {
        alignas(64) RTCRay16 r;
        alignas(64) int valid[16];
        const std::size_t m = std::min<std::size_t>(16, end - i);
        fill(r, rays.subspan(i, m), valid);
        rtcOccluded16(valid, scene, &ctx, &r);
        for (std::size_t j = 0; j < m; ++j) blocked[i + j] = r.tfar[j] < 0.0f ? 1 : 0;
      }
    });
  }

 private:
  // Blocks of rays in parallel in the caller's arena, as bench::timeTrace splits its loops, with
  // Embree's recommended floating-point mode on every thread that traces.
  template <class Fn>
  static void forBlocks(std::size_t n, const Fn& fn) {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, n, kBlock),
        [&](const tbb::blocked_range<std::size_t>& range) {
          bench::setFtzDaz();
          fn(range.begin(), range.end());
        },
        tbb::simple_partitioner());
  }
  static void fill(RTCRay16& ray, std::span<const Ray> rays, int* valid) {
    for (std::size_t j = 0; j < 16; ++j) {
      const bool on = j < rays.size();
      valid[j] = on ? -1 : 0;
      const Ray& r = rays[on ? j : 0];
      ray.org_x[j] = r.origin.x;
      ray.org_y[j] = r.origin.y;
      ray.org_z[j] = r.origin.z;
      ray.dir_x[j] = r.dir.x;
      ray.dir_y[j] = r.dir.y;
      ray.dir_z[j] = r.dir.z;
      ray.tnear[j] = r.tnear;
      ray.tfar[j] = r.tfar;
      ray.time[j] = 0.0f;
      ray.mask[j] = 0xFFFFFFFFu;
      ray.id[j] = 0;
      ray.flags[j] = 0;
    }
  }

  bench::EmbreeTwoLevel scene_;
  bool packets_;
};
#endif

/// Figures of one side over one run's frames.
struct SideFigures {
  std::vector<double> frame_ms, edit_ms, trace_ms, primary_ms, shadow_ms;
  std::vector<std::uint64_t> primary_hits, shadow_rays, shadow_blocked;
  Side::Result static_frame;
  void add(const Side::Result& r) {
    frame_ms.push_back(r.edit_ms + r.trace_ms);
    edit_ms.push_back(r.edit_ms);
    trace_ms.push_back(r.trace_ms);
    primary_ms.push_back(r.primary_ms);
    shadow_ms.push_back(r.trace_ms - r.primary_ms);
    primary_hits.push_back(r.primary_hits);
    shadow_rays.push_back(r.shadow_rays);
    shadow_blocked.push_back(r.shadow_blocked);
  }
  [[nodiscard]] nlohmann::ordered_json json() const {
    nlohmann::ordered_json j;
    j["frame_ms_median"] = median(frame_ms);
    j["edit_commit_ms_median"] = median(edit_ms);
    j["trace_ms_median"] = median(trace_ms);
    j["primary_ms_median"] = median(primary_ms);
    j["shadow_ms_median"] = median(shadow_ms);
    j["frame_ms_min"] = *std::min_element(frame_ms.begin(), frame_ms.end());
    j["frame_ms_max"] = *std::max_element(frame_ms.begin(), frame_ms.end());
    j["static_primary_hits"] = static_frame.primary_hits;
    j["static_shadow_blocked"] = static_frame.shadow_blocked;
    j["frame_ms"] = frame_ms;
    j["edit_commit_ms"] = edit_ms;
    j["trace_ms"] = trace_ms;
    j["primary_hits"] = primary_hits;
    j["shadow_rays"] = shadow_rays;
    j["shadow_blocked"] = shadow_blocked;
    return j;
  }
};

#if DUPLEX_BENCH_HAVE_EMBREE
std::uint64_t absDiff(std::uint64_t a, std::uint64_t b) { return a > b ? a - b : b - a; }
#endif

}  // namespace

nlohmann::ordered_json runBenchFrame(const BenchFrameOptions& options) {
  if (options.frames < 1) throw InvalidArgument("--frames must be at least 1");
  if (options.moves.empty()) throw InvalidArgument("--moves: give at least one count or percentage");
  if (options.threads.empty()) throw InvalidArgument("--threads: give at least one thread count");
  for (const int t : options.threads)
    if (t < 1) throw InvalidArgument("--threads: thread counts must be at least 1");
  const int max_threads = *std::max_element(options.threads.begin(), options.threads.end());
  WorkerThreads workers(max_threads);

  std::optional<SceneDocument> doc;
  workers.arena.execute([&] { doc.emplace(loadDocumentNamed(options.scene, documentOptions(options.structure))); });
  SceneGraph& graph = *doc->graph;
  const ObjectLibrary& library = graph.library();

  // The benchmark's instances: the visible ones, in document order, with what resets them.
  const std::vector<NodeId> instances = visibleInstances(*doc, options.scene);
  std::vector<Affine> initial, initial_local;
  std::vector<std::optional<Affine>> parent_from_world;
  for (const NodeId node : instances) {
    initial.push_back(graph.worldTransform(node));
    const NodeInfo info = graph.node(node);
    initial_local.push_back(info.local);
    // Parents never move: an instance below transform nodes gets the local transform of its world one.
    parent_from_world.push_back(info.parent == kRootNode ? std::nullopt
                                                         : std::optional(graph.worldTransform(info.parent).inverse()));
  }
  const std::size_t n = instances.size();
  std::vector<std::size_t> moves;
  for (const std::string& spec : options.moves) moves.push_back(parseMoves(spec, n));
  // The frame's buffers, per side: the camera rays (shared), hits, shadow rays and their flags.
  const std::uint64_t pixels = std::uint64_t{options.width} * options.height;
  std::size_t side_count = 1;
#if DUPLEX_BENCH_HAVE_EMBREE
  side_count += options.embree_top.size() * options.embree_queries.size();
#endif
  requireMemory(
      saturatingAdd(arrayBytes(pixels, sizeof(Ray)), arrayBytes(pixels, side_count * (sizeof(Hit) + sizeof(Ray) + 1))),
      "bench frame: " + std::to_string(options.width) + " x " + std::to_string(options.height) + " pixels, " +
          std::to_string(side_count) + " side(s)");
  const Box bounds = visibleWorldBounds(*doc);
  const double cube_side = 0.05 * glm::length(glm::dvec3(bounds.hi) - glm::dvec3(bounds.lo));
  const std::vector<Ray> rays = tiledPrimaryRays(bounds, options.width, options.height);
  const glm::vec3 light = lightOf(bounds);

#if DUPLEX_BENCH_HAVE_EMBREE
  // Embree's side takes the same meshes: a scene with other object types is refused.
  std::vector<std::shared_ptr<const Object>> held;
  std::vector<const TriangleMesh*> meshes;
  for (ObjectId i = 0; i < library.size(); ++i) {
    held.push_back(library.get(i));
    const auto* m = dynamic_cast<const MeshObject*>(held.back().get());
    if (!m)
      throw InvalidArgument(options.scene.string() + ": object '" + library.name(i) + "' is of type " +
                            library.typeName(i) + ": Embree's side of bench frame takes mesh objects only");
    meshes.push_back(&m->mesh());
  }
  std::vector<bench::EmbreeInstanceDesc> embree_instances;
  for (std::size_t i = 0; i < n; ++i) embree_instances.push_back({graph.node(instances[i]).object, initial[i]});
#endif

  nlohmann::ordered_json out;
  out["scene"] = options.scene.string();
  out["format"] = doc->format;
  out["objects"] = library.size();
  out["instances"] = n;
  out["triangles"] = doc->figures.count("triangles");
  out["width"] = options.width;
  out["height"] = options.height;
  out["primary_rays"] = rays.size();
  out["frames"] = options.frames;
  out["seed"] = options.seed;
  out["move_cube_side"] = cube_side;
  out["light"] = {light.x, light.y, light.z};
  out["hit_tolerance"] = options.hit_tolerance;
  nlohmann::ordered_json runs = nlohmann::ordered_json::array();
  nlohmann::ordered_json side_names;

  bench::Arenas arenas;
  for (const int threads : options.threads) {
    tbb::task_arena& arena = arenas.get(threads);
#if DUPLEX_BENCH_HAVE_EMBREE
    // One device at a time, limited to this run's threads: Embree's commits build in its arena.
    bench::EmbreeDevice device(threads, "");
#endif
    for (std::size_t r = 0; r < moves.size(); ++r) {
      std::cerr << "bench frame: " << threads << " thread(s), " << options.moves[r] << " moved (" << moves[r]
                << " instance(s)) per frame\n";
      // Every run starts from the loaded transforms, with a fresh tracer.
      for (std::size_t i = 0; i < n; ++i) graph.setTransform(instances[i], initial_local[i]);
      arena.execute([&] { (void)graph.commit(); });
      const std::vector<Frame> plan = makeFrames(n, moves[r], options.frames, options.seed, cube_side);

      std::vector<std::unique_ptr<Side>> sides;
      arena.execute([&] {
        sides.push_back(std::make_unique<Ours>(graph, instances, parent_from_world, rays.size(), initial));
#if DUPLEX_BENCH_HAVE_EMBREE
        for (const std::string& top : options.embree_top)
          for (const std::string& queries : options.embree_queries)
            sides.push_back(std::make_unique<EmbreeSide>(
                device, meshes, embree_instances,
                top == "dynamic_low" ? bench::EmbreeTopLevelMode::DynamicLow : bench::EmbreeTopLevelMode::Default,
                queries == "16", rays.size(), initial));
#endif
      });
      std::vector<SideFigures> figures(sides.size());
      // An untimed frame without moves first: lazy set-up out of the timed frames, and the static hits.
      arena.execute([&] {
        for (std::size_t s = 0; s < sides.size(); ++s) figures[s].static_frame = sides[s]->frame({}, rays, light);
      });
      for (int f = 0; f < options.frames; ++f) {
        arena.execute([&] {
          for (std::size_t k = 0; k < sides.size(); ++k) {
            const std::size_t s = (k + static_cast<std::size_t>(f)) % sides.size();
            figures[s].add(sides[s]->frame(plan[static_cast<std::size_t>(f)], rays, light));
          }
        });
      }

      nlohmann::ordered_json run;
      run["threads"] = threads;
      run["moves_spec"] = options.moves[r];
      run["moves"] = moves[r];
      side_names = nlohmann::ordered_json::array();
      for (std::size_t s = 0; s < sides.size(); ++s) {
        run[sides[s]->name()] = figures[s].json();
        side_names.push_back(sides[s]->name());
      }
#if DUPLEX_BENCH_HAVE_EMBREE
      if (sides.size() > 1) {
        std::size_t best = 1;
        for (std::size_t s = 2; s < sides.size(); ++s)
          if (median(figures[s].frame_ms) < median(figures[best].frame_ms)) best = s;
        const SideFigures& ours = figures[0];
        const SideFigures& e = figures[best];
        run["embree_best"] = sides[best]->name();
        run["embree_frame_ms_median"] = median(e.frame_ms);
        run["embree_edit_commit_ms_median"] = median(e.edit_ms);
        run["embree_trace_ms_median"] = median(e.trace_ms);
        run["ratio_frame"] = median(ours.frame_ms) / median(e.frame_ms);
        run["ratio_edit_commit"] = median(ours.edit_ms) / median(e.edit_ms);
        run["ratio_trace"] = median(ours.trace_ms) / median(e.trace_ms);
        nlohmann::ordered_json per_side;
        std::uint64_t hits_diff = 0, shadow_diff = 0;
        for (std::size_t s = 1; s < sides.size(); ++s) {
          per_side[sides[s]->name()] = median(ours.frame_ms) / median(figures[s].frame_ms);
          hits_diff =
              std::max(hits_diff, absDiff(ours.static_frame.primary_hits, figures[s].static_frame.primary_hits));
          shadow_diff =
              std::max(shadow_diff, absDiff(ours.static_frame.shadow_blocked, figures[s].static_frame.shadow_blocked));
          for (std::size_t f = 0; f < ours.frame_ms.size(); ++f) {
            hits_diff = std::max(hits_diff, absDiff(ours.primary_hits[f], figures[s].primary_hits[f]));
            shadow_diff = std::max(shadow_diff, absDiff(ours.shadow_blocked[f], figures[s].shadow_blocked[f]));
          }
        }
        run["ratio_frame_per_side"] = per_side;
        run["hits_max_diff"] = hits_diff;
        run["shadow_max_diff"] = shadow_diff;
        // Both counts against the frame's pixels: a shadow ray starts where its side's own primary hit
        // lies, so rounding moves a few starts across a nearby surface.
        const double allowed = options.hit_tolerance * static_cast<double>(rays.size());
        run["hits_agree"] = static_cast<double>(hits_diff) <= allowed && static_cast<double>(shadow_diff) <= allowed;
      }
#endif
      runs.push_back(std::move(run));
      // The tracer and Embree's scenes go before the graph is reset and before the device.
      arena.execute([&] { sides.clear(); });
    }
  }
  out["sides"] = side_names;
  out["runs"] = std::move(runs);
  out["machine"] = bench::machineInfo(bench::thisBuild());
  return out;
}

}  // namespace duplex::cli
