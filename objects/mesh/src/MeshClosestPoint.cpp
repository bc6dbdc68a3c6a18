// The closest-point kernels (MeshClosestPoint.h), compiled three times from
// MeshClosestPointSearch.inl: SSE2 (two doubles per register), AVX2 and AVX-512 (four). Each copy
// lives in its own namespace inside a target region (SimdTarget.h), as the BVH ray kernels
// (MeshBvh.cpp): every header is included before the first region.

#include "MeshClosestPoint.h"

#include "duplex/accel/SimdTarget.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/PointQuery.h"
#include "duplex/accel/SimdTarget.h"
#include "MeshLeafTest.h"

#include <glm/geometric.hpp>
#include <immintrin.h>

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>

namespace duplex::detail {

namespace sse2 {
namespace {

struct D4 {
  struct V {
    __m128d lo, hi;  // lanes 0-1, 2-3
  };
  static V zero() { return {_mm_setzero_pd(), _mm_setzero_pd()}; }
  static V set1(double x) { return {_mm_set1_pd(x), _mm_set1_pd(x)}; }
  static V fromFloats(__m128 f) { return {_mm_cvtps_pd(f), _mm_cvtps_pd(_mm_movehl_ps(f, f))}; }
  static V add(V a, V b) { return {_mm_add_pd(a.lo, b.lo), _mm_add_pd(a.hi, b.hi)}; }
  static V sub(V a, V b) { return {_mm_sub_pd(a.lo, b.lo), _mm_sub_pd(a.hi, b.hi)}; }
  static V mul(V a, V b) { return {_mm_mul_pd(a.lo, b.lo), _mm_mul_pd(a.hi, b.hi)}; }
  // a > b ? a : b per lane (maxpd).
  static V max(V a, V b) { return {_mm_max_pd(a.lo, b.lo), _mm_max_pd(a.hi, b.hi)}; }
  static unsigned lt(V a, V b) {
    return static_cast<unsigned>(_mm_movemask_pd(_mm_cmplt_pd(a.lo, b.lo)) | _mm_movemask_pd(_mm_cmplt_pd(a.hi, b.hi))
                                                                                 << 2);
  }
  static void store(double* p, V a) {
    _mm_store_pd(p, a.lo);
    _mm_store_pd(p + 2, a.hi);
  }
};

#include "MeshClosestPointSearch.inl"

}  // namespace
}  // namespace sse2

DUPLEX_TARGET_AVX2_BEGIN
namespace avx2 {
namespace {

struct D4 {
  using V = __m256d;
  static V zero() { return _mm256_setzero_pd(); }
  static V set1(double x) { return _mm256_set1_pd(x); }
  static V fromFloats(__m128 f) { return _mm256_cvtps_pd(f); }
  static V add(V a, V b) { return _mm256_add_pd(a, b); }
  static V sub(V a, V b) { return _mm256_sub_pd(a, b); }
  static V mul(V a, V b) { return _mm256_mul_pd(a, b); }
  static V max(V a, V b) { return _mm256_max_pd(a, b); }
  static unsigned lt(V a, V b) { return static_cast<unsigned>(_mm256_movemask_pd(_mm256_cmp_pd(a, b, _CMP_LT_OQ))); }
  static void store(double* p, V a) { _mm256_store_pd(p, a); }
};

#include "MeshClosestPointSearch.inl"

}  // namespace
}  // namespace avx2
DUPLEX_TARGET_END

DUPLEX_TARGET_AVX512_BEGIN
namespace avx512 {
namespace {

// AVX2's operations, inlined into code compiled for AVX-512 (32 registers, mask compares).
using D4 = avx2::D4;

#include "MeshClosestPointSearch.inl"

}  // namespace
}  // namespace avx512
DUPLEX_TARGET_END

MeshClosestPointKernel meshClosestPointKernel(SimdIsa isa) {
  switch (isa) {
    case SimdIsa::Avx512: return avx512::closestPointEntry;
    case SimdIsa::Avx2: return avx2::closestPointEntry;
    case SimdIsa::Sse2: return sse2::closestPointEntry;
  }
  return sse2::closestPointEntry;
}

MeshClosestPointKernel meshClosestPointKernel() {
  static const MeshClosestPointKernel chosen = meshClosestPointKernel(widestSimdIsa());
  return chosen;
}

}  // namespace duplex::detail
