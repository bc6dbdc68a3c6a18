// duplex_bench_packets: ray packets against single rays on single meshes, with Embree 3's packet
// and single-ray queries as the baseline, all interleaved in one process on the same rays.
//
// Tracers: ours single (MeshObject::intersect / occluded per ray), ours packets
// (MeshObject::intersectPacket / occludedPacket on 16 consecutive rays; the kernels trace them in
// packets of the SIMD path's width, DUPLEX_ISA chooses it), Embree rtcIntersect1 / rtcOccluded1
// and rtcIntersect4/8/16 / rtcOccluded4/8/16 with the coherent context flag.
// Ray sets: primary rays of `duplex rays --primary`'s camera in tiles of 4 x 4 pixels (the order a
// renderer hands rays over), the same jittered inside each pixel, random rays (randomRays), and
// shadow rays from the primary hits towards a point light (any hit).
// Output: JSON with Mrays/s per tracer, ray set, mesh and thread count (medians of interleaved
// repetitions) and the ratios; scripts/plot_packets.py draws the chart.

#include "BenchBuild.h"
#include "BenchCommon.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"

#include "duplex/objects/BuiltinTypes.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#include "EmbreeTwoLevel.h"
#endif

#if DUPLEX_BENCH_HAVE_CALLGRIND
#include <valgrind/callgrind.h>
#endif

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <filesystem>
#include <bit>
#include <atomic>
#include <cstring>
#include <functional>
#include <exception>
#include <iostream>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace duplex::bench {
namespace {

constexpr std::size_t kPacket = 16;  // rays per call of every packet tracer (Embree: per rtcIntersect16)

/// Primary rays of the `duplex rays --primary` camera, in tiles of 4 x 4 pixels (row-major tiles,
/// row-major pixels inside a tile); `jitter`: a random point inside each pixel instead of its centre.
std::vector<Ray> tiledPrimaryRays(const Box& bounds, std::uint32_t side, bool jitter, std::uint64_t seed) {
  const PinholeCamera cam = PinholeCamera::looking_at_box(bounds);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Ray> rays;
  rays.reserve(static_cast<std::size_t>(side) * side);
  for (std::uint32_t ty = 0; ty < side; ty += 4)
    for (std::uint32_t tx = 0; tx < side; tx += 4)
      for (std::uint32_t y = ty; y < std::min(ty + 4, side); ++y)
        for (std::uint32_t x = tx; x < std::min(tx + 4, side); ++x) {
          Ray r;
          r.origin = glm::vec3(cam.eye);
          const double ox = jitter ? u(rng) : 0.5, oy = jitter ? u(rng) : 0.5;
          r.dir = glm::vec3(cam.directionAt(x + ox, y + oy, side, side));
          rays.push_back(r);
        }
  return rays;
}

using Tracer = std::function<std::uint64_t(std::span<const Ray>)>;  // hits or blocked rays in the span

/// Times tracer over `rays` in `arena`: chunks of 4096 rays (a multiple of kPacket) per task.
std::pair<double, std::uint64_t> timeTracer(tbb::task_arena& arena, std::span<const Ray> rays, const Tracer& trace) {
  std::atomic<std::uint64_t> count{0};
  const Timing t = timeIt(arena.max_concurrency(), [&] {
    arena.execute([&] {
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, rays.size(), kTraceChunk),
          [&](const tbb::blocked_range<std::size_t>& r) {
            setFtzDaz();
            count.fetch_add(trace(rays.subspan(r.begin(), r.size())), std::memory_order_relaxed);
          },
          tbb::simple_partitioner());
    });
  });
  return {t.wall_ms, count.load()};
}

