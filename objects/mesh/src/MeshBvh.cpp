// The mesh BVH kernels (MeshBvh.h), compiled three times from MeshBvhTraversal.inl: SSE2 (two
// 4-wide halves per node), AVX2 (one 8-wide test) and AVX-512 (8 wide with mask registers). Each
// copy lives in its own namespace inside a target region (SimdTarget.h), so that only the code of
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

#include "duplex/accel/SimdTarget.h"
#include "MeshLeafTest.h"
#include "MeshRay.h"

#include <immintrin.h>

#include <algorithm>
#include <array>
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

// kCompact[mask]: the lanes of the set bits of `mask`, lowest first, 3 bits each (lane j of the
// result in bits 3j..3j+2): compacts the entered children of a node to the front of a vector.
constexpr std::array<std::uint32_t, 256> makeCompactTable() {
  std::array<std::uint32_t, 256> t{};
  for (unsigned m = 0; m < 256; ++m) {
    unsigned j = 0;
    for (unsigned k = 0; k < 8; ++k)
      if (m >> k & 1u) t[m] |= k << (3 * j++);
  }
  return t;
}
constexpr std::array<std::uint32_t, 256> kCompact = makeCompactTable();

// The rays of a packet group bounded per axis (object space), for a node test that stands for all
// of them at once: near_o / far_o are the origin bounds that give each axis's smallest entry and
// largest exit (the largest origin on an axis the rays go up, the smallest on one they go down),
// inv_lo / inv_hi bound the inverse directions (one sign per axis: the group shares an octant).
// With the same slab arithmetic as a ray's, monotonic rounding makes every bound entry no later
// and every bound exit no earlier than any of the rays' own: a child no bound enters, no ray
// enters. A product 0 * inf (NaN) drops the axis, as a ray's own NaN does.
struct PacketBounds {
  float near_o[3], far_o[3], inv_lo[3], inv_hi[3];
  float t_lo;  // the smallest tnear of the rays
};

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
  // The children that a ray bounded by `b` may enter before t_hi, as bits by rank in the node's
  // order for kOct (bit 0: farthest).
  template <int kOct>
  static unsigned frustum(const BvhNode8& node, const PacketBounds& b, float t_hi) {
    const __m128 sign = _mm_set1_ps(-0.0f), widen = _mm_set1_ps(kBoxWiden);
    unsigned mask = 0;
    for (int h = 0; h < 8; h += 4) {
      const float* base = &node.lo[0][0] + h;
      __m128 tn = _mm_set1_ps(b.t_lo), tf = _mm_set1_ps(t_hi);
      for (int a = 2; a >= 0; --a) {
        const __m128 lo = _mm_set1_ps(b.inv_lo[a]), hi = _mm_set1_ps(b.inv_hi[a]);
        const bool neg = (kOct >> a & 1) != 0;
        const __m128 d = _mm_sub_ps(_mm_load_ps(base + (neg ? hiRow(a) : loRow(a))), _mm_set1_ps(b.near_o[a]));
        const __m128 e = _mm_sub_ps(_mm_load_ps(base + (neg ? loRow(a) : hiRow(a))), _mm_set1_ps(b.far_o[a]));
        tn = _mm_max_ps(_mm_min_ps(_mm_mul_ps(d, lo), _mm_mul_ps(d, hi)), tn);
        tf = _mm_min_ps(_mm_max_ps(_mm_mul_ps(e, lo), _mm_mul_ps(e, hi)), tf);
      }
      tn = _mm_sub_ps(tn, _mm_mul_ps(_mm_andnot_ps(sign, tn), widen));
      tf = _mm_add_ps(tf, _mm_mul_ps(_mm_andnot_ps(sign, tf), widen));
      mask |= static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(tn, tf))) << h;
    }
    unsigned ranked = 0;
    for (int rank = 0; rank < 8; ++rank) ranked |= (mask >> node.orderedSlot(kOct, rank) & 1u) << rank;
    return ranked;
  }
  // The entered children in the node's order for kOct, farthest first, at refs / dists; returns
  // their count. Writes 8 entries whatever the count (the stack has room).
  template <int kOct>
  static int push(const BvhNode8& node, const BoxRay& r, float t_best, std::uint32_t* refs, float* dists) {
    alignas(16) float dist[8];
    const unsigned mask = test<kOct>(node, r, t_best, dist);
    int n = 0;
    for (int rank = 0; rank < 8; ++rank) {
      const int k = node.orderedSlot(kOct, rank);
      refs[n] = node.child[k];
      dists[n] = dist[k];
      n += static_cast<int>(mask >> k & 1u);
    }
    return n;
  }
};

