#include "duplex/objects/TriangleClip.h"
#include "duplex/accel/FloatRounding.h"

#include <glm/vec3.hpp>

#include <emmintrin.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex {

namespace {

using detail::floatAbove;
using detail::floatBelow;

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
//
// On SSE lanes (x, y, z, unused): the corners as one vector each, a crossing's three coordinates
// as two double pairs, its outward rounding by integer steps on the float bits of all lanes at
// once. The operations are the scalar ones lane by lane (same products, sums and comparisons, and
// min(p, lo) / max(p, hi) keep the earlier value on ties as std::min(lo, p) / std::max(hi, p)
// do), so the bounds are the same bit for bit, zeros' signs included.
void splitInsideTriangle(const __m128 (&v)[3], const Box& lower_box, const Box& upper_box, int axis, float pos,
                         Box& lower, Box& upper) {
  alignas(16) float coord[3][4];
  for (int i = 0; i < 3; ++i) _mm_store_ps(coord[i], v[i]);
  const double plane = pos;
  const double d[3] = {static_cast<double>(coord[0][axis]) - plane, static_cast<double>(coord[1][axis]) - plane,
                       static_cast<double>(coord[2][axis]) - plane};
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 ninf = _mm_set1_ps(-std::numeric_limits<float>::infinity());
  alignas(16) std::int32_t axis_bits[4] = {0, 0, 0, 0};
  axis_bits[axis] = -1;
  const __m128 on_axis = _mm_castsi128_ps(_mm_load_si128(reinterpret_cast<const __m128i*>(axis_bits)));
  const __m128 pos4 = _mm_set1_ps(pos);
  const __m128i one = _mm_set1_epi32(1);
  __m128 lo[2] = {inf, inf}, hi[2] = {ninf, ninf};
  bool any[2] = {false, false};
  int prev = 2;
  for (int i = 0; i < 3; ++i) {
    const double d_prev = d[prev], d_cur = d[i];
    if ((d_prev < 0.0 && d_cur > 0.0) || (d_prev > 0.0 && d_cur < 0.0)) {
      // The crossing p + t (q - p) in double on every lane, exactly on the plane along `axis`.
      const __m128d t = _mm_set1_pd(d_prev / (d_prev - d_cur));
      const __m128d p01 = _mm_cvtps_pd(v[prev]), p23 = _mm_cvtps_pd(_mm_movehl_ps(v[prev], v[prev]));
      const __m128d q01 = _mm_cvtps_pd(v[i]), q23 = _mm_cvtps_pd(_mm_movehl_ps(v[i], v[i]));
      const __m128d x01 = _mm_add_pd(p01, _mm_mul_pd(t, _mm_sub_pd(q01, p01)));
      const __m128d x23 = _mm_add_pd(p23, _mm_mul_pd(t, _mm_sub_pd(q23, p23)));
      // Nearest floats, and whether each lies above (below) the double it rounds.
      const __m128 f = _mm_movelh_ps(_mm_cvtpd_ps(x01), _mm_cvtpd_ps(x23));
      const __m128d f01 = _mm_cvtps_pd(f), f23 = _mm_cvtps_pd(_mm_movehl_ps(f, f));
      const __m128i above = _mm_castps_si128(_mm_shuffle_ps(
          _mm_castpd_ps(_mm_cmpgt_pd(f01, x01)), _mm_castpd_ps(_mm_cmpgt_pd(f23, x23)), _MM_SHUFFLE(2, 0, 2, 0)));
      const __m128i below = _mm_castps_si128(_mm_shuffle_ps(
          _mm_castpd_ps(_mm_cmplt_pd(f01, x01)), _mm_castpd_ps(_mm_cmplt_pd(f23, x23)), _MM_SHUFFLE(2, 0, 2, 0)));
      // floatBelow / floatAbove on the bits: one step away from zero for a negative float going
      // down or a positive one going up, towards zero otherwise.
      const __m128i u = _mm_castps_si128(f);
      const __m128i sign = _mm_srli_epi32(u, 31);
      const __m128i step_down = _mm_sub_epi32(_mm_add_epi32(sign, sign), one);  // 2 s - 1
      const __m128i step_up = _mm_sub_epi32(one, _mm_add_epi32(sign, sign));    // 1 - 2 s
      __m128 x_lo = _mm_castsi128_ps(_mm_add_epi32(u, _mm_and_si128(step_down, above)));
      __m128 x_hi = _mm_castsi128_ps(_mm_add_epi32(u, _mm_and_si128(step_up, below)));
      x_lo = _mm_or_ps(_mm_and_ps(on_axis, pos4), _mm_andnot_ps(on_axis, x_lo));
      x_hi = _mm_or_ps(_mm_and_ps(on_axis, pos4), _mm_andnot_ps(on_axis, x_hi));
      for (int side = 0; side < 2; ++side) {
        any[side] = true;
        lo[side] = _mm_min_ps(x_lo, lo[side]);
        hi[side] = _mm_max_ps(x_hi, hi[side]);
      }
    }
    if (d_cur <= 0.0) {
      any[0] = true;
      lo[0] = _mm_min_ps(v[i], lo[0]);
      hi[0] = _mm_max_ps(v[i], hi[0]);
    }
    if (d_cur >= 0.0) {
      any[1] = true;
      lo[1] = _mm_min_ps(v[i], lo[1]);
      hi[1] = _mm_max_ps(v[i], hi[1]);
    }
    prev = i;
  }
  // Limited to each half box, as DBox::rounded does (max(box, lo) keeps lo on ties like
  // std::max(lo, box)).
  auto limited = [&](int side, const Box& box) {
    if (!any[side]) return Box();
    alignas(16) float l[4], h[4];
    _mm_store_ps(l, _mm_max_ps(_mm_setr_ps(box.lo.x, box.lo.y, box.lo.z, 0.0f), lo[side]));
    _mm_store_ps(h, _mm_min_ps(_mm_setr_ps(box.hi.x, box.hi.y, box.hi.z, 0.0f), hi[side]));
    return Box({l[0], l[1], l[2]}, {h[0], h[1], h[2]});
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

void splitTriangleInBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box, int axis, float pos,
                        Box& lower, Box& upper) {
  if (box.empty()) {
    lower = upper = Box();
    return;
  }
  Box lower_box = box, upper_box = box;
  lower_box.hi[axis] = std::min(lower_box.hi[axis], pos);
  upper_box.lo[axis] = std::max(upper_box.lo[axis], pos);
  // The triangle's bounds (as Box::extend forms them: min(b, a) keeps a on ties like glm::min(a, b))
  // and whether they lie inside the box, on SSE lanes.
  const __m128 v[3] = {_mm_setr_ps(a.x, a.y, a.z, 0.0f), _mm_setr_ps(b.x, b.y, b.z, 0.0f),
                       _mm_setr_ps(c.x, c.y, c.z, 0.0f)};
  const __m128 own_lo = _mm_min_ps(v[2], _mm_min_ps(v[1], v[0]));
  const __m128 own_hi = _mm_max_ps(v[2], _mm_max_ps(v[1], v[0]));
  const __m128 box_lo = _mm_setr_ps(box.lo.x, box.lo.y, box.lo.z, 0.0f);
  const __m128 box_hi = _mm_setr_ps(box.hi.x, box.hi.y, box.hi.z, 0.0f);
  if ((_mm_movemask_ps(_mm_and_ps(_mm_cmpge_ps(own_lo, box_lo), _mm_cmple_ps(own_hi, box_hi))) & 7) == 7) {
    splitInsideTriangle(v, lower_box, upper_box, axis, pos, lower, upper);
    return;
  }
  lower = upper = Box();
  const Box own = ownBounds(a, b, c);
  P buffers[2][kMaxCorners];
  P* poly = buffers[0];
  const int n = clipPolygon(a, b, c, box, own, buffers[0], buffers[1], poly);
  if (n == 0) return;
  if (n < 0) {
    // Too complex after rounding (not inside: that case returned above): clip each side.
    lower = clipTriangleToBox(a, b, c, lower_box);
    upper = clipTriangleToBox(a, b, c, upper_box);
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
