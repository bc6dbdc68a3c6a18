/// \file SensorBench.cpp
/// duplex_bench_sensor: prints one JSON object.
///
/// "overhead": a room of Lambertian walls with meshes inside and a point light, traced with
/// 0, 1, 100 and 10,000 sensors. Each configuration runs the same emitted paths twice, as a sensor
/// run (crossing query, deposits) and as plain closest-hit tracing (SensorRunConfig::
/// closest_hit_only: the same paths, nothing recorded), interleaved, median of --repeat.
/// Sensors never change a path, so every configuration traces the same segments:
/// overhead_ratio compares the two runs in one scene (the cost of recording), and
/// overhead_vs_no_sensors compares the sensor run with closest-hit tracing of the scene without
/// sensors (what adding the sensors costs in all).
///
/// "sensor_level": the crossing query alone on the 10,000 small sensors: the sensors' tree built
/// with several SAH parameters (TopLevelConfig::crossing_build, crossing_grid off) and the shipped
/// walk (the uniform grid, TopLevelConfig::crossing_grid), CPU time per query against the main
/// level's tree defaults (sensorLevelSweep; --sweep-segments 0 skips it).
///
/// "convergence": two configurations with exact answers, the relative error of the total flux
/// against emitted rays and seconds, root mean square over --seeds seeds, beside the standard error
/// the run reports and the 1/sqrt(N) law:
/// - a point source above a small square sensor: flux = (P / 4 pi) * solid angle;
/// - a Lambertian rectangle facing a parallel coaxial disk: flux = P * F, the configuration factor
///   F = (1/A) integral over the rectangle of the point-to-disk factor (Gauss-Legendre).

#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/ProceduralMesh.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/sensors/SensorObject.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <thread>
#include <vector>

namespace duplex {
namespace {

constexpr double kPi = std::numbers::pi;

/// A graph with its materials; the SensorScene refers to the graph, so both live here.
struct Setup {
  SceneGraph graph;
  std::vector<Material> materials;
  std::unique_ptr<SensorScene> scene;

