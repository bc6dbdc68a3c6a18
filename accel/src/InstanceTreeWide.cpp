// The closest-hit and any-hit walks of a blocking instance tree's wide form (WideTop.h), compiled
// twice from InstanceTreeWide.inl: SSE2 (two 4-wide halves per node) and AVX2 (one 8-wide test).
// As in the mesh kernels (objects/mesh/src/MeshBvh.cpp), each copy lives in its own namespace inside
// a target region, and every header is included before the first region, so that no inline
// function of a header is compiled for the wider set (the linker could pick that copy for the
// baseline path).
//
// The box test is the kd-tree's slab test on 8 boxes: per axis (plane - origin) * (1 / direction),
// without fused multiply-add so that both paths compute the same values; the largest entry and the
// smallest exit are widened once by 6 ulp-style steps (monotonic: the same as widening each axis).
// A zero direction has 1 / d = +-inf: a plane through the origin then gives NaN, which max / min
// skip because the accumulated value is always their second operand, so such a ray is inside the
// closed slab; a box whose entry is +inf (or exit -inf) widens to NaN, which every comparison
// rejects.

#include "InstanceTreeWide.h"

#include "duplex/accel/SimdTarget.h"
#include "duplex/accel/SimdIsa.h"

#include <immintrin.h>

#include <bit>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace duplex::toplevel_detail {

namespace {
constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();

// A packet's rays as rows of lanes (structure of arrays), for the box tests of all lanes at once.
struct PacketRays {
  alignas(32) float org[3][kMaxPacketRays];
  alignas(32) float inv[3][kMaxPacketRays];
  alignas(32) float tnear[kMaxPacketRays];
  alignas(32) float t[kMaxPacketRays];  // best distance so far (closest hit), tfar (any hit)
  int near_row[3];                      // as WideRay's: the packet's rays share their direction signs
  // Bounds of the lanes' rays per axis, for one test of a node's children that stands for all of
  // them (packetBounds): the origin that enters latest and exits earliest, the range of the
  // inverse direction, the smallest tnear. With the lanes' own slab operations, monotonic
  // rounding makes the bound entry no later and the bound exit no earlier than any lane's; a
  // 0 * inf (NaN) drops the axis, as a lane's own NaN does.
  float near_o[3], far_o[3], inv_lo[3], inv_hi[3];
  float t_lo;
};
}  // namespace

namespace sse2 {
namespace {

// The ray's values broadcast per axis, and the row of each axis's near planes.
struct WideRay {
  __m128 org[3], inv[3];
  int near_row[3];
  float tnear;
};

// The children of `node` the ray meets within [tnear, t_max] as a bit mask, with their widened
// entries in t_enter.
inline std::uint32_t wideHits(const WideRay& r, const WideNode& node, float t_max, float t_enter[8]) {
  const __m128 widen = _mm_set1_ps(kWiden), sign = _mm_set1_ps(-0.0f);
  const __m128 tnear = _mm_set1_ps(r.tnear), tmax = _mm_set1_ps(t_max);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  std::uint32_t mask = 0;
  for (int half = 0; half < 2; ++half) {
    const int o = 4 * half;
    __m128 tn = _mm_xor_ps(inf, sign), tf = inf;
    for (int a = 0; a < 3; ++a) {
      const __m128 n = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(node.bounds[r.near_row[a]] + o), r.org[a]), r.inv[a]);
      const __m128 f = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(node.bounds[r.near_row[a] ^ 1] + o), r.org[a]), r.inv[a]);
      tn = _mm_max_ps(n, tn);
      tf = _mm_min_ps(f, tf);
    }
    const __m128 enter = _mm_max_ps(tnear, _mm_sub_ps(tn, _mm_mul_ps(_mm_andnot_ps(sign, tn), widen)));
    const __m128 leave = _mm_min_ps(tmax, _mm_add_ps(tf, _mm_mul_ps(_mm_andnot_ps(sign, tf), widen)));
    _mm_store_ps(t_enter + o, enter);
    mask |= static_cast<std::uint32_t>(_mm_movemask_ps(_mm_cmple_ps(enter, leave))) << o;
  }
  return mask & node.valid;
}

