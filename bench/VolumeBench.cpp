// duplex_bench_volume: accuracy against speed for volume objects, one JSON
// object on stdout (scripts/plot_volumes.py draws docs/volumes/*.png from it).
//
//   levelset_sphere  hit error against the analytic sphere (OpenVDB's createLevelSetSphere), per
//                    voxel size and root-refinement steps (bisection steps after the bracket)
//   levelset_mesh    hit error against the mesh the level set was made from (meshToLevelSet of a
//                    shared mesh, spot.obj by default): |t_levelset - t_mesh| |dir| for rays that
//                    hit both, and the share of rays where only one of them hits
//   fog              transmittance error against the analytic value (homogeneous box, homogeneous
//                    sphere, linear ramp) and against the exact integral of the voxelised field, for
//                    exact HDDA integration, fixed-step marching, ratio and delta tracking, with the
//                    time per ray
//
// Times are CPU nanoseconds per ray of the benchmark's one thread (CLOCK_THREAD_CPUTIME_ID: other
// processes on a shared machine do not count); compare them as ratios within a run.

#include "duplex/accel/QueryContext.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/VolumeObjectVdb.h"
#include "duplex/accel/KdTree.h"

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace {

using namespace duplex;
using Clock = std::chrono::steady_clock;
using json = nlohmann::ordered_json;
constexpr float kInf = std::numeric_limits<float>::infinity();

glm::dvec3 randomUnit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return glm::normalize(glm::dvec3(n(rng), n(rng), n(rng)));
}

// CPU time of this thread in ns: the machine is shared, and wall-clock time per ray would measure
// the other processes as much as ours.
double threadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e9 + double(ts.tv_nsec);
}

// Calls f() over all rays, repeating the pass until at least 30 ms of CPU time have passed; CPU ns
// per ray.
template <class F>
double nsPerRay(std::size_t rays, F&& f) {
  int passes = 0;
  const double t0 = threadCpuNs();
  double elapsed = 0.0;
  do {
    f();
    ++passes;
    elapsed = threadCpuNs() - t0;
  } while (elapsed < 3e7);
  return elapsed / (double(passes) * double(rays));
}

// ns per ray of closest-hit queries against one object.
double intersectNs(const Object& object, const std::vector<Ray>& rays, QueryContext& ctx) {
  return nsPerRay(rays.size(), [&] {
    for (const Ray& r : rays) {
      Hit h;
      (void)object.intersect(r, h, ctx);
    }
  });
}

struct ErrorStats {
  double rms = 0.0, max = 0.0, mean = 0.0;
  std::size_t n = 0;
  void add(double e) {
    rms += e * e;
    mean += e;
    max = std::max(max, std::abs(e));
    ++n;
  }
  json finish() const {
    json j;
    j["n"] = n;
    j["rms"] = n ? std::sqrt(rms / double(n)) : 0.0;
    j["mean"] = n ? mean / double(n) : 0.0;
    j["max"] = max;
    return j;
  }
};

// ---- level sets ----

json levelSetSphere(std::size_t ray_count) {
  json out = json::array();
  const double radius = 1.0;
  // Rays from outside aimed clearly through the sphere (impact parameter below 0.9 R).
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Ray> rays;
  std::vector<double> entry;
  while (rays.size() < ray_count) {
    const glm::dvec3 o = 3.0 * randomUnit(rng);
    const glm::dvec3 d = glm::normalize(0.9 * radius * std::cbrt(u(rng)) * randomUnit(rng) - o) * (0.5 + u(rng));
    const double a = glm::dot(d, d), b = glm::dot(o, d), c = glm::dot(o, o) - radius * radius;
    const double disc = b * b - a * c;
    if (disc <= 0.0) continue;
    rays.push_back(Ray{glm::vec3(o), 0.0f, glm::vec3(d), kInf});
    entry.push_back((-b - std::sqrt(disc)) / a);
  }
  for (const double voxel : {0.1, 0.05, 0.02, 0.01}) {
    auto grid =
        openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(float(radius), openvdb::Vec3f(0.0f), float(voxel));
    const auto base = makeVolumeObject(grid, VolumeKind::LevelSet, "sphere");
    for (const int refine : {0, 1, 2, 4, 6, 8, 10, 13, 16, 20}) {
      VolumeQueryConfig c;
      c.refine_steps = refine;
      const auto v = base->withConfig(c);
      QueryContext ctx;
      ErrorStats t_err, r_err;
      std::size_t misses = 0;
      for (std::size_t k = 0; k < rays.size(); ++k) {
        Hit h;
        if (!v->intersect(rays[k], h, ctx)) {
          ++misses;
          continue;
        }
        const glm::dvec3 d(rays[k].dir);
        const glm::dvec3 p = glm::dvec3(rays[k].origin) + double(h.t) * d;
        t_err.add(std::abs(double(h.t) - entry[k]) * glm::length(d));  // along the ray
        r_err.add(std::abs(glm::length(p) - radius));                  // distance to the surface
      }
      const double ns = intersectNs(*v, rays, ctx);
      json j;
      j["voxel"] = voxel;
      j["refine_steps"] = refine;
      j["rays"] = rays.size();
      j["misses"] = misses;
      j["error_along_ray"] = t_err.finish();
      j["distance_to_surface"] = r_err.finish();
      j["ns_per_ray"] = ns;
      out.push_back(j);
    }
  }
  return out;
}