  ObjectId object(std::shared_ptr<const Object> o, const std::string& name, Material m = {}) {
    const ObjectId id = graph.library().add(name, std::move(o));
    materials.resize(graph.library().size());
    materials[id] = m;
    return id;
  }
  void place(ObjectId id, const Affine& world, const std::string& name) {
    (void)graph.addInstance(kRootNode, id, world, name);
  }
  void finish(std::vector<Light> lights) {
    (void)graph.commit();
    scene = std::make_unique<SensorScene>(graph, std::move(lights), materials);
  }
};

std::shared_ptr<const Object> meshObject(TriangleMesh mesh) {
  return std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(std::move(mesh)));
}

std::shared_ptr<const Object> sensorObject(double w, double h, std::uint32_t nx, std::uint32_t ny, SensorShape shape,
                                           const std::string& name) {
  return std::make_shared<const SensorObject>(name,
                                              SensorSpec{.shape = shape, .width = w, .height = h, .nx = nx, .ny = ny});
}

Affine translate(const glm::dvec3& t) {
  Affine a;
  a.translation = t;
  return a;
}

/// A rotation taking +z to `n` (unit), placed at `at`.
Affine facing(const glm::dvec3& n, const glm::dvec3& at) {
  // An orthonormal frame around n (Duff et al. 2017, "Building an orthonormal basis, revisited").
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z), b = n.x * n.y * a;
  const glm::dvec3 t(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  const glm::dvec3 s(b, sign + n.y * n.y * a, -n.y);
  Affine m = translate(at);
  m.linear = glm::dmat3(t, s, n);
  return m;
}

Light pointLight(const glm::dvec3& p, double power) {
  Light l;
  l.type = LightType::Point;
  l.name = "point";
  l.position = p;
  l.power_w = power;
  return l;
}

/// Where the overhead scene's small sensors go: random places in the room (10 x 10 x 4, 0.2 from
/// the walls), random orientations.
std::vector<Affine> smallSensorPlacements(std::size_t count) {
  std::vector<Affine> out;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (std::size_t k = 0; k < count; ++k) {
    const glm::dvec3 at(-4.8 + 9.6 * u(rng), -4.8 + 9.6 * u(rng), 0.2 + 3.6 * u(rng));
    const double z = 2.0 * u(rng) - 1.0, phi = 2.0 * kPi * u(rng), r = std::sqrt(1.0 - z * z);
    out.push_back(facing({r * std::cos(phi), r * std::sin(phi), z}, at));
  }
  return out;
}

/// The overhead scene: a 10 x 10 x 4 room (Lambertian walls, albedo 0.5), meshes on the floor
/// (the shared data's spot and koala when present, else spheres), a 100 W point light under the
/// ceiling, and `sensors` sensors: one 1 x 1 sensor of 32 x 32 bins, or small 0.1 x 0.1 sensors
/// of 4 x 4 bins at random places and orientations.
std::unique_ptr<Setup> roomScene(std::size_t sensors, const std::string& data_dir, std::string& meshes_used) {
  auto s = std::make_unique<Setup>();
  const Material wall = Lambertian{0.5};
  const Material body = Lambertian{0.7};
  const ObjectId room = s->object(meshObject(makeBox({10.0, 10.0, 4.0}, "room")), "room", wall);
  s->place(room, translate({0, 0, 2}), "room");
  std::vector<std::pair<ObjectId, double>> shapes;  // object, scale to about 1.5 units
  meshes_used.clear();
  for (const char* name : {"spot.obj", "koala.obj"}) {
    const std::filesystem::path file = std::filesystem::path(data_dir) / "meshes" / name;
    if (!std::filesystem::exists(file)) continue;
    TriangleMesh mesh = loadMesh(file);
    const Box b = mesh.bounds();
    const glm::vec3 e = b.hi - b.lo;
    const double scale = 1.5 / std::max({e.x, e.y, e.z});
    shapes.emplace_back(s->object(meshObject(std::move(mesh)), name, body), scale);
    meshes_used += (meshes_used.empty() ? "" : ",") + std::string(name);
  }
  if (shapes.empty()) {
    shapes.emplace_back(s->object(meshObject(makeSphere(0.75, 4, "sphere")), "sphere", body), 1.0);
    meshes_used = "procedural spheres (shared data absent)";
  }
  // Nine copies on a grid on the floor.
  for (int k = 0; k < 9; ++k) {
    Affine a;
    const double sc = shapes[k % shapes.size()].second;
    a.linear = glm::dmat3(sc);
    a.translation = {-3.0 + 3.0 * (k % 3), -3.0 + 3.0 * (k / 3), 1.0};
    s->place(shapes[k % shapes.size()].first, a, "body" + std::to_string(k));
  }
  if (sensors == 1) {
    s->place(s->object(sensorObject(1.0, 1.0, 32, 32, SensorShape::Rectangle, "big"), "big"),
             translate({1.5, 1.5, 0.5}), "sensor0");
  } else if (sensors > 1) {
    const ObjectId small = s->object(sensorObject(0.1, 0.1, 4, 4, SensorShape::Rectangle, "small"), "small");
    const std::vector<Affine> at = smallSensorPlacements(sensors);
    for (std::size_t k = 0; k < sensors; ++k) s->place(small, at[k], "sensor" + std::to_string(k));
  }
  s->finish({pointLight({0.3, -0.2, 3.5}, 100.0)});
  return s;
}

double seconds(const std::chrono::steady_clock::time_point& t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// The figures of one kd-tree level in the benchmark's JSON.
nlohmann::json treeJson(const KdTreeStats& t) {
  return {{"nodes", t.nodes},           {"leaves", t.leaves},       {"empty_leaves", t.empty_leaves},
          {"references", t.references}, {"max_depth", t.max_depth}, {"sah_cost", t.sah_cost}};
}

nlohmann::json overhead(std::size_t sensors, std::uint64_t rays, unsigned threads, int repeat,
                        const std::string& data_dir) {
  std::string meshes;
  const auto setup = roomScene(sensors, data_dir, meshes);
  std::vector<double> with, without, with_cpu, without_cpu;
  SensorRunCounters counters;
  SensorRunResults results;
  for (int r = 0; r < repeat; ++r) {
    for (const bool plain : {false, true}) {
      SensorRunConfig cfg;
      cfg.threads = threads;
      cfg.seed = 11;
      cfg.closest_hit_only = plain;
      SensorRun run(*setup->scene, cfg);
      const auto t0 = std::chrono::steady_clock::now();
      const std::clock_t c0 = std::clock();
      (void)run.runUntil(rays);
      (plain ? without : with).push_back(seconds(t0));
      (plain ? without_cpu : with_cpu).push_back(static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
      if (!plain) {
        counters = run.counters();
        results = run.results();
      }
    }
  }
  double recorded = 0.0;
  for (const SensorResult& s : results.sensors) recorded += s.total_flux_w;
  // FNV-1a over every bin's flux, standard error and ray count and every sensor's total: equal
  // hashes across revisions mean bit-identical results (the sensors' fast paths must not change a
  // bit).
  std::uint64_t hash = 1469598103934665603ull;
  auto add = [&hash](const void* p, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) hash = (hash ^ static_cast<const unsigned char*>(p)[i]) * 1099511628211ull;
  };
  for (const SensorResult& s : results.sensors) {
    add(s.flux_w.data(), s.flux_w.size() * sizeof(double));
    add(s.flux_stderr_w.data(), s.flux_stderr_w.size() * sizeof(double));
    add(s.ray_count.data(), s.ray_count.size() * sizeof(s.ray_count[0]));
    add(&s.total_flux_w, sizeof(double));
    add(&s.total_flux_stderr_w, sizeof(double));
  }
  const double t_with = median(with), t_without = median(without);
  const TopLevelStats top = setup->scene->tracer().topLevel().stats();
  nlohmann::json crossingLevel = treeJson(top.crossing_tree);
  crossingLevel["grid_cells"] = top.crossing_grid_cells;
  crossingLevel["grid_entries"] = top.crossing_grid_entries;
  return {{"sensors", sensors},
          {"top_level", treeJson(top.tree)},
          {"sensor_level", crossingLevel},
          {"bins", setup->scene->binCount()},
          {"instances", setup->graph.instances().size()},
          {"meshes", meshes},
          {"rays", rays},
          {"segments", counters.segments},
          {"crossings", counters.crossings},
          {"sensor_run_s", t_with},
          {"closest_hit_s", t_without},
          {"sensor_rays_per_s", static_cast<double>(rays) / t_with},
          {"closest_hit_rays_per_s", static_cast<double>(rays) / t_without},
          {"overhead_ratio", t_with / t_without},
          // Process CPU time (all threads): on a shared machine a one-thread run's CPU time leaves
          // out the time it waited for a core, so its ratio is steadier than the wall-clock one.
          {"sensor_run_cpu_s", median(with_cpu)},
          {"closest_hit_cpu_s", median(without_cpu)},
          {"overhead_ratio_cpu", median(with_cpu) / median(without_cpu)},
          {"recorded_flux_w", recorded},
          {"results_hash", std::to_string(hash)}};
}

/// "sensor_level": the crossing query alone on the overhead scene's 10,000 small sensors (no
/// meshes), with the sensors' tree built with several intersection costs and empty bonuses
/// (TopLevelConfig::crossing_build, walked without the grid), and as shipped (the grid): process CPU time per query
/// (best of `repeat` interleaved rounds; CPU time, because the machine may be shared) on wall-to-wall segments of the
/// room, each from a random wall point (by area) in a cosine-distributed direction, as diffuse bounces leave.
nlohmann::json sensorLevelSweep(std::size_t sensors, std::size_t segments, int repeat) {
  SensorSpec spec;
  spec.width = 0.1;
  spec.height = 0.1;
  spec.nx = 4;
  spec.ny = 4;
  const auto small = std::make_shared<const SensorObject>("small", spec);
  std::vector<InstanceDesc> instances;
  const std::vector<Affine> at = smallSensorPlacements(sensors);
  for (std::size_t k = 0; k < sensors; ++k) instances.push_back({small, at[k], static_cast<std::uint32_t>(k)});
  std::vector<Ray> rays;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec3 lo(-5, -5, 0), hi(5, 5, 4);
  while (rays.size() < segments) {
    const double pick = 180.0 * u(rng);  // wall areas: 2 x 40 (x), 2 x 40 (y), 2 x 100 (z)
    const int axis = pick < 40.0 ? 0 : pick < 80.0 ? 1 : 2;
    const bool upper = u(rng) < 0.5;
    glm::dvec3 o(lo.x + 10.0 * u(rng), lo.y + 10.0 * u(rng), lo.z + 4.0 * u(rng));
    o[axis] = upper ? hi[axis] : lo[axis];
    const double r1 = u(rng), phi = 2.0 * kPi * u(rng), s = std::sqrt(r1);
    glm::dvec3 d(0.0);
    d[(axis + 1) % 3] = s * std::cos(phi);
    d[(axis + 2) % 3] = s * std::sin(phi);
    d[axis] = (upper ? -1.0 : 1.0) * std::sqrt(1.0 - r1);
    double t_exit = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) {
      if (d[k] > 0.0) t_exit = std::min(t_exit, (hi[k] - o[k]) / d[k]);
      if (d[k] < 0.0) t_exit = std::min(t_exit, (lo[k] - o[k]) / d[k]);
    }
    Ray ray;
    ray.origin = glm::vec3(o);
    ray.dir = glm::vec3(d);
    ray.tfar = static_cast<float>(t_exit);
    rays.push_back(ray);
  }
  struct Variant {
    float intersection_cost, empty_bonus;
    bool grid;  // TopLevelConfig::crossing_grid: the uniform grid instead of the tree
  };
  const KdBuildConfig shipped = crossingLevelBuildDefaults(), main_level = topLevelBuildDefaults();
  const std::vector<Variant> variants{{main_level.intersection_cost, main_level.empty_bonus, false},
                                      {0.3f, 0.0f, false},
                                      {0.1f, 0.0f, false},
                                      {0.1f, 0.2f, false},
                                      {0.05f, 0.0f, false},
                                      {0.02f, 0.0f, false},
                                      {0.01f, 0.0f, false},
                                      {shipped.intersection_cost, shipped.empty_bonus, true}};
  std::vector<std::unique_ptr<TopLevel>> tops;
  for (const Variant& v : variants) {
    TopLevelConfig c;
    c.crossing_build.intersection_cost = v.intersection_cost;
    c.crossing_build.empty_bonus = v.empty_bonus;
    c.crossing_grid = v.grid;
    tops.push_back(std::make_unique<TopLevel>(c));
    tops.back()->build(instances);
  }
  std::vector<double> best(variants.size(), std::numeric_limits<double>::infinity());
  std::vector<std::uint64_t> crossings(variants.size(), 0);
  for (int round = 0; round < repeat; ++round) {
    for (std::size_t k = 0; k < tops.size(); ++k) {
      QueryContext ctx;
      std::vector<Crossing> found;
      std::uint64_t n = 0;
      const std::clock_t c0 = std::clock();
      for (const Ray& r : rays) {
        (void)tops[k]->intersectWithCrossings(r, found, ctx);
        n += found.size();
      }
      best[k] = std::min(best[k], static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
      crossings[k] = n;
    }
  }
  nlohmann::json rows = nlohmann::json::array();
  for (std::size_t k = 0; k < variants.size(); ++k) {
    const TopLevelStats tst = tops[k]->stats();
    const KdTreeStats& st = tst.crossing_tree;
    rows.push_back({{"intersection_cost", variants[k].intersection_cost},
                    {"empty_bonus", variants[k].empty_bonus},
                    {"grid", variants[k].grid},
                    {"grid_cells", tst.crossing_grid_cells},
                    {"grid_entries", tst.crossing_grid_entries},
                    {"shipped", k + 1 == variants.size()},
                    {"nodes", st.nodes},
                    {"references", st.references},
                    {"sah_cost", st.sah_cost},
                    {"crossings", crossings[k]},
                    {"cpu_ns_per_query", best[k] * 1e9 / static_cast<double>(rays.size())},
                    {"vs_main_level_defaults", best[k] / best[0]}});
  }
  return {{"sensors", sensors}, {"segments", segments}, {"repeat", repeat}, {"variants", rows}};
}

/// Gauss-Legendre nodes and weights on [-1, 1] (Newton on the Legendre recurrence).
void gaussLegendre(int n, std::vector<double>& x, std::vector<double>& w) {
  x.assign(n, 0.0);
  w.assign(n, 0.0);
  for (int i = 0; i < n; ++i) {
    double z = std::cos(kPi * (i + 0.75) / (n + 0.5)), dp = 0.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = 0.0;
      for (int k = 1; k <= n; ++k) {
        const double p2 = p1;
        p1 = p0;
        p0 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p2) / k;
      }
      dp = n * (z * p0 - p1) / (z * z - 1.0);
      const double dz = p0 / dp;
      z -= dz;
      if (std::abs(dz) < 1e-15) break;
    }
    x[i] = z;
    w[i] = 2.0 / ((1.0 - z * z) * dp * dp);
  }
}

