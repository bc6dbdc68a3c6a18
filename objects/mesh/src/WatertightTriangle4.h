#pragma once
// Four watertight ray/triangle tests at once with SSE2 (baseline x86-64, no run-time dispatch) on
// a TriangleBlock4 (structure of arrays: no gather, no transpose). Private to the objects library:
// MeshObject's leaves call it.
//
// Every lane computes exactly the operations of the scalar intersectWatertight<KX, KY, KZ>, in the
// same order (SSE2 has no fused multiply-add), so a vertex shared by two triangles gets the same
// sheared coordinates in a lane as in scalar code: the watertightness argument carries over. Lanes
// with an edge function exactly zero are handed to the scalar test, which redoes them in double.

#include "duplex/objects/WatertightTriangle.h"
#include "TriangleBlock4.h"

#include <emmintrin.h>

#include <cstdint>

namespace duplex::detail {

/// Result lanes of one 4-wide test: for lane i, bit i of `fast` means "hit candidate decided in
/// float" (then sT/abs_det/T/det/V/W hold its values); bit i of `exact` means "edge function zero:
/// decide with the scalar test".
struct Watertight4 {
  int fast = 0;
  int exact = 0;
  alignas(16) float sT[4];
  alignas(16) float abs_det[4];
  alignas(16) float T[4];
  alignas(16) float det[4];
  alignas(16) float V[4];  // edge functions weighing v1 and v2: u = V / det, v = W / det
  alignas(16) float W[4];
};

/// The per-ray constants of WatertightRay broadcast to four lanes, once per ray rather than once
/// per block, in permuted order: o[0], o[1], o[2] are the origin's kx, ky, kz coordinates. The
/// permutation is a run-time value: a block's coordinate rows are loaded at offsets kx, ky, kz,
/// which costs the same as constant offsets and needs no dispatch per ray.
struct WatertightRay4 {
  __m128 o[3];
  __m128 sx, sy, sz;
  __m128 tnear;
  int kx, ky, kz;  // unset in a default-made one (MeshRay holds one the 8-lane leaves never fill)

  WatertightRay4() = default;
  explicit WatertightRay4(const WatertightRay& ray)
      : o{_mm_set1_ps(ray.origin[ray.kx]), _mm_set1_ps(ray.origin[ray.ky]), _mm_set1_ps(ray.origin[ray.kz])},
        sx(_mm_set1_ps(ray.sx)),
        sy(_mm_set1_ps(ray.sy)),
        sz(_mm_set1_ps(ray.sz)),
        tnear(_mm_set1_ps(ray.tnear)),
        kx(ray.kx),
        ky(ray.ky),
        kz(ray.kz) {}
};

/// Watertight4 in registers (what the leaf step reads, without a round trip through memory).
struct Watertight4v {
  int fast = 0;
  int exact = 0;
  __m128 sT, abs_det, T, det, V, W;
};

/// Tests the lanes in `lanes` (bit i: lane i holds one of the leaf's triangles) of `block`.
[[gnu::always_inline]] inline Watertight4v intersectWatertight4v(const WatertightRay4& ray, const TriangleBlock4& block,
                                                                 int lanes, float t_max) {
  // Rows of coordinate kx / ky / kz of vertex 0; vertex k's rows follow 12 k floats further
  // (block.v[3 k + axis]), so each row is one pointer plus a constant offset: three live pointers
  // instead of nine row addresses, which the compiler kept on the stack.
  const float* rx = block.v[ray.kx];
  const float* ry = block.v[ray.ky];
  const float* rz = block.v[ray.kz];
  const __m128 sx = ray.sx, sy = ray.sy, sz = ray.sz;
  // Relative to the origin and sheared vertex by vertex (the scalar test's operations, same order).
  const __m128 Az = _mm_sub_ps(_mm_load_ps(rz), ray.o[2]);
  const __m128 ax = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(rx), ray.o[0]), _mm_mul_ps(sx, Az));
  const __m128 ay = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(ry), ray.o[1]), _mm_mul_ps(sy, Az));
  const __m128 Bz = _mm_sub_ps(_mm_load_ps(rz + 12), ray.o[2]);
  const __m128 bx = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(rx + 12), ray.o[0]), _mm_mul_ps(sx, Bz));
  const __m128 by = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(ry + 12), ray.o[1]), _mm_mul_ps(sy, Bz));
  const __m128 Cz = _mm_sub_ps(_mm_load_ps(rz + 24), ray.o[2]);
  const __m128 cx = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(rx + 24), ray.o[0]), _mm_mul_ps(sx, Cz));
  const __m128 cy = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(ry + 24), ray.o[1]), _mm_mul_ps(sy, Cz));
  Watertight4v r;
  r.V = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
  r.W = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
  const __m128 U = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
  const __m128 V = r.V, W = r.W;
  const __m128 zero = _mm_setzero_ps();

  const __m128 any_zero = _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(U, zero), _mm_cmpeq_ps(V, zero)), _mm_cmpeq_ps(W, zero));
  r.exact = _mm_movemask_ps(any_zero) & lanes;
  // Same-sign test and det != 0, as in the scalar code.
  const __m128 mixed = _mm_and_ps(_mm_cmplt_ps(_mm_min_ps(U, _mm_min_ps(V, W)), zero),
                                  _mm_cmpgt_ps(_mm_max_ps(U, _mm_max_ps(V, W)), zero));
  r.det = _mm_add_ps(_mm_add_ps(U, V), W);
  const int candidates = ~_mm_movemask_ps(_mm_or_ps(mixed, _mm_cmpeq_ps(r.det, zero))) & lanes & ~r.exact;
  if (candidates == 0) {
    r.T = r.sT = r.abs_det = zero;  // not read: no lane is decided in float
    return r;
  }
  r.T = _mm_add_ps(_mm_add_ps(_mm_mul_ps(U, _mm_mul_ps(sz, Az)), _mm_mul_ps(V, _mm_mul_ps(sz, Bz))),
                   _mm_mul_ps(W, _mm_mul_ps(sz, Cz)));
  const __m128 sign = _mm_and_ps(r.det, _mm_set1_ps(-0.0f));
  r.abs_det = _mm_andnot_ps(_mm_set1_ps(-0.0f), r.det);
  r.sT = _mm_xor_ps(r.T, sign);
  const __m128 outside = _mm_or_ps(_mm_cmplt_ps(r.sT, _mm_mul_ps(ray.tnear, r.abs_det)),
                                   _mm_cmpgt_ps(r.sT, _mm_mul_ps(_mm_set1_ps(t_max), r.abs_det)));
  r.fast = candidates & ~_mm_movemask_ps(outside);
  return r;
}

/// The same test with its values stored per lane (for code that reads them lane by lane).
inline Watertight4 intersectWatertight4(const WatertightRay4& ray, const TriangleBlock4& block, int lanes,
                                        float t_max) {
  const Watertight4v v = intersectWatertight4v(ray, block, lanes, t_max);
  Watertight4 r;
  r.fast = v.fast;
  r.exact = v.exact;
  _mm_store_ps(r.sT, v.sT);
  _mm_store_ps(r.abs_det, v.abs_det);
  _mm_store_ps(r.T, v.T);
  _mm_store_ps(r.det, v.det);
  _mm_store_ps(r.V, v.V);
  _mm_store_ps(r.W, v.W);
  return r;
}

}  // namespace duplex::detail
