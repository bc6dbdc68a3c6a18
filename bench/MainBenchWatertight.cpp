// The main benchmark's watertightness count: rays aimed at shared vertices and edges of a closed
// mesh from outside, each from a direction that faces every triangle around its target, must hit
// no farther than the target; a miss or a first hit beyond it is a leak (see MainBenchParts.h).
// The construction follows objects/mesh/tests/WatertightTest.cpp (near the origin: rays built in
// double and rounded, the allowed t widened by the rounding).

#include "MainBenchParts.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <atomic>
#include <iostream>
#include <map>
#include <random>

namespace duplex::bench::main_detail {

namespace {

struct Target {
  glm::dvec3 point;
  std::vector<std::uint32_t> triangles;
};

double signedVolume(const TriangleMesh& m) {
  double v = 0.0;
  for (std::size_t i = 0; i < m.triangleCount(); ++i) {
    if (!m.isValid(i)) continue;
    const auto p = m.vertices(i);
    v += glm::dot(glm::dvec3(p[0]), glm::cross(glm::dvec3(p[1]), glm::dvec3(p[2])));
  }
  return v / 6.0;
}

// Smallest -d.n over the target's triangles (positive: d faces all of them), d normalised.
double minFacing(const glm::dvec3& d, const Target& target, const std::vector<glm::dvec3>& normals) {
  const glm::dvec3 u = glm::normalize(d);
  double m = 1.0;
  for (const std::uint32_t t : target.triangles) m = std::min(m, -glm::dot(u, normals[t]));
  return m;
}

[[gnu::noinline]] glm::vec3 roundToFloat(const glm::dvec3& v) { return glm::vec3(v); }

struct AimedRay {
  Ray ray;
  double t_allowed;
};

}  // namespace

void MeshBench::watertight(const TriangleMesh& mesh, nlohmann::json& out) {
  nlohmann::json j;
  const std::size_t budget = options_.watertight_rays;
  // Closed: encloses a volume and (nearly) every edge has two triangles.
  std::vector<std::vector<std::uint32_t>> vertex_tris(mesh.positions().size());
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::uint32_t>> edge_tris;
  for (std::size_t i = 0; i < mesh.triangleCount(); ++i) {
    if (!mesh.isValid(i)) continue;
    const auto& t = mesh.triangles()[i];
    for (int k = 0; k < 3; ++k) {
      vertex_tris[t[k]].push_back(static_cast<std::uint32_t>(i));
      edge_tris[std::minmax(t[k], t[(k + 1) % 3])].push_back(static_cast<std::uint32_t>(i));
    }
  }
  std::size_t open_edges = 0;
  for (const auto& [edge, tris] : edge_tris) open_edges += tris.size() != 2;
  const double volume = signedVolume(mesh);
  const bool closed = volume != 0.0 && open_edges <= edge_tris.size() / 1000;
  j["closed"] = closed;
  j["edges"] = edge_tris.size();
  j["edges_not_shared_by_two"] = open_edges;
  if (!closed || budget == 0) {
    j["note"] = budget == 0 ? "skipped (--watertight-rays 0)"
                            : "not a closed mesh (more than 1 in 1000 edges not shared by exactly two triangles)";
    out["watertight"] = j;
    return;
  }
  const double sign = volume > 0.0 ? 1.0 : -1.0;
  std::vector<glm::dvec3> normals(mesh.triangleCount(), glm::dvec3(0.0));
  for (std::size_t i = 0; i < mesh.triangleCount(); ++i) {
    if (!mesh.isValid(i)) continue;
    const auto v = mesh.vertices(i);
    normals[i] =
        sign * glm::normalize(glm::cross(glm::dvec3(v[1]) - glm::dvec3(v[0]), glm::dvec3(v[2]) - glm::dvec3(v[0])));
  }
  std::vector<Target> targets;
  std::size_t vertex_targets = 0;
  for (std::size_t v = 0; v < vertex_tris.size(); ++v)
    if (vertex_tris[v].size() >= 3) targets.push_back({glm::dvec3(mesh.positions()[v]), vertex_tris[v]});
  vertex_targets = targets.size();
  for (const auto& [edge, tris] : edge_tris) {
    if (tris.size() != 2) continue;
    const glm::dvec3 a(mesh.positions()[edge.first]), b(mesh.positions()[edge.second]);
    for (int k = 1; k <= 3; ++k) targets.push_back({a + (k / 4.0) * (b - a), tris});
  }
  // The rays: targets in a shuffled cycle, each with a fresh direction facing its triangles
  // (negated mean normal, perturbed); targets without one (saddle vertices) are skipped.
  std::mt19937_64 rng(options_.seed);
  std::shuffle(targets.begin(), targets.end(), rng);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double diag = glm::length(glm::dvec3(mesh.bounds().extent()));
  std::vector<AimedRay> rays;
  std::size_t draws = 0, skipped = 0;
  while (rays.size() < budget && draws < 4 * budget) {
    const Target& target = targets[draws++ % targets.size()];
    glm::dvec3 mean(0.0);
    for (const std::uint32_t t : target.triangles) mean += normals[t];
    if (glm::length(mean) == 0.0) {
      ++skipped;
      continue;
    }
    mean = glm::normalize(mean);
    glm::dvec3 dir0;
    bool found = false;
    for (int attempt = 0; attempt < 8 && !found; ++attempt) {
      const double amount = attempt < 4 ? 0.4 : (attempt < 7 ? 0.1 : 0.0);
      dir0 = glm::normalize(-mean + amount * glm::dvec3(g(rng), g(rng), g(rng)));
      found = minFacing(dir0, target, normals) > 0.05;
    }
    if (!found) {
      ++skipped;
      continue;
    }
    const double dist = diag * (0.05 + 0.45 * u01(rng));
    Ray ray;
    ray.origin = roundToFloat(target.point - dir0 * dist);
    ray.dir = roundToFloat(target.point - glm::dvec3(ray.origin));
    const double facing = minFacing(glm::dvec3(ray.dir), target, normals);
    if (!(facing > 0.0)) continue;
    const glm::dvec3 o(ray.origin), d(ray.dir);
    const double t_star = glm::dot(target.point - o, d) / glm::dot(d, d);
    const double delta = glm::length(o + t_star * d - target.point);
    rays.push_back({ray, t_star * (1.0 + 1e-5) + 4.0 * delta / (glm::length(d) * facing)});
  }
  j["targets"] = targets.size();
  j["vertex_targets"] = vertex_targets;
  j["edge_points_per_edge"] = 3;
  j["skipped_draws"] = skipped;
  j["rays"] = rays.size();
  j["method"] =
      "rays from outside (0.05-0.5 bounds diagonals away) aimed at shared vertices and points on shared edges, "
      "facing every triangle around the target; leak = miss (closest hit) or first hit beyond the target (t "
      "widened by the ray's rounding); occluded_failures: occluded() false with tfar at the allowed t";
  std::cerr << "  watertight  " << thousands(rays.size()) << " rays at vertices and edges:";
  for (const int k : live()) {
    std::atomic<std::uint64_t> misses{0}, beyond{0}, occlusion{0};
    parallelFor(arenas_.get(threads_.back()), rays.size(), [&](std::size_t i) {
      const AimedRay& a = rays[i];
      Hit hit;
      if (!intersect(k, a.ray, hit)) {
        misses.fetch_add(1, std::memory_order_relaxed);
      } else if (hit.t > a.t_allowed) {
        beyond.fetch_add(1, std::memory_order_relaxed);
      }
      Ray limited = a.ray;
      limited.tfar = static_cast<float>(a.t_allowed);
      if (static_cast<double>(limited.tfar) < a.t_allowed) limited.tfar = std::nextafter(limited.tfar, INFINITY);
      if (!occluded(k, limited)) occlusion.fetch_add(1, std::memory_order_relaxed);
    });
    const std::uint64_t leaks = misses.load() + beyond.load();
    j["by_structure"][defs_[k].key] = {
        {"leaks", leaks},
        {"misses", misses.load()},
        {"beyond_target", beyond.load()},
        {"occluded_failures", occlusion.load()},
        {"leak_fraction", rays.empty() ? 0.0 : static_cast<double>(leaks) / static_cast<double>(rays.size())}};
    std::cerr << " " << defs_[k].key << " " << thousands(leaks);
  }
  std::cerr << " leaks\n";
  out["watertight"] = j;
}

}  // namespace duplex::bench::main_detail
