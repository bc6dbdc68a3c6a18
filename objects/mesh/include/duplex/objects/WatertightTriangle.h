#pragma once
/// \file WatertightTriangle.h
/// Watertight ray/triangle intersection after Woop, Benthin and Wald, "Watertight Ray/Triangle
/// Intersection", JCGT 2(1), 2013. Edge functions are evaluated in a ray-aligned sheared frame, so
/// two triangles sharing an edge compute the same edge function (with opposite sign) and no ray
/// passes between them; a zero edge function is re-evaluated in double.

#include "duplex/accel/Ray.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>
#include <utility>

namespace duplex {

/// Per-ray constants of the watertight test (computed once per ray and space).
struct WatertightRay {
  float origin[3];  ///< ray origin, in the space of the triangles
  /// \var kx
  /// First axis of the sheared frame (0 x, 1 y, 2 z).
  /// \var ky
  /// Second axis of the sheared frame, chosen with kx so that the winding is kept.
  /// \var kz
  /// Dominant axis of the ray's direction.
  int kx, ky, kz;  // axis permutation: kz = dominant direction axis
  /// \var sx
  /// Shear of axis kx: dir[kx] / dir[kz].
  /// \var sy
  /// Shear of axis ky: dir[ky] / dir[kz].
  /// \var sz
  /// Scale of axis kz: 1 / dir[kz].
  float sx, sy, sz;  // shear constants
  float tnear;       ///< start of the segment, in units of the ray's direction

  /// Uninitialised; for code that computes the constants itself (MeshObject's per-ray setup).
  WatertightRay() = default;
  /// The constants for ray `r`, given in the space of the triangles.
  explicit WatertightRay(const Ray& r) : origin{r.origin.x, r.origin.y, r.origin.z}, tnear(r.tnear) {
    const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
    const float a[3] = {std::abs(d[0]), std::abs(d[1]), std::abs(d[2])};
    // Without branches: for random directions each of these choices is a coin flip.
    const int x_dominant = static_cast<int>(a[0] >= a[1]) & static_cast<int>(a[0] >= a[2]);
    kz = (1 - x_dominant) * (2 - static_cast<int>(a[1] >= a[2]));
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    // Keep the winding, so the sign of det is meaningful: swap kx and ky when d[kz] < 0.
    const int flip = (kx ^ ky) & -static_cast<int>(d[kz] < 0.0f);
    kx ^= flip;
    ky ^= flip;
    sx = d[kx] / d[kz];
    sy = d[ky] / d[kz];
    sz = 1.0f / d[kz];
  }
};

/// Two-sided test of triangle (a, b, c) for a ray whose axis permutation (kx, ky, kz) is known at
/// compile time: the permuted coordinates are then plain member accesses, which more than halves
/// the instruction count of the test. On a hit with t in [ray.tnear, t_max] stores t and the
/// barycentrics (u weighs b, v weighs c) and returns true.
template <int KX, int KY, int KZ>
inline bool intersectWatertight(const WatertightRay& ray, const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                                float t_max, float& t, float& u, float& v) {
  const glm::vec3 o(ray.origin[0], ray.origin[1], ray.origin[2]);
  const glm::vec3 A = a - o, B = b - o, C = c - o;
  const float ax = A[KX] - ray.sx * A[KZ];
  const float ay = A[KY] - ray.sy * A[KZ];
  const float bx = B[KX] - ray.sx * B[KZ];
  const float by = B[KY] - ray.sy * B[KZ];
  const float cx = C[KX] - ray.sx * C[KZ];
  const float cy = C[KY] - ray.sy * C[KZ];
  float U = cx * by - cy * bx;
  float V = ax * cy - ay * cx;
  float W = bx * ay - by * ax;
  // One test for "some edge function is exactly zero" (a product of non-zero values may
  // underflow to zero too; that only costs a needless, still exact, recomputation).
  if (U * V * W == 0.0f) [[unlikely]] {
    // The ray passes (nearly) through an edge or vertex: decide the sign exactly.
    U = static_cast<float>(static_cast<double>(cx) * by - static_cast<double>(cy) * bx);
    V = static_cast<float>(static_cast<double>(ax) * cy - static_cast<double>(ay) * cx);
    W = static_cast<float>(static_cast<double>(bx) * ay - static_cast<double>(by) * ax);
  }
  // Signs differ: the ray passes outside an edge (min/max compile to two compares, no branches).
  if (std::min(U, std::min(V, W)) < 0.0f && std::max(U, std::max(V, W)) > 0.0f) return false;
  const float det = U + V + W;
  if (det == 0.0f) return false;
  const float T = U * (ray.sz * A[KZ]) + V * (ray.sz * B[KZ]) + W * (ray.sz * C[KZ]);
  // Compare T / det with the interval without dividing: flip both signs when det < 0.
  const float abs_det = std::abs(det);
  const float sT = det < 0.0f ? -T : T;
  if (sT < ray.tnear * abs_det || sT > t_max * abs_det) return false;
  const float inv = 1.0f / det;
  t = T * inv;
  u = V * inv;
  v = W * inv;
  return true;
}

/// Calls `f.template operator()<KX, KY, KZ>()` with the ray's permutation as template arguments:
/// the one run-time dispatch per ray that lets the per-triangle code use constant indices.
template <class F>
inline decltype(auto) dispatchPermutation(const WatertightRay& ray, F&& f) {
  switch (ray.kz * 3 + ray.kx) {
    case 0 * 3 + 1: return f.template operator()<1, 2, 0>();
    case 0 * 3 + 2: return f.template operator()<2, 1, 0>();
    case 1 * 3 + 2: return f.template operator()<2, 0, 1>();
    case 1 * 3 + 0: return f.template operator()<0, 2, 1>();
    case 2 * 3 + 0: return f.template operator()<0, 1, 2>();
    default: return f.template operator()<1, 0, 2>();
  }
}

/// Same test with the permutation chosen at run time (for callers outside hot loops).
inline bool intersectWatertight(const WatertightRay& ray, const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                                float t_max, float& t, float& u, float& v) {
  return dispatchPermutation(
      ray, [&]<int KX, int KY, int KZ>() { return intersectWatertight<KX, KY, KZ>(ray, a, b, c, t_max, t, u, v); });
}

}  // namespace duplex
