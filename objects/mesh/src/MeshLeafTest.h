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
/// and is recorded in `best`. Lanes are resolved in order with the scalar interval test, so the
/// result equals testing the triangles one by one. Returns whether anything was recorded.
inline bool closestInLeaf(const MeshRay& ray, const TriangleBlock4* block, std::uint32_t count, float& t_max,
                          ClosestHit& best) {
  bool found = false;
  for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
    const Watertight4 r = intersectWatertight4(ray.wray4, *block, kLeafLaneMask[std::min(left, 4)], t_max);
    for (int lanes = r.fast | r.exact; lanes != 0; lanes &= lanes - 1) {
      const int k = std::countr_zero(static_cast<unsigned>(lanes));
      float t, u, v;
      if (r.exact >> k & 1) {
        if (!intersectWatertight(ray.wray, block->vertex(k, 0), block->vertex(k, 1), block->vertex(k, 2), t_max, t, u,
                                 v))
          continue;
      } else {
        if (r.sT[k] > t_max * r.abs_det[k]) continue;
        const float inv = 1.0f / r.det[k];  // the scalar test's final step
        t = r.T[k] * inv;
        u = r.V[k] * inv;
        v = r.W[k] * inv;
      }
      t_max = t;
      best = {block, k, u, v};
      found = true;
    }
  }
  return found;
}

/// Whether any of the `count` triangles of the blocks from `block` on is hit within t_max.
inline bool anyInLeaf(const MeshRay& ray, const TriangleBlock4* block, std::uint32_t count, float t_max) {
  for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
    const Watertight4 r = intersectWatertight4(ray.wray4, *block, kLeafLaneMask[std::min(left, 4)], t_max);
    if (r.fast) return true;
    for (int lanes = r.exact; lanes != 0; lanes &= lanes - 1) {
      const int k = std::countr_zero(static_cast<unsigned>(lanes));
      float t, u, v;
      if (intersectWatertight(ray.wray, block->vertex(k, 0), block->vertex(k, 1), block->vertex(k, 2), t_max, t, u, v))
        return true;
    }
  }
  return false;
}

/// Fills `hit` (object space) from the recorded closest hit at distance t.
inline void fillHit(const ClosestHit& best, float t, Hit& hit) {
  const glm::vec3 v0 = best.block->vertex(best.lane, 0);
  hit.t = t;
  hit.u = best.u;
  hit.v = best.v;
  hit.prim_id = best.block->prim[best.lane];
  hit.ng = glm::cross(best.block->vertex(best.lane, 1) - v0, best.block->vertex(best.lane, 2) - v0);
}

}  // namespace duplex::detail