// The leaf step: one 4-wide test per block (MeshLeafTest.h). The any-hit test is inlined into the
// walk (as in the wider paths): a call would spill the walk's ray constants around every leaf.
struct Leaf {
  static constexpr bool kUsesRay4 = true;  // the 4-wide test reads MeshRay::wray4
  struct RayConstants {
    explicit RayConstants(const MeshRay&) {}
  };
  static bool closest(const MeshRay& ray, const RayConstants&, const TriangleBlock4* blocks, std::uint32_t count,
                      float& t_max, ClosestHit& best) {
    return closestInLeaf(ray, blocks, count, t_max, best);
  }
  // As avx2::Leaf::closestLanes.
  static unsigned closestLanes(const MeshRay* const* rays, unsigned lanes, const TriangleBlock4* blocks,
                               std::uint32_t count, float* t_max, ClosestHit* best) {
    unsigned found = 0;
    for (; lanes != 0; lanes &= lanes - 1) {
      const int j = std::countr_zero(lanes);
      if (closestInLeaf(*rays[j], blocks, count, t_max[j], best[j])) found |= 1u << j;
    }
    return found;
  }
  [[gnu::always_inline]] static bool any(const MeshRay& ray, const RayConstants&, const TriangleBlock4* blocks,
                                         std::uint32_t count, float t_max) {
    return anyInLeaf(ray, blocks, count, t_max);
  }
};

// The packet traversal's lanes (MeshBvhTraversal.inl): one ray each, 4 rays.
struct PV {
  using V = __m128;
  static constexpr int kWidth = 4;
  static constexpr int kFallback = 1;
  static constexpr int kMinPacket = 1;
  static V load(const float* p) { return _mm_load_ps(p); }
  static void store(float* p, V x) { _mm_store_ps(p, x); }
  static V set1(float x) { return _mm_set1_ps(x); }
  static V add(V a, V b) { return _mm_add_ps(a, b); }
  static V sub(V a, V b) { return _mm_sub_ps(a, b); }
  static V mul(V a, V b) { return _mm_mul_ps(a, b); }
  static V max(V a, V b) { return _mm_max_ps(a, b); }
  static V min(V a, V b) { return _mm_min_ps(a, b); }
  static V abs(V a) { return _mm_andnot_ps(_mm_set1_ps(-0.0f), a); }
  static unsigned le(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmple_ps(a, b))); }
  static unsigned gt(V a, V b) { return static_cast<unsigned>(_mm_movemask_ps(_mm_cmpgt_ps(a, b))); }
  // The smallest / largest of the lanes (none NaN).
  static float hmin(V a) {
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm_cvtss_f32(_mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2))));
  }
  static float hmax(V a) {
    a = _mm_max_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm_cvtss_f32(_mm_max_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2))));
  }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Sse2,    intersectEntry,       occludedEntry,
                              forEachLeafEntry, intersectPacketEntry, occludedPacketEntry,
                              PV::kWidth,       intersectViewEntry,   occludedViewEntry};
}  // namespace sse2

DUPLEX_TARGET_AVX2_BEGIN
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

// The node's child order for kOct: lane i holds the slot at rank i (0: farthest).
template <int kOct>
inline __m256i childOrder(const BvhNode8& node) {
  const __m256i packed = _mm256_load_si256(reinterpret_cast<const __m256i*>(node.order));
  return _mm256_and_si256(_mm256_srli_epi32(packed, 3 * kOct), _mm256_set1_epi32(7));
}

