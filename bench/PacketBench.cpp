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

#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <atomic>
#include <cstring>
#include <functional>
#include <iostream>
#include <map>
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

/// Shadow rays from the hits of `primary` towards a point light above and beside the camera; rays
/// that missed give no shadow ray. Order: that of the primary rays (coherent).
std::vector<Ray> shadowRays(const MeshObject& object, const std::vector<Ray>& primary, const Box& bounds) {
  const glm::vec3 c = bounds.center(), ext = bounds.hi - bounds.lo;
  const glm::vec3 light = c + glm::vec3(0.3f * ext.x, 1.5f * ext.y, 0.9f * ext.z);
  std::vector<Ray> rays;
  for (const Ray& r : primary) {
    Hit h;
    if (!object.intersect(r, h)) continue;
    Ray s;
    s.origin = r.origin + h.t * r.dir;
    s.dir = light - s.origin;
    s.tnear = 1e-4f;
    s.tfar = 1.0f - 1e-4f;
    rays.push_back(s);
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
void fillEmbree(RH& rh, std::span<const Ray> rays, int* valid, bool hit) {
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
    (void)hit;
  }
}

template <int N, class RH, class R, class FI, class FO>
std::map<std::string, Tracer> embreePacketTracers(RTCScene scene, bool closest, FI intersectN, FO occludedN,
                                                  const std::string& name) {
  std::map<std::string, Tracer> t;
  if (closest) {
    t[name] = [scene, intersectN](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      for (std::size_t i = 0; i < rays.size(); i += N) {
        alignas(64) RH rh;
        alignas(64) int valid[N];
        const std::size_t m = std::min<std::size_t>(N, rays.size() - i);
        fillEmbree<N>(rh, rays.subspan(i, m), valid, true);
        intersectN(valid, scene, &ctx, &rh);
        for (std::size_t j = 0; j < m; ++j) n += rh.hit.geomID[j] != RTC_INVALID_GEOMETRY_ID ? 1 : 0;
      }
      return n;
    };
  } else {
    t[name] = [scene, occludedN](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      RTCIntersectContext ctx;
      rtcInitIntersectContext(&ctx);
      ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
      for (std::size_t i = 0; i < rays.size(); i += N) {
        alignas(64) R r;
        alignas(64) int valid[N];
        const std::size_t m = std::min<std::size_t>(N, rays.size() - i);
        fillEmbree<N>(r, rays.subspan(i, m), valid, false);
        occludedN(valid, scene, &ctx, &r);
        for (std::size_t j = 0; j < m; ++j) n += r.tfar[j] < 0.0f ? 1 : 0;
      }
      return n;
    };
  }
  return t;
}

std::map<std::string, Tracer> embreeTracers(const EmbreeMesh& mesh, bool closest) {
  std::map<std::string, Tracer> t;
  if (closest)
    t["embree_1"] = [&mesh](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      for (const Ray& r : rays) {
        Hit h;
        n += mesh.intersect(r, h) ? 1 : 0;
      }
      return n;
    };
  else
    t["embree_1"] = [&mesh](std::span<const Ray> rays) {
      std::uint64_t n = 0;
      for (const Ray& r : rays) n += mesh.occluded(r) ? 1 : 0;
      return n;
    };
  t.merge(embreePacketTracers<4, RTCRayHit4, RTCRay4>(mesh.scene(), closest, rtcIntersect4, rtcOccluded4, "embree_4"));
  t.merge(embreePacketTracers<8, RTCRayHit8, RTCRay8>(mesh.scene(), closest, rtcIntersect8, rtcOccluded8, "embree_8"));
  t.merge(embreePacketTracers<16, RTCRayHit16, RTCRay16>(mesh.scene(), closest, rtcIntersect16, rtcOccluded16,
                                                         "embree_16"));
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

int run(int argc, char** argv) {
  CLI::App app{"Ray packets against single rays on single meshes, Embree 3 as the baseline"};
  std::vector<std::string> meshes = {"spot.obj", "hammer.obj", "koala.obj", "abb_irb6640/link_1.stl"};
  std::string data_dir = DUPLEX_BENCH_DATA_DIR;
  std::string out = "packet_bench.json";
  std::uint32_t side = 1024;
  std::size_t random_count = 1u << 20;
  std::vector<int> threads = {1, 2};
  int reps = 3;
  app.add_option("--meshes", meshes, "meshes below <data>/meshes");
  app.add_option("--data", data_dir, "the shared data folder");
  app.add_option("--side", side, "primary rays: side x side pixels")->check(CLI::Range(16u, 8192u));
  app.add_option("--random", random_count, "random rays")->check(CLI::Range(std::size_t{1024}, std::size_t{1} << 26));
  app.add_option("--threads", threads, "thread counts")->check(CLI::Range(1, 64));
  app.add_option("--reps", reps, "interleaved repetitions (medians)")->check(CLI::Range(1, 50));
  app.add_option("--out", out, "JSON output");
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
  for (const std::string& name : meshes) {
    const auto mesh = std::make_shared<const TriangleMesh>(loadMesh(std::filesystem::path(data_dir) / "meshes" / name));
    const MeshObject object(mesh, BvhBuildConfig{});
    const Box bounds = mesh->bounds();
    std::map<std::string, std::vector<Ray>> sets;
    sets["primary"] = tiledPrimaryRays(bounds, side, false, 1);
    sets["primary_jittered"] = tiledPrimaryRays(bounds, side, true, 2);
    sets["random"] = randomRays(bounds, random_count, 3);
    sets["shadow"] = shadowRays(object, sets["primary"], bounds);
#if DUPLEX_BENCH_HAVE_EMBREE
    EmbreeDevice device(*std::max_element(threads.begin(), threads.end()), "");
    const EmbreeMesh embree(device, *mesh, RTC_BUILD_QUALITY_MEDIUM);
#endif
    for (const auto& [set, rays] : sets) {
      const bool closest = set != "shadow";
      std::map<std::string, Tracer> tracers = oursTracers(object, closest);
#if DUPLEX_BENCH_HAVE_EMBREE
      tracers.merge(embreeTracers(embree, closest));
#endif
      const std::size_t mismatches = packetMismatches(object, rays);
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
        nlohmann::json row = {{"mesh", name},
                              {"triangles", mesh->triangleCount()},
                              {"rays", set},
                              {"ray_count", rays.size()},
                              {"threads", n},
                              {"query", closest ? "closest" : "any"},
                              {"mismatches_packet_vs_single", mismatches}};
        std::map<std::string, double> mrays;
        for (const auto& [tname, samples] : ms) {
          mrays[tname] = static_cast<double>(rays.size()) / (median(samples) * 1e3);
          row["mrays_per_s"][tname] = mrays[tname];
          row["hits"][tname] = counts[tname];
        }
        row["ratio"]["packet_vs_single"] = mrays["ours_packet"] / mrays["ours_single"];
        if (mrays.count("embree_16")) {
          row["ratio"]["packet_vs_embree_16"] = mrays["ours_packet"] / mrays["embree_16"];
          row["ratio"]["packet_vs_embree_1"] = mrays["ours_packet"] / mrays["embree_1"];
          row["ratio"]["single_vs_embree_1"] = mrays["ours_single"] / mrays["embree_1"];
          row["ratio"]["embree_16_vs_embree_1"] = mrays["embree_16"] / mrays["embree_1"];
        }
        std::cerr << name << " " << set << " " << n << "T: " << row["ratio"].dump() << "\n";
        doc["results"].push_back(row);
      }
    }
  }
  doc["machine"]["load_average_after"] = loadAverage();
  writeJson(out, doc);
  return 0;
}

}  // namespace
}  // namespace duplex::bench

int main(int argc, char** argv) { return duplex::bench::run(argc, argv); }
