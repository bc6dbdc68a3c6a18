#pragma once
// Private to accel/src: the world boxes of a kd-tree's references in leaf order, structure of
// arrays, for a leaf step that tests many boxes per leaf (the sensors' level: leaves of a dozen or
// more small sensors, most of which a ray misses). A leaf's boxes are one contiguous run, tested
// 16, 8 or 4 at a time (AVX-512, AVX2 or SSE2: the widest the CPU runs, chosen once at refresh()),
// and nothing else about a reference is read unless its box is met.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/SimdIsa.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#if defined(__GNUC__) && defined(__x86_64__)
#define DUPLEX_LEAF_BOXES_X86 1
#include <immintrin.h>
#endif

namespace duplex::toplevel_detail {

struct LeafBoxes {
  // lo[k][i], hi[k][i]: axis k of the box of reference i (tree.prim_indices order), padded by
  // kPad entries so that a 16-wide load at the last reference stays inside.
  static constexpr std::size_t kPad = 15;
  static constexpr std::uint32_t kMaxLanes = 16;
  std::vector<float> lo[3], hi[3];
  std::size_t count = 0;
  // Boxes per vector test: 16 (AVX-512F), 8 (AVX2), 4 (SSE2) or 1 (scalar); set by refresh().
  std::uint32_t lanes = 1;

  // Copies boxes[prim_indices[i]] for every reference (O(references)).
  void refresh(const std::vector<Box>& boxes, const std::vector<std::uint32_t>& prim_indices) {
    assign(prim_indices.size(), [&](std::size_t i) -> const Box& { return boxes[prim_indices[i]]; });
  }
  // Copies boxes[i] for every reference i (boxes already in reference order).
  void refresh(const std::vector<Box>& boxes) {
    assign(boxes.size(), [&](std::size_t i) -> const Box& { return boxes[i]; });
  }

  // Calls hit(i) for every reference i in [begin, begin + n) whose box the ray meets within
  // [ray.tnear, t_max], in order: every box that clipIntervalToBox accepts (the same slabs and
  // widening; the vector tests widen the largest entry and the smallest exit once instead of every
  // axis's, which gives the same bounds because the widening is monotonic; NaN counts as "meets").
  // A superset is harmless: a met box only selects the sensors the exact test is asked about.
  template <class F>
  void forEachMet(const KdRay& ray, std::uint32_t begin, std::uint32_t n, float t_max, F&& hit) const {
#if defined(DUPLEX_LEAF_BOXES_X86)
    if (lanes > 1 && !(ray.zero[0] | ray.zero[1] | ray.zero[2])) {
      // Up to 64 references per call: one call covers a leaf, and the ray's broadcasts stay in
      // registers across its vectors.
      std::uint32_t met[64 + kMaxLanes];
      for (std::uint32_t j = 0; j < n; j += 64) {
        const std::uint32_t run[2] = {begin + j, begin + std::min<std::uint32_t>(n, j + 64)};
        const std::uint32_t count_met = metInRuns(ray, t_max, run, 1, met);
        for (std::uint32_t k = 0; k < count_met; ++k) hit(met[k]);
      }
      return;
    }
#endif
    // Rays with a zero direction component (and targets without the vector tests): the scalar test.
    for (std::uint32_t i = begin; i < begin + n; ++i) {
      const Box b(glm::vec3(lo[0][i], lo[1][i], lo[2][i]), glm::vec3(hi[0][i], hi[1][i], hi[2][i]));
      float t0 = ray.tnear, t1 = t_max;
      if (clipIntervalToBox(ray, b, t0, t1)) hit(i);
    }
  }