// Sets `w` up for `ray` (false: not queryable): the origin and 1 / direction broadcast per axis,
// from registers (1 / d is +-inf with the sign of d for a zero component).
inline bool setupRay(const Ray& ray, WideRay& w) {
  const __m128 o = _mm_loadu_ps(&ray.origin.x), d = _mm_loadu_ps(&ray.dir.x);
  if (!kd_detail::queryableSse(o, d, ray)) return false;
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), d);
  w.org[0] = _mm_shuffle_ps(o, o, _MM_SHUFFLE(0, 0, 0, 0));
  w.org[1] = _mm_shuffle_ps(o, o, _MM_SHUFFLE(1, 1, 1, 1));
  w.org[2] = _mm_shuffle_ps(o, o, _MM_SHUFFLE(2, 2, 2, 2));
  w.inv[0] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(0, 0, 0, 0));
  w.inv[1] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(1, 1, 1, 1));
  w.inv[2] = _mm_shuffle_ps(inv, inv, _MM_SHUFFLE(2, 2, 2, 2));
  const int neg = _mm_movemask_ps(inv);
  for (int a = 0; a < 3; ++a) w.near_row[a] = 2 * a + ((neg >> a) & 1);
  w.tnear = ray.tnear;
  return true;
}

inline Ray objectRay(const Record& rec, const WorldRay& w) { return toObject(rec, w); }

// The children of `node` that some lane of `p` (bounded by p's bounds) may meet before t_hi, as a
// bit mask: the per-lane tests (packetChildHits) are needed only for these.
inline std::uint32_t packetBoundsHits(const PacketRays& p, const WideNode& node, float t_hi) {
  const __m128 widen = _mm_set1_ps(kWiden), sign = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  std::uint32_t mask = 0;
  for (int half = 0; half < 2; ++half) {
    const int o = 4 * half;
    __m128 tn = _mm_xor_ps(inf, sign), tf = inf;
    for (int a = 0; a < 3; ++a) {
      const __m128 lo = _mm_set1_ps(p.inv_lo[a]), hi = _mm_set1_ps(p.inv_hi[a]);
      const __m128 d = _mm_sub_ps(_mm_load_ps(node.bounds[p.near_row[a]] + o), _mm_set1_ps(p.near_o[a]));
      const __m128 e = _mm_sub_ps(_mm_load_ps(node.bounds[p.near_row[a] ^ 1] + o), _mm_set1_ps(p.far_o[a]));
      tn = _mm_max_ps(_mm_min_ps(_mm_mul_ps(d, lo), _mm_mul_ps(d, hi)), tn);
      tf = _mm_min_ps(_mm_max_ps(_mm_mul_ps(e, lo), _mm_mul_ps(e, hi)), tf);
    }
    const __m128 enter = _mm_max_ps(_mm_set1_ps(p.t_lo), _mm_sub_ps(tn, _mm_mul_ps(_mm_andnot_ps(sign, tn), widen)));
    const __m128 leave = _mm_min_ps(_mm_set1_ps(t_hi), _mm_add_ps(tf, _mm_mul_ps(_mm_andnot_ps(sign, tf), widen)));
    mask |= static_cast<std::uint32_t>(_mm_movemask_ps(_mm_cmple_ps(enter, leave))) << o;
  }
  return mask & node.valid;
}