// sse2::Node::frustum's test of the 8 children: lane k is whether a ray bounded by `b` may enter
// child slot k before t_hi.
template <int kOct>
inline __m256 frustumEnters(const BvhNode8& node, const PacketBounds& b, float t_hi) {
  const float* base = &node.lo[0][0];
  const __m256 sign = _mm256_set1_ps(-0.0f), widen = _mm256_set1_ps(kBoxWiden);
  __m256 tn = _mm256_set1_ps(b.t_lo), tf = _mm256_set1_ps(t_hi);
  for (int a = 2; a >= 0; --a) {
    const __m256 lo = _mm256_set1_ps(b.inv_lo[a]), hi = _mm256_set1_ps(b.inv_hi[a]);
    const bool neg = (kOct >> a & 1) != 0;
    const __m256 d = _mm256_sub_ps(_mm256_load_ps(base + (neg ? hiRow(a) : loRow(a))), _mm256_set1_ps(b.near_o[a]));
    const __m256 e = _mm256_sub_ps(_mm256_load_ps(base + (neg ? loRow(a) : hiRow(a))), _mm256_set1_ps(b.far_o[a]));
    tn = _mm256_max_ps(_mm256_min_ps(_mm256_mul_ps(d, lo), _mm256_mul_ps(d, hi)), tn);
    tf = _mm256_min_ps(_mm256_max_ps(_mm256_mul_ps(e, lo), _mm256_mul_ps(e, hi)), tf);
  }
  tn = _mm256_sub_ps(tn, _mm256_mul_ps(_mm256_andnot_ps(sign, tn), widen));
  tf = _mm256_add_ps(tf, _mm256_mul_ps(_mm256_andnot_ps(sign, tf), widen));
  return _mm256_cmp_ps(tn, tf, _CMP_LE_OQ);
}

struct Node {
  // As sse2::Node::push: the entered children ordered, then compacted to the front through
  // kCompact, and stored with one 8-lane write each for references and distances.
  template <int kOct>
  static int push(const BvhNode8& node, const BoxRay& r, float t_best, std::uint32_t* refs, float* dists) {
    __m256 tf;
    const __m256 tn = entryAndExit<kOct>(node, r, t_best, tf);
    const __m256i order = childOrder<kOct>(node);
    const auto mask =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_permutevar8x32_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ), order)));
    const __m256i lanes = _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(static_cast<int>(kCompact[mask])),
                                                             _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21)),
                                           _mm256_set1_epi32(7));
    const __m256i idx = _mm256_permutevar8x32_epi32(order, lanes);
    const __m256i child = _mm256_load_si256(reinterpret_cast<const __m256i*>(node.child));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(refs), _mm256_permutevar8x32_epi32(child, idx));
    _mm256_storeu_ps(dists, _mm256_permutevar8x32_ps(tn, idx));
    return std::popcount(mask);
  }
  // As sse2::Node::frustum.
  template <int kOct>
  static unsigned frustum(const BvhNode8& node, const PacketBounds& b, float t_hi) {
    return static_cast<unsigned>(
        _mm256_movemask_ps(_mm256_permutevar8x32_ps(frustumEnters<kOct>(node, b, t_hi), childOrder<kOct>(node))));
  }
};

// The leaf step on two blocks at once: intersectWatertight4v (WatertightTriangle4.h) with 8 lanes,
// lane for lane the same operations (no fused multiply-add), so every lane decides as the 4-wide
// and the scalar tests do. Lanes 0..3 are the first block, 4..7 the second.
struct Watertight8v {
  int fast = 0;
  int exact = 0;
  __m256 T, det, V, W;
};

// Row `row` of two blocks (lo: lanes 0..3, hi: lanes 4..7).
inline __m256 rows2(const float* lo, const float* hi) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(lo)), _mm_load_ps(hi), 1);
}