/// Configuration factor from a w x h rectangle to a parallel coaxial disk of radius a at distance
/// d: the mean over the rectangle of the point-to-disk factor
/// F(rho) = (1 - (d^2 + rho^2 - a^2) / sqrt((d^2 + rho^2 + a^2)^2 - 4 a^2 rho^2)) / 2.
double rectangleToDiskFactor(double w, double h, double a, double d) {
  std::vector<double> x, g;
  gaussLegendre(24, x, g);
  const int cells = 16;  // composite rule: the integrand is smooth, 16 x 16 cells of 24^2 points
  double sum = 0.0;
  for (int ci = 0; ci < cells; ++ci)
    for (int cj = 0; cj < cells; ++cj)
      for (std::size_t i = 0; i < x.size(); ++i)
        for (std::size_t j = 0; j < x.size(); ++j) {
          const double px = w * ((ci + 0.5 * (x[i] + 1.0)) / cells - 0.5);
          const double py = h * ((cj + 0.5 * (x[j] + 1.0)) / cells - 0.5);
          const double rho2 = px * px + py * py;
          const double s = d * d + rho2 + a * a;
          const double f = 0.5 * (1.0 - (d * d + rho2 - a * a) / std::sqrt(s * s - 4.0 * a * a * rho2));
          sum += g[i] * g[j] * f;
        }
  return sum / (4.0 * cells * cells);
}