// The lanes of `lanes` whose ray meets child `c` of `node` within [tnear, t], and the smallest of
// their widened entries in `key`: the same bounds as wideHits, four lanes at a time.
inline std::uint32_t packetChildHits(const PacketRays& p, const WideNode& node, int c, std::uint32_t lanes,
                                     float& key) {
  const __m128 widen = _mm_set1_ps(kWiden), sign = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  __m128 nplane[3], fplane[3];
  for (int a = 0; a < 3; ++a) {
    nplane[a] = _mm_set1_ps(node.bounds[p.near_row[a]][c]);
    fplane[a] = _mm_set1_ps(node.bounds[p.near_row[a] ^ 1][c]);
  }
  std::uint32_t mask = 0;
  __m128 kmin = inf;
  for (int k = 0; k < kMaxPacketRays; k += 4) {
    const std::uint32_t want = (lanes >> k) & 0xFu;
    if (want == 0) continue;
    __m128 tn = _mm_xor_ps(inf, sign), tf = inf;
    for (int a = 0; a < 3; ++a) {
      const __m128 o = _mm_load_ps(p.org[a] + k), i = _mm_load_ps(p.inv[a] + k);
      tn = _mm_max_ps(_mm_mul_ps(_mm_sub_ps(nplane[a], o), i), tn);
      tf = _mm_min_ps(_mm_mul_ps(_mm_sub_ps(fplane[a], o), i), tf);
    }
    const __m128 enter =
        _mm_max_ps(_mm_load_ps(p.tnear + k), _mm_sub_ps(tn, _mm_mul_ps(_mm_andnot_ps(sign, tn), widen)));
    const __m128 leave = _mm_min_ps(_mm_load_ps(p.t + k), _mm_add_ps(tf, _mm_mul_ps(_mm_andnot_ps(sign, tf), widen)));
    const __m128 in = _mm_cmple_ps(enter, leave);
    const std::uint32_t m = static_cast<std::uint32_t>(_mm_movemask_ps(in)) & want;
    if (m == 0) continue;
    mask |= m << k;
    kmin = _mm_min_ps(kmin, _mm_or_ps(_mm_and_ps(in, enter), _mm_andnot_ps(in, inf)));
  }
  kmin = _mm_min_ps(kmin, _mm_shuffle_ps(kmin, kmin, _MM_SHUFFLE(1, 0, 3, 2)));
  kmin = _mm_min_ps(kmin, _mm_shuffle_ps(kmin, kmin, _MM_SHUFFLE(2, 3, 0, 1)));
  key = _mm_cvtss_f32(kmin);
  return mask;
}

#include "InstanceTreeWide.inl"

}  // namespace
const WideKernels kKernels{SimdIsa::Sse2,      closestEntry,       occludedEntry,       closestBatchEntry,
                           occludedBatchEntry, closestPacketEntry, occludedPacketEntry, walkEntry};
}  // namespace sse2

DUPLEX_TARGET_AVX2_BEGIN
namespace avx2 {
namespace {

struct WideRay {
  __m256 org[3], inv[3];
  int near_row[3];
  float tnear;
};

inline std::uint32_t wideHits(const WideRay& r, const WideNode& node, float t_max, float t_enter[8]) {
  const __m256 widen = _mm256_set1_ps(kWiden), sign = _mm256_set1_ps(-0.0f);
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  __m256 tn = _mm256_xor_ps(inf, sign), tf = inf;
  for (int a = 0; a < 3; ++a) {
    const __m256 n = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(node.bounds[r.near_row[a]]), r.org[a]), r.inv[a]);
    const __m256 f = _mm256_mul_ps(_mm256_sub_ps(_mm256_load_ps(node.bounds[r.near_row[a] ^ 1]), r.org[a]), r.inv[a]);
    tn = _mm256_max_ps(n, tn);
    tf = _mm256_min_ps(f, tf);
  }
  const __m256 enter =
      _mm256_max_ps(_mm256_set1_ps(r.tnear), _mm256_sub_ps(tn, _mm256_mul_ps(_mm256_andnot_ps(sign, tn), widen)));
  const __m256 leave =
      _mm256_min_ps(_mm256_set1_ps(t_max), _mm256_add_ps(tf, _mm256_mul_ps(_mm256_andnot_ps(sign, tf), widen)));
  _mm256_store_ps(t_enter, enter);
  return static_cast<std::uint32_t>(_mm256_movemask_ps(_mm256_cmp_ps(enter, leave, _CMP_LE_OQ))) & node.valid;
}