json levelSetMesh(const std::filesystem::path& mesh_file, std::size_t ray_count) {
  json out = json::object();
  if (!std::filesystem::exists(mesh_file)) {
    out["skipped"] = "no " + mesh_file.string() + " (the shared data folder is absent)";
    std::cerr << "duplex_bench_volume: " << out["skipped"].get<std::string>() << "\n";
    return out;
  }
  auto mesh = std::make_shared<const TriangleMesh>(loadMesh(mesh_file));
  const auto mesh_object = std::make_shared<const MeshObject>(mesh);
  const Box b = mesh_object->bounds();
  const glm::dvec3 lo(b.lo), hi(b.hi), centre = 0.5 * (lo + hi);
  const double diag = glm::length(hi - lo);
  std::vector<openvdb::Vec3s> points;
  for (const glm::vec3& p : mesh->positions()) points.emplace_back(p.x, p.y, p.z);
  std::vector<openvdb::Vec3I> tris;
  for (const auto& t : mesh->triangles()) tris.emplace_back(t[0], t[1], t[2]);
  // Rays from a sphere around the mesh towards random points of its box; both methods see them.
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Ray> rays;
  for (std::size_t k = 0; k < ray_count; ++k) {
    const glm::dvec3 o = centre + diag * randomUnit(rng);
    const glm::dvec3 target = lo + glm::dvec3(u(rng), u(rng), u(rng)) * (hi - lo);
    rays.push_back(Ray{glm::vec3(o), 0.0f, glm::vec3(target - o), kInf});
  }
  QueryContext ctx;
  std::vector<Hit> mesh_hits(rays.size());
  for (std::size_t k = 0; k < rays.size(); ++k) (void)mesh_object->intersect(rays[k], mesh_hits[k], ctx);
  out["mesh"] = mesh_file.filename().string();
  out["triangles"] = mesh->triangles().size();
  out["diagonal"] = diag;
  json results = json::array();
  for (const double fraction : {1.0 / 50, 1.0 / 100, 1.0 / 200, 1.0 / 400}) {
    const double voxel = diag * fraction;
    const auto xf = openvdb::math::Transform::createLinearTransform(voxel);
    const auto t0 = Clock::now();
    auto grid = openvdb::tools::meshToLevelSet<openvdb::FloatGrid>(*xf, points, tris, 3.0f);
    const double convert_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    const auto base = makeVolumeObject(grid, VolumeKind::LevelSet, "mesh");
    for (const int refine : {0, 4, 13}) {
      VolumeQueryConfig c;
      c.refine_steps = refine;
      const auto v = base->withConfig(c);
      ErrorStats err;
      std::size_t only_mesh = 0, only_levelset = 0, both = 0;
      for (std::size_t k = 0; k < rays.size(); ++k) {
        Hit h;
        const bool got = v->intersect(rays[k], h, ctx);
        const bool ref = mesh_hits[k].valid();
        if (got && ref) {
          ++both;
          err.add(std::abs(double(h.t) - double(mesh_hits[k].t)) * glm::length(glm::dvec3(rays[k].dir)));
        }
        only_mesh += ref && !got;
        only_levelset += got && !ref;
      }
      const double ns = intersectNs(*v, rays, ctx);
      json j;
      j["voxel"] = voxel;
      j["voxel_per_diagonal"] = fraction;
      j["refine_steps"] = refine;
      j["active_voxels"] = v->activeVoxelCount();
      j["mesh_to_volume_ms"] = convert_ms;
      j["both_hit"] = both;
      j["only_mesh_hit"] = only_mesh;
      j["only_levelset_hit"] = only_levelset;
      j["error_along_ray"] = err.finish();
      j["ns_per_ray"] = ns;
      results.push_back(j);
    }
  }
  const double ns_mesh = intersectNs(*mesh_object, rays, ctx);
  out["mesh_ns_per_ray"] = ns_mesh;
  out["results"] = results;
  return out;
}