  // The vector test over several runs of references at once (the grid walk: the runs of the cells
  // a ray passes, one call per ray): for each run [runs[2r], runs[2r + 1]) appends the references
  // whose box the ray meets within [ray.tnear, t_max] to `out` (room for every reference of the
  // runs, plus kMaxLanes: the vector paths write whole vectors), in order; returns how many.
  // `records`, when given, holds a 64-byte record per reference that the caller reads for every
  // reference met: the 16- and 8-wide tests ask for the record of the first box each vector meets
  // as soon as it is known, so that its load overlaps the remaining tests (without a branch: when
  // a vector meets nothing, the prefetched line is that of the vector's next reference, which
  // costs nothing). That index comes from the mask, not from `out`: reading back the index just
  // stored waits for the store (on AMD Zen 5 a stall on every vector; docs/design/sensors.md, "Speed").
  std::uint32_t metInRuns(const KdRay& ray, float t_max, const std::uint32_t* runs, std::uint32_t run_count,
                          std::uint32_t* out, const void* records = nullptr) const {
#if defined(DUPLEX_LEAF_BOXES_X86)
    // Prefetch addresses are computed as integers (a stale index may lie past the records; a
    // prefetch never faults). Without records, the prefetches go to `out` itself.
    const std::uintptr_t base = reinterpret_cast<std::uintptr_t>(records ? records : out);
    const unsigned shift = records ? 6u : 0u;
    if (lanes == 16) return runs16(ray, t_max, runs, run_count, out, base, shift);
    if (lanes == 8) return runs8(ray, t_max, runs, run_count, out, base, shift);
    if (lanes == 4) return runs4(ray, t_max, runs, run_count, out);
#endif
    std::uint32_t n = 0;
    for (std::uint32_t r = 0; r < run_count; ++r)
      forEachMet(ray, runs[2 * r], runs[2 * r + 1] - runs[2 * r], t_max, [&](std::uint32_t i) { out[n++] = i; });
    return n;
  }

 private:
  template <class BoxOf>
  void assign(std::size_t n, BoxOf&& box_of) {
    count = 0;
    lanes = widestTest();
    for (int k = 0; k < 3; ++k) {
      lo[k].assign(n + kPad, 0.0f);
      hi[k].assign(n + kPad, 0.0f);
    }
    for (std::size_t i = 0; i < n; ++i) {
      const Box& b = box_of(i);
      for (int k = 0; k < 3; ++k) {
        lo[k][i] = b.lo[k];
        hi[k][i] = b.hi[k];
      }
    }
    count = n;
  }

  static constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();

  // The widest test the CPU runs, capped by DUPLEX_ISA (SimdIsa.h): the paths differ only in vector
  // width, so their results are equal.
  static std::uint32_t widestTest() {
#if defined(DUPLEX_LEAF_BOXES_X86)
    switch (widestSimdIsa()) {
      case SimdIsa::Avx512: return 16u;
      case SimdIsa::Avx2: return 8u;
      case SimdIsa::Sse2: return 4u;
    }
    return 4u;
#else
    return 1u;
#endif
  }

#if defined(DUPLEX_LEAF_BOXES_X86)
  // The lanes of a vector at reference i that lie in a run ending at `end`: `left` = end - i
  // lanes (all of them when left >= 16). Without a branch: whether a vector is a run's last is a
  // coin flip for runs of a dozen references.
  static std::uint32_t inRun(std::uint32_t left) {
    return static_cast<std::uint32_t>((std::uint64_t{1} << std::min<std::uint32_t>(left, 32u)) - 1u);
  }
  // The lane of the lowest set bit of `met`, or `lanes` when none is set (no branch: the record
  // prefetched for an empty mask is that of the next vector's first reference).
  static std::uint32_t firstLane(std::uint32_t met, std::uint32_t lanes) {
    return static_cast<std::uint32_t>(std::countr_zero(met | (1u << lanes)));
  }
  // The positions of the set bits of every 8-bit mask, packed: byte k of kPacked[m] is the lane of
  // the k-th set bit of m. Met boxes are appended by storing a whole vector of i + those lanes and
  // advancing by the bit count, with no branch per met box (a loop over the set bits mispredicts
  // its exit about once per vector).
  static constexpr std::array<std::uint64_t, 256> kPacked = [] {
    std::array<std::uint64_t, 256> t{};
    for (std::uint32_t m = 0; m < 256; ++m) {
      int k = 0;
      for (std::uint64_t lane = 0; lane < 8; ++lane)
        if (m & (1u << lane)) t[m] |= lane << (8 * k++);
    }
    return t;
  }();