inline bool setupRay(const Ray& ray, WideRay& w) {
  const __m128 o = _mm_loadu_ps(&ray.origin.x), d = _mm_loadu_ps(&ray.dir.x);
  if (!kd_detail::queryableSse(o, d, ray)) return false;
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), d);
  w.org[0] = _mm256_broadcastss_ps(o);
  w.org[1] = _mm256_broadcastss_ps(_mm_shuffle_ps(o, o, _MM_SHUFFLE(1, 1, 1, 1)));
  w.org[2] = _mm256_broadcastss_ps(_mm_movehl_ps(o, o));
  w.inv[0] = _mm256_broadcastss_ps(inv);
  w.inv[1] = _mm256_broadcastss_ps(_mm_shuffle_ps(inv, inv, _MM_SHUFFLE(1, 1, 1, 1)));
  w.inv[2] = _mm256_broadcastss_ps(_mm_movehl_ps(inv, inv));
  const int neg = _mm_movemask_ps(inv);
  for (int a = 0; a < 3; ++a) w.near_row[a] = 2 * a + ((neg >> a) & 1);
  w.tnear = ray.tnear;
  return true;
}

inline std::uint32_t packetChildHits(const PacketRays& p, const WideNode& node, int c, std::uint32_t lanes,
                                     float& key) {
  const __m256 widen = _mm256_set1_ps(kWiden), sign = _mm256_set1_ps(-0.0f);
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  __m256 nplane[3], fplane[3];
  for (int a = 0; a < 3; ++a) {
    nplane[a] = _mm256_set1_ps(node.bounds[p.near_row[a]][c]);
    fplane[a] = _mm256_set1_ps(node.bounds[p.near_row[a] ^ 1][c]);
  }
  std::uint32_t mask = 0;
  __m256 kmin = inf;
  for (int k = 0; k < kMaxPacketRays; k += 8) {
    const std::uint32_t want = (lanes >> k) & 0xFFu;
    if (want == 0) continue;
    __m256 tn = _mm256_xor_ps(inf, sign), tf = inf;
    for (int a = 0; a < 3; ++a) {
      const __m256 o = _mm256_load_ps(p.org[a] + k), i = _mm256_load_ps(p.inv[a] + k);
      tn = _mm256_max_ps(_mm256_mul_ps(_mm256_sub_ps(nplane[a], o), i), tn);
      tf = _mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(fplane[a], o), i), tf);
    }
    const __m256 enter =
        _mm256_max_ps(_mm256_load_ps(p.tnear + k), _mm256_sub_ps(tn, _mm256_mul_ps(_mm256_andnot_ps(sign, tn), widen)));
    const __m256 leave =
        _mm256_min_ps(_mm256_load_ps(p.t + k), _mm256_add_ps(tf, _mm256_mul_ps(_mm256_andnot_ps(sign, tf), widen)));
    const __m256 in = _mm256_cmp_ps(enter, leave, _CMP_LE_OQ);
    const std::uint32_t m = static_cast<std::uint32_t>(_mm256_movemask_ps(in)) & want;
    if (m == 0) continue;
    mask |= m << k;
    kmin = _mm256_min_ps(kmin, _mm256_blendv_ps(inf, enter, in));
  }
  __m128 h = _mm_min_ps(_mm256_castps256_ps128(kmin), _mm256_extractf128_ps(kmin, 1));
  h = _mm_min_ps(h, _mm_shuffle_ps(h, h, _MM_SHUFFLE(1, 0, 3, 2)));
  h = _mm_min_ps(h, _mm_shuffle_ps(h, h, _MM_SHUFFLE(2, 3, 0, 1)));
  key = _mm_cvtss_f32(h);
  return mask;
}

