#pragma once
// Private to accel/src: the world boxes of a kd-tree's references in leaf order, structure of
// arrays, for a leaf step that tests many boxes per leaf (the sensors' level: leaves of a few
// small sensors, most of which a ray misses). A leaf's boxes are one contiguous run, tested four
// at a time (SSE2 where available), and nothing else about a reference is read unless its box is
// met.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace duplex::toplevel_detail {

struct LeafBoxes {
  // lo[k][i], hi[k][i]: axis k of the box of reference i (tree.prim_indices order), padded by
  // kPad entries so that a 4-wide load at the last reference stays inside.
  static constexpr std::size_t kPad = 3;
  std::vector<float> lo[3], hi[3];
  std::size_t count = 0;

  // Copies boxes[prim_indices[i]] for every reference (O(references)).
  void refresh(const std::vector<Box>& boxes, const std::vector<std::uint32_t>& prim_indices) {
    count = 0;
    for (int k = 0; k < 3; ++k) {
      lo[k].assign(prim_indices.size() + kPad, 0.0f);
      hi[k].assign(prim_indices.size() + kPad, 0.0f);
    }
    for (std::size_t i = 0; i < prim_indices.size(); ++i) {
      const Box& b = boxes[prim_indices[i]];
      for (int k = 0; k < 3; ++k) {
        lo[k][i] = b.lo[k];
        hi[k][i] = b.hi[k];
      }
    }
    count = prim_indices.size();
  }

  // Calls hit(i) for every reference i in [begin, begin + n) whose box the ray meets within
  // [ray.tnear, t_max], in order; the same answer as clipIntervalToBox (a superset of its "yes"
  // only where the two round differently: the widening is the same, NaN counts as "meets").
  template <class F>
  void forEachMet(const KdRay& ray, std::uint32_t begin, std::uint32_t n, float t_max, F&& hit) const {
#if defined(__SSE2__)
    if (!(ray.zero[0] | ray.zero[1] | ray.zero[2])) {
      constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
      const __m128 widen = _mm_set1_ps(kWiden);
      const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
      const __m128 t_near = _mm_set1_ps(ray.tnear), t_far = _mm_set1_ps(t_max);
      for (std::uint32_t j = 0; j < n; j += 4) {
        const std::uint32_t i = begin + j;
        __m128 t_in = t_near, t_out = t_far;
        for (int k = 0; k < 3; ++k) {
          const __m128 o = _mm_set1_ps(ray.origin[k]), inv = _mm_set1_ps(ray.inv_dir[k]);
          const __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(&lo[k][i]), o), inv);
          const __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(&hi[k][i]), o), inv);
          __m128 a = _mm_min_ps(t0, t1), b = _mm_max_ps(t0, t1);
          a = _mm_sub_ps(a, _mm_mul_ps(_mm_and_ps(a, abs_mask), widen));
          b = _mm_add_ps(b, _mm_mul_ps(_mm_and_ps(b, abs_mask), widen));
          // The ray's bound as the second operand: a NaN slab bound (0 * inf) leaves it.
          t_in = _mm_max_ps(a, t_in);
          t_out = _mm_min_ps(b, t_out);
        }
        int met = _mm_movemask_ps(_mm_cmple_ps(t_in, t_out));
        if (n - j < 4) met &= (1 << (n - j)) - 1;
        while (met != 0) {
          const int m = std::countr_zero(static_cast<unsigned>(met));
          hit(i + static_cast<std::uint32_t>(m));
          met &= met - 1;
        }
      }
      return;
    }
#endif
    // Rays with a zero direction component (and targets without SSE2): the scalar test.
    for (std::uint32_t i = begin; i < begin + n; ++i) {
      const Box b(glm::vec3(lo[0][i], lo[1][i], lo[2][i]), glm::vec3(hi[0][i], hi[1][i], hi[2][i]));
      float t0 = ray.tnear, t1 = t_max;
      if (clipIntervalToBox(ray, b, t0, t1)) hit(i);
    }
  }
};

}  // namespace duplex::toplevel_detail
