// The main benchmark: per mesh, our kd-tree against Embree 3 (medium and high build quality) on the
// same rays, builds and traces interleaved per repetition, medians of the repetitions, ratios taken
// within the run.

#include "BenchBuild.h"
#include "BenchChecks.h"
#include "BenchMeshes.h"
#include "BenchModes.h"
// The objects library's private per-ray setup, for the time split only (as its unit test does).
#include "../objects/mesh/src/MeshRay.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <sstream>
#include <tuple>

namespace duplex::bench {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The tracers of one run: ours always, Embree's two qualities when available.
enum Tracer { kOurs = 0, kEmbreeMedium = 1, kEmbreeHigh = 2, kTracers = 3 };
constexpr const char* kTracerKey[kTracers] = {"ours", "embree_medium", "embree_high"};

struct RaySet {
  std::string name;
  std::vector<Ray> rays;
};

// The cumulative parts of a closest-hit query that MeshBench::timeSplit times, each called out of
// line as MeshObject::intersect is: the harness alone (read the ray, write the hit), + the per-ray
// setup, + the traversal visiting every leaf the full query visits (t_best starts at the ray's final
// hit distance) with leaves counted but no triangle test.
[[gnu::noinline]] bool splitHarness(const Ray& ray, Hit& hit) {
  hit.t = ray.tfar;
  return !(ray.tnear <= ray.tfar);
}
[[gnu::noinline]] bool splitSetup(const MeshObject& object, const Ray& ray, Hit& hit) {
  detail::MeshRay r;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray, object.tree().bounds, r, tmin, tmax)) return false;
  hit.t = tmin;
  hit.u = tmax;
  return false;
}
// The tree's nodes are those of the query's tree (only leaf offsets differ, which are not read here).
[[gnu::noinline]] bool splitTraversal(const MeshObject& object, const Ray& ray, float t_final, Hit& hit) {
  detail::MeshRay r;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray, object.tree().bounds, r, tmin, tmax)) return false;
  float t_best = std::min(t_final, ray.tfar);
  std::uint32_t leaves = 0;
  traverseKdTreeClipped<false>(object.tree(), r.kd, tmin, tmax, t_best, [&](std::uint32_t, std::uint32_t, float&) {
    ++leaves;
    return false;
  });
  hit.t = t_best;
  hit.prim_id = leaves;
  return false;
}
#if DUPLEX_BENCH_HAVE_EMBREE
[[gnu::noinline]] bool splitEmbreeHarness(const Ray& ray, Hit& hit) {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh = toRayHit(ray, std::min(ray.tfar, hit.t));
  asm volatile("" : : "r"(&rh), "r"(&context) : "memory");  // built as for rtcIntersect1, not traced
  hit.t = rh.ray.tfar;
  return rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
}
#endif

nlohmann::json configJson(const KdBuildConfig& c) {
  return {{"heuristic", std::string(toString(c.heuristic))},
          {"traversal_cost", c.traversal_cost},
          {"intersection_cost", c.intersection_cost},
          {"empty_bonus", c.empty_bonus},
          {"max_depth", c.max_depth},
          {"max_leaf_size", c.max_leaf_size},
          {"parallel_threshold", c.parallel_threshold},
          {"clip_primitives", c.clip_primitives}};
}

nlohmann::json statsJson(const KdTreeStats& s) {
  return {{"nodes", s.nodes},
          {"inner_nodes", s.inner_nodes},
          {"leaves", s.leaves},
          {"empty_leaves", s.empty_leaves},
          {"references", s.references},
          {"max_depth", s.max_depth},
          {"avg_leaf_size", s.avg_leaf_size},
          {"sah_cost", s.sah_cost},
          {"bytes", s.bytes}};
}

double ratio(double a, double b) { return (std::isfinite(a) && std::isfinite(b) && b > 0.0) ? a / b : kNaN; }

// JSON number or null (nlohmann writes NaN as null anyway; this keeps the intent visible).
nlohmann::json num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

// Embree's side of a run: whether it takes part, and the device and scenes being traced. Only one
// device lives at a time (see EmbreeBaseline.h: a second device with more threads lets a
// "threads=1" device build on two).
struct EmbreeSide {
  bool enabled_ = false;
#if DUPLEX_BENCH_HAVE_EMBREE
  std::string config;
  std::unique_ptr<EmbreeDevice> device;
  std::unique_ptr<EmbreeMesh> scenes[kTracers];  // [kEmbreeMedium], [kEmbreeHigh]
  void release() {
    for (auto& scene : scenes) scene.reset();  // scenes before their device
    device.reset();
  }
#endif
  [[nodiscard]] bool enabled() const { return enabled_; }
};