// As sse2's packetBoundsHits, the 8 children at once.
inline std::uint32_t packetBoundsHits(const PacketRays& p, const WideNode& node, float t_hi) {
  const __m256 widen = _mm256_set1_ps(kWiden), sign = _mm256_set1_ps(-0.0f);
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  __m256 tn = _mm256_xor_ps(inf, sign), tf = inf;
  for (int a = 0; a < 3; ++a) {
    const __m256 lo = _mm256_set1_ps(p.inv_lo[a]), hi = _mm256_set1_ps(p.inv_hi[a]);
    const __m256 d = _mm256_sub_ps(_mm256_load_ps(node.bounds[p.near_row[a]]), _mm256_set1_ps(p.near_o[a]));
    const __m256 e = _mm256_sub_ps(_mm256_load_ps(node.bounds[p.near_row[a] ^ 1]), _mm256_set1_ps(p.far_o[a]));
    tn = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(d, lo), _mm256_mul_ps(d, hi)), tn);
    tf = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(e, lo), _mm256_mul_ps(e, hi)), tf);
  }
  const __m256 enter =
      _mm256_max_ps(_mm256_set1_ps(p.t_lo), _mm256_sub_ps(tn, _mm256_mul_ps(_mm256_andnot_ps(sign, tn), widen)));
  const __m256 leave =
      _mm256_min_ps(_mm256_set1_ps(t_hi), _mm256_add_ps(tf, _mm256_mul_ps(_mm256_andnot_ps(sign, tf), widen)));
  return static_cast<std::uint32_t>(_mm256_movemask_ps(_mm256_cmp_ps(enter, leave, _CMP_LE_OQ))) & node.valid;
}

// toObject with the three columns and the translation as 4-wide double vectors: the same
// products and sums in the same order (no fused multiply-add), so the same values.
inline Ray objectRay(const Record& rec, const WorldRay& w) {
  if (rec.identity) return w.f;
  static_assert(offsetof(Record, object_from_world) + sizeof(Affine) + 8 <= sizeof(Record),
                "the translation's 4-wide load reads 8 bytes past the transform, inside the record");
  __m256d o, d;
  if (w.d) {
    o = _mm256_setr_pd(w.d->origin.x, w.d->origin.y, w.d->origin.z, 0.0);
    d = _mm256_setr_pd(w.d->dir.x, w.d->dir.y, w.d->dir.z, 0.0);
  } else {
    o = _mm256_cvtps_pd(_mm_loadu_ps(&w.f.origin.x));  // lane 3: tnear, unused
    d = _mm256_cvtps_pd(_mm_loadu_ps(&w.f.dir.x));     // lane 3: tfar, unused
  }
  const double* m = &rec.object_from_world.linear[0][0];
  const __m256d c0 = _mm256_loadu_pd(m), c1 = _mm256_loadu_pd(m + 3), c2 = _mm256_loadu_pd(m + 6);
  const __m256d t = _mm256_loadu_pd(&rec.object_from_world.translation.x);
  auto apply = [&](__m256d v) {
    const __m256d x = _mm256_permute4x64_pd(v, 0x00), y = _mm256_permute4x64_pd(v, 0x55),
                  z = _mm256_permute4x64_pd(v, 0xAA);
    return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(c0, x), _mm256_mul_pd(c1, y)), _mm256_mul_pd(c2, z));
  };
  Ray r;
  _mm_storeu_ps(&r.origin.x, _mm256_cvtpd_ps(_mm256_add_pd(apply(o), t)));
  _mm_storeu_ps(&r.dir.x, _mm256_cvtpd_ps(apply(d)));
  r.tnear = w.f.tnear;
  r.tfar = w.f.tfar;
  return r;
}

#include "InstanceTreeWide.inl"

}  // namespace
const WideKernels kKernels{SimdIsa::Avx2,      closestEntry,       occludedEntry,       closestBatchEntry,
                           occludedBatchEntry, closestPacketEntry, occludedPacketEntry, walkEntry};
}  // namespace avx2
DUPLEX_TARGET_END

const WideKernels& wideKernels() {
  static const WideKernels& k = widestSimdIsa() >= SimdIsa::Avx2 ? avx2::kKernels : sse2::kKernels;
  return k;
}

}  // namespace duplex::toplevel_detail