// Leaf::any is inlined into the any-hit walk: a call would make the walk spill and reload its
// broadcast ray constants around every leaf, and the callee save registers and realign its frame,
// which costs more than the 8-lane test itself.
struct Leaf {
  // The constants come from the ray's scalar WatertightRay, broadcast once per ray here: the
  // 4-lane copy (MeshRay::wray4) is not needed, and the ray set-up skips it.
  static constexpr bool kUsesRay4 = false;
  /// WatertightRay4's constants on 8 lanes, once per ray.
  struct RayConstants {
    __m256 o[3], sx, sy, sz, tnear;
    [[gnu::always_inline]] explicit RayConstants(const MeshRay& ray)
        : o{_mm256_set1_ps(ray.wray.origin[ray.wray.kx]), _mm256_set1_ps(ray.wray.origin[ray.wray.ky]),
            _mm256_set1_ps(ray.wray.origin[ray.wray.kz])},
          sx(_mm256_set1_ps(ray.wray.sx)),
          sy(_mm256_set1_ps(ray.wray.sy)),
          sz(_mm256_set1_ps(ray.wray.sz)),
          tnear(_mm256_set1_ps(ray.wray.tnear)) {}
  };

  [[gnu::always_inline]] static Watertight8v test8(const MeshRay& ray, const RayConstants& c, const TriangleBlock4& b0,
                                                   const TriangleBlock4& b1, int lanes, float t_max) {
    const int kx = ray.wray.kx, ky = ray.wray.ky, kz = ray.wray.kz;
    const float *rx0 = b0.v[kx], *ry0 = b0.v[ky], *rz0 = b0.v[kz];
    const float *rx1 = b1.v[kx], *ry1 = b1.v[ky], *rz1 = b1.v[kz];
    const __m256 Az = _mm256_sub_ps(rows2(rz0, rz1), c.o[2]);
    const __m256 ax = _mm256_sub_ps(_mm256_sub_ps(rows2(rx0, rx1), c.o[0]), _mm256_mul_ps(c.sx, Az));
    const __m256 ay = _mm256_sub_ps(_mm256_sub_ps(rows2(ry0, ry1), c.o[1]), _mm256_mul_ps(c.sy, Az));
    const __m256 Bz = _mm256_sub_ps(rows2(rz0 + 12, rz1 + 12), c.o[2]);
    const __m256 bx = _mm256_sub_ps(_mm256_sub_ps(rows2(rx0 + 12, rx1 + 12), c.o[0]), _mm256_mul_ps(c.sx, Bz));
    const __m256 by = _mm256_sub_ps(_mm256_sub_ps(rows2(ry0 + 12, ry1 + 12), c.o[1]), _mm256_mul_ps(c.sy, Bz));
    const __m256 Cz = _mm256_sub_ps(rows2(rz0 + 24, rz1 + 24), c.o[2]);
    const __m256 cx = _mm256_sub_ps(_mm256_sub_ps(rows2(rx0 + 24, rx1 + 24), c.o[0]), _mm256_mul_ps(c.sx, Cz));
    const __m256 cy = _mm256_sub_ps(_mm256_sub_ps(rows2(ry0 + 24, ry1 + 24), c.o[1]), _mm256_mul_ps(c.sy, Cz));
    Watertight8v r;
    r.V = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
    r.W = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
    const __m256 U = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
    const __m256 V = r.V, W = r.W;
    const __m256 zero = _mm256_setzero_ps();
    const __m256 any_zero =
        _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(U, zero, _CMP_EQ_OQ), _mm256_cmp_ps(V, zero, _CMP_EQ_OQ)),
                     _mm256_cmp_ps(W, zero, _CMP_EQ_OQ));
    r.exact = _mm256_movemask_ps(any_zero) & lanes;
    const __m256 mixed = _mm256_and_ps(_mm256_cmp_ps(_mm256_min_ps(U, _mm256_min_ps(V, W)), zero, _CMP_LT_OQ),
                                       _mm256_cmp_ps(_mm256_max_ps(U, _mm256_max_ps(V, W)), zero, _CMP_GT_OQ));
    r.det = _mm256_add_ps(_mm256_add_ps(U, V), W);
    const int candidates =
        ~_mm256_movemask_ps(_mm256_or_ps(mixed, _mm256_cmp_ps(r.det, zero, _CMP_EQ_OQ))) & lanes & ~r.exact;
    if (candidates == 0) {
      r.T = zero;
      return r;
    }
    r.T = _mm256_add_ps(
        _mm256_add_ps(_mm256_mul_ps(U, _mm256_mul_ps(c.sz, Az)), _mm256_mul_ps(V, _mm256_mul_ps(c.sz, Bz))),
        _mm256_mul_ps(W, _mm256_mul_ps(c.sz, Cz)));
    const __m256 sign_bit = _mm256_set1_ps(-0.0f);
    const __m256 abs_det = _mm256_andnot_ps(sign_bit, r.det);
    const __m256 sT = _mm256_xor_ps(r.T, _mm256_and_ps(r.det, sign_bit));
    const __m256 outside = _mm256_or_ps(_mm256_cmp_ps(sT, _mm256_mul_ps(c.tnear, abs_det), _CMP_LT_OQ),
                                        _mm256_cmp_ps(sT, _mm256_mul_ps(_mm256_set1_ps(t_max), abs_det), _CMP_GT_OQ));
    r.fast = candidates & ~_mm256_movemask_ps(outside);
    return r;
  }

  /// closestInLeaf (MeshLeafTest.h) two blocks at a time; a last lone block fills both halves with
  /// itself, its upper lanes masked off (one code path: no second loop to mispredict into).
  static bool closest(const MeshRay& ray, const RayConstants& c, const TriangleBlock4* block, std::uint32_t count,
                      float& t_max, ClosestHit& best) {
    return closestIn(ray, c, block, count, t_max, best);
  }

  /// closest() for each lane j of `lanes` (rays[j], t_max[j], best[j]) in one call: a packet's
  /// leaf pays one call, not one per lane. Returns the lanes that found a hit.
  static unsigned closestLanes(const MeshRay* const* rays, unsigned lanes, const TriangleBlock4* block,
                               std::uint32_t count, float* t_max, ClosestHit* best) {
    unsigned found = 0;
    for (; lanes != 0; lanes &= lanes - 1) {
      const int j = std::countr_zero(lanes);
      if (closestIn(*rays[j], RayConstants(*rays[j]), block, count, t_max[j], best[j])) found |= 1u << j;
    }
    return found;
  }

  [[gnu::always_inline]] static bool closestIn(const MeshRay& ray, const RayConstants& c, const TriangleBlock4* block,
                                               std::uint32_t count, float& t_max, ClosestHit& best) {
    bool found = false;
    for (int left = static_cast<int>(count); left > 0; left -= 8, block += 2) {
      const int lanes = left >= 8 ? 0xFF : (1 << left) - 1;
      const Watertight8v r = test8(ray, c, block[0], block[left > 4 ? 1 : 0], lanes, t_max);
      if (r.fast != 0) {
        const __m256 inv = _mm256_div_ps(_mm256_set1_ps(1.0f), r.det);  // the scalar test's final step
        const __m256 t = _mm256_mul_ps(r.T, inv);
        const __m256i bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        const __m256 fast =
            _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(r.fast), bits), bits));
        // The smallest t of the fast lanes, broadcast; its first lane wins ties.
        __m256 m = _mm256_blendv_ps(_mm256_set1_ps(std::numeric_limits<float>::infinity()), t, fast);
        m = _mm256_min_ps(m, _mm256_permute_ps(m, _MM_SHUFFLE(2, 3, 0, 1)));
        m = _mm256_min_ps(m, _mm256_permute_ps(m, _MM_SHUFFLE(1, 0, 3, 2)));
        m = _mm256_min_ps(m, _mm256_permute2f128_ps(m, m, 1));
        const int k = std::countr_zero(
            static_cast<unsigned>(_mm256_movemask_ps(_mm256_and_ps(fast, _mm256_cmp_ps(t, m, _CMP_EQ_OQ)))));
        alignas(32) float tv[8], uv[8], vv[8];
        _mm256_store_ps(tv, t);
        _mm256_store_ps(uv, _mm256_mul_ps(r.V, inv));
        _mm256_store_ps(vv, _mm256_mul_ps(r.W, inv));
        t_max = tv[k];
        best = {block + (k >> 2), k & 3, uv[k], vv[k]};
        found = true;
      }
      for (int lanes_left = r.exact; lanes_left != 0; lanes_left &= lanes_left - 1) {
        const int k = std::countr_zero(static_cast<unsigned>(lanes_left));
        const TriangleBlock4& b = block[k >> 2];
        float t, u, v;
        if (!intersectWatertight(ray.wray, b.vertex(k & 3, 0), b.vertex(k & 3, 1), b.vertex(k & 3, 2), t_max, t, u, v))
          continue;
        t_max = t;
        best = {&b, k & 3, u, v};
        found = true;
      }
    }
    return found;
  }

  /// anyInLeaf (MeshLeafTest.h) two blocks at a time, a last lone block as in closest().
  [[gnu::always_inline]] static bool any(const MeshRay& ray, const RayConstants& c, const TriangleBlock4* block,
                                         std::uint32_t count, float t_max) {
    for (int left = static_cast<int>(count); left > 0; left -= 8, block += 2) {
      const Watertight8v r =
          test8(ray, c, block[0], block[left > 4 ? 1 : 0], left >= 8 ? 0xFF : (1 << left) - 1, t_max);
      if (r.fast != 0) return true;
      if (r.exact != 0 && anyExact(ray, block, r.exact, t_max)) return true;
    }
    return false;
  }

  /// The lanes of `exact` (an edge function zero: bit i, lane i & 3 of block[i >> 2]) decided by
  /// the scalar test. Rare, so out of line: it keeps the inlined any() small.
  [[gnu::noinline, gnu::cold]] static bool anyExact(const MeshRay& ray, const TriangleBlock4* block, int exact,
                                                    float t_max) {
    for (; exact != 0; exact &= exact - 1) {
      const int k = std::countr_zero(static_cast<unsigned>(exact));
      const TriangleBlock4& b = block[k >> 2];
      float t, u, v;
      if (intersectWatertight(ray.wray, b.vertex(k & 3, 0), b.vertex(k & 3, 1), b.vertex(k & 3, 2), t_max, t, u, v))
        return true;
    }
    return false;
  }
};