struct Exact {
  std::unique_ptr<Setup> setup;
  double flux_w = 0.0;
  std::string what;
  std::string label;  // short, for chart legends
};

Exact pointOnSquare() {
  // 4 pi W isotropic (1 W/sr) at height 1 above the centre of a 0.2 x 0.2 sensor.
  Exact e;
  e.setup = std::make_unique<Setup>();
  e.setup->place(e.setup->object(sensorObject(0.2, 0.2, 1, 1, SensorShape::Rectangle, "square"), "square"),
                 Affine::identity(), "square");
  e.setup->finish({pointLight({0, 0, 1}, 4.0 * kPi)});
  // Solid angle of a centred a x b rectangle at distance d: 4 asin(ab / sqrt((a^2 + d^2)(b^2 + d^2))),
  // a, b half sizes.
  const double a = 0.1, d = 1.0;
  e.flux_w = 4.0 * std::asin(a * a / (a * a + d * d));
  e.what = "isotropic point source (1 W/sr) 1 unit above the centre of a 0.2 x 0.2 sensor";
  e.label = "point source -> square sensor";
  return e;
}

Exact areaOnDisk() {
  // A 1 x 0.5 Lambertian rectangle of 1 W facing down, 0.8 above a coaxial disk of radius 0.3.
  Exact e;
  e.setup = std::make_unique<Setup>();
  e.setup->place(e.setup->object(sensorObject(0.6, 0.6, 1, 1, SensorShape::Disk, "disk"), "disk"), Affine::identity(),
                 "disk");
  Light l;
  l.type = LightType::Area;
  l.name = "panel";
  l.power_w = 1.0;
  l.width = 1.0;
  l.height = 0.5;
  l.world_from_light = translate({0, 0, 0.8});
  l.world_from_light.linear = glm::dmat3(1, 0, 0, 0, -1, 0, 0, 0, -1);  // emits towards -z
  e.setup->finish({l});
  e.flux_w = rectangleToDiskFactor(1.0, 0.5, 0.3, 0.8);
  e.what = "1 W Lambertian 1 x 0.5 rectangle facing a coaxial disk of radius 0.3 at distance 0.8";
  e.label = "Lambertian rectangle -> coaxial disk";
  return e;
}

