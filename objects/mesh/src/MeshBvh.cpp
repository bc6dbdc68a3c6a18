// The mesh BVH kernels (MeshBvh.h), compiled three times from MeshBvhTraversal.inl: SSE2 (two
// 4-wide halves per node), AVX2 (one 8-wide test) and AVX-512 (8 wide with mask registers). Each
// copy lives in its own namespace inside a `#pragma GCC target` region, so that only the code of
// that region may use the wider instructions: every header is included before the first region
// (standard library and helper templates are compiled for the baseline, not per region, and the
// linker cannot merge a wide copy into the baseline path).
//
// The box test is the kd-tree's slab test (KdTraversal.h) on 8 boxes at once: per axis the entry
// and exit (plane - origin) * (1 / direction), without fused multiply-add so that every path
// computes the same values; the largest entry and the smallest exit are widened once by 6 ulp-style
// steps (the widening is monotonic, so this equals widening every axis), which keeps hits on box
// faces from being culled by rounding. A zero direction has 1/d = +-inf, and a plane through the
// origin then gives NaN: max / min return their second operand when either is NaN, and the
// accumulated value is always the second, so NaN counts as "inside the slab" (closed boxes).
// Empty child slots have boxes [+inf, -inf], whose entry is +inf: no ray enters them.

#include "MeshBvh.h"

#include "MeshLeafTest.h"
#include "MeshRay.h"

#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <type_traits>

namespace duplex::detail {

namespace {
constexpr float kBoxWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
// Offsets (in floats) of the lo and hi rows of axis a within a BvhNode8.
constexpr int loRow(int a) { return 8 * a; }
constexpr int hiRow(int a) { return 24 + 8 * a; }
static_assert(offsetof(BvhNode8, hi) == sizeof(float) * 24);
}  // namespace

// The ray's octant (bit a set: direction negative on axis a) selects, per axis, which row of a node
// holds the entry planes: a template parameter, so that the rows are constant offsets and the
// traversal keeps no per-ray offsets in registers.
template <int kOct, int kAxis>
constexpr int nearRow() {
  return (kOct >> kAxis & 1) ? hiRow(kAxis) : loRow(kAxis);
}
template <int kOct, int kAxis>
constexpr int farRow() {
  return (kOct >> kAxis & 1) ? loRow(kAxis) : hiRow(kAxis);
}

namespace sse2 {
namespace {

struct BoxRay {
  __m128 o[3], inv[3], tnear;
  explicit BoxRay(const KdRay& r) : tnear(_mm_set1_ps(r.tnear)) {
    for (int a = 0; a < 3; ++a) {
      o[a] = _mm_set1_ps(r.origin[a]);
      inv[a] = _mm_set1_ps(r.inv_dir[a]);
    }
  }
};

struct Node {
  template <int kOct, int kAxis>
  static void slab(const float* base, const BoxRay& r, __m128& tn, __m128& tf) {
    const __m128 n = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(base + nearRow<kOct, kAxis>()), r.o[kAxis]), r.inv[kAxis]);
    const __m128 f = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(base + farRow<kOct, kAxis>()), r.o[kAxis]), r.inv[kAxis]);
    tn = _mm_max_ps(n, tn);
    tf = _mm_min_ps(f, tf);
  }
  template <int kOct>
  static unsigned test(const BvhNode8& node, const BoxRay& r, float t_best, float* dist) {
    const __m128 tb = _mm_set1_ps(t_best);
    const __m128 sign = _mm_set1_ps(-0.0f), widen = _mm_set1_ps(kBoxWiden);
    unsigned mask = 0;
    for (int h = 0; h < 8; h += 4) {
      const float* base = &node.lo[0][0] + h;
      __m128 tn = r.tnear, tf = tb;
      slab<kOct, 2>(base, r, tn, tf);
      slab<kOct, 1>(base, r, tn, tf);
      slab<kOct, 0>(base, r, tn, tf);
      tn = _mm_sub_ps(tn, _mm_mul_ps(_mm_andnot_ps(sign, tn), widen));
      tf = _mm_add_ps(tf, _mm_mul_ps(_mm_andnot_ps(sign, tf), widen));
      mask |= static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(tn, tf))) << h;
      _mm_store_ps(dist + h, tn);
    }
    return mask;
  }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Sse2, intersectEntry, occludedEntry, forEachLeafEntry};
}  // namespace sse2

