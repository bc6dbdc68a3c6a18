#pragma once
// Private to accel/src: the SAH cost of a split plane in the kd-tree build, one plane at a time or
// four on SSE lanes (the same operations in the same order, so the same results bit for bit).

#include "duplex/accel/Box.h"
#include "duplex/accel/KdBuildConfig.h"

#include <emmintrin.h>

#include <cstddef>
#include <cstdint>

namespace duplex::kd_detail {

// SAH cost terms of one node: the surface area of a child is 2 (ab + len (a + b)) where a, b are
// the node's extents on the other two axes and len its extent on the split axis.
struct NodeGeometry {
  float lo[3], hi[3];
  float ab[3], a_plus_b[3];
  float inv_half_area;
  explicit NodeGeometry(const Box& box) {
    lo[0] = box.lo.x, lo[1] = box.lo.y, lo[2] = box.lo.z;
    hi[0] = box.hi.x, hi[1] = box.hi.y, hi[2] = box.hi.z;
    const float e[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    for (int axis = 0; axis < 3; ++axis) {
      const float a = e[(axis + 1) % 3], b = e[(axis + 2) % 3];
      ab[axis] = a * b;
      a_plus_b[axis] = a + b;
    }
    const float half_area = e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
    inv_half_area = half_area > 0.0f ? 1.0f / half_area : 0.0f;
  }
};

// The cost terms of the build configuration. Defined in this header, so that the sweeps and the
// binned evaluation inline them (they run per candidate plane).
struct SahCost {
  const KdBuildConfig& cfg;

  float splitCost(const NodeGeometry& g, int axis, float pos, std::size_t n_lower, std::size_t n_upper) const {
    const float p_lower = (g.ab[axis] + (pos - g.lo[axis]) * g.a_plus_b[axis]) * g.inv_half_area;
    const float p_upper = (g.ab[axis] + (g.hi[axis] - pos) * g.a_plus_b[axis]) * g.inv_half_area;
    float cost = cfg.traversal_cost + cfg.intersection_cost * (p_lower * static_cast<float>(n_lower) +
                                                               p_upper * static_cast<float>(n_upper));
    if (n_lower == 0 || n_upper == 0) cost *= 1.0f - cfg.empty_bonus;
    return cost;
  }

  // splitCost of four planes `p` on `axis` with references `nl` below and `nu` above, on SSE lanes:
  // splitCost's operations in the same order, so the same results bit for bit.
  __m128 splitCost4(const NodeGeometry& g, int axis, __m128 p, __m128i nl, __m128i nu) const {
    const __m128 lo = _mm_set1_ps(g.lo[axis]), hi = _mm_set1_ps(g.hi[axis]);
    const __m128 ab = _mm_set1_ps(g.ab[axis]), a_plus_b = _mm_set1_ps(g.a_plus_b[axis]);
    const __m128 inv_half_area = _mm_set1_ps(g.inv_half_area);
    const __m128 ct = _mm_set1_ps(cfg.traversal_cost), ci = _mm_set1_ps(cfg.intersection_cost);
    const __m128 p_lower = _mm_mul_ps(_mm_add_ps(ab, _mm_mul_ps(_mm_sub_ps(p, lo), a_plus_b)), inv_half_area);
    const __m128 p_upper = _mm_mul_ps(_mm_add_ps(ab, _mm_mul_ps(_mm_sub_ps(hi, p), a_plus_b)), inv_half_area);
    const __m128 c = _mm_add_ps(ct, _mm_mul_ps(ci, _mm_add_ps(_mm_mul_ps(p_lower, _mm_cvtepi32_ps(nl)),
                                                              _mm_mul_ps(p_upper, _mm_cvtepi32_ps(nu)))));
    const __m128i zero = _mm_setzero_si128();
    const __m128 one_empty = _mm_castsi128_ps(_mm_or_si128(_mm_cmpeq_epi32(nl, zero), _mm_cmpeq_epi32(nu, zero)));
    const __m128 bonus = _mm_set1_ps(1.0f - cfg.empty_bonus);
    return _mm_or_ps(_mm_and_ps(one_empty, _mm_mul_ps(c, bonus)), _mm_andnot_ps(one_empty, c));
  }
};

}  // namespace duplex::kd_detail
