#include "duplex/accel/TriangleClip.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex {

namespace {

// Neighbouring floats of a finite f (std::nextafter is a library call, and this runs for every
// straddling triangle of a kd-tree build).
// Largest float <= d and smallest float >= d, for d within the float range. The step to the
// neighbouring float is integer arithmetic on the bits rather than a branch: whether a crossing
// rounds up or down is a coin flip. A step down from f happens only when d < f, so f is not +0
// (d < 0 rounds to -0 or below); -0 steps to -denorm_min. Likewise a step up never starts at -0.
float floatBelow(double d) {
  const auto f = static_cast<float>(d);
  const auto u = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t step = 2u * (u >> 31) - 1u;  // +1 for negative f (away from 0), -1 for positive
  const std::uint32_t need = 0u - static_cast<std::uint32_t>(static_cast<double>(f) > d);
  return std::bit_cast<float>(u + (step & need));
}
float floatAbove(double d) {
  const auto f = static_cast<float>(d);
  const auto u = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t step = 1u - 2u * (u >> 31);  // +1 for positive f (away from 0), -1 for negative
  const std::uint32_t need = 0u - static_cast<std::uint32_t>(static_cast<double>(f) < d);
  return std::bit_cast<float>(u + (step & need));
}

struct P {
  double v[3];
};

// A triangle clipped by six planes has at most 9 corners; rounding can add a few more where the
// polygon is nearly degenerate. Past this capacity the clip gives up and returns a safe box.
constexpr int kMaxCorners = 24;

// The triangle clipped to `box` as a polygon in `poly` (capacity kMaxCorners); returns its corner
// count (0: misses the box), or -1 when the triangle lies inside the box (poly untouched) or
// rounding made the polygon too complex (the caller then uses the triangle's bounds in the box).
int clipPolygon(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box, const Box& own,
                P* buffers_a, P* buffers_b, P*& poly) {
  const float box_lo[3] = {box.lo.x, box.lo.y, box.lo.z};
  const float box_hi[3] = {box.hi.x, box.hi.y, box.hi.z};
  bool inside = true;
  for (int k = 0; k < 3; ++k) {
    if (own.hi[k] < box_lo[k] || own.lo[k] > box_hi[k]) return 0;
    inside = inside && own.lo[k] >= box_lo[k] && own.hi[k] <= box_hi[k];
  }
  if (inside) return -1;
  // Sutherland-Hodgman in double against the planes the polygon crosses, between two buffers.
  poly = buffers_a;
  P* next = buffers_b;
  int n = 3;
  poly[0] = {{a.x, a.y, a.z}};
  poly[1] = {{b.x, b.y, b.z}};
  poly[2] = {{c.x, c.y, c.z}};
  for (int axis = 0; axis < 3; ++axis) {
    double vmin = poly[0].v[axis], vmax = vmin;
    for (int i = 1; i < n; ++i) {
      vmin = std::min(vmin, poly[i].v[axis]);
      vmax = std::max(vmax, poly[i].v[axis]);
    }
    // vmin/vmax stay valid for the second face: clipping one face only moves corners onto it.
    for (int side = 0; side < 2; ++side) {
      const double plane = side == 0 ? box_lo[axis] : box_hi[axis];
      const double sign = side == 0 ? 1.0 : -1.0;  // distance inside the face is >= 0
      if (side == 0 ? vmin >= plane : vmax <= plane) continue;
      if (side == 0 ? vmax < plane : vmin > plane) return 0;
      // Cannot happen for a convex polygon (each plane adds at most one corner); stay safe.
      if (2 * n > kMaxCorners) return -1;
      int m = 0;
      const P* prev = &poly[n - 1];
      double d_prev = sign * (prev->v[axis] - plane);
      for (int i = 0; i < n; ++i) {
        const P& cur = poly[i];
        const double d_cur = sign * (cur.v[axis] - plane);
        if ((d_prev >= 0.0) != (d_cur >= 0.0)) {
          // The edge crosses the plane: the crossing, exactly on the plane along `axis`.
          const double t = d_prev / (d_prev - d_cur);
          P x;
          for (int k = 0; k < 3; ++k) x.v[k] = prev->v[k] + t * (cur.v[k] - prev->v[k]);
          x.v[axis] = plane;
          next[m++] = x;
        }
        if (d_cur >= 0.0) next[m++] = cur;
        prev = &cur;
        d_prev = d_cur;
      }
      std::swap(poly, next);
      n = m;
      if (n == 0) return 0;
    }
  }
  return n;
}

// Bounds in double of points, extended by `p`.
struct DBox {
  double lo[3] = {INFINITY, INFINITY, INFINITY};
  double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  bool any = false;
  void extend(const P& p) {
    any = true;
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], p.v[k]);
      hi[k] = std::max(hi[k], p.v[k]);
    }
  }
  // Rounded outward to float, so that it contains the exact points, then limited to `box`.
  [[nodiscard]] Box rounded(const Box& box) const {
    if (!any) return {};
    Box out;
    for (int k = 0; k < 3; ++k) {
      out.lo[k] = std::max(floatBelow(lo[k]), box.lo[k]);
      out.hi[k] = std::min(floatAbove(hi[k]), box.hi[k]);
    }
    return out;
  }
};