// ---- fog ----

struct FogProfile {
  std::string name;
  openvdb::FloatGrid::Ptr grid;
  // Analytic transmittance of a ray (object space) through the continuous profile.
  std::function<double(const Ray&)> analytic;
};

// [t0, t1] of the ray in the box [lo, hi]^3 (object space).
std::optional<std::pair<double, double>> clip(const Ray& r, double lo, double hi) {
  double t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    double ta = (lo - r.origin[a]) / r.dir[a], tb = (hi - r.origin[a]) / r.dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 < t1)) return std::nullopt;
  return std::make_pair(t0, t1);
}

std::vector<FogProfile> fogProfiles() {
  std::vector<FogProfile> out;
  const double voxel = 0.02;  // 1 object unit = 50 voxels
  auto grid = [&](const std::string& name) {
    auto g = openvdb::FloatGrid::create(0.0f);
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    g->setName(name);
    return g;
  };
  // Homogeneous box: voxels [0, 49]^3 = object [-0.01, 0.99]^3, density 2 (as voxels, no tiles).
  {
    auto g = grid("box");
    const float sigma = 2.0f;
    g->tree().fill(openvdb::CoordBBox(openvdb::Coord(0), openvdb::Coord(49)), sigma, true);
    g->tree().voxelizeActiveTiles();
    const double lo = -0.5 * voxel, hi = 49.5 * voxel;
    out.push_back({"homogeneous box", g, [=](const Ray& r) {
                     const auto s = clip(r, lo, hi);
                     return s ? std::exp(-sigma * (s->second - s->first) * glm::length(glm::dvec3(r.dir))) : 1.0;
                   }});
  }
  // Homogeneous sphere: density 2 within radius 0.5 of (0.5, 0.5, 0.5), voxelised by centres.
  {
    auto g = grid("sphere");
    const float sigma = 2.0f;
    const glm::dvec3 c(0.5);
    const double R = 0.5;
    auto acc = g->getAccessor();
    for (int i = -2; i <= 52; ++i)
      for (int j = -2; j <= 52; ++j)
        for (int k = -2; k <= 52; ++k)
          if (glm::length(glm::dvec3(i, j, k) * voxel - c) < R) acc.setValue(openvdb::Coord(i, j, k), sigma);
    out.push_back({"homogeneous sphere", g, [=](const Ray& r) {
                     const glm::dvec3 o = glm::dvec3(r.origin) - c, d(r.dir);
                     const double a = glm::dot(d, d), b = glm::dot(o, d), cc = glm::dot(o, o) - R * R;
                     const double disc = b * b - a * cc;
                     if (disc <= 0.0) return 1.0;
                     const double s = std::sqrt(disc);
                     const double t0 = std::max<double>(r.tnear, (-b - s) / a),
                                  t1 = std::min<double>(r.tfar, (-b + s) / a);
                     return t1 > t0 ? std::exp(-sigma * (t1 - t0) * std::sqrt(a)) : 1.0;
                   }});
  }
  // Linear ramp: density 4 x over the box [0, 1]^3 (voxels [0, 49] hold their centre's value,
  // 4 (i + 0.5) voxel, over cells [i, i + 1) voxel: voxel ijk centred at (ijk + 0.5) voxel).
  {
    auto g = grid("ramp");
    const double a = 4.0;
    g->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
    // Shift by half a voxel so that the cells tile [0, 1] exactly.
    g->transform().postTranslate(openvdb::Vec3d(0.5 * voxel));
    auto acc = g->getAccessor();
    for (int i = 0; i < 50; ++i)
      for (int j = 0; j < 50; ++j)
        for (int k = 0; k < 50; ++k) acc.setValue(openvdb::Coord(i, j, k), float(a * (i + 0.5) * voxel));
    out.push_back({"linear ramp", g, [=](const Ray& r) {
                     const auto s = clip(r, 0.0, 1.0);
                     if (!s) return 1.0;
                     // Integral of a x(t) |d| dt over [t0, t1], x(t) = ox + t dx.
                     const double t0 = s->first, t1 = s->second;
                     const double integral = a * (r.origin.x * (t1 - t0) + 0.5 * r.dir.x * (t1 * t1 - t0 * t0));
                     return std::exp(-integral * glm::length(glm::dvec3(r.dir)));
                   }});
  }
  return out;
}

