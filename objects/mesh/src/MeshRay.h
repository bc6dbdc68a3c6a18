#pragma once
// Everything a mesh query computes once per ray (object space), in one pass with SSE: the kd
// traversal's inverse direction and sign masks, the watertight test's axis permutation and shear
// constants (scalar and broadcast to four lanes), and the ray clipped to the tree's box. Private to
// the objects library: MeshObject's queries build one per ray.
//
// The values are bit for bit those of isQueryable, KdRay, WatertightRay and clipRayToBox (accel /
// objects headers; only the sign of a zero tmin / tmax may differ, which no comparison sees), as
// objects/mesh/tests/MeshRaySetupTest.cpp checks; only the way they are computed differs: two vector
// divisions instead of six scalar ones, the three slabs of the box at once, one branch for the
// validity checks, and no dispatch per ray together with the run-time permutation of the
// triangle test (docs/design/kdtree.md, "Traversal").

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/WatertightTriangle.h"
#include "WatertightTriangle4.h"

#include <emmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex::detail {

struct MeshRay {
  KdRay kd;              // the kd traversal's values (inverse direction, sign masks)
  WatertightRay wray;    // scalar constants (the exact fallback of a zero edge function)
  WatertightRay4 wray4;  // the same, broadcast and permuted for the 4-wide test
};

/// Fills the triangle test's part of `r` (r.wray, and r.wray4 with kWithRay4) from `ray` (object
/// space), which must be queryable (isQueryable in Ray.h). With kWithRay4 false, r.wray4 is left
/// unset, for leaf tests that broadcast the scalar constants themselves (the 8-lane leaves). Kept
/// apart from the box part (prepareKdRay) because a BVH walk needs it only once it reaches a leaf:
/// many visits of an instance end at the root's boxes.
template <bool kWithRay4 = true>
[[gnu::always_inline]] inline void prepareWatertight(const Ray& ray, MeshRay& r) {
  const __m128 d = _mm_loadu_ps(&ray.dir.x);

  // Permutation and shear (WatertightRay's rules, kept in scalar form because the choice is
  // integer logic; the three divisions become one vector division d / d[kz] and lane 3 = 1/d[kz]).
  WatertightRay& w = r.wray;
  // Table lookups rather than WatertightRay's arithmetic, which the compiler turned into a branch
  // on |dy| >= |dz| (a coin flip on random rays, half a misprediction per ray). kDominant by the
  // three comparisons |dx| >= |dy|, |dx| >= |dz|, |dy| >= |dz| (one vector compare, bits 0-2):
  // x when it is >= both others, else y when |dy| >= |dz|, else z.
  static constexpr std::int8_t kDominant[8] = {2, 2, 2, 0, 1, 1, 1, 0};
  // (kx, ky) by kz and the sign of d[kz]: the next two axes, swapped when d[kz] < 0 (winding).
  static constexpr std::int8_t kCross[3][2][2] = {{{1, 2}, {2, 1}}, {{2, 0}, {0, 2}}, {{0, 1}, {1, 0}}};
  const __m128 a = _mm_andnot_ps(_mm_set1_ps(-0.0f), d);
  const __m128 lhs = _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 1, 0, 0));  // |dx|, |dx|, |dy|
  const __m128 rhs = _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 2, 2, 1));  // |dy|, |dz|, |dz|
  const int kz = kDominant[_mm_movemask_ps(_mm_cmpge_ps(lhs, rhs)) & 7];
  const float dkz = (&ray.dir.x)[kz];
  const int negative = static_cast<int>(dkz < 0.0f);
  const int kx = kCross[kz][negative][0];
  const int ky = kCross[kz][negative][1];
  alignas(16) float q[4];
  // {dx, dy, dz, 1} / dkz: lane k = d[k] / d[kz] (the shear of axis k), lane 3 = 1 / d[kz].
  const __m128 num =
      _mm_or_ps(_mm_and_ps(d, _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0))), _mm_setr_ps(0.0f, 0.0f, 0.0f, 1.0f));
  _mm_store_ps(q, _mm_div_ps(num, _mm_set1_ps(dkz)));
  w.origin[0] = ray.origin.x;
  w.origin[1] = ray.origin.y;
  w.origin[2] = ray.origin.z;
  w.tnear = ray.tnear;
  w.kx = kx;
  w.ky = ky;
  w.kz = kz;
  w.sx = q[kx];
  w.sy = q[ky];
  w.sz = q[3];
  if constexpr (kWithRay4) r.wray4 = WatertightRay4(w);
}

/// The box part of `r` for the BVH walks of single rays, from `ray` (object space): r.kd's origin,
/// inv_dir and tnear, the values prepareKdRay computes, and the ray's octant (bit a set: direction
/// negative on axis a, as KdRay::neg_mask says). r.kd's sign masks, zero flags and tfar are left
/// unset: the BVH's box test reads none of them, and each visit of an instance pays this set-up.
/// Returns false when the ray is not queryable (isQueryable in Ray.h).
[[gnu::always_inline]] inline bool prepareBvhRay(const Ray& ray, MeshRay& r, int& octant) {
  const __m128 o = _mm_loadu_ps(&ray.origin.x), d = _mm_loadu_ps(&ray.dir.x);
  if (!kd_detail::queryableSse(o, d, ray)) return false;
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), d);
  _mm_storeu_ps(r.kd.origin, o);     // lane 3 (tnear) lands in inv_dir[0], written next
  _mm_storeu_ps(r.kd.inv_dir, inv);  // lane 3 lands in neg_mask[0], unused here
  r.kd.tnear = ray.tnear;
  octant = _mm_movemask_ps(inv) & 7;  // the sign bits of 1 / d: -0 gives -inf, as neg_mask has it
  return true;
}

/// Fills `r` from `ray` (object space): returns false when the ray is not queryable (isQueryable in
/// Ray.h). The BVH traversal needs no more (its root's box test clips the ray). kWithRay4: as in
/// prepareWatertight.
template <bool kWithRay4 = true>
[[gnu::always_inline]] inline bool prepareMeshRay(const Ray& ray, MeshRay& r) {
  if (!prepareKdRay(ray, r.kd)) return false;
  prepareWatertight<kWithRay4>(ray, r);
  return true;
}

/// Fills `r` from `ray` (object space) and clips it to `box`: returns false when the ray is not
/// queryable (isQueryable in Ray.h) or misses the box, else the interval [tmin, tmax] as
/// clipRayToBox computes it.
inline bool setupMeshRay(const Ray& ray, const Box& box, MeshRay& r, float& tmin, float& tmax) {
  return prepareMeshRay(ray, r) && clipPreparedRay(ray, r.kd, box, tmin, tmax);
}

}  // namespace duplex::detail