class MeshBench {
 public:
  MeshBench(const Options& options, const std::vector<int>& threads, Arenas& arenas, EmbreeSide& embree)
      : options_(options), threads_(threads), arenas_(arenas), embree_(embree) {}

  nlohmann::json run(const LoadedMesh& loaded);

 private:
  [[nodiscard]] bool haveEmbree() const { return embree_.enabled(); }
  void build(const LoadedMesh& loaded, nlohmann::json& out);
  void checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out);
  void trace(const std::vector<RaySet>& sets, nlohmann::json& out);
  void timeSplit(const RaySet& random, nlohmann::json& out);

  const Options& options_;
  const std::vector<int>& threads_;
  Arenas& arenas_;
  KdBuildConfig config_{};
  EmbreeSide& embree_;
  std::unique_ptr<MeshObject> ours_;
};

nlohmann::json MeshBench::run(const LoadedMesh& loaded) {
  const TriangleMesh& mesh = *loaded.mesh;
  const std::size_t triangles = mesh.triangleCount();
  std::cerr << "\n== " << loaded.spec.label() << ": " << thousands(triangles) << " triangles ("
            << mesh.degenerateCount() << " degenerate)\n";
  nlohmann::json out;
  out["mesh"] = loaded.spec.label();
  out["file"] = loaded.path;
  out["loop_steps"] = loaded.spec.loop_steps;
  out["triangles"] = triangles;
  out["vertices"] = mesh.positions().size();
  out["degenerate_triangles"] = mesh.degenerateCount();
  out["load_ms"] = loaded.load_ms;
  out["subdivide_ms"] = loaded.subdivide_ms;

  build(loaded, out);

  // The rays of `duplex rays`: random rays in the bounds and the default camera's primary rays.
  std::vector<RaySet> sets;
  sets.push_back({"random", randomRays(mesh.bounds(), options_.random_rays, options_.seed)});
  sets.push_back({"primary", primaryRays(mesh.bounds(), options_.primary_width, options_.primary_height)});
  out["rays"] = {{"random", sets[0].rays.size()},
                 {"primary", sets[1].rays.size()},
                 {"primary_width", options_.primary_width},
                 {"primary_height", options_.primary_height},
                 {"seed", options_.seed}};

  checkAgreement(mesh, sets, out);

  // Work per ray of our closest-hit query (untimed), on every k-th ray: a prefix of the primary rays
  // would be the top rows of the image, which miss.
  nlohmann::json counters;
  for (const RaySet& set : sets) {
    const std::size_t stride = std::max<std::size_t>(1, set.rays.size() / 200'000);
    std::vector<Ray> sample;
    for (std::size_t i = 0; i < set.rays.size(); i += stride) sample.push_back(set.rays[i]);
    const TraversalCounts c = countTraversal(arenas_.get(threads_.back()), *ours_, sample);
    counters[set.name] = c.toJson();
    counters[set.name]["rays"] = sample.size();
    counters[set.name]["stride"] = stride;
  }
  out["ours"]["traversal"] = counters;

  trace(sets, out);
  timeSplit(sets[0], out);
  ours_.reset();
#if DUPLEX_BENCH_HAVE_EMBREE
  embree_.release();
#endif
  return out;
}

void MeshBench::build(const LoadedMesh& loaded, nlohmann::json& out) {
  const TriangleMesh& mesh = *loaded.mesh;
  const double triangles = static_cast<double>(mesh.triangleCount());
  // Wall ms per tracer and thread count; CPU ms (calling thread) for one thread only, with the
  // process's CPU ms next to it to check that one thread did all the work.
  std::map<int, std::vector<double>> ms[kTracers], cpu_ms[kTracers], process_cpu_ms[kTracers];
  double bytes[kTracers] = {0.0, 0.0, 0.0};
  const Stopwatch phase;
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (const int t : threads_) {
      auto record = [&](int tracer, const Timing& time) {
        ms[tracer][t].push_back(time.wall_ms);
        if (t == 1) {
          cpu_ms[tracer][t].push_back(time.cpu_ms);
          process_cpu_ms[tracer][t].push_back(time.process_cpu_ms);
        }
      };
      auto buildOurs = [&] {
        ours_.reset();
        record(kOurs, timeIt(t, [&] {
                 arenas_.get(t).execute([&] { ours_ = std::make_unique<MeshObject>(loaded.mesh, config_); });
               }));
      };
      auto buildEmbree = [&] {
#if DUPLEX_BENCH_HAVE_EMBREE
        if (!haveEmbree()) return;
        // A fresh device limited to t threads, the only one alive while it builds.
        embree_.release();
        embree_.device = std::make_unique<EmbreeDevice>(t, embree_.config);
        for (const Tracer e : {kEmbreeMedium, kEmbreeHigh}) {
          std::unique_ptr<EmbreeMesh> scene;
          record(e, timeIt(t, [&] {
                   scene = std::make_unique<EmbreeMesh>(
                       *embree_.device, mesh, e == kEmbreeMedium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
                 }));
          bytes[e] = static_cast<double>(scene->accelBytes());
        }
        embree_.release();
#endif
      };
      // Alternate the order between repetitions so that drift on the shared machine hits both sides.
      if (rep % 2 == 0) {
        buildOurs();
        buildEmbree();
      } else {
        buildEmbree();
        buildOurs();
      }
    }
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  // The scenes that are traced (untimed builds, on a device with the most threads).
  if (haveEmbree()) {
    embree_.device = std::make_unique<EmbreeDevice>(threads_.back(), embree_.config);
    embree_.scenes[kEmbreeMedium] = std::make_unique<EmbreeMesh>(*embree_.device, mesh, RTC_BUILD_QUALITY_MEDIUM);
    embree_.scenes[kEmbreeHigh] = std::make_unique<EmbreeMesh>(*embree_.device, mesh, RTC_BUILD_QUALITY_HIGH);
  }
#endif
  std::cerr << "  builds: " << options_.repeat << " x " << threads_.size() << " thread counts in "
            << fmt(phase.ms() / 1e3, 1) << " s\n";

  const KdTreeStats stats = ours_->tree().stats(config_.traversal_cost, config_.intersection_cost);
  nlohmann::json& ours = out["ours"];
  ours["config"] = configJson(config_);
  ours["stats"] = statsJson(stats);
  ours["accel_bytes"] = ours_->accelBytes();
  ours["memory_bytes"] = ours_->memoryBytes();
  ours["bytes_per_triangle"] = static_cast<double>(ours_->accelBytes()) / triangles;
  double bytes_per_triangle[kTracers] = {static_cast<double>(ours_->accelBytes()) / triangles, kNaN, kNaN};
#if DUPLEX_BENCH_HAVE_EMBREE
  if (haveEmbree()) {
    for (const Tracer e : {kEmbreeMedium, kEmbreeHigh}) {
      nlohmann::json& j = out[kTracerKey[e]];
      j["quality"] = toString(e == kEmbreeMedium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
      j["accel_bytes"] = embree_.scenes[e]->accelBytes();
      j["total_bytes"] = embree_.scenes[e]->totalBytes();
      j["accel_bytes_timed_build"] = bytes[e];
      bytes_per_triangle[e] = static_cast<double>(embree_.scenes[e]->accelBytes()) / triangles;
      j["bytes_per_triangle"] = bytes_per_triangle[e];
    }
  }
#endif
  nlohmann::json builds = nlohmann::json::array();
  std::cerr << "  build ms    " << pad("threads", 9) << lpad("ours", 10) << lpad("emb-med", 10) << lpad("emb-high", 10)
            << lpad("/med", 8) << lpad("/high", 8) << lpad("/med cpu", 10) << "\n";
  for (const int t : threads_) {
    double med[kTracers], cpu[kTracers];
    for (int k = 0; k < kTracers; ++k) {
      med[k] = ms[k].count(t) ? median(ms[k][t]) : kNaN;
      cpu[k] = cpu_ms[k].count(t) ? median(cpu_ms[k][t]) : kNaN;
    }
    nlohmann::json rec{{"threads", t}};
    for (int k = 0; k < kTracers; ++k) {
      if (!std::isfinite(med[k])) continue;
      const std::string name = kTracerKey[k];
      rec[name + "_ms"] = med[k];
      rec[name + "_ms_samples"] = ms[k][t];
      out[name]["build_ms"][std::to_string(t)] = med[k];
      if (std::isfinite(cpu[k])) {
        rec[name + "_cpu_ms"] = cpu[k];
        rec[name + "_cpu_ms_samples"] = cpu_ms[k][t];
        rec[name + "_process_cpu_ms"] = median(process_cpu_ms[k][t]);
        out[name]["build_cpu_ms"][std::to_string(t)] = cpu[k];
        // A one-thread build whose process used clearly more CPU than the calling thread ran elsewhere too.
        const double process = median(process_cpu_ms[k][t]);
        if (process > 1.2 * cpu[k] + 5.0)
          std::cerr << "  WARNING: the 1-thread build of " << name << " used " << fmt(process / cpu[k])
                    << "x the CPU of the calling thread\n";
      }
    }
    rec["ratio_vs_embree_medium"] = num(ratio(med[kOurs], med[kEmbreeMedium]));
    rec["ratio_vs_embree_high"] = num(ratio(med[kOurs], med[kEmbreeHigh]));
    rec["ratio_cpu_vs_embree_medium"] = num(ratio(cpu[kOurs], cpu[kEmbreeMedium]));
    rec["ratio_cpu_vs_embree_high"] = num(ratio(cpu[kOurs], cpu[kEmbreeHigh]));
    builds.push_back(rec);
    std::cerr << "              " << pad(std::to_string(t), 9) << lpad(fmt(med[kOurs], 1), 10)
              << lpad(fmt(med[kEmbreeMedium], 1), 10) << lpad(fmt(med[kEmbreeHigh], 1), 10)
              << lpad(fmt(ratio(med[kOurs], med[kEmbreeMedium])) + "x", 8)
              << lpad(fmt(ratio(med[kOurs], med[kEmbreeHigh])) + "x", 8)
              << lpad(fmt(ratio(cpu[kOurs], cpu[kEmbreeMedium])) + "x", 10) << "\n";
  }
  out["build"] = builds;
  std::cerr << "  bytes/tri   ours " << fmt(bytes_per_triangle[kOurs], 1) << "  emb-med "
            << fmt(bytes_per_triangle[kEmbreeMedium], 1) << "  emb-high " << fmt(bytes_per_triangle[kEmbreeHigh], 1)
            << "\n";
  std::cerr << "  tree        nodes " << thousands(stats.nodes) << "  leaves " << thousands(stats.leaves) << " ("
            << thousands(stats.empty_leaves) << " empty)  avg leaf " << fmt(stats.avg_leaf_size) << "  SAH "
            << fmt(stats.sah_cost, 1) << "  depth " << stats.max_depth << "\n";
  out["ratios"]["vs_embree_medium"]["bytes_per_triangle"] =
      num(ratio(bytes_per_triangle[kOurs], bytes_per_triangle[kEmbreeMedium]));
  out["ratios"]["vs_embree_high"]["bytes_per_triangle"] =
      num(ratio(bytes_per_triangle[kOurs], bytes_per_triangle[kEmbreeHigh]));
  for (const auto& rec : builds) {
    const std::string key = std::to_string(rec["threads"].get<int>()) + "T";
    out["ratios"]["vs_embree_medium"]["build"][key] = rec["ratio_vs_embree_medium"];
    out["ratios"]["vs_embree_high"]["build"][key] = rec["ratio_vs_embree_high"];
    if (!rec["ratio_cpu_vs_embree_medium"].is_null()) {
      out["ratios"]["vs_embree_medium"]["build_cpu"][key] = rec["ratio_cpu_vs_embree_medium"];
      out["ratios"]["vs_embree_high"]["build_cpu"][key] = rec["ratio_cpu_vs_embree_high"];
    }
  }
}

void MeshBench::checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out) {
  nlohmann::json agreement;
  if (!haveEmbree()) {
    out["agreement"] = nullptr;
    return;
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  tbb::task_arena& arena = arenas_.get(threads_.back());
  const float inf = std::numeric_limits<float>::infinity();
  for (const RaySet& set : sets) {
    const std::size_t n = set.rays.size();
    std::vector<float> t[kTracers];
    std::vector<std::uint8_t> occluded_ours(n), occluded_medium(n);
    for (auto& v : t) v.assign(n, inf);
    parallelFor(arena, n, [&](std::size_t i) {
      const Ray& r = set.rays[i];
      Hit h[kTracers];
      if (ours_->intersect(r, h[kOurs])) t[kOurs][i] = h[kOurs].t;
      if (embree_.scenes[kEmbreeMedium]->intersect(r, h[kEmbreeMedium])) t[kEmbreeMedium][i] = h[kEmbreeMedium].t;
      if (embree_.scenes[kEmbreeHigh]->intersect(r, h[kEmbreeHigh])) t[kEmbreeHigh][i] = h[kEmbreeHigh].t;
      occluded_ours[i] = ours_->occluded(r);
      occluded_medium[i] = embree_.scenes[kEmbreeMedium]->occluded(r);
    });
    std::uint64_t hits[kTracers] = {}, hitmiss_medium = 0, hitmiss_high = 0, t_mismatch = 0, any_disagree = 0,
                  ours_any_vs_closest = 0;
    std::vector<std::size_t> disputed;
    const double scale = glm::length(mesh.bounds().extent());
    for (std::size_t i = 0; i < n; ++i) {
      const bool ho = t[kOurs][i] < inf, hm = t[kEmbreeMedium][i] < inf, hh = t[kEmbreeHigh][i] < inf;
      hits[kOurs] += ho;
      hits[kEmbreeMedium] += hm;
      hits[kEmbreeHigh] += hh;
      if (ho != hm) {
        ++hitmiss_medium;
        disputed.push_back(i);
      }
      hitmiss_high += ho != hh;
      if (ho && hm) {
        const double dt = std::abs(static_cast<double>(t[kOurs][i]) - t[kEmbreeMedium][i]);
        if (dt > 1e-4 * std::max<double>(t[kOurs][i], t[kEmbreeMedium][i]) + 1e-6 * scale) ++t_mismatch;
      }
      any_disagree += occluded_ours[i] != occluded_medium[i];
      ours_any_vs_closest += (occluded_ours[i] != 0) != ho;
    }
    // A double-precision brute force decides a sample of the disputed rays.
    constexpr std::size_t kRefereeSample = 48;
    std::uint64_t referee_ours = 0, referee_embree = 0;
    const std::size_t examined = std::min(disputed.size(), kRefereeSample);
    nlohmann::json wrong_ours = nlohmann::json::array();  // rays to reproduce where the referee says we are wrong
    for (std::size_t k = 0; k < examined; ++k) {
      const std::size_t i = disputed[k * disputed.size() / examined];
      const Ray& r = set.rays[i];
      const bool truth = refereeHits(arena, mesh, r);
      if (truth == (t[kOurs][i] < inf)) {
        ++referee_ours;
      } else if (wrong_ours.size() < 5) {
        wrong_ours.push_back({{"index", i},
                              {"origin", {r.origin.x, r.origin.y, r.origin.z}},
                              {"dir", {r.dir.x, r.dir.y, r.dir.z}},
                              {"tnear", r.tnear},
                              {"ours_t", num(t[kOurs][i])},
                              {"embree_medium_t", num(t[kEmbreeMedium][i])},
                              {"referee_hits", truth}});
      }
      if (truth == (t[kEmbreeMedium][i] < inf)) ++referee_embree;
    }
    agreement[set.name] = {{"rays", n},
                           {"hits_ours", hits[kOurs]},
                           {"hits_embree_medium", hits[kEmbreeMedium]},
                           {"hits_embree_high", hits[kEmbreeHigh]},
                           {"hitmiss_disagree_vs_medium", hitmiss_medium},
                           {"hitmiss_disagree_vs_high", hitmiss_high},
                           {"t_mismatch_vs_medium", t_mismatch},
                           {"anyhit_disagree_vs_medium", any_disagree},
                           {"ours_anyhit_vs_closest_disagree", ours_any_vs_closest},
                           {"referee_examined", examined},
                           {"referee_sides_with_ours", referee_ours},
                           {"referee_sides_with_embree", referee_embree},
                           {"rays_referee_says_ours_wrong", wrong_ours}};
    std::cerr << "  agreement   " << pad(set.name, 8) << thousands(hitmiss_medium) << " hit/miss (vs high "
              << thousands(hitmiss_high) << "), " << thousands(any_disagree) << " any-hit, " << thousands(t_mismatch)
              << " t differ, of " << thousands(n) << "; referee on " << examined << ": ours right " << referee_ours
              << ", Embree right " << referee_embree << "\n";
    if (ours_any_vs_closest != 0)
      std::cerr << "  WARNING: our occluded() and intersect() disagree on " << ours_any_vs_closest << " rays\n";
  }
#endif
  out["agreement"] = agreement;
}

void MeshBench::trace(const std::vector<RaySet>& sets, nlohmann::json& out) {
  using Key = std::tuple<std::size_t, Query, int>;  // ray set, query, threads
  std::map<Key, std::vector<double>> ms[kTracers], cpu_ms[kTracers];
  std::map<Key, std::uint64_t> hits[kTracers];
  const int tracers = haveEmbree() ? kTracers : 1;
  const Stopwatch phase;
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (const int t : threads_) {
      tbb::task_arena& arena = arenas_.get(t);
      for (std::size_t s = 0; s < sets.size(); ++s) {
        for (const Query q : {Query::Closest, Query::Any}) {
          const Key key{s, q, t};
          for (int k = 0; k < tracers; ++k) {
            // Interleave ours and Embree's, alternating the order between repetitions.
            const int tracer = rep % 2 == 0 ? k : tracers - 1 - k;
            TraceTiming timing;
            if (tracer == kOurs) {
              timing = timeQuery(arena, sets[s].rays, *ours_, q);
            } else {
#if DUPLEX_BENCH_HAVE_EMBREE
              timing = timeQuery(arena, sets[s].rays, *embree_.scenes[tracer], q);
#endif
            }
            ms[tracer][key].push_back(timing.time.wall_ms);
            cpu_ms[tracer][key].push_back(timing.time.cpu_ms);
            hits[tracer][key] = timing.hits;
          }
        }
      }
    }
  }
  std::cerr << "  traces: " << fmt(phase.ms() / 1e3, 1) << " s\n";
  std::cerr << "  Mrays/s     " << pad("rays", 9) << pad("query", 8) << pad("T", 3) << lpad("ours", 8)
            << lpad("emb-med", 9) << lpad("emb-high", 9) << lpad("/med", 8) << lpad("/high", 8) << lpad("/med cpu", 10)
            << "\n";
  nlohmann::json records = nlohmann::json::array();
  for (const int t : threads_) {
    for (std::size_t s = 0; s < sets.size(); ++s) {
      for (const Query q : {Query::Closest, Query::Any}) {
        const Key key{s, q, t};
        const std::size_t n = sets[s].rays.size();
        nlohmann::json rec{{"rays", sets[s].name}, {"query", toString(q)}, {"threads", t}, {"ray_count", n}};
        double mrays[kTracers] = {kNaN, kNaN, kNaN}, mrays_cpu[kTracers] = {kNaN, kNaN, kNaN};
        for (int k = 0; k < tracers; ++k) {
          const double med = median(ms[k][key]), cpu = median(cpu_ms[k][key]);
          mrays[k] = n / (med * 1e3);
          mrays_cpu[k] = n / (cpu * 1e3);
          const std::string name = kTracerKey[k];
          rec[name + "_ms"] = med;
          rec[name + "_ms_samples"] = ms[k][key];
          rec[name + "_mrays"] = mrays[k];
          rec[name + "_cpu_ms"] = cpu;
          rec[name + "_cpu_ms_samples"] = cpu_ms[k][key];
          rec[name + "_mrays_cpu"] = mrays_cpu[k];
          rec[name + "_hits"] = hits[k][key];
        }
        rec["ratio_vs_embree_medium"] = num(ratio(mrays[kOurs], mrays[kEmbreeMedium]));
        rec["ratio_vs_embree_high"] = num(ratio(mrays[kOurs], mrays[kEmbreeHigh]));
        rec["ratio_cpu_vs_embree_medium"] = num(ratio(mrays_cpu[kOurs], mrays_cpu[kEmbreeMedium]));
        rec["ratio_cpu_vs_embree_high"] = num(ratio(mrays_cpu[kOurs], mrays_cpu[kEmbreeHigh]));
        const std::string label = sets[s].name + " " + toString(q) + " " + std::to_string(t) + "T";
        for (const char* which : {"vs_embree_medium", "vs_embree_high"}) {
          out["ratios"][which]["trace"][label] = rec[std::string("ratio_") + which];
          out["ratios"][which]["trace_cpu"][label] = rec[std::string("ratio_cpu_") + which];
        }
        records.push_back(rec);
        std::cerr << "              " << pad(sets[s].name, 9) << pad(toString(q), 8) << pad(std::to_string(t), 3)
                  << lpad(fmt(mrays[kOurs]), 8) << lpad(fmt(mrays[kEmbreeMedium]), 9)
                  << lpad(fmt(mrays[kEmbreeHigh]), 9) << lpad(fmt(ratio(mrays[kOurs], mrays[kEmbreeMedium])) + "x", 8)
                  << lpad(fmt(ratio(mrays[kOurs], mrays[kEmbreeHigh])) + "x", 8)
                  << lpad(fmt(ratio(mrays_cpu[kOurs], mrays_cpu[kEmbreeMedium])) + "x", 10) << "\n";
      }
    }
  }
  out["trace"] = records;
}

// Where the time of a random closest-hit ray goes, one thread, CPU time, medians of the repetitions
// with the order alternating: the cumulative parts above, our full query and Embree's (medium).
// Differences of the medians give harness, setup, traversal and triangle tests (docs/kdtree.md,
// "Where the time goes").
void MeshBench::timeSplit(const RaySet& random, nlohmann::json& out) {
  const std::span<const Ray> rays = random.rays;
  if (rays.empty()) return;
  tbb::task_arena& arena = arenas_.get(1);
  const MeshObject& object = *ours_;
  std::vector<float> t_final(rays.size());
  parallelFor(arenas_.get(threads_.back()), rays.size(), [&](std::size_t i) {
    Hit hit;
    (void)object.intersect(rays[i], hit);
    t_final[i] = hit.t;
  });
  auto at = [&](const Ray& r) { return t_final[static_cast<std::size_t>(&r - rays.data())]; };
  enum Part { kHarness, kSetup, kTraversal, kFull, kEmbreeHarness, kEmbreeFull, kParts };
  constexpr const char* kKey[kParts] = {"harness", "setup", "traversal", "ours", "embree_harness", "embree_medium"};
  const int parts = haveEmbree() ? kParts : kEmbreeHarness;
  // Each part gets a fresh Hit per ray, as timeQuery gives the full query.
  auto timePart = [&](const auto& part) {
    return timeTrace(arena, rays, [&](const Ray& r) {
      Hit hit;
      return part(r, hit);
    });
  };
  std::vector<double> cpu_ms[kParts];
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (int k = 0; k < parts; ++k) {
      const int part = rep % 2 == 0 ? k : parts - 1 - k;
      TraceTiming timing;
      switch (part) {
        case kHarness: timing = timePart([](const Ray& r, Hit& hit) { return splitHarness(r, hit); }); break;
        case kSetup: timing = timePart([&](const Ray& r, Hit& hit) { return splitSetup(object, r, hit); }); break;
        case kTraversal:
          timing = timePart([&](const Ray& r, Hit& hit) { return splitTraversal(object, r, at(r), hit); });
          break;
        case kFull: timing = timeQuery(arena, rays, object, Query::Closest); break;
#if DUPLEX_BENCH_HAVE_EMBREE
        case kEmbreeHarness:
          timing = timePart([](const Ray& r, Hit& hit) { return splitEmbreeHarness(r, hit); });
          break;
        case kEmbreeFull: timing = timeQuery(arena, rays, *embree_.scenes[kEmbreeMedium], Query::Closest); break;
#endif
        default: break;
      }
      cpu_ms[part].push_back(timing.time.cpu_ms);
    }
  }
  double ns[kParts];
  nlohmann::json split{{"rays", random.name}, {"ray_count", rays.size()}, {"threads", 1}};
  for (int k = 0; k < kParts; ++k) {
    ns[k] = k < parts ? median(cpu_ms[k]) * 1e6 / static_cast<double>(rays.size()) : kNaN;
    split[std::string(kKey[k]) + "_ns"] = num(ns[k]);
    if (k < parts) split[std::string(kKey[k]) + "_cpu_ms_samples"] = cpu_ms[k];
  }
  split["setup_only_ns"] = num(ns[kSetup] - ns[kHarness]);
  split["traversal_only_ns"] = num(ns[kTraversal] - ns[kSetup]);
  split["triangles_only_ns"] = num(ns[kFull] - ns[kTraversal]);
  split["traversal_share"] = num((ns[kTraversal] - ns[kSetup]) / ns[kFull]);
  out["time_split"] = split;
  std::cerr << "  time split  ns per random closest-hit ray, 1T, CPU: harness " << fmt(ns[kHarness], 1) << ", setup "
            << fmt(ns[kSetup] - ns[kHarness], 1) << ", traversal " << fmt(ns[kTraversal] - ns[kSetup], 1)
            << ", triangles " << fmt(ns[kFull] - ns[kTraversal], 1) << ", ours " << fmt(ns[kFull], 1)
            << "; embree harness " << fmt(ns[kEmbreeHarness], 1) << ", embree " << fmt(ns[kEmbreeFull], 1) << "\n";
}

// The goals, evaluated on this run's ratios.
nlohmann::json evaluateGoals(const nlohmann::json& meshes) {
  nlohmann::json trace = nlohmann::json::array(), build = nlohmann::json::array();
  for (const auto& m : meshes) {
    for (const auto& rec : m["trace"]) {
      if (rec["rays"] != "random" || rec["query"] != "closest" || rec["ratio_vs_embree_medium"].is_null()) continue;
      const double r = rec["ratio_vs_embree_medium"].get<double>();
      trace.push_back({{"mesh", m["mesh"]},
                       {"threads", rec["threads"]},
                       {"ratio", r},
                       {"ratio_cpu", rec["ratio_cpu_vs_embree_medium"]},
                       {"goal", 1.0},
                       {"met", r >= 1.0},
                       {"floor", 0.7},
                       {"above_floor", r >= 0.7}});
    }
    if (m["triangles"].get<std::size_t>() < 1'000'000) continue;
    for (const auto& rec : m["build"]) {
      if (rec["ratio_vs_embree_medium"].is_null()) continue;
      const double r = rec["ratio_vs_embree_medium"].get<double>();
      build.push_back({{"mesh", m["mesh"]},
                       {"threads", rec["threads"]},
                       {"ratio", r},
                       {"ratio_cpu", rec["ratio_cpu_vs_embree_medium"]},
                       {"goal", 3.0},
                       {"met", r <= 3.0}});
    }
  }
  return {
      {"random_closest_throughput_vs_embree_medium", trace},
      {"build_time_vs_embree_medium_1M_triangles", build},
      {"note",
       "throughput ratio = our Mrays/s / Embree's (goal >= 1.0, issue unresolved below 0.7); build ratio = our ms / "
       "Embree's (goal <= 3.0, meshes of >= 10^6 triangles); 'ratio' from wall-clock medians, 'ratio_cpu' from CPU "
       "time (see config.clocks); 'met' judges the wall-clock ratio"}};
}

void printSummary(const nlohmann::json& meshes, const std::vector<int>& threads) {
  std::vector<std::string> keys;
  std::ostringstream head;
  head << pad("mesh", 22) << lpad("tris", 10);
  for (const char* rays : {"random", "primary"})
    for (const char* q : {"closest", "any"})
      for (const int t : threads) {
        keys.push_back(std::string(rays) + " " + q + " " + std::to_string(t) + "T");
        head << lpad(std::string(rays).substr(0, 3) + "-" + std::string(q).substr(0, 3) + "-" + std::to_string(t) + "T",
                     11);
      }
  for (const int t : threads) head << lpad("build-" + std::to_string(t) + "T", 10);
  head << lpad("B/tri", 8);
  for (const bool cpu : {false, true}) {
    std::cerr << "\n== Summary: ours / Embree medium, " << (cpu ? "CPU time" : "wall clock")
              << " (throughput: >1 means we are faster; build: <1 means we are faster)\n"
              << head.str() << "\n";
    for (const auto& m : meshes) {
      std::ostringstream row;
      row << pad(m["mesh"].get<std::string>(), 22) << lpad(thousands(m["triangles"].get<std::uint64_t>()), 10);
      const auto& r = m["ratios"]["vs_embree_medium"];
      const auto cell = [](const nlohmann::json& v, std::size_t width) {
        return lpad(v.is_number() ? fmt(v.get<double>()) : "-", width);
      };
      const nlohmann::json none;
      const auto& trace = r.contains(cpu ? "trace_cpu" : "trace") ? r[cpu ? "trace_cpu" : "trace"] : none;
      const auto& build = r.contains(cpu ? "build_cpu" : "build") ? r[cpu ? "build_cpu" : "build"] : none;
      for (const auto& k : keys) row << cell(trace.is_object() && trace.contains(k) ? trace[k] : none, 11);
      for (const int t : threads) {
        const std::string k = std::to_string(t) + "T";
        row << cell(build.is_object() && build.contains(k) ? build[k] : none, 10);
      }
      row << cell(r.contains("bytes_per_triangle") ? r["bytes_per_triangle"] : none, 8);
      std::cerr << row.str() << "\n";
    }
  }
}

}  // namespace