nlohmann::json convergence(const Exact& e, std::uint64_t max_rays, int seeds, unsigned threads) {
  nlohmann::json points = nlohmann::json::array();
  for (std::uint64_t n = 1000; n <= max_rays; n *= 4) {
    double sq = 0.0, reported = 0.0, time = 0.0;
    for (int k = 0; k < seeds; ++k) {
      SensorRunConfig cfg;
      cfg.threads = threads;
      cfg.seed = 1000 + static_cast<std::uint64_t>(k);
      SensorRun run(*e.setup->scene, cfg);
      const auto t0 = std::chrono::steady_clock::now();
      (void)run.runUntil(n);
      time += seconds(t0);
      const SensorRunResults r = run.results();
      const double rel = (r.sensors.at(0).total_flux_w - e.flux_w) / e.flux_w;
      sq += rel * rel;
      reported += r.sensors.at(0).relative_stderr;
    }
    points.push_back({{"rays", n},
                      {"rms_relative_error", std::sqrt(sq / seeds)},
                      {"mean_reported_relative_stderr", reported / seeds},
                      {"mean_seconds", time / seeds}});
  }
  return {{"case", e.what}, {"label", e.label}, {"exact_flux_w", e.flux_w}, {"seeds", seeds}, {"points", points}};
}

}  // namespace
}  // namespace duplex

