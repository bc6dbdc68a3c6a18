#pragma once
/// \file BenchChecks.h
/// Untimed checks that make the timings trustworthy: traversal counters (leaves and triangle tests
/// per ray, from a replica of MeshObject's closest-hit query: the library's traverseKdTree over
/// tree() with a double-precision triangle test, its hits compared with the library's on every ray)
/// and a double-precision brute-force referee for rays on which two tracers disagree.

#include "BenchCommon.h"

#include "duplex/accel/Ray.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"

#include <nlohmann/json.hpp>

#include <span>

namespace duplex::bench {

/// Mean work per ray of our closest-hit query.
struct TraversalCounts {
  double leaves_per_ray = 0.0;          ///< non-empty leaves whose triangles were tested
  double triangle_tests_per_ray = 0.0;  ///< watertight triangle tests
  /// Rays where the replica's hit triangle differs from the library's: a handful (ties, edges) is
  /// expected; many mean the library's traversal changed and the counters no longer describe it.
  std::uint64_t replica_mismatches = 0;
  [[nodiscard]] nlohmann::json toJson() const;
};

/// Counts over `rays` (parallel on `arena`). Assumes tree().prim_indices holds mesh triangle ids.
[[nodiscard]] TraversalCounts countTraversal(tbb::task_arena& arena, const MeshObject& object,
                                             std::span<const Ray> rays);

/// Whether any valid triangle of `mesh` meets `ray` within [tnear, tfar], in double precision over
/// all triangles (edges and vertices count as inside). Slow: for a few disputed rays only.
[[nodiscard]] bool refereeHits(tbb::task_arena& arena, const TriangleMesh& mesh, const Ray& ray);

}  // namespace duplex::bench
