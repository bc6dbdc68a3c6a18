/// \file ClosestBench.cpp
/// --closest: closest-point queries on single meshes, ours (MeshObject::closestPoint through the
/// BVH, distances in double) against Embree 3's rtcPointQuery with a callback like its
/// closest-point tutorial's (Ericson's closest point on a triangle in float, the query radius
/// shrunk to each better distance). The same points for both: uniform in the mesh's box enlarged
/// by half its size on each side (near and inside), and on a sphere of ten diagonals (far), one
/// thread, interleaved repetitions; agreement of the distances.

#include "BenchBuild.h"
#include "BenchCommon.h"
#include "BenchMeshes.h"
#include "BenchModes.h"

#include "duplex/accel/PointQuery.h"
#include "duplex/objects/MeshObject.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif

#include <glm/geometric.hpp>

#include <cmath>
#include <iostream>
#include <random>
#include <vector>

namespace duplex::bench {

namespace {

std::vector<glm::vec3> queryPoints(const Box& b, std::size_t count, bool far, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const glm::vec3 lo = b.lo - 0.5f * b.extent(), hi = b.hi + 0.5f * b.extent();
  const glm::vec3 centre = (b.lo + b.hi) * 0.5f;
  const float radius = 10.0f * glm::length(b.extent());
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::vector<glm::vec3> out(count);
  for (glm::vec3& p : out) {
    if (far) {
      p = centre + radius * glm::normalize(glm::vec3(n(rng), n(rng), n(rng)));
    } else {
      const float x = u(rng), y = u(rng), z = u(rng);
      p = lo + glm::vec3(x, y, z) * (hi - lo);
    }
  }
  return out;
}

#if DUPLEX_BENCH_HAVE_EMBREE
struct EmbreeClosest {
  const TriangleMesh* mesh;
  float distance;
  std::uint32_t prim;
};

bool embreeClosestCallback(RTCPointQueryFunctionArguments* args) {
  auto* r = static_cast<EmbreeClosest*>(args->userPtr);
  const auto v = r->mesh->vertices(args->primID);
  const glm::vec3 q(args->query->x, args->query->y, args->query->z);
  const float d = glm::length(q - closestPointOnTriangle(q, v[0], v[1], v[2]));
  if (!(d < args->query->radius)) return false;
  args->query->radius = d;
  r->distance = d;
  r->prim = args->primID;
  return true;
}

float embreeClosest(RTCScene scene, const TriangleMesh& mesh, const glm::vec3& p) {
  RTCPointQuery query;
  query.x = p.x;
  query.y = p.y;
  query.z = p.z;
  query.radius = std::numeric_limits<float>::infinity();
  query.time = 0.0f;
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  EmbreeClosest result{&mesh, std::numeric_limits<float>::infinity(), RTC_INVALID_GEOMETRY_ID};
  rtcPointQuery(scene, &query, &context, embreeClosestCallback, &result);
  return result.distance;
}
#endif

}  // namespace

nlohmann::json runClosestBench(const Options& options) {
  nlohmann::json doc;
  doc["kind"] = "duplex_bench_closest";
  doc["machine"] = machineInfo(thisBuild());
  doc["config"] = {{"meshes", options.meshes},
                   {"points", options.closest_points},
                   {"threads", 1},
                   {"repeat", options.repeat},
                   {"seed", options.seed},
                   {"ours", "MeshObject::closestPoint, BVH medium, identity transform, double precision"},
                   {"embree", "rtcPointQuery, medium build, the closest-point tutorial's float callback"},
                   {"clock", "medians of the calling thread's CPU time per repetition"}};
  Arenas arenas;
  tbb::task_arena& one = arenas.get(1);
  MeshCache cache(options.data_dir);
  nlohmann::json meshes = nlohmann::json::array();
  for (const std::string& spec_text : options.meshes) {
    const LoadedMesh& loaded = cache.get(MeshSpec::parse(spec_text));
    const TriangleMesh& mesh = *loaded.mesh;
    nlohmann::json m;
    m["mesh"] = loaded.spec.label();
    m["triangles"] = mesh.triangleCount();
    std::cerr << "== closest " << loaded.spec.label() << ": " << mesh.triangleCount() << " triangles\n";
    const MeshObject ours(loaded.mesh, BvhBuildConfig{});
#if DUPLEX_BENCH_HAVE_EMBREE
    EmbreeDevice device(1, options.embree_config);
    const EmbreeMesh embree(device, mesh, RTC_BUILD_QUALITY_MEDIUM);
    // The tutorial's callback is passed to rtcPointQuery; geometries need the query enabled.
#endif
    for (const bool far : {false, true}) {
      const std::vector<glm::vec3> points = queryPoints(mesh.bounds(), options.closest_points, far, options.seed);
      std::vector<double> ours_d(points.size()), ours_ms, embree_ms;
      std::vector<float> embree_d(points.size());
      for (int rep = 0; rep < options.repeat; ++rep) {
        one.execute([&] {
          const Timing t = timeIt(1, [&] {
            QueryContext ctx;
            for (std::size_t i = 0; i < points.size(); ++i) {
              ClosestPoint best;
              (void)ours.closestPoint(PointQuery::make(glm::dvec3(points[i]), Affine::identity(), Affine::identity()),
                                      best, ctx);
              ours_d[i] = best.distance;
            }
          });
          ours_ms.push_back(t.cpu_ms);
#if DUPLEX_BENCH_HAVE_EMBREE
          const Timing e = timeIt(1, [&] {
            for (std::size_t i = 0; i < points.size(); ++i)
              embree_d[i] = embreeClosest(embree.scene(), mesh, points[i]);
          });
          embree_ms.push_back(e.cpu_ms);
#endif
        });
      }
      const std::string key = far ? "far" : "near";
      nlohmann::json q;
      q["points"] = points.size();
      q["ours_ms"] = median(ours_ms);
      q["ours_mqueries_per_s"] = static_cast<double>(points.size()) / (median(ours_ms) * 1e3);
#if DUPLEX_BENCH_HAVE_EMBREE
      q["embree_ms"] = median(embree_ms);
      q["embree_mqueries_per_s"] = static_cast<double>(points.size()) / (median(embree_ms) * 1e3);
      q["ratio"] = median(embree_ms) / median(ours_ms);
      // Agreement: the float callback's distance within float rounding of ours.
      std::size_t agree = 0;
      double worst = 0.0;
      for (std::size_t i = 0; i < points.size(); ++i) {
        const double diff = std::abs(ours_d[i] - static_cast<double>(embree_d[i]));
        const double tol = 1e-4 * (ours_d[i] + glm::length(mesh.bounds().extent()));
        agree += diff <= tol;
        worst = std::max(worst, diff / std::max(ours_d[i], 1e-30));
      }
      q["agreement"] = static_cast<double>(agree) / static_cast<double>(points.size());
      q["worst_relative_difference"] = worst;
      std::cerr << "  " << key << ": ours " << q["ours_mqueries_per_s"].get<double>() << " Mq/s, Embree "
                << q["embree_mqueries_per_s"].get<double>() << " Mq/s, ratio " << q["ratio"].get<double>()
                << ", agreement " << q["agreement"].get<double>() << "\n";
#endif
      m[key] = q;
    }
    meshes.push_back(m);
  }
  doc["meshes"] = meshes;
  return doc;
}

}  // namespace duplex::bench