std::map<std::string, Tracer> oursTracers(const MeshObject& object, bool closest) {
  std::map<std::string, Tracer> t;
  if (closest) {
    t["ours_single"] = [&object](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      for (const Ray& r : rays) {
        Hit h;
        n += object.intersect(r, h) ? 1 : 0;
      }
      return n;
    };
    t["ours_packet"] = [&object](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      QueryContext ctx;
      for (std::size_t i = 0; i < rays.size(); i += kPacket) {
        const std::size_t m = std::min(kPacket, rays.size() - i);
        Hit h[kPacket];
        n += static_cast<std::uint64_t>(
            std::popcount(object.intersectPacket(rays.subspan(i, m), std::span<Hit>(h, m), 0xFFFFu, ctx)));
      }
      return n;
    };
  } else {
    t["ours_single"] = [&object](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      for (const Ray& r : rays) n += object.occluded(r) ? 1 : 0;
      return n;
    };
    t["ours_packet"] = [&object](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      QueryContext ctx;
      for (std::size_t i = 0; i < rays.size(); i += kPacket)
        n += static_cast<std::uint64_t>(
            std::popcount(object.occludedPacket(rays.subspan(i, std::min(kPacket, rays.size() - i)), 0xFFFFu, ctx)));
      return n;
    };
  }
  return t;
}

#if DUPLEX_BENCH_HAVE_EMBREE
template <int N, class RH>
void fillEmbree(RH& rh, std::span<const Ray> rays, int* valid) {
  for (int j = 0; j < N; ++j) {
    const bool on = static_cast<std::size_t>(j) < rays.size();
    valid[j] = on ? -1 : 0;
    const Ray& r = rays[on ? j : 0];
    auto& ray = [&]() -> auto& {
      if constexpr (requires { rh.ray; }) return rh.ray;
      else return rh;
    }
    ();
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
    if constexpr (requires { rh.hit; }) {
      rh.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
    }
  }
}

// One Embree packet query (rtcIntersectN or rtcOccludedN on a record of type Rec) over a span, in
// packets of N consecutive rays with the coherent flag; count(record, m) counts the hits among m rays.
template <int N, class Rec, class Query, class Count>
Tracer embreePackets(RTCScene scene, Query query, Count count) {
  return [scene, query, count](std::span<const Ray> rays) {
    std::uint64_t n = 0;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    for (std::size_t i = 0; i < rays.size(); i += N) {
      alignas(64) Rec rec;
      alignas(64) int valid[N];
      const std::size_t m = std::min<std::size_t>(N, rays.size() - i);
      fillEmbree<N>(rec, rays.subspan(i, m), valid);
      query(valid, scene, &ctx, &rec);
      n += count(rec, m);
    }
    return n;
  };
}

template <int N, class RH, class R, class FI, class FO>
std::map<std::string, Tracer> embreePacketTracers(RTCScene scene, bool closest, FI intersectN, FO occludedN,
                                                  const std::string& name) {
  std::map<std::string, Tracer> t;
  if (closest) {
    t[name] = embreePackets<N, RH>(scene, intersectN, [](const RH& rh, std::size_t m) {
      std::uint64_t n = 0;
      for (std::size_t j = 0; j < m; ++j) n += rh.hit.geomID[j] != RTC_INVALID_GEOMETRY_ID ? 1 : 0;
      return n;
    });
  } else {
    t[name] = embreePackets<N, R>(scene, occludedN, [](const R& r, std::size_t m) {
      std::uint64_t n = 0;
      for (std::size_t j = 0; j < m; ++j) n += r.tfar[j] < 0.0f ? 1 : 0;
      return n;
    });
  }
  return t;
}

// Embree's single-ray and packet queries on `scene` (a mesh's or a two-level scene's).
std::map<std::string, Tracer> embreeTracers(RTCScene scene, bool closest) {
  std::map<std::string, Tracer> t;
  t["embree_1"] = [scene, closest](std::span<const Ray> rays) {
    std::uint64_t n = 0;
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (const Ray& r : rays) {
      RTCRayHit rh = toRayHit(r, r.tfar);
      if (closest) {
        rtcIntersect1(scene, &ctx, &rh);
        n += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID ? 1 : 0;
      } else {
        rtcOccluded1(scene, &ctx, &rh.ray);
        n += rh.ray.tfar < 0.0f ? 1 : 0;
      }
    }
    return n;
  };
  t.merge(embreePacketTracers<4, RTCRayHit4, RTCRay4>(scene, closest, rtcIntersect4, rtcOccluded4, "embree_4"));
  t.merge(embreePacketTracers<8, RTCRayHit8, RTCRay8>(scene, closest, rtcIntersect8, rtcOccluded8, "embree_8"));
  t.merge(embreePacketTracers<16, RTCRayHit16, RTCRay16>(scene, closest, rtcIntersect16, rtcOccluded16, "embree_16"));
  return t;
}
#endif