// The packet traversal's lanes (MeshBvhTraversal.inl): one ray each, 8 rays.
struct PV {
  using V = __m256;
  static constexpr int kWidth = 8;
  static constexpr int kFallback = 1;
  static constexpr int kMinPacket = 2;
  static V load(const float* p) { return _mm256_load_ps(p); }
  static void store(float* p, V x) { _mm256_store_ps(p, x); }
  static V set1(float x) { return _mm256_set1_ps(x); }
  static V add(V a, V b) { return _mm256_add_ps(a, b); }
  static V sub(V a, V b) { return _mm256_sub_ps(a, b); }
  static V mul(V a, V b) { return _mm256_mul_ps(a, b); }
  static V max(V a, V b) { return _mm256_max_ps(a, b); }
  static V min(V a, V b) { return _mm256_min_ps(a, b); }
  static V abs(V a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a); }
  static unsigned le(V a, V b) { return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ))); }
  static unsigned gt(V a, V b) { return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_GT_OQ))); }
  static float hmin(V a) { return sse2::PV::hmin(_mm_min_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1))); }
  static float hmax(V a) { return sse2::PV::hmax(_mm_max_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1))); }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Avx2,    intersectEntry,       occludedEntry,
                              forEachLeafEntry, intersectPacketEntry, occludedPacketEntry,
                              PV::kWidth,       intersectViewEntry,   occludedViewEntry};
}  // namespace avx2
DUPLEX_TARGET_END

