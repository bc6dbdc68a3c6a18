#include "duplex/accel/TriangleClip.h"

#include <glm/vec3.hpp>

#include <cmath>

namespace duplex {

Box clipTriangleToBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box) {
  if (box.empty()) return {};
  // Sutherland-Hodgman in double: a triangle clipped by 6 planes has at most 9 vertices.
  glm::dvec3 poly[12], next[12];
  int n = 3;
  poly[0] = glm::dvec3(a);
  poly[1] = glm::dvec3(b);
  poly[2] = glm::dvec3(c);
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    for (int side = 0; side < 2 && n > 0; ++side) {
      const double plane = side == 0 ? box.lo[axis] : box.hi[axis];
      // inside: coordinate >= plane (lower face) or <= plane (upper face)
      auto inside = [&](const glm::dvec3& p) { return side == 0 ? p[axis] >= plane : p[axis] <= plane; };
      int m = 0;
      for (int i = 0; i < n; ++i) {
        const glm::dvec3& p = poly[i];
        const glm::dvec3& q = poly[(i + 1) % n];
        const bool pin = inside(p), qin = inside(q);
        if (pin) next[m++] = p;
        if (pin != qin) {
          const double t = (plane - p[axis]) / (q[axis] - p[axis]);
          glm::dvec3 x = p + t * (q - p);
          x[axis] = plane;  // exactly on the plane
          next[m++] = x;
        }
      }
      n = m;
      for (int i = 0; i < n; ++i) poly[i] = next[i];
    }
  }
  if (n == 0) return {};
  glm::dvec3 lo = poly[0], hi = poly[0];
  for (int i = 1; i < n; ++i) {
    lo = glm::min(lo, poly[i]);
    hi = glm::max(hi, poly[i]);
  }
  Box out;
  for (int k = 0; k < 3; ++k) {
    // Round outward so the float box contains the exact clipped polygon, then stay inside `box`.
    float l = static_cast<float>(lo[k]), h = static_cast<float>(hi[k]);
    if (static_cast<double>(l) > lo[k]) l = std::nextafter(l, -INFINITY);
    if (static_cast<double>(h) < hi[k]) h = std::nextafter(h, INFINITY);
    out.lo[k] = std::max(l, box.lo[k]);
    out.hi[k] = std::min(h, box.hi[k]);
  }
  return out;
}

}  // namespace duplex