/// Rays of the packet path whose hit differs in any bit from the single path's (closest hit), or
/// whose occlusion differs: must be 0.
std::size_t packetMismatches(const MeshObject& object, const std::vector<Ray>& rays) {
  std::size_t bad = 0;
  QueryContext ctx;
  for (std::size_t i = 0; i < rays.size(); i += kPacket) {
    const std::size_t m = std::min(kPacket, rays.size() - i);
    const std::span<const Ray> span(rays.data() + i, m);
    Hit got[kPacket];
    const std::uint32_t found = object.intersectPacket(span, std::span<Hit>(got, m), 0xFFFFu, ctx);
    const std::uint32_t blocked = object.occludedPacket(span, 0xFFFFu, ctx);
    for (std::size_t j = 0; j < m; ++j) {
      Hit want;
      const bool f = object.intersect(span[j], want);
      const bool same = f == ((found >> j & 1u) != 0) && std::memcmp(&got[j].t, &want.t, 12) == 0 &&
                        got[j].prim_id == want.prim_id && object.occluded(span[j]) == ((blocked >> j & 1u) != 0);
      bad += same ? 0 : 1;
    }
  }
  return bad;
}

/// Light for the shadow rays: above and beside the box's centre.
glm::vec3 lightOf(const Box& bounds) {
  const glm::vec3 c = bounds.center(), ext = bounds.hi - bounds.lo;
  return c + glm::vec3(0.3f * ext.x, 1.5f * ext.y, 0.9f * ext.z);
}

/// The shadow ray from the hit of `r` at distance t towards `light`.
Ray shadowRay(const Ray& r, float t, const glm::vec3& light) {
  Ray s;
  s.origin = r.origin + t * r.dir;
  s.dir = light - s.origin;
  s.tnear = 1e-4f;
  s.tfar = 1.0f - 1e-4f;
  return s;
}

/// The interleaved measurement of every tracer on every ray set and thread count, appended to
/// `results`. makeTracers(closest) gives the tracers of a ray set; mismatches(rays, closest) the rays
/// whose packet result differs from the single one (must be 0).
/// With --callgrind: each tracer once over the first `count` rays of each set on the calling thread,
/// instrumented and dumped under "<mesh or scene>/<set>/<tracer>" (run the program under
/// `valgrind --tool=callgrind --instr-atstart=no`); no timing.
std::size_t g_callgrind_rays = 0;
// --kd-walk: the two-level scenes also through the kd-tree walk.
bool g_kd_walk = false;
// --embree-robust: the two-level scenes also through Embree's robust (watertight) mode.
bool g_embree_robust = false;
/// --sets: the ray sets measured (empty: all).
std::vector<std::string> g_sets;
/// Writes the JSON with the rows measured so far.
std::function<void()> g_partial;

template <class MakeTracers>
void callgrindTracers(const nlohmann::json& what, const std::map<std::string, std::vector<Ray>>& sets,
                      MakeTracers&& makeTracers) {
  for (const auto& [set, all] : sets) {
    if (!g_sets.empty() && std::find(g_sets.begin(), g_sets.end(), set) == g_sets.end()) continue;
    const std::span<const Ray> rays(all.data(), std::min(all.size(), g_callgrind_rays));
    for (const auto& [tname, trace] : makeTracers(set != "shadow")) {
      (void)trace(rays.first(std::min<std::size_t>(rays.size(), 64)));  // lazy binding and caches outside the count
      const std::string name = std::string(what.value("mesh", what.value("scene", ""))) + "/" + set + "/" + tname;
#if DUPLEX_BENCH_HAVE_CALLGRIND
      CALLGRIND_ZERO_STATS;
      CALLGRIND_START_INSTRUMENTATION;
#endif
      const std::uint64_t n = trace(rays);
#if DUPLEX_BENCH_HAVE_CALLGRIND
      CALLGRIND_STOP_INSTRUMENTATION;
      CALLGRIND_DUMP_STATS_AT(name.c_str());
#endif
      std::cerr << name << ": " << rays.size() << " rays, " << n << " hits\n";
    }
  }
}