int main(int argc, char** argv) {
  using namespace duplex;
  CLI::App app{
      "duplex_bench_sensor: sensor overhead against closest-hit tracing, and convergence against exact answers"};
  std::uint64_t rays = 200000, max_rays = 1024000;
  unsigned threads = 1;
  int repeat = 3, seeds = 16;
  std::vector<std::size_t> counts{0, 1, 100, 10000};
  std::string data_dir = DUPLEX_BENCH_DATA_DIR;
  bool quick = false;
  std::size_t sweep_segments = 50000;
  app.add_option("--rays", rays, "emitted rays per overhead run")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "worker threads (0: all)");
  app.add_option("--repeat", repeat, "runs per configuration (median)")->check(CLI::PositiveNumber);
  app.add_option("--sensors", counts, "sensor counts of the overhead runs");
  app.add_option("--max-rays", max_rays, "largest run of the convergence series (1000 * 4^k)")
      ->check(CLI::PositiveNumber);
  app.add_option("--seeds", seeds, "runs per convergence point")->check(CLI::PositiveNumber);
  app.add_option("--data", data_dir, "shared data folder (meshes/spot.obj, meshes/koala.obj)");
  app.add_option("--sweep-segments", sweep_segments,
                 "segments of the sensors' tree sweep (crossing query alone, 10,000 sensors; 0: skip)");
  app.add_flag("--quick", quick,
               "small run for tests: 20,000 rays, one repeat, convergence up to 64,000 rays, 4 seeds");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    rays = 20000;
    repeat = 1;
    max_rays = 64000;
    seeds = 4;
    sweep_segments = 2000;
  }
  try {
    nlohmann::json out;
    out["bench"] = "sensor";
    out["threads"] = threads == 0 ? std::thread::hardware_concurrency() : threads;
    out["repeat"] = repeat;
    nlohmann::json rows = nlohmann::json::array();
    for (const std::size_t c : counts) rows.push_back(overhead(c, rays, threads, repeat, data_dir));
    // What adding sensors costs in all: the run with sensors against the same paths without them.
    for (const auto& base : rows)
      if (base["sensors"] == 0)
        for (auto& row : rows)
          row["overhead_vs_no_sensors"] = row["sensor_run_s"].get<double>() / base["closest_hit_s"].get<double>();
    out["overhead"] = rows;
    if (sweep_segments > 0) out["sensor_level"] = sensorLevelSweep(10000, sweep_segments, std::max(repeat, 3));
    out["convergence"] = {convergence(pointOnSquare(), max_rays, seeds, threads),
                          convergence(areaOnDisk(), max_rays, seeds, threads)};
    std::cout << out.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_sensor: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
