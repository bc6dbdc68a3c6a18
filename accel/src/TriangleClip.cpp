#include "duplex/accel/TriangleClip.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>

namespace duplex {

Box clipTriangleToBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box) {
  if (box.empty()) return {};
  // Sutherland-Hodgman in double: a triangle clipped by 6 planes has at most 9 vertices.
  // Points as plain double[3] (indexed by a run-time axis; GLM's operator[] is a switch).
  struct P {
    double v[3];
  };
  const float box_lo[3] = {box.lo.x, box.lo.y, box.lo.z};
  const float box_hi[3] = {box.hi.x, box.hi.y, box.hi.z};
  P poly[12], next[12];
  int n = 3;
  poly[0] = {{a.x, a.y, a.z}};
  poly[1] = {{b.x, b.y, b.z}};
  poly[2] = {{c.x, c.y, c.z}};
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    // Skip planes no vertex crosses: the common case for a triangle mostly inside the box.
    double vmin = poly[0].v[axis], vmax = vmin;
    for (int i = 1; i < n; ++i) {
      vmin = std::min(vmin, poly[i].v[axis]);
      vmax = std::max(vmax, poly[i].v[axis]);
    }
    for (int side = 0; side < 2 && n > 0; ++side) {
      const double plane = side == 0 ? box_lo[axis] : box_hi[axis];
      if (side == 0 ? vmin >= plane : vmax <= plane) continue;
      // inside: coordinate >= plane (lower face) or <= plane (upper face)
      auto inside = [&](const P& p) { return side == 0 ? p.v[axis] >= plane : p.v[axis] <= plane; };
      int m = 0;
      for (int i = 0; i < n; ++i) {
        const P& p = poly[i];
        const P& q = poly[(i + 1) % n];
        const bool pin = inside(p), qin = inside(q);
        if (pin) next[m++] = p;
        if (pin != qin) {
          const double t = (plane - p.v[axis]) / (q.v[axis] - p.v[axis]);
          P x;
          for (int k = 0; k < 3; ++k) x.v[k] = p.v[k] + t * (q.v[k] - p.v[k]);
          x.v[axis] = plane;  // exactly on the plane
          next[m++] = x;
        }
      }
      n = m;
      for (int i = 0; i < n; ++i) poly[i] = next[i];
      // vmin/vmax of this axis stay valid for the other side: clipping one side only moves
      // vertices onto that plane.
    }
  }
  if (n == 0) return {};
  double lo[3] = {poly[0].v[0], poly[0].v[1], poly[0].v[2]};
  double hi[3] = {lo[0], lo[1], lo[2]};
  for (int i = 1; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], poly[i].v[k]);
      hi[k] = std::max(hi[k], poly[i].v[k]);
    }
  Box out;
  for (int k = 0; k < 3; ++k) {
    // Round outward so the float box contains the exact clipped polygon, then stay inside `box`.
    float l = static_cast<float>(lo[k]), h = static_cast<float>(hi[k]);
    if (static_cast<double>(l) > lo[k]) l = std::nextafter(l, -INFINITY);
    if (static_cast<double>(h) < hi[k]) h = std::nextafter(h, INFINITY);
    out.lo[k] = std::max(l, box_lo[k]);
    out.hi[k] = std::min(h, box_hi[k]);
  }
  return out;
}

}  // namespace duplex