template <class MakeTracers, class Mismatches>
void measure(const nlohmann::json& what, const std::map<std::string, std::vector<Ray>>& sets,
             const std::vector<int>& threads, int reps, Arenas& arenas, MakeTracers&& makeTracers,
             Mismatches&& mismatches, nlohmann::json& results) {
  if (g_callgrind_rays != 0) {
    callgrindTracers(what, sets, makeTracers);
    return;
  }
  for (const auto& [set, rays] : sets) {
    if (!g_sets.empty() && std::find(g_sets.begin(), g_sets.end(), set) == g_sets.end()) continue;
    const bool closest = set != "shadow";
    const std::map<std::string, Tracer> tracers = makeTracers(closest);
    const std::size_t bad = mismatches(rays, closest);
    for (int n : threads) {
      tbb::task_arena& arena = arenas.get(n);
      std::map<std::string, std::vector<double>> ms;
      std::map<std::string, std::uint64_t> counts;
      for (int rep = 0; rep < reps; ++rep)
        for (const auto& [tname, trace] : tracers) {
          const auto [wall, count] = timeTracer(arena, rays, trace);
          ms[tname].push_back(wall);
          counts[tname] = count;
        }
      nlohmann::json row = what;
      row["rays"] = set;
      row["ray_count"] = rays.size();
      row["threads"] = n;
      row["query"] = closest ? "closest" : "any";
      row["mismatches_packet_vs_single"] = bad;
      std::map<std::string, double> mrays;
      for (const auto& [tname, samples] : ms) {
        mrays[tname] = static_cast<double>(rays.size()) / (median(samples) * 1e3);
        row["mrays_per_s"][tname] = mrays[tname];
        row["hits"][tname] = counts[tname];
      }
      row["ratio"]["packet_vs_single"] = mrays["ours_packet"] / mrays["ours_single"];
      if (mrays.count("embree_16") != 0) {
        row["ratio"]["packet_vs_embree_16"] = mrays["ours_packet"] / mrays["embree_16"];
        row["ratio"]["packet_vs_embree_1"] = mrays["ours_packet"] / mrays["embree_1"];
        row["ratio"]["single_vs_embree_1"] = mrays["ours_single"] / mrays["embree_1"];
        row["ratio"]["embree_16_vs_embree_1"] = mrays["embree_16"] / mrays["embree_1"];
      }
      std::cerr << what.dump() << " " << set << " " << n << "T: " << row["ratio"].dump() << "\n";
      results.push_back(row);
      if (g_partial) g_partial();  // the file holds every finished row, should a later one not finish
    }
  }
}

/// Primary, jittered primary and random rays of `bounds`.
std::map<std::string, std::vector<Ray>> raySets(const Box& bounds, std::uint32_t side, std::size_t random_count) {
  std::map<std::string, std::vector<Ray>> sets;
  sets["primary"] = tiledPrimaryRays(bounds, side, false, 1);
  sets["primary_jittered"] = tiledPrimaryRays(bounds, side, true, 2);
  sets["random"] = randomRays(bounds, random_count, 3);
  return sets;
}

