#pragma once
/// \file WatertightTriangle.h
/// Watertight ray/triangle intersection after Woop, Benthin and Wald, "Watertight Ray/Triangle
/// Intersection", JCGT 2(1), 2013. Edge functions are evaluated in a ray-aligned sheared frame, so
/// two triangles sharing an edge compute the same edge function (with opposite sign) and no ray
/// passes between them; a zero edge function is re-evaluated in double.

#include "duplex/accel/Ray.h"

#include <glm/vec3.hpp>

#include <cmath>
#include <utility>

namespace duplex {

/// Per-ray constants of the watertight test (computed once per ray and space).
struct WatertightRay {
  float origin[3];
  int kx, ky, kz;       // axis permutation: kz = dominant direction axis
  float sx, sy, sz;     // shear constants
  float tnear;

  explicit WatertightRay(const Ray& r) : origin{r.origin.x, r.origin.y, r.origin.z}, tnear(r.tnear) {
    const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
    const float a[3] = {std::abs(d[0]), std::abs(d[1]), std::abs(d[2])};
    kz = (a[0] >= a[1] && a[0] >= a[2]) ? 0 : (a[1] >= a[2] ? 1 : 2);
    kx = (kz + 1) % 3;
    ky = (kx + 1) % 3;
    if (d[kz] < 0.0f) std::swap(kx, ky);  // keep the winding, so the sign of det is meaningful
    sx = d[kx] / d[kz];
    sy = d[ky] / d[kz];
    sz = 1.0f / d[kz];
  }
};

/// Two-sided test of triangle (a, b, c). On a hit with t in [ray.tnear, t_max] stores t and the
/// barycentrics (u weighs b, v weighs c) and returns true.
inline bool intersectWatertight(const WatertightRay& ray, const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                                float t_max, float& t, float& u, float& v) {
  // Plain arrays: indexed by the run-time permutation below (GLM's operator[] is a switch).
  const float A[3] = {a.x - ray.origin[0], a.y - ray.origin[1], a.z - ray.origin[2]};
  const float B[3] = {b.x - ray.origin[0], b.y - ray.origin[1], b.z - ray.origin[2]};
  const float C[3] = {c.x - ray.origin[0], c.y - ray.origin[1], c.z - ray.origin[2]};
  const float ax = A[ray.kx] - ray.sx * A[ray.kz];
  const float ay = A[ray.ky] - ray.sy * A[ray.kz];
  const float bx = B[ray.kx] - ray.sx * B[ray.kz];
  const float by = B[ray.ky] - ray.sy * B[ray.kz];
  const float cx = C[ray.kx] - ray.sx * C[ray.kz];
  const float cy = C[ray.ky] - ray.sy * C[ray.kz];
  float U = cx * by - cy * bx;
  float V = ax * cy - ay * cx;
  float W = bx * ay - by * ax;
  if (U == 0.0f || V == 0.0f || W == 0.0f) [[unlikely]] {
    // The ray passes (nearly) through an edge or vertex: decide the sign exactly.
    U = static_cast<float>(static_cast<double>(cx) * by - static_cast<double>(cy) * bx);
    V = static_cast<float>(static_cast<double>(ax) * cy - static_cast<double>(ay) * cx);
    W = static_cast<float>(static_cast<double>(bx) * ay - static_cast<double>(by) * ax);
  }
  if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
  const float det = U + V + W;
  if (det == 0.0f) return false;
  const float az = ray.sz * A[ray.kz];
  const float bz = ray.sz * B[ray.kz];
  const float cz = ray.sz * C[ray.kz];
  const float T = U * az + V * bz + W * cz;
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

}  // namespace duplex