  // The slab tests of the references of each run, `lanes` at a time; the indices of the boxes met
  // go to `out`. Per axis the entry is min(t0, t1) and the exit max(t0, t1); the largest entry
  // and the smallest exit are widened by their magnitude times kWiden (as clipIntervalToBox
  // widens each axis's) and clipped to [tnear, t_max]. The running bound is the second operand of
  // max / min: a NaN slab bound (0 * inf) leaves it. Loads past a run's end read the next run or
  // the padding; their bits are cleared. The three differ only in vector width. The 16-wide test
  // packs the met lanes in a register and stores the whole vector (`out` has room): the compress
  // store to memory is slower on AMD Zen 4 / 5.
  __attribute__((target("avx512f,popcnt"))) std::uint32_t runs16(const KdRay& ray, float t_max,
                                                                 const std::uint32_t* runs, std::uint32_t run_count,
                                                                 std::uint32_t* out, std::uintptr_t records,
                                                                 unsigned shift) const {
    constexpr __mmask16 kAll = 0xFFFF;
    const __m512 o[3] = {_mm512_set1_ps(ray.origin[0]), _mm512_set1_ps(ray.origin[1]), _mm512_set1_ps(ray.origin[2])};
    const __m512 inv[3] = {_mm512_set1_ps(ray.inv_dir[0]), _mm512_set1_ps(ray.inv_dir[1]),
                           _mm512_set1_ps(ray.inv_dir[2])};
    const __m512 widen = _mm512_set1_ps(kWiden), t_near = _mm512_set1_ps(ray.tnear), t_far = _mm512_set1_ps(t_max);
    const __m512 minus_inf = _mm512_set1_ps(-std::numeric_limits<float>::infinity());
    const __m512 plus_inf = _mm512_set1_ps(std::numeric_limits<float>::infinity());
    const __m512i iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const float* lo_k[3] = {lo[0].data(), lo[1].data(), lo[2].data()};
    const float* hi_k[3] = {hi[0].data(), hi[1].data(), hi[2].data()};
    std::uint32_t n = 0;
    for (std::uint32_t r = 0; r < run_count; ++r) {
      const std::uint32_t end = runs[2 * r + 1];
      for (std::uint32_t i = runs[2 * r]; i < end; i += 16) {
        __m512 enter = minus_inf, leave = plus_inf;
        for (int k = 0; k < 3; ++k) {
          const __m512 t0 = _mm512_mul_ps(_mm512_sub_ps(_mm512_loadu_ps(lo_k[k] + i), o[k]), inv[k]);
          const __m512 t1 = _mm512_mul_ps(_mm512_sub_ps(_mm512_loadu_ps(hi_k[k] + i), o[k]), inv[k]);
          enter = _mm512_maskz_max_ps(kAll, _mm512_maskz_min_ps(kAll, t0, t1), enter);
          leave = _mm512_maskz_min_ps(kAll, _mm512_maskz_max_ps(kAll, t0, t1), leave);
        }
        enter = _mm512_maskz_max_ps(kAll, _mm512_sub_ps(enter, _mm512_mul_ps(_mm512_abs_ps(enter), widen)), t_near);
        leave = _mm512_maskz_min_ps(kAll, _mm512_add_ps(leave, _mm512_mul_ps(_mm512_abs_ps(leave), widen)), t_far);
        const __mmask16 met = _mm512_cmp_ps_mask(enter, leave, _CMP_LE_OQ) & inRun(end - i);
        const __m512i index = _mm512_add_epi32(_mm512_set1_epi32(static_cast<int>(i)), iota);
        _mm512_storeu_si512(out + n, _mm512_maskz_compress_epi32(met, index));
        const std::uint32_t first = i + firstLane(met, 16);
        __builtin_prefetch(reinterpret_cast<const void*>(records + (std::uintptr_t{first} << shift)));
        n += static_cast<std::uint32_t>(std::popcount(static_cast<unsigned>(met)));
      }
    }
    return n;
  }

