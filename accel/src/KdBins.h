#pragma once
// Private to accel/src: the bins of the kd-tree build's binned SAH (counts of reference starts and
// ends per bin and axis), filled by the partition of the parent or by one pass over a node.

#include "KdBuildRefs.h"

#include <tbb/parallel_for.h>

#include <emmintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace duplex::kd_detail {

constexpr int kMaxBins = 32;

inline int binsFor(std::size_t n) { return n < 64 ? 8 : (n < 1024 ? 16 : kMaxBins); }

// j / count for j = 0 .. count (count 8, 16 or 32) and a padding entry, as Bins::boundary computes
// it, so a boundary can be formed without a division per candidate.
inline const float* binFractions(int count) {
  struct Table {
    float f[3][kMaxBins + 2];
    Table() {
      for (int t = 0; t < 3; ++t)
        for (int j = 0; j < kMaxBins + 2; ++j) f[t][j] = static_cast<float>(j) / static_cast<float>(8 << t);
    }
  };
  static const Table table;
  return table.f[count == 8 ? 0 : count == 16 ? 1 : 2];
}

// Counts of reference starts and ends per bin on each axis, over a frame (a box containing every
// counted reference). Bin boundary j of an axis is frame_lo + (frame_hi - frame_lo) * j / count.
struct Bins {
  int count = 0;
  float frame_lo[3] = {}, frame_hi[3] = {};
  __m128 sse_lo, sse_scale, sse_max;
  std::uint32_t start[3][kMaxBins], end[3][kMaxBins];

  void init(const float lo[3], const float hi[3], int bins) {
    count = bins;
    float scale[3];
    for (int k = 0; k < 3; ++k) {
      frame_lo[k] = lo[k];
      frame_hi[k] = hi[k];
      scale[k] = hi[k] > lo[k] ? static_cast<float>(bins) / (hi[k] - lo[k]) : 0.0f;
    }
    sse_lo = _mm_setr_ps(lo[0], lo[1], lo[2], 0.0f);
    sse_scale = _mm_setr_ps(scale[0], scale[1], scale[2], 0.0f);  // the fourth lane bins to 0
    sse_max = _mm_set1_ps(static_cast<float>(bins - 1));
    std::fill_n(&start[0][0], 3 * kMaxBins, 0u);
    std::fill_n(&end[0][0], 3 * kMaxBins, 0u);
  }
  // Bin indices of the three axes at once. Clamping in float before the conversion keeps values
  // outside the frame (rounding at its faces) and the ignored fourth lane defined.
  void add(__m128 rlo, __m128 rhi) { addWith(rlo, rhi, sse_lo, sse_scale, sse_max); }
  // add() with the frame's constants passed in (a pass keeps them in registers).
  void addWith(__m128 rlo, __m128 rhi, __m128 frame_lo, __m128 scale, __m128 last_bin) {
    alignas(16) std::int32_t b0[4], b1[4];
    const __m128 f0 = _mm_mul_ps(_mm_sub_ps(rlo, frame_lo), scale);
    const __m128 f1 = _mm_mul_ps(_mm_sub_ps(rhi, frame_lo), scale);
    _mm_store_si128(reinterpret_cast<__m128i*>(b0),
                    _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f0, _mm_setzero_ps()), last_bin)));
    _mm_store_si128(reinterpret_cast<__m128i*>(b1),
                    _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f1, _mm_setzero_ps()), last_bin)));
    for (int k = 0; k < 3; ++k) {
      ++start[k][b0[k]];
      ++end[k][b1[k]];
    }
  }
  void merge(const Bins& o) {
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < count; ++j) {
        start[k][j] += o.start[k][j];
        end[k][j] += o.end[k][j];
      }
  }
  [[nodiscard]] float boundary(int axis, int j) const {
    return frame_lo[axis] + (frame_hi[axis] - frame_lo[axis]) * (static_cast<float>(j) / static_cast<float>(count));
  }
};

// Bins every reference into `bins` (initialised, counts zero): chunks bin into copies whose
// counts are added.
inline void binRefs(const RefVec& refs, Bins& bins, bool parallel) {
  const std::size_t n = refs.size(), chunks = passChunkCount(n, parallel);
  if (chunks == 1) {
    for (const PrimRef& r : refs) bins.add(r.loadLo(), r.loadHi());
    return;
  }
  std::vector<Bins> parts(chunks, bins);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    const std::size_t end = std::min(n, (c + 1) * kPassChunk);
    for (std::size_t i = c * kPassChunk; i < end; ++i) parts[c].add(refs[i].loadLo(), refs[i].loadHi());
  });
  for (const Bins& part : parts) bins.merge(part);
}

}  // namespace duplex::kd_detail