// splitTriangleInBox for a triangle inside the box (two thirds of the calls in a mesh build): the
// corners are floats and enter the bounds as they are; only the edge crossings are computed in
// double and rounded outward, once for both sides. Rounding outward is monotonic, so this gives
// the bounds of the polygon loop below (same points, same order) rounded at the end.
void splitInsideTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& lower_box,
                         const Box& upper_box, int axis, float pos, Box& lower, Box& upper) {
  const float v[3][3] = {{a.x, a.y, a.z}, {b.x, b.y, b.z}, {c.x, c.y, c.z}};
  const double plane = pos;
  const double d[3] = {static_cast<double>(v[0][axis]) - plane, static_cast<double>(v[1][axis]) - plane,
                       static_cast<double>(v[2][axis]) - plane};
  constexpr float inf = std::numeric_limits<float>::infinity();
  float lo[2][3] = {{inf, inf, inf}, {inf, inf, inf}};
  float hi[2][3] = {{-inf, -inf, -inf}, {-inf, -inf, -inf}};
  bool any[2] = {false, false};
  auto extend = [&](int side, const float* p) {
    any[side] = true;
    for (int k = 0; k < 3; ++k) {
      lo[side][k] = std::min(lo[side][k], p[k]);
      hi[side][k] = std::max(hi[side][k], p[k]);
    }
  };
  int prev = 2;
  for (int i = 0; i < 3; ++i) {
    const double d_prev = d[prev], d_cur = d[i];
    if ((d_prev < 0.0 && d_cur > 0.0) || (d_prev > 0.0 && d_cur < 0.0)) {
      // The crossing, exactly on the plane along `axis`, rounded outward on the other axes.
      const double t = d_prev / (d_prev - d_cur);
      float x_lo[3], x_hi[3];
      for (int k = 0; k < 3; ++k) {
        if (k == axis) {
          x_lo[k] = x_hi[k] = pos;
          continue;
        }
        const double p = static_cast<double>(v[prev][k]);
        const double x = p + t * (static_cast<double>(v[i][k]) - p);
        x_lo[k] = floatBelow(x);
        x_hi[k] = floatAbove(x);
      }
      for (int side = 0; side < 2; ++side) {
        any[side] = true;
        for (int k = 0; k < 3; ++k) {
          lo[side][k] = std::min(lo[side][k], x_lo[k]);
          hi[side][k] = std::max(hi[side][k], x_hi[k]);
        }
      }
    }
    if (d_cur <= 0.0) extend(0, v[i]);
    if (d_cur >= 0.0) extend(1, v[i]);
    prev = i;
  }
  // Limited to each half box, as DBox::rounded does.
  auto limited = [&](int side, const Box& box) {
    if (!any[side]) return Box();
    Box out;
    for (int k = 0; k < 3; ++k) {
      out.lo[k] = std::max(lo[side][k], box.lo[k]);
      out.hi[k] = std::min(hi[side][k], box.hi[k]);
    }
    return out;
  };
  lower = limited(0, lower_box);
  upper = limited(1, upper_box);
}

Box ownBounds(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  Box own;
  own.extend(a);
  own.extend(b);
  own.extend(c);
  return own;
}

}  // namespace

Box clipTriangleToBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box) {
  if (box.empty()) return {};
  // A triangle inside the box needs no clipping, one whose bounds miss the box is empty.
  const Box own = ownBounds(a, b, c);
  P buffers[2][kMaxCorners];
  P* poly = nullptr;
  const int n = clipPolygon(a, b, c, box, own, buffers[0], buffers[1], poly);
  if (n < 0) return intersection(own, box);
  DBox bounds;
  for (int i = 0; i < n; ++i) bounds.extend(poly[i]);
  return bounds.rounded(box);
}

void splitTriangleInBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box, int axis,
                        float pos, Box& lower, Box& upper) {
  lower = upper = Box();
  if (box.empty()) return;
  Box lower_box = box, upper_box = box;
  lower_box.hi[axis] = std::min(lower_box.hi[axis], pos);
  upper_box.lo[axis] = std::max(upper_box.lo[axis], pos);
  const Box own = ownBounds(a, b, c);
  P buffers[2][kMaxCorners];
  P* poly = buffers[0];
  int n = clipPolygon(a, b, c, box, own, buffers[0], buffers[1], poly);
  if (n == 0) return;
  if (n < 0) {
    // Inside the box (or too complex): split the triangle itself (the fallback clips each side).
    if (intersection(own, box) != own) {
      lower = clipTriangleToBox(a, b, c, lower_box);
      upper = clipTriangleToBox(a, b, c, upper_box);
      return;
    }
    splitInsideTriangle(a, b, c, lower_box, upper_box, axis, pos, lower, upper);
    return;
  }
  // Each side gets the corners on its closed side of the plane and the crossings of the edges
  // (exactly on the plane along `axis`), as clipping to each half box would give.
  DBox lo_bounds, hi_bounds;
  const double plane = pos;
  const P* prev = &poly[n - 1];
  double d_prev = prev->v[axis] - plane;
  for (int i = 0; i < n; ++i) {
    const P& cur = poly[i];
    const double d_cur = cur.v[axis] - plane;
    if ((d_prev < 0.0 && d_cur > 0.0) || (d_prev > 0.0 && d_cur < 0.0)) {
      const double t = d_prev / (d_prev - d_cur);
      P x;
      for (int k = 0; k < 3; ++k) x.v[k] = prev->v[k] + t * (cur.v[k] - prev->v[k]);
      x.v[axis] = plane;
      lo_bounds.extend(x);
      hi_bounds.extend(x);
    }
    if (d_cur <= 0.0) lo_bounds.extend(cur);
    if (d_cur >= 0.0) hi_bounds.extend(cur);
    prev = &cur;
    d_prev = d_cur;
  }
  lower = lo_bounds.rounded(lower_box);
  upper = hi_bounds.rounded(upper_box);
}

}  // namespace duplex