nlohmann::json runMainBench(const Options& options) {
  std::vector<int> threads = options.threads;
  std::sort(threads.begin(), threads.end());
  threads.erase(std::unique(threads.begin(), threads.end()), threads.end());

  EmbreeSide embree;
#if DUPLEX_BENCH_HAVE_EMBREE
  embree.enabled_ = options.with_embree;
  embree.config = options.embree_config;
#endif
  Arenas arenas;
  for (const int t : threads) arenas.get(t);

  nlohmann::json doc;
  doc["kind"] = "duplex_bench_mesh";
  doc["machine"] = machineInfo(thisBuild());
  doc["config"] = {
      {"data", options.data_dir},
      {"meshes", options.meshes},
      {"random_rays", options.random_rays},
      {"primary", {options.primary_width, options.primary_height}},
      {"threads", threads},
      {"repeat", options.repeat},
      {"seed", options.seed},
      {"trace_chunk", kTraceChunk},
      {"quick", options.quick},
      {"embree", embree.enabled()},
      {"embree_config", options.embree_config},
      {"clocks",
       "every figure has a wall-clock median (fields *_ms, *_mrays, ratio_*) and a CPU-time median "
       "(*_cpu_ms, *_mrays_cpu, ratio_cpu_*): CPU time of the calling thread for 1 thread, process CPU "
       "time / N for N-thread traces; N-thread builds have wall clock only. The machine is shared: "
       "compare machine.loadavg_*; CPU-time ratios repeat better under load"},
      {"method",
       "builds: MeshObject constructor inside a tbb::task_arena of N threads vs Embree geometry setup + "
       "rtcCommitScene on a device made with threads=N for that measurement (the only Embree device alive: "
       "with a second device of more threads alive, a threads=1 device builds on two); traces: the same "
       "tbb::parallel_for over chunks of "
       "4096 rays in a task_arena of N threads, one call per ray (MeshObject::intersect with a fresh Hit / "
       "occluded vs rtcIntersect1 / rtcOccluded1), FTZ+DAZ set per chunk; ours and Embree interleaved per "
       "repetition, figures are medians of the repetitions"}};
  MeshBench bench(options, threads, arenas, embree);
  MeshCache cache(options.data_dir);
  nlohmann::json meshes = nlohmann::json::array();
  for (const std::string& spec : options.meshes) meshes.push_back(bench.run(cache.get(MeshSpec::parse(spec))));
  doc["meshes"] = meshes;
  doc["goals"] = evaluateGoals(meshes);
  printSummary(meshes, threads);
  return doc;
}

}  // namespace duplex::bench