#pragma GCC push_options
#pragma GCC target("avx2")
namespace avx2 {
namespace {

struct BoxRay {
  __m256 o[3], inv[3], tnear;
  explicit BoxRay(const KdRay& r) : tnear(_mm256_set1_ps(r.tnear)) {
    for (int a = 0; a < 3; ++a) {
      o[a] = _mm256_set1_ps(r.origin[a]);
      inv[a] = _mm256_set1_ps(r.inv_dir[a]);
    }
  }
};

template <int kOct, int kAxis>
inline void slab(const float* base, const BoxRay& r, __m256& tn, __m256& tf) {
  const __m256 n =
      _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(base + nearRow<kOct, kAxis>()), r.o[kAxis]), r.inv[kAxis]);
  const __m256 f = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(base + farRow<kOct, kAxis>()), r.o[kAxis]), r.inv[kAxis]);
  tn = _mm256_max_ps(n, tn);
  tf = _mm256_min_ps(f, tf);
}

// The widened entry distances of the 8 children; `tf` gets the widened exits.
template <int kOct>
inline __m256 entryAndExit(const BvhNode8& node, const BoxRay& r, float t_best, __m256& tf) {
  const float* base = &node.lo[0][0];
  const __m256 sign = _mm256_set1_ps(-0.0f), widen = _mm256_set1_ps(kBoxWiden);
  __m256 tn = r.tnear;
  tf = _mm256_set1_ps(t_best);
  slab<kOct, 2>(base, r, tn, tf);
  slab<kOct, 1>(base, r, tn, tf);
  slab<kOct, 0>(base, r, tn, tf);
  tf = _mm256_add_ps(tf, _mm256_mul_ps(_mm256_andnot_ps(sign, tf), widen));
  return _mm256_sub_ps(tn, _mm256_mul_ps(_mm256_andnot_ps(sign, tn), widen));
}

struct Node {
  template <int kOct>
  static unsigned test(const BvhNode8& node, const BoxRay& r, float t_best, float* dist) {
    __m256 tf;
    const __m256 tn = entryAndExit<kOct>(node, r, t_best, tf);
    _mm256_store_ps(dist, tn);
    return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ)));
  }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Avx2, intersectEntry, occludedEntry, forEachLeafEntry};
}  // namespace avx2
#pragma GCC pop_options

#pragma GCC push_options
#pragma GCC target("avx2,avx512f,avx512vl,avx512dq,avx512bw")
namespace avx512 {
namespace {

using avx2::BoxRay;

struct Node {
  template <int kOct>
  static unsigned test(const BvhNode8& node, const BoxRay& r, float t_best, float* dist) {
    __m256 tf;
    const __m256 tn = avx2::entryAndExit<kOct>(node, r, t_best, tf);
    _mm256_store_ps(dist, tn);
    return static_cast<unsigned>(_mm256_cmp_ps_mask(tn, tf, _CMP_LE_OQ));
  }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Avx512, intersectEntry, occludedEntry, forEachLeafEntry};
}  // namespace avx512
#pragma GCC pop_options

const MeshBvhKernels& meshBvhKernels(SimdIsa isa) {
  switch (isa) {
    case SimdIsa::Avx512: return avx512::kKernels;
    case SimdIsa::Avx2: return avx2::kKernels;
    case SimdIsa::Sse2: return sse2::kKernels;
  }
  return sse2::kKernels;
}

const MeshBvhKernels& meshBvhKernels() {
  static const MeshBvhKernels& chosen = meshBvhKernels(widestSimdIsa());
  return chosen;
}

}  // namespace duplex::detail
