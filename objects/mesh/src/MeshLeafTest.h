#pragma once
// The leaf step of both mesh structures (kd-tree and BVH): the triangles of one leaf, stored as
// consecutive 4-wide blocks, tested against a ray (object space). Private to the objects library.
// Defined inline with the baseline target so that the traversals compiled for wider instruction
// sets (MeshBvh.cpp) inline the same code and get the same results.

#include "duplex/accel/Hit.h"
#include "duplex/objects/WatertightTriangle.h"
#include "MeshRay.h"
#include "TriangleBlock4.h"
#include "WatertightTriangle4.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <limits>

namespace duplex::detail {

// Lane masks of a block holding n (1..4) of the leaf's triangles.
inline constexpr int kLeafLaneMask[5] = {0x0, 0x1, 0x3, 0x7, 0xF};

/// The closest hit found so far: its distance and where its triangle is.
struct ClosestHit {
  const TriangleBlock4* block = nullptr;
  int lane = 0;
  float u = 0.0f, v = 0.0f;
};

/// Tests the `count` triangles of the blocks from `block` on; a hit closer than t_max lowers t_max
/// and is recorded in `best`. The lanes decided in float are resolved together (the closest of
/// them, with the scalar test's final division); lanes with an edge function exactly zero go
/// through the scalar test one by one. Returns whether anything was recorded.
inline bool closestInLeaf(const MeshRay& ray, const TriangleBlock4* block, std::uint32_t count, float& t_max,
                          ClosestHit& best) {
  bool found = false;
  for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
    const Watertight4v r = intersectWatertight4v(ray.wray4, *block, kLeafLaneMask[std::min(left, 4)], t_max);
    if (r.fast != 0) {
      const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), r.det);  // the scalar test's final step
      const __m128 t = _mm_mul_ps(r.T, inv);
      const __m128 fast = _mm_castsi128_ps(_mm_cmpeq_epi32(
          _mm_and_si128(_mm_set1_epi32(r.fast), _mm_setr_epi32(1, 2, 4, 8)), _mm_setr_epi32(1, 2, 4, 8)));
      // The smallest t of the fast lanes, broadcast; its first lane wins ties.
      __m128 m =
          _mm_or_ps(_mm_and_ps(fast, t), _mm_andnot_ps(fast, _mm_set1_ps(std::numeric_limits<float>::infinity())));
      m = _mm_min_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
      m = _mm_min_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
      const int k = std::countr_zero(static_cast<unsigned>(_mm_movemask_ps(_mm_and_ps(fast, _mm_cmpeq_ps(t, m)))));
      alignas(16) float tv[4], uv[4], vv[4];
      _mm_store_ps(tv, t);
      _mm_store_ps(uv, _mm_mul_ps(r.V, inv));
      _mm_store_ps(vv, _mm_mul_ps(r.W, inv));
      t_max = tv[k];
      best = {block, k, uv[k], vv[k]};
      found = true;
    }
    for (int lanes = r.exact; lanes != 0; lanes &= lanes - 1) {
      const int k = std::countr_zero(static_cast<unsigned>(lanes));
      float t, u, v;
      if (!intersectWatertight(ray.wray, block->vertex(k, 0), block->vertex(k, 1), block->vertex(k, 2), t_max, t, u, v))
        continue;
      t_max = t;
      best = {block, k, u, v};
      found = true;
    }
  }
  return found;
}

/// The lanes of `exact` (edge function zero) of `block` decided by the scalar test: whether one is
/// hit within t_max. Rare, so out of line: it keeps the inlined anyInLeaf small.
[[gnu::noinline, gnu::cold]] inline bool anyExactInBlock(const MeshRay& ray, const TriangleBlock4& block, int exact,
                                                         float t_max) {
  for (; exact != 0; exact &= exact - 1) {
    const int k = std::countr_zero(static_cast<unsigned>(exact));
    float t, u, v;
    if (intersectWatertight(ray.wray, block.vertex(k, 0), block.vertex(k, 1), block.vertex(k, 2), t_max, t, u, v))
      return true;
  }
  return false;
}

/// Whether any of the `count` triangles of the blocks from `block` on is hit within t_max: the
/// first block with a lane decided in float ends the search. Inlined into the traversals: a call
/// would spill their ray constants around every leaf.
[[gnu::always_inline]] inline bool anyInLeaf(const MeshRay& ray, const TriangleBlock4* block, std::uint32_t count,
                                             float t_max) {
  for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
    const Watertight4v r = intersectWatertight4v(ray.wray4, *block, kLeafLaneMask[std::min(left, 4)], t_max);
    if (r.fast != 0) return true;
    if (r.exact != 0 && anyExactInBlock(ray, *block, r.exact, t_max)) return true;
  }
  return false;
}

/// Fills `hit` (object space) from the recorded closest hit at distance t.
[[gnu::always_inline]] inline void fillHit(const ClosestHit& best, float t, Hit& hit) {
  const glm::vec3 v0 = best.block->vertex(best.lane, 0);
  hit.t = t;
  hit.u = best.u;
  hit.v = best.v;
  hit.prim_id = best.block->prim[best.lane];
  hit.ng = glm::cross(best.block->vertex(best.lane, 1) - v0, best.block->vertex(best.lane, 2) - v0);
}

}  // namespace duplex::detail
