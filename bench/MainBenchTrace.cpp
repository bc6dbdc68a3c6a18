// The main benchmark's traces and the time split of our closest-hit query (see MainBenchParts.h).

#include "MainBenchParts.h"

// The objects library's private per-ray setup, for the time split only (as its unit test does).
#include "MeshRay.h"

#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTree.h"

#include <algorithm>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <tuple>

namespace duplex::bench::main_detail {

namespace {

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

}  // namespace

void MeshBench::trace(const std::vector<RaySet>& sets, nlohmann::json& out) {
  using Key = std::tuple<std::size_t, Query, int>;  // ray set, query, threads
  const std::size_t n = defs_.size();
  std::vector<std::map<Key, std::vector<double>>> ms(n), cpu_ms(n);
  std::vector<std::map<Key, std::uint64_t>> hits(n);
  const std::vector<int> tracers = live();
  const Stopwatch phase;
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (const int t : threads_) {
      tbb::task_arena& arena = arenas_.get(t);
      for (std::size_t s = 0; s < sets.size(); ++s) {
        for (const Query q : {Query::Closest, Query::Any}) {
          const Key key{s, q, t};
          for (std::size_t i = 0; i < tracers.size(); ++i) {
            // Interleave ours and Embree's, alternating the order between repetitions.
            const int k = tracers[rep % 2 == 0 ? i : tracers.size() - 1 - i];
            const TraceTiming timing = timeTracer(k, arena, sets[s].rays, q);
            ms[k][key].push_back(timing.time.wall_ms);
            cpu_ms[k][key].push_back(timing.time.cpu_ms);
            hits[k][key] = timing.hits;
          }
        }
      }
    }
  }
  std::cerr << "  traces: " << fmt(phase.ms() / 1e3, 1) << " s\n";
  std::cerr << "  Mrays/s     " << pad("rays", 9) << pad("query", 8) << pad("T", 3);
  for (const int k : tracers) std::cerr << " " << lpad(defs_[k].key, 14);
  std::cerr << "\n";
  const int ref = find(kReferenceKey);
  nlohmann::json records = nlohmann::json::array();
  for (const int t : threads_) {
    for (std::size_t s = 0; s < sets.size(); ++s) {
      for (const Query q : {Query::Closest, Query::Any}) {
        const Key key{s, q, t};
        const std::size_t count = sets[s].rays.size();
        nlohmann::json rec{{"rays", sets[s].name}, {"query", toString(q)}, {"threads", t}, {"ray_count", count}};
        std::vector<double> mrays(n, kNaN), mrays_cpu(n, kNaN);
        for (const int k : tracers) {
          const double med = median(ms[k][key]), cpu = median(cpu_ms[k][key]);
          mrays[k] = static_cast<double>(count) / (med * 1e3);
          mrays_cpu[k] = static_cast<double>(count) / (cpu * 1e3);
          const std::string& name = defs_[k].key;
          rec[name + "_ms"] = med;
          rec[name + "_ms_samples"] = ms[k][key];
          rec[name + "_mrays"] = mrays[k];
          rec[name + "_cpu_ms"] = cpu;
          rec[name + "_cpu_ms_samples"] = cpu_ms[k][key];
          rec[name + "_mrays_cpu"] = mrays_cpu[k];
          rec[name + "_hits"] = hits[k][key];
        }
        for (const int k : tracers) {
          if (ref < 0 || k == ref) continue;
          const std::string& name = defs_[k].key;
          rec["ratio_" + name + "_vs_embree_medium"] = num(ratio(mrays[k], mrays[ref]));
          rec["ratio_cpu_" + name + "_vs_embree_medium"] = num(ratio(mrays_cpu[k], mrays_cpu[ref]));
          if (defs_[k].is_default) {
            rec["ratio_vs_embree_medium"] = rec["ratio_" + name + "_vs_embree_medium"];
            rec["ratio_cpu_vs_embree_medium"] = rec["ratio_cpu_" + name + "_vs_embree_medium"];
          }
        }
        const std::string label = sets[s].name + " " + toString(q) + " " + std::to_string(t) + "T";
        addRatios(out, "trace", label, mrays);
        addRatios(out, "trace_cpu", label, mrays_cpu);
        records.push_back(rec);
        std::cerr << "              " << pad(sets[s].name, 9) << pad(toString(q), 8) << pad(std::to_string(t), 3);
        for (const int k : tracers) {
          std::string cell = fmt(mrays[k]);
          if (ref >= 0 && k != ref) cell += " (" + fmt(ratio(mrays[k], mrays[ref])) + ")";
          std::cerr << lpad(cell, 15);
        }
        std::cerr << "\n";
      }
    }
  }
  out["trace"] = records;
}

// Where the time of a random closest-hit ray of the kd-tree goes (when it is measured), one thread, CPU time, medians
// of the repetitions with the order alternating: the cumulative parts above, our full query and Embree's (medium).
// Differences of the medians give harness, setup, traversal and triangle tests (docs/design/kdtree.md,
// "Where the time goes").
void MeshBench::timeSplit(const RaySet& random, nlohmann::json& out) {
  const std::span<const Ray> rays = random.rays;
  const int kd = find("kdtree"), embree = find(kReferenceKey);
  if (rays.empty() || kd < 0) return;
  tbb::task_arena& arena = arenas_.get(1);
  const MeshObject& object = *built_[static_cast<std::size_t>(kd)].object;
  std::vector<float> t_final(rays.size());
  parallelFor(arenas_.get(threads_.back()), rays.size(), [&](std::size_t i) {
    Hit hit;
    (void)object.intersect(rays[i], hit);
    t_final[i] = hit.t;
  });
  auto at = [&](const Ray& r) { return t_final[static_cast<std::size_t>(&r - rays.data())]; };
  enum Part { kHarness, kSetup, kTraversal, kFull, kEmbreeHarness, kEmbreeFull, kParts };
  constexpr const char* kKey[kParts] = {"harness", "setup", "traversal", "ours", "embree_harness", "embree_medium"};
  const int parts = embree >= 0 ? kParts : kEmbreeHarness;
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
        case kEmbreeFull: timing = timeTracer(embree, arena, rays, Query::Closest); break;
#endif
        default: break;
      }
      cpu_ms[part].push_back(timing.time.cpu_ms);
    }
  }
  double ns[kParts];
  nlohmann::json split{{"structure", "kdtree"}, {"rays", random.name}, {"ray_count", rays.size()}, {"threads", 1}};
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

}  // namespace duplex::bench::main_detail
