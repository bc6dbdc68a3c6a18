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
// triangle test (docs/kdtree.md, "Traversal").

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

/// Fills `r` from `ray` (object space): returns false when the ray is not queryable (isQueryable in
/// Ray.h). The BVH traversal needs no more (its root's box test clips the ray).
[[gnu::always_inline]] inline bool prepareMeshRay(const Ray& ray, MeshRay& r) {
  // Ray is {ox, oy, oz, tnear, dx, dy, dz, tfar}: two unaligned loads.
  const __m128 o = _mm_loadu_ps(&ray.origin.x);
  const __m128 d = _mm_loadu_ps(&ray.dir.x);
  const __m128 one = _mm_set1_ps(1.0f);
  const __m128 sign_bit = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  // isQueryable (Ray.h) with one branch: origin and direction finite (|x| < inf is false for NaN
  // and inf), some direction component non-zero, tnear <= tfar.
  const int finite = _mm_movemask_ps(
      _mm_and_ps(_mm_cmplt_ps(_mm_andnot_ps(sign_bit, o), inf), _mm_cmplt_ps(_mm_andnot_ps(sign_bit, d), inf)));
  const int nonzero = _mm_movemask_ps(_mm_cmpneq_ps(d, _mm_setzero_ps()));
  if (((finite & 7) != 7) | ((nonzero & 7) == 0) | !(ray.tnear <= ray.tfar)) return false;
  // 1/d is already +-inf with the sign of d for a zero (or denormal) component, which is what
  // KdRay stores for them. Lane 3 (1/tfar) is never read.
  const __m128 inv = _mm_div_ps(one, d);
  const __m128 zero_dir = _mm_cmpeq_ps(_mm_andnot_ps(sign_bit, inv), inf);
  {
    alignas(16) float inv_dir[4];
    alignas(16) std::uint32_t neg_mask[4];
    _mm_store_ps(inv_dir, inv);
    _mm_store_si128(reinterpret_cast<__m128i*>(neg_mask), _mm_srai_epi32(_mm_castps_si128(inv), 31));
    const int zero = _mm_movemask_ps(zero_dir);
    KdRay& k = r.kd;
    for (int a = 0; a < 3; ++a) {
      k.origin[a] = (&ray.origin.x)[a];
      k.inv_dir[a] = inv_dir[a];
      k.neg_mask[a] = neg_mask[a];
      k.zero[a] = (zero >> a & 1) != 0;
    }
    k.tnear = ray.tnear;
    k.tfar = ray.tfar;
  }

  // Permutation and shear (WatertightRay's rules, kept in scalar form because the choice is
  // integer logic; the three divisions become one vector division d / d[kz] and lane 3 = 1/d[kz]).
  WatertightRay& w = r.wray;
  const float dx = ray.dir.x, dy = ray.dir.y, dz = ray.dir.z;
  const float a0 = std::abs(dx), a1 = std::abs(dy), a2 = std::abs(dz);
  // Table lookups rather than WatertightRay's arithmetic, which the compiler turned into a branch
  // on |dy| >= |dz| (a coin flip on random rays, half a misprediction per ray). kDominant by the
  // three comparisons: x when it is >= both others, else y when |dy| >= |dz|, else z.
  static constexpr std::int8_t kDominant[8] = {2, 2, 2, 0, 1, 1, 1, 0};
  // (kx, ky) by kz and the sign of d[kz]: the next two axes, swapped when d[kz] < 0 (winding).
  static constexpr std::int8_t kCross[3][2][2] = {{{1, 2}, {2, 1}}, {{2, 0}, {0, 2}}, {{0, 1}, {1, 0}}};
  const int kz =
      kDominant[static_cast<int>(a0 >= a1) | static_cast<int>(a0 >= a2) << 1 | static_cast<int>(a1 >= a2) << 2];
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
  r.wray4 = WatertightRay4(w);

  return true;
}

/// Fills `r` from `ray` (object space) and clips it to `box`: returns false when the ray is not
/// queryable (isQueryable in Ray.h) or misses the box, else the interval [tmin, tmax] as
/// clipRayToBox computes it.
inline bool setupMeshRay(const Ray& ray, const Box& box, MeshRay& r, float& tmin, float& tmax) {
  if (!prepareMeshRay(ray, r)) return false;
  const __m128 o = _mm_loadu_ps(&ray.origin.x);
  const __m128 d = _mm_loadu_ps(&ray.dir.x);
  const __m128 sign_bit = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 inv = _mm_setr_ps(r.kd.inv_dir[0], r.kd.inv_dir[1], r.kd.inv_dir[2], 0.0f);
  const __m128 zero_dir = _mm_cmpeq_ps(_mm_andnot_ps(sign_bit, inv), inf);
  // Clip to the box, three slabs at once, with clipIntervalToBox's rules and results: per axis the
  // entry and exit are widened, and a widened value that is NaN (an infinite distance) is ignored,
  // as std::max / std::min ignore it there; SSE's max / min return their second operand when either
  // is NaN. An axis with zero direction only tests the origin against the closed slab.
  const __m128 lo = _mm_setr_ps(box.lo.x, box.lo.y, box.lo.z, 0.0f);
  const __m128 hi = _mm_setr_ps(box.hi.x, box.hi.y, box.hi.z, 0.0f);
  const __m128 outside = _mm_or_ps(_mm_cmplt_ps(o, lo), _mm_cmpgt_ps(o, hi));
  if ((_mm_movemask_ps(_mm_and_ps(zero_dir, outside)) & 7) != 0) return false;
  const __m128 t0 = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
  const __m128 t1 = _mm_mul_ps(_mm_sub_ps(hi, o), inv);
  // std::min(t0, t1) is t1 < t0 ? t1 : t0, as _mm_min_ps(t1, t0).
  const __m128 t_in = _mm_min_ps(t1, t0);
  const __m128 t_out = _mm_max_ps(t1, t0);
  constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
  const __m128 widen = _mm_set1_ps(kWiden);
  __m128 w_in = _mm_sub_ps(t_in, _mm_mul_ps(_mm_andnot_ps(sign_bit, t_in), widen));
  __m128 w_out = _mm_add_ps(t_out, _mm_mul_ps(_mm_andnot_ps(sign_bit, t_out), widen));
  // Zero-direction lanes do not limit the interval (-inf / +inf are neutral below).
  w_in = _mm_or_ps(_mm_and_ps(zero_dir, _mm_xor_ps(inf, sign_bit)), _mm_andnot_ps(zero_dir, w_in));
  w_out = _mm_or_ps(_mm_and_ps(zero_dir, inf), _mm_andnot_ps(zero_dir, w_out));
  // max(tnear, w) per lane (a NaN w gives tnear), then the largest of lanes 0..2; min likewise.
  const __m128 m_in = _mm_max_ps(w_in, _mm_shuffle_ps(o, o, _MM_SHUFFLE(3, 3, 3, 3)));
  const __m128 m_out = _mm_min_ps(w_out, _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 3, 3, 3)));
  tmin = _mm_cvtss_f32(_mm_max_ss(_mm_max_ss(m_in, _mm_shuffle_ps(m_in, m_in, 1)), _mm_movehl_ps(m_in, m_in)));
  tmax = _mm_cvtss_f32(_mm_min_ss(_mm_min_ss(m_out, _mm_shuffle_ps(m_out, m_out, 1)), _mm_movehl_ps(m_out, m_out)));
  return tmin <= tmax;
}

}  // namespace duplex::detail
