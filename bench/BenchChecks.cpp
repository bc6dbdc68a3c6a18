#include "BenchChecks.h"

#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTree.h"

#include <tbb/parallel_reduce.h>

#include <glm/geometric.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace duplex::bench {

nlohmann::json TraversalCounts::toJson() const {
  return {{"leaves_per_ray", leaves_per_ray},
          {"triangle_tests_per_ray", triangle_tests_per_ray},
          {"replica_mismatches", replica_mismatches}};
}

namespace {

// Moeller-Trumbore in double with closed edges (the referee, and the triangle test of the counting
// replica: deliberately not the library's test, whose interface changes as it is optimised). On a hit
// with t in [tnear, tfar] stores t.
bool hitsTriangle(const glm::dvec3& o, const glm::dvec3& d, double tnear, double tfar, const glm::dvec3& a,
                  const glm::dvec3& b, const glm::dvec3& c, double& t) {
  const glm::dvec3 e1 = b - a, e2 = c - a;
  const glm::dvec3 p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (det == 0.0) return false;
  const double inv = 1.0 / det;
  const glm::dvec3 s = o - a;
  const double u = glm::dot(s, p) * inv;
  if (u < 0.0 || u > 1.0) return false;
  const glm::dvec3 q = glm::cross(s, e1);
  const double v = glm::dot(d, q) * inv;
  if (v < 0.0 || u + v > 1.0) return false;
  t = glm::dot(e2, q) * inv;
  return t >= tnear && t <= tfar;
}

}  // namespace

TraversalCounts countTraversal(tbb::task_arena& arena, const MeshObject& object, std::span<const Ray> rays) {
  const KdTree& tree = object.tree();
  const TriangleMesh& mesh = object.mesh();
  const std::uint32_t* refs = tree.prim_indices.data();
  std::atomic<std::uint64_t> leaves{0}, tests{0}, mismatches{0};
  parallelFor(arena, rays.size(), [&](std::size_t i) {
    const Ray& ray = rays[i];
    // Replica of MeshObject::intersect (closest hit) with counters.
    std::uint64_t my_leaves = 0, my_tests = 0;
    std::uint32_t best = kInvalidId;
    float best_t = 0.0f;
    if (isQueryable(ray) && !tree.empty()) {
      const KdRay kray(ray);
      const glm::dvec3 o(ray.origin), d(ray.dir);
      float t_best = ray.tfar;
      traverseKdTree<false>(tree, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
        ++my_leaves;
        my_tests += count;
        bool found = false;
        for (std::uint32_t k = begin; k < begin + count; ++k) {
          const auto v = mesh.vertices(refs[k]);
          double t;
          if (hitsTriangle(o, d, ray.tnear, t_max, glm::dvec3(v[0]), glm::dvec3(v[1]), glm::dvec3(v[2]), t)) {
            t_max = static_cast<float>(t);
            best_t = t_max;
            best = refs[k];
            found = true;
          }
        }
        return found;
      });
    }
    Hit hit;
    const bool library_hit = object.intersect(ray, hit);
    // Ties between triangles sharing an edge may go either way: a different triangle at the same t
    // is not a mismatch.
    const bool same =
        library_hit == (best != kInvalidId) &&
        (!library_hit || hit.prim_id == best || std::abs(hit.t - best_t) <= 1e-5f * std::max(1.0f, hit.t));
    if (!same) mismatches.fetch_add(1, std::memory_order_relaxed);
    leaves.fetch_add(my_leaves, std::memory_order_relaxed);
    tests.fetch_add(my_tests, std::memory_order_relaxed);
  });
  TraversalCounts c;
  const double n = rays.empty() ? 1.0 : static_cast<double>(rays.size());
  c.leaves_per_ray = static_cast<double>(leaves.load()) / n;
  c.triangle_tests_per_ray = static_cast<double>(tests.load()) / n;
  c.replica_mismatches = mismatches.load();
  return c;
}

bool refereeHits(tbb::task_arena& arena, const TriangleMesh& mesh, const Ray& ray) {
  const glm::dvec3 o(ray.origin), d(ray.dir);
  const double tnear = ray.tnear, tfar = ray.tfar;
  bool any = false;
  arena.execute([&] {
    any = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, mesh.triangleCount(), 1 << 14), false,
        [&](const tbb::blocked_range<std::size_t>& r, bool found) {
          for (std::size_t i = r.begin(); i != r.end() && !found; ++i) {
            if (!mesh.isValid(i)) continue;
            const auto v = mesh.vertices(i);
            double t;
            found = hitsTriangle(o, d, tnear, tfar, glm::dvec3(v[0]), glm::dvec3(v[1]), glm::dvec3(v[2]), t);
          }
          return found;
        },
        [](bool x, bool y) { return x || y; });
  });
  return any;
}

}  // namespace duplex::bench