DUPLEX_TARGET_AVX512_BEGIN
namespace avx512 {
namespace {

using avx2::BoxRay;
using avx2::Leaf;

struct Node {
  // As avx2::Node::push, with the compaction in registers (vpcompressd / vcompressps).
  template <int kOct>
  static int push(const BvhNode8& node, const BoxRay& r, float t_best, std::uint32_t* refs, float* dists) {
    __m256 tf;
    const __m256 tn = avx2::entryAndExit<kOct>(node, r, t_best, tf);
    const __m256i order = avx2::childOrder<kOct>(node);
    const __m256 tn_ordered = _mm256_permutevar8x32_ps(tn, order);
    const __mmask8 mask = _mm256_cmp_ps_mask(tn_ordered, _mm256_permutevar8x32_ps(tf, order), _CMP_LE_OQ);
    const __m256i child = _mm256_load_si256(reinterpret_cast<const __m256i*>(node.child));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(refs),
                        _mm256_maskz_compress_epi32(mask, _mm256_permutevar8x32_epi32(child, order)));
    _mm256_storeu_ps(dists, _mm256_maskz_compress_ps(mask, tn_ordered));
    return std::popcount(static_cast<unsigned>(mask));
  }
  template <int kOct>
  static unsigned frustum(const BvhNode8& node, const PacketBounds& b, float t_hi) {
    return avx2::Node::frustum<kOct>(node, b, t_hi);
  }
};

// The packet traversal's lanes (MeshBvhTraversal.inl): one ray each, 16 rays.
struct PV {
  using V = __m512;
  static constexpr int kWidth = 16;
  static constexpr int kFallback = 2;
  static constexpr int kMinPacket = 3;
  static V load(const float* p) { return _mm512_load_ps(p); }
  static void store(float* p, V x) { _mm512_store_ps(p, x); }
  static V set1(float x) { return _mm512_set1_ps(x); }
  static V add(V a, V b) { return _mm512_add_ps(a, b); }
  static V sub(V a, V b) { return _mm512_sub_ps(a, b); }
  static V mul(V a, V b) { return _mm512_mul_ps(a, b); }
  // The masked forms with every lane set: GCC warns about the unmasked forms' undefined pass-through.
  static V max(V a, V b) { return _mm512_mask_max_ps(a, 0xFFFF, a, b); }
  static V min(V a, V b) { return _mm512_mask_min_ps(a, 0xFFFF, a, b); }
  static V abs(V a) { return _mm512_abs_ps(a); }
  static unsigned le(V a, V b) { return _mm512_cmp_ps_mask(a, b, _CMP_LE_OQ); }
  static unsigned gt(V a, V b) { return _mm512_cmp_ps_mask(a, b, _CMP_GT_OQ); }
  // The two halves folded, then avx2's reduction. The masked extracts with every lane set, as
  // above: GCC 12's reductions and casts expand to unmasked forms and warn.
  template <int kHalf>
  static __m256 half(V a) {
    return _mm512_mask_extractf32x8_ps(_mm256_setzero_ps(), 0xFF, a, kHalf);
  }
  static float hmin(V a) { return avx2::PV::hmin(_mm256_min_ps(half<0>(a), half<1>(a))); }
  static float hmax(V a) { return avx2::PV::hmax(_mm256_max_ps(half<0>(a), half<1>(a))); }
};

#include "MeshBvhTraversal.inl"

}  // namespace
const MeshBvhKernels kKernels{SimdIsa::Avx512,  intersectEntry,       occludedEntry,
                              forEachLeafEntry, intersectPacketEntry, occludedPacketEntry,
                              PV::kWidth,       intersectViewEntry,   occludedViewEntry};
}  // namespace avx512
DUPLEX_TARGET_END

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