// Rays through the unit box: from outside, from inside, finite and infinite.
std::vector<Ray> fogRays(std::size_t count) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Ray> rays;
  const glm::dvec3 c(0.5);
  for (std::size_t k = 0; k < count; ++k) {
    const glm::dvec3 o = k % 4 == 0 ? c + 0.3 * randomUnit(rng) : c + 1.5 * randomUnit(rng);
    const glm::dvec3 target = c + 0.4 * u(rng) * randomUnit(rng);
    Ray r{glm::vec3(o), 0.0f, glm::vec3(glm::normalize(target - o)), kInf};
    if (k % 3 == 1) r.tfar = static_cast<float>(0.3 + 1.5 * u(rng));
    rays.push_back(r);
  }
  return rays;
}

json fogRun(const FogProfile& profile, const std::vector<Ray>& rays, std::size_t max_samples) {
  json out = json::array();
  const auto base = makeVolumeObject(profile.grid, VolumeKind::Fog, profile.name);
  QueryContext ctx;
  std::vector<double> analytic(rays.size()), exact(rays.size());
  for (std::size_t k = 0; k < rays.size(); ++k) {
    analytic[k] = profile.analytic(rays[k]);
    exact[k] = base->transmittance(rays[k], ctx, FogMethod::Exact, 0);
  }
  auto measure = [&](const std::string& label, FogMethod method, const VolumeQueryConfig& c, double param) {
    const auto v = base->withConfig(c);
    ErrorStats vs_analytic, vs_exact;
    std::uint64_t seed = 1;
    for (std::size_t k = 0; k < rays.size(); ++k) {
      const double x = v->transmittance(rays[k], ctx, method, seed++);
      vs_analytic.add(x - analytic[k]);
      vs_exact.add(x - exact[k]);
    }
    const double ns = nsPerRay(rays.size(), [&] {
      for (const Ray& r : rays) (void)v->transmittance(r, ctx, method, seed++);
    });
    json j;
    j["profile"] = profile.name;
    j["method"] = label;
    j["param"] = param;
    j["samples"] = c.samples;
    j["majorant_level"] = c.majorant_level;
    j["error_vs_analytic"] = vs_analytic.finish();
    j["error_vs_exact"] = vs_exact.finish();
    j["ns_per_ray"] = ns;
    out.push_back(j);
  };
  VolumeQueryConfig c;
  measure("exact", FogMethod::Exact, c, 0.0);
  for (const double step : {4.0, 2.0, 1.0, 0.5, 0.25, 0.1}) {
    VolumeQueryConfig m;
    m.march_step = step;
    measure("march", FogMethod::RayMarching, m, step);
  }
  for (std::uint32_t s = 1; s <= max_samples; s *= 4) {
    VolumeQueryConfig r;
    r.samples = s;
    measure("ratio (residual, leaf majorants)", FogMethod::RatioTracking, r, s);
    r.residual = false;
    measure("ratio (leaf majorants)", FogMethod::RatioTracking, r, s);
    r.majorant_level = 2;
    measure("ratio (upper-node majorants)", FogMethod::RatioTracking, r, s);
    VolumeQueryConfig d;
    d.samples = s;
    measure("delta (leaf majorants)", FogMethod::DeltaTracking, d, s);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"duplex_bench_volume: accuracy against speed of volume objects (JSON on stdout)"};
  std::filesystem::path data = DUPLEX_BENCH_DATA_DIR;
  std::string mesh = "meshes/spot.obj";
  std::size_t rays = 2000;
  std::size_t max_samples = 256;
  app.add_option("--data", data, "Shared data folder (meshes/)");
  app.add_option("--mesh", mesh, "Mesh for the mesh-to-level-set comparison, relative to --data");
  app.add_option("--rays", rays, "Rays per configuration")->check(CLI::Range(10, 10000000));
  app.add_option("--max-samples", max_samples, "Largest sample count of the stochastic estimators")
      ->check(CLI::Range(1, 1 << 20));
  CLI11_PARSE(app, argc, argv);
  try {
    openvdb::initialize();
    json report;
    report["rays"] = rays;
    report["default_method"] = std::string(toString(VolumeQueryConfig{}.transmittance));
    report["levelset_sphere"] = levelSetSphere(rays);
    report["levelset_mesh"] = levelSetMesh(data / mesh, rays);
    json fog = json::array();
    const auto fog_rays = fogRays(rays);
    for (const FogProfile& p : fogProfiles())
      for (json& j : fogRun(p, fog_rays, max_samples)) fog.push_back(std::move(j));
    report["fog"] = fog;
    std::cout << report.dump() << "\n";
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_volume: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