void benchMesh(const std::filesystem::path& path, const std::string& name, std::uint32_t side, std::size_t random_count,
               const std::vector<int>& threads, int reps, Arenas& arenas, nlohmann::json& results) {
  const auto mesh = std::make_shared<const TriangleMesh>(loadMesh(path));
  const MeshObject object(mesh, BvhBuildConfig{});
  const Box bounds = mesh->bounds();
  auto sets = raySets(bounds, side, random_count);
  const glm::vec3 light = lightOf(bounds);
  for (const Ray& r : sets["primary"]) {
    Hit h;
    if (object.intersect(r, h)) sets["shadow"].push_back(shadowRay(r, h.t, light));
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  EmbreeDevice device(*std::max_element(threads.begin(), threads.end()), "");
  const EmbreeMesh embree(device, *mesh, RTC_BUILD_QUALITY_MEDIUM);
#endif
  auto make = [&](bool closest) {
    std::map<std::string, Tracer> tracers = oursTracers(object, closest);
#if DUPLEX_BENCH_HAVE_EMBREE
    tracers.merge(embreeTracers(embree.scene(), closest));
#endif
    return tracers;
  };
  const nlohmann::json what = {{"kind", "mesh"}, {"mesh", name}, {"triangles", mesh->triangleCount()}};
  measure(
      what, sets, threads, reps, arenas, make,
      [&](const std::vector<Ray>& rays, bool) { return packetMismatches(object, rays); }, results);
}

/// A two-level scene: ours through SceneTracer's batch queries (packets on and off), Embree's
/// two-level scene (one scene per object, one instance geometry per instance).
void benchScene(const std::filesystem::path& path, std::uint32_t side, std::size_t random_count,
                const std::vector<int>& threads, int reps, Arenas& arenas, nlohmann::json& results) {
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  SceneGraph& graph = *doc.graph;
  SceneTracer tracer(graph);
  // The same scene walked through the kd-tree instead of the wide form (TopLevelConfig::wide_traversal),
  // when --kd-walk asks for it.
  TopLevelConfig kd_config;
  kd_config.wide_traversal = false;
  std::optional<SceneTracer> kd_tracer;
  if (g_kd_walk) kd_tracer.emplace(graph, kd_config);
  const Box bounds = tracer.bounds();
  auto sets = raySets(bounds, side, random_count);
  {
    std::vector<Hit> hits(sets["primary"].size());
    tracer.intersect(sets["primary"], hits);
    const glm::vec3 light = lightOf(bounds);
    for (std::size_t i = 0; i < hits.size(); ++i)
      if (hits[i].valid()) sets["shadow"].push_back(shadowRay(sets["primary"][i], hits[i].t, light));
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  std::vector<std::shared_ptr<const Object>> held;
  std::vector<const TriangleMesh*> meshes;
  for (ObjectId i = 0; i < graph.library().size(); ++i) {
    held.push_back(graph.library().get(i));
    const auto* m = dynamic_cast<const MeshObject*>(held.back().get());
    if (m == nullptr) throw InvalidArgument(path.string() + ": objects other than meshes are not compared with Embree");
    meshes.push_back(&m->mesh());
  }
  std::vector<EmbreeInstanceDesc> instances;
  for (const NodeId node : graph.visibleInstances())
    instances.push_back({graph.node(node).object, graph.worldTransform(node)});
  EmbreeDevice device(*std::max_element(threads.begin(), threads.end()), "");
  const EmbreeTwoLevel embree(device, meshes, instances, EmbreeTopLevelMode::Default);
  std::optional<EmbreeTwoLevel> robust;
  if (g_embree_robust) robust.emplace(device, meshes, instances, EmbreeTopLevelMode::Robust);
#endif
  auto batch = [](SceneTracer& tracer, bool packets, bool closest) -> Tracer {
    return [&tracer, packets, closest](std::span<const Ray> rays) {
      tracer.setBatchPackets(packets);
      std::uint64_t n = 0;
      if (closest) {
        std::vector<Hit> hits(rays.size());
        tracer.intersect(rays, hits);
        for (const Hit& h : hits) n += h.valid() ? 1 : 0;
      } else {
        std::vector<std::uint8_t> blocked(rays.size());
        tracer.occluded(rays, blocked);
        for (const std::uint8_t b : blocked) n += b;
      }
      return n;
    };
  };
  auto make = [&](bool closest) {
    std::map<std::string, Tracer> tracers;
    tracers["ours_single"] = batch(tracer, false, closest);
    tracers["ours_packet"] = batch(tracer, true, closest);
    if (kd_tracer) {
      tracers["ours_kd_single"] = batch(*kd_tracer, false, closest);
      tracers["ours_kd_packet"] = batch(*kd_tracer, true, closest);
    }
#if DUPLEX_BENCH_HAVE_EMBREE
    tracers.merge(embreeTracers(embree.scene(), closest));
    if (robust)  // embree_robust_1, embree_robust_4, ...
      for (auto& [name, t] : embreeTracers(robust->scene(), closest))
        tracers["embree_robust" + name.substr(std::string("embree").size())] = std::move(t);
#endif
    return tracers;
  };
  auto mismatches = [&](const std::vector<Ray>& rays, bool closest) {
    std::size_t bad = 0;
    if (closest) {
      std::vector<Hit> a(rays.size()), b(rays.size());
      tracer.setBatchPackets(true);
      tracer.intersect(rays, a);
      tracer.setBatchPackets(false);
      tracer.intersect(rays, b);
      for (std::size_t i = 0; i < rays.size(); ++i)
        bad += std::memcmp(&a[i].t, &b[i].t, 12) == 0 && a[i].prim_id == b[i].prim_id &&
                       a[i].instance_id == b[i].instance_id
                   ? 0
                   : 1;
    } else {
      std::vector<std::uint8_t> a(rays.size()), b(rays.size());
      tracer.setBatchPackets(true);
      tracer.occluded(rays, a);
      tracer.setBatchPackets(false);
      tracer.occluded(rays, b);
      for (std::size_t i = 0; i < rays.size(); ++i) bad += a[i] == b[i] ? 0 : 1;
    }
    return bad;
  };
  const nlohmann::json what = {{"kind", "scene"},
                               {"scene", path.filename().string()},
                               {"instances", graph.visibleInstances().size()},
                               {"triangles", doc.figures.count("triangles")}};
  measure(what, sets, threads, reps, arenas, make, mismatches, results);
}

int run(int argc, char** argv) {
  CLI::App app{"Ray packets against single rays on single meshes and two-level scenes, Embree 3 as the baseline"};
  std::vector<std::string> meshes = {"spot.obj", "hammer.obj", "koala.obj", "abb_irb6640/link_1.stl"};
  std::vector<std::string> scenes;
  std::string data_dir = DUPLEX_BENCH_DATA_DIR;
  std::string out = "packet_bench.json";
  std::uint32_t side = 1024;
  std::size_t random_count = 1u << 20;
  std::vector<int> threads = {1, 2};
  int reps = 3;
  app.add_option("--meshes", meshes, "meshes below <data>/meshes (none: --meshes '')");
  app.add_option("--scenes", scenes, "scene files (scene-json-v1 or duplex-scene-v1) of meshes: two-level");
  app.add_option("--data", data_dir, "the shared data folder");
  app.add_option("--side", side, "primary rays: side x side pixels")->check(CLI::Range(16u, 8192u));
  app.add_option("--random", random_count, "random rays")->check(CLI::Range(std::size_t{1024}, std::size_t{1} << 26));
  app.add_option("--threads", threads, "thread counts")->check(CLI::Range(1, 64));
  app.add_option("--reps", reps, "interleaved repetitions (medians)")->check(CLI::Range(1, 50));
  std::vector<std::string> only_sets;
  app.add_option("--sets", only_sets, "ray sets to run (primary, primary_jittered, random, shadow; default: all)");
  app.add_option("--out", out, "JSON output");
  app.add_flag("--kd-walk", g_kd_walk,
               "two-level scenes: also trace through the kd-tree walk (TopLevelConfig::wide_traversal off), "
               "as ours_kd_single and ours_kd_packet");
  app.add_flag("--embree-robust", g_embree_robust,
               "two-level scenes: also Embree's scene built with RTC_SCENE_FLAG_ROBUST (top level and objects), "
               "as embree_robust_1, embree_robust_4, ...");
  app.add_option("--callgrind", g_callgrind_rays,
                 "instead of timing: count each tracer over the first N rays of each set (under valgrind "
                 "--tool=callgrind --instr-atstart=no)");
  CLI11_PARSE(app, argc, argv);

  setFtzDaz();
  Arenas arenas;
  nlohmann::json doc;
  doc["machine"] = machineInfo(thisBuild());
  doc["config"] = {{"side", side},
                   {"random", random_count},
                   {"reps", reps},
                   {"packet_call_rays", kPacket},
                   {"simd_isa", toString(widestSimdIsa())}};
  doc["results"] = nlohmann::json::array();
  g_sets = only_sets;
  g_partial = [&] {
    doc["machine"]["load_average_after"] = loadAverage();
    writeJson(out, doc);
  };
  for (const std::string& name : meshes)
    if (!name.empty())
      benchMesh(std::filesystem::path(data_dir) / "meshes" / name, name, side, random_count, threads, reps, arenas,
                doc["results"]);
  for (const std::string& scene : scenes) benchScene(scene, side, random_count, threads, reps, arenas, doc["results"]);
  doc["machine"]["load_average_after"] = loadAverage();
  writeJson(out, doc);
  return 0;
}

}  // namespace
}  // namespace duplex::bench

int main(int argc, char** argv) {
  // A refused input (a missing scene file, a bad option value) ends with its message, not an abort.
  try {
    return duplex::bench::run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_packets: " << e.what() << '\n';
    return 1;
  }
}