  __attribute__((target("avx2,popcnt"))) std::uint32_t runs8(const KdRay& ray, float t_max, const std::uint32_t* runs,
                                                             std::uint32_t run_count, std::uint32_t* out,
                                                             std::uintptr_t records, unsigned shift) const {
    const __m256 o[3] = {_mm256_set1_ps(ray.origin[0]), _mm256_set1_ps(ray.origin[1]), _mm256_set1_ps(ray.origin[2])};
    const __m256 inv[3] = {_mm256_set1_ps(ray.inv_dir[0]), _mm256_set1_ps(ray.inv_dir[1]),
                           _mm256_set1_ps(ray.inv_dir[2])};
    const __m256 widen = _mm256_set1_ps(kWiden), t_near = _mm256_set1_ps(ray.tnear), t_far = _mm256_set1_ps(t_max);
    const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
    const __m256 minus_inf = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
    const __m256 plus_inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
    const float* lo_k[3] = {lo[0].data(), lo[1].data(), lo[2].data()};
    const float* hi_k[3] = {hi[0].data(), hi[1].data(), hi[2].data()};
    std::uint32_t n = 0;
    for (std::uint32_t r = 0; r < run_count; ++r) {
      const std::uint32_t end = runs[2 * r + 1];
      for (std::uint32_t i = runs[2 * r]; i < end; i += 8) {
        __m256 enter = minus_inf, leave = plus_inf;
        for (int k = 0; k < 3; ++k) {
          const __m256 t0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(lo_k[k] + i), o[k]), inv[k]);
          const __m256 t1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(hi_k[k] + i), o[k]), inv[k]);
          enter = _mm256_max_ps(_mm256_min_ps(t0, t1), enter);
          leave = _mm256_min_ps(_mm256_max_ps(t0, t1), leave);
        }
        enter = _mm256_max_ps(_mm256_sub_ps(enter, _mm256_mul_ps(_mm256_and_ps(enter, abs_mask), widen)), t_near);
        leave = _mm256_min_ps(_mm256_add_ps(leave, _mm256_mul_ps(_mm256_and_ps(leave, abs_mask), widen)), t_far);
        const std::uint32_t met =
            static_cast<std::uint32_t>(_mm256_movemask_ps(_mm256_cmp_ps(enter, leave, _CMP_LE_OQ))) & inRun(end - i);
        const __m256i lanes_met =
            _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&kPacked[met])));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(out + n),
                            _mm256_add_epi32(_mm256_set1_epi32(static_cast<int>(i)), lanes_met));
        const std::uint32_t first = i + firstLane(met, 8);
        __builtin_prefetch(reinterpret_cast<const void*>(records + (std::uintptr_t{first} << shift)));
        n += static_cast<std::uint32_t>(std::popcount(met));
      }
    }
    return n;
  }

  std::uint32_t runs4(const KdRay& ray, float t_max, const std::uint32_t* runs, std::uint32_t run_count,
                      std::uint32_t* out) const {
    const __m128 o[3] = {_mm_set1_ps(ray.origin[0]), _mm_set1_ps(ray.origin[1]), _mm_set1_ps(ray.origin[2])};
    const __m128 inv[3] = {_mm_set1_ps(ray.inv_dir[0]), _mm_set1_ps(ray.inv_dir[1]), _mm_set1_ps(ray.inv_dir[2])};
    const __m128 widen = _mm_set1_ps(kWiden), t_near = _mm_set1_ps(ray.tnear), t_far = _mm_set1_ps(t_max);
    const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
    const __m128 minus_inf = _mm_set1_ps(-std::numeric_limits<float>::infinity());
    const __m128 plus_inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
    const float* lo_k[3] = {lo[0].data(), lo[1].data(), lo[2].data()};
    const float* hi_k[3] = {hi[0].data(), hi[1].data(), hi[2].data()};
    std::uint32_t n = 0;
    for (std::uint32_t r = 0; r < run_count; ++r) {
      const std::uint32_t end = runs[2 * r + 1];
      for (std::uint32_t i = runs[2 * r]; i < end; i += 4) {
        __m128 enter = minus_inf, leave = plus_inf;
        for (int k = 0; k < 3; ++k) {
          const __m128 t0 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(lo_k[k] + i), o[k]), inv[k]);
          const __m128 t1 = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(hi_k[k] + i), o[k]), inv[k]);
          enter = _mm_max_ps(_mm_min_ps(t0, t1), enter);
          leave = _mm_min_ps(_mm_max_ps(t0, t1), leave);
        }
        enter = _mm_max_ps(_mm_sub_ps(enter, _mm_mul_ps(_mm_and_ps(enter, abs_mask), widen)), t_near);
        leave = _mm_min_ps(_mm_add_ps(leave, _mm_mul_ps(_mm_and_ps(leave, abs_mask), widen)), t_far);
        // (SSE2 has no byte shuffle to pack the lanes with: a loop over the set bits.)
        const std::uint32_t met =
            static_cast<std::uint32_t>(_mm_movemask_ps(_mm_cmple_ps(enter, leave))) & inRun(end - i);
        for (std::uint32_t m = met; m != 0; m &= m - 1u) out[n++] = i + static_cast<std::uint32_t>(std::countr_zero(m));
      }
    }
    return n;
  }
#endif
};

}  // namespace duplex::toplevel_detail
