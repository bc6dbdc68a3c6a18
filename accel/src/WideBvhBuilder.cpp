// The wide BVH builder (WideBvh.h): top-down binned SAH that fills each 8-wide node directly.
//
// A node starts with its whole range as one child; the child of largest surface area that the SAH
// (or the leaf size) wants split is split in two, until the node has 8 children or none wants a
// split. This is the tree a greedy largest-area-first collapse of the binary SAH tree would give,
// without building the binary tree first. Children that are not leaves become nodes the same way,
// as TBB tasks when they are large. Nodes are written to a temporary pool in completion order and
// then laid out depth-first in one serial pass, so that the result does not depend on the thread
// count or the scheduling.
//
// With spatial splits (Stich et al. 2009) a range owns free room after its references (its
// "extended" end): a spatial split writes the references it duplicates there, and every split
// shares the room left between the two sides in proportion to their sizes, so that the total
// duplication stays within the budget and no range ever grows into another's.

#include "duplex/accel/WideBvh.h"

#include "duplex/accel/Check.h"
#include "duplex/accel/Error.h"

#include <tbb/blocked_range.h>
#include <tbb/concurrent_vector.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_group.h>

#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#if defined(__GNUC__) && defined(__x86_64__)
#define DUPLEX_WIDE_BVH_SSE 1
#include <emmintrin.h>
#endif

namespace duplex {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Below this many wide levels the SAH chooses the splits; deeper (a pathological distribution
// splitting off one primitive at a time) nodes split at the object median, which bounds the depth
// the traversal stack must hold.
constexpr int kSahDepth = 40;
// Ranges of at least this many references are binned in parallel chunks of kBinChunk.
constexpr std::uint32_t kParallelBinning = 1u << 15;
constexpr std::uint32_t kBinChunk = 1u << 13;
// Spatial splits are tried in ranges of at least this many references: in smaller ones most
// references cross several bins (a clip each) for little gain.
constexpr std::uint32_t kSpatialMinRefs = 64;
// Primitive boxes per task of the pass that makes the references.
constexpr std::size_t kRefChunk = 1u << 15;
// Bins per axis of a spatial split at most.
constexpr std::uint32_t kSpatialBins = 16;

// Four floats, one SSE register where there is SSE2 (x86-64 always has it).
#if defined(DUPLEX_WIDE_BVH_SSE)
struct V4 {
  __m128 v;
};
inline V4 load4(const float* p) { return {_mm_load_ps(p)}; }
inline void store4(float* p, V4 a) { _mm_store_ps(p, a.v); }
inline V4 splat4(float x) { return {_mm_set1_ps(x)}; }
inline V4 set4(float x, float y, float z, float w) { return {_mm_setr_ps(x, y, z, w)}; }
inline V4 min4(V4 a, V4 b) { return {_mm_min_ps(a.v, b.v)}; }
inline V4 max4(V4 a, V4 b) { return {_mm_max_ps(a.v, b.v)}; }
inline V4 add4(V4 a, V4 b) { return {_mm_add_ps(a.v, b.v)}; }
inline V4 sub4(V4 a, V4 b) { return {_mm_sub_ps(a.v, b.v)}; }
inline V4 mul4(V4 a, V4 b) { return {_mm_mul_ps(a.v, b.v)}; }
// Bit i set when lane i of a is below lane i of b.
inline int lessMask4(V4 a, V4 b) { return _mm_movemask_ps(_mm_cmplt_ps(a.v, b.v)); }
// s ? a : b without a branch.
inline V4 select4(bool s, V4 a, V4 b) {
  const __m128 m = _mm_castsi128_ps(_mm_set1_epi32(-static_cast<int>(s)));
  return {_mm_or_ps(_mm_and_ps(m, a.v), _mm_andnot_ps(m, b.v))};
}
// Rows to columns.
inline void transpose4(V4& a, V4& b, V4& c, V4& d) { _MM_TRANSPOSE4_PS(a.v, b.v, c.v, d.v); }
// Lanes of `mask` set: a; others: b.
inline V4 select4(int mask, V4 a, V4 b) {
  const __m128i bits = _mm_setr_epi32(1, 2, 4, 8);
  const __m128 m = _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_and_si128(_mm_set1_epi32(mask), bits), bits));
  return {_mm_or_ps(_mm_and_ps(m, a.v), _mm_andnot_ps(m, b.v))};
}
// Four 32-bit integers.
struct I4 {
  __m128i v;
};
inline I4 zero4i() { return {_mm_setzero_si128()}; }
inline I4 splat4i(std::int32_t x) { return {_mm_set1_epi32(x)}; }
inline I4 load4i(const std::uint32_t* p) { return {_mm_load_si128(reinterpret_cast<const __m128i*>(p))}; }
inline I4 add4i(I4 a, I4 b) { return {_mm_add_epi32(a.v, b.v)}; }
inline int positiveMask4i(I4 a) { return _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(a.v, _mm_setzero_si128()))); }
inline int lessMask4i(I4 a, I4 b) { return _mm_movemask_ps(_mm_castsi128_ps(_mm_cmplt_epi32(a.v, b.v))); }
// ceil(lane / 4) as floats (the leaf blocks of a count).
inline V4 blocks4(I4 a) { return {_mm_cvtepi32_ps(_mm_srli_epi32(_mm_add_epi32(a.v, _mm_set1_epi32(3)), 2))}; }
// Truncates lanes to integers (the lanes are in [0, 2^24)).
inline void truncate4(V4 a, std::int32_t* out) {
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_cvttps_epi32(a.v));
}
#else
struct V4 {
  float f[4];
};
inline V4 load4(const float* p) { return {{p[0], p[1], p[2], p[3]}}; }
inline void store4(float* p, V4 a) { std::memcpy(p, a.f, sizeof a.f); }
inline V4 splat4(float x) { return {{x, x, x, x}}; }
inline V4 set4(float x, float y, float z, float w) { return {{x, y, z, w}}; }
template <class F>
inline V4 map4(V4 a, V4 b, F f) {
  return {{f(a.f[0], b.f[0]), f(a.f[1], b.f[1]), f(a.f[2], b.f[2]), f(a.f[3], b.f[3])}};
}
// As minps/maxps: the second operand when the comparison is false (NaN included).
inline V4 min4(V4 a, V4 b) {
  return map4(a, b, [](float x, float y) { return x < y ? x : y; });
}
inline V4 max4(V4 a, V4 b) {
  return map4(a, b, [](float x, float y) { return x > y ? x : y; });
}
inline V4 add4(V4 a, V4 b) {
  return map4(a, b, [](float x, float y) { return x + y; });
}
inline V4 sub4(V4 a, V4 b) {
  return map4(a, b, [](float x, float y) { return x - y; });
}
inline V4 mul4(V4 a, V4 b) {
  return map4(a, b, [](float x, float y) { return x * y; });
}
inline int lessMask4(V4 a, V4 b) {
  int m = 0;
  for (int i = 0; i < 4; ++i) m |= (a.f[i] < b.f[i] ? 1 : 0) << i;
  return m;
}
inline V4 select4(bool s, V4 a, V4 b) { return s ? a : b; }
inline void transpose4(V4& a, V4& b, V4& c, V4& d) {
  V4* rows[4] = {&a, &b, &c, &d};
  float m[4][4];
  for (int i = 0; i < 4; ++i) store4(m[i], *rows[i]);
  for (int i = 0; i < 4; ++i) *rows[i] = set4(m[0][i], m[1][i], m[2][i], m[3][i]);
}
inline V4 select4(int mask, V4 a, V4 b) {
  V4 out;
  for (int i = 0; i < 4; ++i) out.f[i] = (mask >> i) & 1 ? a.f[i] : b.f[i];
  return out;
}
struct I4 {
  std::int32_t i[4];
};
inline I4 zero4i() { return {{0, 0, 0, 0}}; }
inline I4 splat4i(std::int32_t x) { return {{x, x, x, x}}; }
inline I4 load4i(const std::uint32_t* p) {
  return {{static_cast<std::int32_t>(p[0]), static_cast<std::int32_t>(p[1]), static_cast<std::int32_t>(p[2]),
           static_cast<std::int32_t>(p[3])}};
}
inline I4 add4i(I4 a, I4 b) { return {{a.i[0] + b.i[0], a.i[1] + b.i[1], a.i[2] + b.i[2], a.i[3] + b.i[3]}}; }
inline int positiveMask4i(I4 a) {
  int m = 0;
  for (int k = 0; k < 4; ++k) m |= (a.i[k] > 0 ? 1 : 0) << k;
  return m;
}
inline int lessMask4i(I4 a, I4 b) {
  int m = 0;
  for (int k = 0; k < 4; ++k) m |= (a.i[k] < b.i[k] ? 1 : 0) << k;
  return m;
}
inline V4 blocks4(I4 a) {
  V4 out;
  for (int k = 0; k < 4; ++k) out.f[k] = static_cast<float>((a.i[k] + 3) >> 2);
  return out;
}
inline void truncate4(V4 a, std::int32_t* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<std::int32_t>(a.f[i]);
}
#endif

// A reference: a primitive's box (or, with spatial splits, the box of a part of it), 32 bytes so
// that each corner is one aligned vector load (lane 3 of lo holds the primitive's bits, ignored).
struct alignas(32) Ref {
  float lo[3];
  std::uint32_t prim;
  float hi[3];
  float pad;

  [[nodiscard]] V4 vlo() const { return load4(lo); }
  [[nodiscard]] V4 vhi() const { return load4(hi); }
  // Twice the centroid: the binning works on lo + hi, which saves a multiply and rounds the same.
  [[nodiscard]] V4 centroid2() const { return add4(vlo(), vhi()); }
  [[nodiscard]] Box box() const { return Box({lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}); }
  static Ref make(const Box& b, std::uint32_t prim) {
    return Ref{{b.lo.x, b.lo.y, b.lo.z}, prim, {b.hi.x, b.hi.y, b.hi.z}, 0.0f};
  }
};
static_assert(sizeof(Ref) == 32);

// Bounds accumulated in vectors (lane 3 unused).
struct VBox {
  V4 lo = splat4(kInf), hi = splat4(-kInf);
  void extend(V4 l, V4 h) {
    lo = min4(lo, l);
    hi = max4(hi, h);
  }
  void extend(const VBox& b) { extend(b.lo, b.hi); }
  void extendPoint(V4 p) { extend(p, p); }
  [[nodiscard]] Box box() const {
    alignas(16) float l[4], h[4];
    store4(l, lo);
    store4(h, hi);
    return Box({l[0], l[1], l[2]}, {h[0], h[1], h[2]});
  }
  // Box::area() of box(), without the conversion.
  [[nodiscard]] float area() const {
    alignas(16) float e[4];
    store4(e, sub4(hi, lo));
    if (!(e[0] >= 0.0f && e[1] >= 0.0f && e[2] >= 0.0f)) return 0.0f;
    return 2.0f * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]);
  }
};

// Box::area() of three non-empty boxes in lanes 0..2 (lane 3 undefined).
V4 areas3(const VBox* box) {
  V4 x = sub4(box[0].hi, box[0].lo), y = sub4(box[1].hi, box[1].lo), z = sub4(box[2].hi, box[2].lo), w = splat4(0.0f);
  transpose4(x, y, z, w);
  return mul4(splat4(2.0f), add4(add4(mul4(x, y), mul4(y, z)), mul4(z, x)));
}

VBox toVBox(const Box& b) { return {set4(b.lo.x, b.lo.y, b.lo.z, 0.0f), set4(b.hi.x, b.hi.y, b.hi.z, 0.0f)}; }

// A range of the reference array with its bounds and the bounds of its doubled centroids; [end,
// ext) is free room for duplicated references (empty without spatial splits).
struct Range {
  std::uint32_t begin = 0, end = 0, ext = 0;
  Box box, centroids2;
  [[nodiscard]] std::uint32_t size() const { return end - begin; }
  [[nodiscard]] std::uint32_t room() const { return ext - end; }
};

// The bin of a doubled centroid per axis, k bins over the range's centroid bounds. The binning and
// the partition both use it, so that the partition sends every reference where the binning counted
// it.
struct Binner {
  V4 lo, scale, top;
  Binner(const Range& r, std::uint32_t k) : lo(toVBox(r.centroids2).lo), top(splat4(static_cast<float>(k - 1))) {
    float s[3];
    for (int a = 0; a < 3; ++a) {
      const float ext = r.centroids2.hi[a] - r.centroids2.lo[a];
      // A flat axis bins everything into bin 0 (and is not split along). So does an extent so small
      // (subnormal) that the scale overflows: 0 * inf would be NaN, which the binning clamps to bin 0
      // but the partition's comparison sends right, and the two must agree.
      const float scale = ext > 0.0f ? static_cast<float>(k) * (1.0f - 1e-6f) / ext : 0.0f;
      s[a] = std::isfinite(scale) ? scale : 0.0f;
    }
    scale = set4(s[0], s[1], s[2], 0.0f);
  }
  void bins(const Ref& ref, std::int32_t* out) const {
    // max4 returns 0 for a NaN lane (the ignored lane 3), min4 keeps it inside the bins.
    truncate4(min4(max4(mul4(sub4(ref.centroid2(), lo), scale), splat4(0.0f)), top), out);
  }
};

// Per-bin counts of the three axes, count[bin][axis] (lane 3 unused): one vector load per bin in
// the sweep.
struct alignas(16) Counts {
  std::uint32_t count[BvhBuildConfig::kMaxBins][4];
  void clear(std::uint32_t k) { std::memset(count, 0, sizeof(count[0]) * k); }
};

// Bins of the three axes, k per axis, box lo[bin][axis], hi[bin][axis] (only the first k bins are
// initialised).
struct Bins {
  std::uint32_t k = 0;
  V4 lo[BvhBuildConfig::kMaxBins][3], hi[BvhBuildConfig::kMaxBins][3];
  Counts counts;
  explicit Bins(std::uint32_t k_) : k(k_) {
    std::fill_n(&lo[0][0], 3 * k, splat4(kInf));
    std::fill_n(&hi[0][0], 3 * k, splat4(-kInf));
    counts.clear(k);
  }
  [[nodiscard]] VBox box(int a, std::uint32_t b) const { return {lo[b][a], hi[b][a]}; }
  void extend(int a, std::uint32_t b, V4 l, V4 h) {
    lo[b][a] = min4(lo[b][a], l);
    hi[b][a] = max4(hi[b][a], h);
  }
  void merge(const Bins& o) {
    for (std::uint32_t b = 0; b < k; ++b) {
      for (int a = 0; a < 3; ++a) {
        extend(a, b, o.lo[b][a], o.hi[b][a]);
        counts.count[b][a] += o.counts.count[b][a];
      }
    }
  }
};

// The best split of a range. An object split (spatial false) sends references whose centroid falls
// in bins [0, bin] of `bins` bins left, or, with axis -1, splits at the middle index; the sides'
// bounds come from the bins. A spatial split cuts at plane `pos` on `axis`, duplicating the
// references it crosses.
struct Split {
  int axis = -1;
  bool spatial = false;
  std::uint32_t bins = 0, bin = 0;
  float pos = 0.0f;
  float cost = kInf;
  Box left_box, right_box;
};

// Partitions [lo, hi) so that the references for which goesLeft holds come first; leaves `lo` at
// the first of the others. Blocks of predicates are evaluated into offset lists before any swap
// (Edelkamp and Weiss's BlockQuicksort partition), so that the predicate's outcome is never a
// branch in the scan.
template <class Pred>
void blockPartition(Ref*& lo, Ref*& hi, Pred& goesLeft) {
  constexpr int kBlock = 64;
  std::uint8_t off_l[kBlock], off_r[kBlock];
  int num_l = 0, num_r = 0, start_l = 0, start_r = 0;
  while (hi - lo > 2 * kBlock) {
    if (num_l == 0) {
      start_l = 0;
      for (int i = 0; i < kBlock; ++i) {
        off_l[num_l] = static_cast<std::uint8_t>(i);
        num_l += goesLeft(lo[i]) ? 0 : 1;
      }
    }
    if (num_r == 0) {
      start_r = 0;
      for (int i = 0; i < kBlock; ++i) {
        off_r[num_r] = static_cast<std::uint8_t>(i);
        num_r += goesLeft(hi[-1 - i]) ? 1 : 0;
      }
    }
    const int num = std::min(num_l, num_r);
    for (int j = 0; j < num; ++j) std::swap(lo[off_l[start_l + j]], hi[-1 - off_r[start_r + j]]);
    num_l -= num;
    num_r -= num;
    start_l += num;
    start_r += num;
    if (num_l == 0) lo += kBlock;
    if (num_r == 0) hi -= kBlock;
  }
  for (;;) {
    while (lo < hi && goesLeft(*lo)) ++lo;
    while (lo < hi && !goesLeft(hi[-1])) --hi;
    if (lo >= hi) break;
    std::swap(*lo, hi[-1]);
  }
}

class Builder {
 public:
  Builder(std::vector<Ref>& refs, const BvhBuildConfig& config, const BvhClipFunction& clip)
      : refs_(refs), c_(config), clip_(clip) {}

  WideBvh run(const Range& root) {
    WideBvh out;
    DUPLEX_CHECK(c_.leaf_block == kLeafBlock);
    out.leaf_block = c_.leaf_block;
    out.bounds = root.box;
    if (root.size() == 0) return out;
    spatial_ = clip_ && c_.spatial_split_alpha > 0.0f && root.room() > 0;
    min_overlap_ = c_.spatial_split_alpha * root.box.area();
    const Split split = findSplit(root, 0);
    std::uint32_t temp_root;
    if (wantsLeaf(root, split)) temp_root = makeLeaf(root);
    else temp_root = buildNode(root, split, 0);
    layout(temp_root, out);
    return out;
  }

 private:
  static constexpr std::uint32_t kTempLeaf = 0x80000000u;
  // The only leaf block validate() accepts: a constant, so that the SAH sweeps shift instead of
  // divide.
  static constexpr std::uint32_t kLeafBlock = 4;

  [[nodiscard]] float blocks(std::uint32_t n) const { return static_cast<float>((n + kLeafBlock - 1) / kLeafBlock); }
  [[nodiscard]] float leafCost(std::uint32_t n) const { return c_.intersection_cost * blocks(n); }

  [[nodiscard]] bool wantsLeaf(const Range& r, const Split& s) const {
    const std::uint32_t n = r.size();
    if (n <= 1) return true;
    if (n > c_.max_leaf_size) return false;
    return leafCost(n) <= s.cost;
  }

  void binRange(std::uint32_t first, std::uint32_t last, const Binner& binner, Bins& out) const {
    const Ref* refs = refs_.data();
    for (std::uint32_t i = first; i < last; ++i) {
      const Ref& ref = refs[i];
      alignas(16) std::int32_t b[4];
      binner.bins(ref, b);
      const V4 lo = ref.vlo(), hi = ref.vhi();
      for (int a = 0; a < 3; ++a) {
        out.extend(a, static_cast<std::uint32_t>(b[a]), lo, hi);
        ++out.counts.count[b[a]][a];
      }
    }
  }

  // The cheapest split over the bins of axes `live`, the three axes in the lanes of one sweep;
  // `best` keeps its value where nothing is cheaper. Left of bin b are bins [0, b] with counts
  // `left`, right bins [b + 1, k) with counts `right`; a left side of `max_left` or more
  // references is not a split. Ties go to the lower axis, then the lower bin.
  void sweep(const Bins& bins, const Counts& left, const Counts& right, std::uint32_t max_left, float inv_area,
             const bool* live, Split& best) const {
    const std::uint32_t k = bins.k;
    alignas(16) float right_cost[BvhBuildConfig::kMaxBins][4];
    I4 right_count[BvhBuildConfig::kMaxBins];
    VBox acc[3];
    I4 count = zero4i();
    for (std::uint32_t b = k - 1; b > 0; --b) {
      for (int a = 0; a < 3; ++a) acc[a].extend(bins.lo[b][a], bins.hi[b][a]);
      count = add4i(count, load4i(right.count[b]));
      right_count[b] = count;
      store4(right_cost[b], mul4(areas3(acc), blocks4(count)));
    }
    for (VBox& box : acc) box = VBox();
    count = zero4i();
    const V4 ct = splat4(c_.traversal_cost), ci = splat4(c_.intersection_cost), inv = splat4(inv_area);
    const int live_mask = (live[0] ? 1 : 0) | (live[1] ? 2 : 0) | (live[2] ? 4 : 0);
    const I4 limit = splat4i(static_cast<std::int32_t>(std::min<std::uint32_t>(max_left, 0x7FFFFFFF)));
    // Per axis (lane) the cheapest cost so far and its bin; strict comparisons keep the lowest bin.
    V4 lane_cost = splat4(best.cost);
    std::int32_t lane_bin[3] = {-1, -1, -1};
    for (std::uint32_t b = 0; b + 1 < k; ++b) {
      for (int a = 0; a < 3; ++a) acc[a].extend(bins.lo[b][a], bins.hi[b][a]);
      count = add4i(count, load4i(left.count[b]));
      const V4 cost = add4(ct, mul4(ci, mul4(add4(mul4(areas3(acc), blocks4(count)), load4(right_cost[b + 1])), inv)));
      const int valid = positiveMask4i(count) & positiveMask4i(right_count[b + 1]) & lessMask4i(count, limit);
      const int better = valid & live_mask & lessMask4(cost, lane_cost);
      if (better == 0) continue;
      lane_cost = select4(better, cost, lane_cost);
      for (int a = 0; a < 3; ++a)
        if (better & (1 << a)) lane_bin[a] = static_cast<std::int32_t>(b);
    }
    alignas(16) float costs[4];
    store4(costs, lane_cost);
    for (int a = 0; a < 3; ++a) {
      if (lane_bin[a] < 0 || !(costs[a] < best.cost || (costs[a] == best.cost && a < best.axis))) continue;
      best.axis = a;
      best.bin = static_cast<std::uint32_t>(lane_bin[a]);
      best.cost = costs[a];
    }
  }

  Split findSplit(const Range& r, int depth, bool allow_spatial = true) const {
    Split best;
    const std::uint32_t n = r.size();
    if (n <= 1) return best;
    if (depth >= kSahDepth) return best;  // the object median (axis -1)
    // A node of few references needs no more bins than references.
    const std::uint32_t k = std::min(c_.bins, std::max(2u, n));
    const Binner binner(r, k);
    Bins bins(k);
    if (n >= kParallelBinning && c_.parallel_threshold > 0) {
      // Fixed chunks merged in order: the same bins whatever the thread count.
      const std::uint32_t chunks = (n + kBinChunk - 1) / kBinChunk;
      std::vector<std::unique_ptr<Bins>> part(chunks);
      tbb::parallel_for(std::uint32_t{0}, chunks, [&](std::uint32_t c) {
        part[c] = std::make_unique<Bins>(k);
        const std::uint32_t first = r.begin + c * kBinChunk;
        binRange(first, std::min(r.end, first + kBinChunk), binner, *part[c]);
      });
      for (const auto& p : part) bins.merge(*p);
    } else {
      binRange(r.begin, r.end, binner, bins);
    }
    const float inv_area = r.box.area() > 0.0f ? 1.0f / r.box.area() : 0.0f;
    bool live[3];
    for (int a = 0; a < 3; ++a) live[a] = r.centroids2.hi[a] > r.centroids2.lo[a];
    const Bins& bs = bins;
    sweep(bins, bins.counts, bins.counts, n + 1, inv_area, live, best);
    if (best.axis >= 0) {
      best.bins = k;
      VBox left, right;
      for (std::uint32_t b = 0; b < k; ++b) (b <= best.bin ? left : right).extend(bs.box(best.axis, b));
      best.left_box = left.box();
      best.right_box = right.box();
      if (allow_spatial && spatial_ && n >= kSpatialMinRefs && r.room() > 0 &&
          intersection(best.left_box, best.right_box).area() > min_overlap_)
        findSpatialSplit(r, inv_area, best);
    }
    return best;
  }

  // Spatial split bins along the range's box, k per axis: references clipped into every bin they
  // cross, counted where they enter and where they leave. Replaces `best` when cheaper within the
  // range's room for duplicates.
  void findSpatialSplit(const Range& r, float inv_area, Split& best) const {
    // Fewer bins than the object split's: each bin a reference crosses costs a clip.
    const std::uint32_t k = std::min(c_.bins, kSpatialBins), n = r.size();
    Bins bins(k);
    Counts exit;
    exit.clear(k);
    bool live[3];
    for (int a = 0; a < 3; ++a) {
      live[a] = r.box.hi[a] > r.box.lo[a];
      if (!live[a]) continue;
      const float lo = r.box.lo[a], scale = static_cast<float>(k) / (r.box.hi[a] - r.box.lo[a]);
      auto binOf = [&](float x) {
        return std::min(k - 1, static_cast<std::uint32_t>(std::max(0.0f, (x - lo) * scale)));
      };
      auto add = [&](std::uint32_t b, const Box& part) {
        const VBox v = toVBox(part);
        bins.extend(a, b, v.lo, v.hi);
      };
      for (std::uint32_t i = r.begin; i < r.end; ++i) {
        const Ref& ref = refs_[i];
        const std::uint32_t first = binOf(ref.lo[a]), last = std::max(first, binOf(ref.hi[a]));
        ++bins.counts.count[first][a];
        ++exit.count[last][a];
        Box rest = ref.box();
        for (std::uint32_t b = first; b < last && !rest.empty(); ++b) {
          Box lower, upper;
          clip_(ref.prim, rest, a, planePos(r.box, a, k, b + 1), lower, upper);
          add(b, lower);
          rest = upper;
        }
        if (!rest.empty()) add(last, rest);
      }
    }
    Split s = best;
    s.axis = -1;
    sweep(bins, bins.counts, exit, n, inv_area, live, s);
    if (s.axis < 0) return;
    std::uint32_t left = 0, right = 0;
    for (std::uint32_t b = 0; b <= s.bin; ++b) left += bins.counts.count[b][s.axis];
    for (std::uint32_t b = s.bin + 1; b < k; ++b) right += exit.count[b][s.axis];
    // Each side must shrink (or the recursion would not end) and the duplicates must fit.
    if (left >= n || right >= n || left + right - n > r.room()) return;
    s.spatial = true;
    s.bins = k;
    s.pos = planePos(r.box, s.axis, k, s.bin + 1);
    best = s;
  }

  static float planePos(const Box& box, int axis, std::uint32_t k, std::uint32_t b) {
    return box.lo[axis] + (box.hi[axis] - box.lo[axis]) * (static_cast<float>(b) / static_cast<float>(k));
  }

  // Bounds and doubled-centroid bounds of refs_[first, last).
  void bound(Range& side) const {
    VBox box, cent;
    for (std::uint32_t i = side.begin; i < side.end; ++i) {
      const Ref& ref = refs_[i];
      box.extend(ref.vlo(), ref.vhi());
      cent.extendPoint(ref.centroid2());
    }
    side.box = box.box();
    side.centroids2 = cent.box();
  }

  // Shares the room of `r` between the sides [r.begin, m) and [m, end_right) in proportion to their
  // sizes, moving the right side up by the left side's share.
  std::pair<Range, Range> shareRoom(const Range& r, std::uint32_t m, std::uint32_t end_right) {
    const std::uint32_t nl = m - r.begin, nr = end_right - m, room = r.ext - end_right;
    const auto left_room = static_cast<std::uint32_t>(std::uint64_t{room} * nl / (nl + nr));
    if (left_room > 0)
      std::copy_backward(refs_.data() + m, refs_.data() + end_right, refs_.data() + end_right + left_room);
    Range left{r.begin, m, m + left_room, Box(), Box()};
    Range right{m + left_room, end_right + left_room, r.ext, Box(), Box()};
    return {left, right};
  }

  // Splits `r` by `s` into two non-empty ranges with their bounds. Returns false (and changes
  // nothing) when a spatial split turns out to leave a side empty or unchanged.
  bool partition(const Range& r, const Split& s, std::pair<Range, Range>& out) {
    if (s.spatial) return partitionSpatial(r, s, out);
    if (s.axis >= 0) {
      const Binner binner(r, s.bins);
      // Bin index <= s.bin exactly when the unclamped bin coordinate is below s.bin + 1 (the
      // coordinate is not NaN on an axis the centroids extend along).
      const V4 limit = splat4(static_cast<float>(s.bin + 1));
      const int axis = s.axis;
      VBox lc, rc;
      // Which side a reference goes to; every evaluation also grows that side's centroid bounds
      // (min and max do not mind a reference evaluated twice).
      auto goesLeft = [&](const Ref& ref) {
        const V4 c = ref.centroid2();
        const bool left = ((lessMask4(mul4(sub4(c, binner.lo), binner.scale), limit) >> axis) & 1) != 0;
        const V4 cl = select4(left, c, lc.lo), cr = select4(left, rc.lo, c);
        lc.extend(cl, select4(left, c, lc.hi));
        rc.extend(cr, select4(left, rc.hi, c));
        return left;
      };
      Ref* lo = refs_.data() + r.begin;
      Ref* hi = refs_.data() + r.end;
      blockPartition(lo, hi, goesLeft);
      const auto m = static_cast<std::uint32_t>(lo - refs_.data());
      // The binned count decided the cost; the same bin rule on the same floats makes the
      // partition agree with it, so neither side can be empty.
      DUPLEX_CHECK(m > r.begin && m < r.end);
      out = r.room() > 0 ? shareRoom(r, m, r.end)
                         : std::pair{Range{r.begin, m, m, {}, {}}, Range{m, r.end, r.end, {}, {}}};
      out.first.box = s.left_box;
      out.first.centroids2 = lc.box();
      out.second.box = s.right_box;
      out.second.centroids2 = rc.box();
      return true;
    }
    // No axis separates the centroids (or too deep for the SAH): the middle by index, after
    // ordering by centroid on the longest axis so that the halves are spatially coherent.
    const std::uint32_t m = r.begin + r.size() / 2;
    const int axis = r.centroids2.longestAxis();
    std::nth_element(refs_.data() + r.begin, refs_.data() + m, refs_.data() + r.end,
                     [axis](const Ref& a, const Ref& b) { return a.lo[axis] + a.hi[axis] < b.lo[axis] + b.hi[axis]; });
    out =
        r.room() > 0 ? shareRoom(r, m, r.end) : std::pair{Range{r.begin, m, m, {}, {}}, Range{m, r.end, r.end, {}, {}}};
    bound(out.first);
    bound(out.second);
    return true;
  }

  bool partitionSpatial(const Range& r, const Split& s, std::pair<Range, Range>& out) {
    std::vector<Ref> left, right;
    left.reserve(r.size());
    right.reserve(r.size());
    const int a = s.axis;
    for (std::uint32_t i = r.begin; i < r.end; ++i) {
      const Ref& ref = refs_[i];
      if (ref.hi[a] <= s.pos) {
        left.push_back(ref);
      } else if (ref.lo[a] >= s.pos) {
        right.push_back(ref);
      } else {
        Box lower, upper;
        clip_(ref.prim, ref.box(), a, s.pos, lower, upper);
        if (!lower.empty()) left.push_back(Ref::make(lower, ref.prim));
        if (!upper.empty()) right.push_back(Ref::make(upper, ref.prim));
      }
    }
    const auto nl = static_cast<std::uint32_t>(left.size()), nr = static_cast<std::uint32_t>(right.size());
    if (nl == 0 || nr == 0 || nl >= r.size() || nr >= r.size() || nl + nr > r.ext - r.begin) return false;
    std::copy(left.begin(), left.end(), refs_.data() + r.begin);
    std::copy(right.begin(), right.end(), refs_.data() + r.begin + nl);
    out = shareRoom(Range{r.begin, r.begin + nl + nr, r.ext, {}, {}}, r.begin + nl, r.begin + nl + nr);
    bound(out.first);
    bound(out.second);
    return true;
  }

  std::uint32_t makeLeaf(const Range& r) {
    const auto it = leaves_.push_back({r.begin, r.size()});
    return kTempLeaf | static_cast<std::uint32_t>(it - leaves_.begin());
  }

  struct Child {
    Range range;
    Split split;
    bool leaf = false;
  };

  std::uint32_t buildNode(const Range& r, const Split& s, int depth) {
    std::array<Child, BvhNode8::kWidth> children;
    int count = 1;
    children[0] = {r, s, false};
    while (count < BvhNode8::kWidth) {
      int pick = -1;
      float pick_area = -1.0f;
      for (int i = 0; i < count; ++i) {
        if (children[i].leaf) continue;
        const float a = children[i].range.box.area();
        if (a > pick_area) {
          pick = i;
          pick_area = a;
        }
      }
      if (pick < 0) break;
      std::pair<Range, Range> sides;
      if (!partition(children[pick].range, children[pick].split, sides)) {
        // The spatial split did not separate the references: the object split instead.
        Child& ch = children[pick];
        ch.split = findSplit(ch.range, depth + 1, false);
        ch.leaf = wantsLeaf(ch.range, ch.split);
        continue;
      }
      // Named references, not a structured binding: lambdas may capture these (clang before 16
      // cannot capture bindings).
      const auto& lo = sides.first;
      const auto& hi = sides.second;
      Split ls, hs;
      if (c_.parallel_threshold > 0 && std::min(lo.size(), hi.size()) >= c_.parallel_threshold) {
        // The splits inside a large node are its subtrees' critical path: bin both sides at once.
        tbb::parallel_invoke([&] { ls = findSplit(lo, depth + 1); }, [&] { hs = findSplit(hi, depth + 1); });
      } else {
        ls = findSplit(lo, depth + 1);
        hs = findSplit(hi, depth + 1);
      }
      children[pick] = {lo, ls, wantsLeaf(lo, ls)};
      children[count++] = {hi, hs, wantsLeaf(hi, hs)};
    }
    BvhNode8 node;
    for (int k = 0; k < BvhNode8::kWidth; ++k) node.setChild(k, BvhRef::kEmpty, Box());
    std::array<std::uint32_t, BvhNode8::kWidth> refs{};
    tbb::task_group tasks;
    bool spawned = false;
    for (int i = 0; i < count; ++i) {
      const Child& ch = children[i];
      if (ch.leaf) {
        refs[i] = makeLeaf(ch.range);
      } else if (c_.parallel_threshold > 0 && ch.range.size() >= c_.parallel_threshold) {
        spawned = true;
        tasks.run([this, &refs, &ch, i, depth] { refs[i] = buildNode(ch.range, ch.split, depth + 1); });
      } else {
        refs[i] = buildNode(ch.range, ch.split, depth + 1);
      }
    }
    if (spawned) tasks.wait();
    for (int i = 0; i < count; ++i) node.setChild(i, refs[i], children[i].range.box);
    node.computeOrder();
    const auto it = nodes_.push_back(node);
    return static_cast<std::uint32_t>(it - nodes_.begin());
  }

  // Depth-first layout of the temporary tree into `out` (iterative: the depth is bounded but the
  // pass should not depend on the call stack).
  void layout(std::uint32_t temp_root, WideBvh& out) {
    out.nodes.reserve(nodes_.size());
    out.prim_indices.reserve(refs_.size() + 3 * leaves_.size());
    struct Pending {
      std::uint32_t temp;
      std::uint32_t parent;  // final index of the parent node, or kNone for the root
      int slot;
    };
    constexpr std::uint32_t kNone = 0xFFFFFFFFu;
    std::vector<Pending> stack{{temp_root, kNone, 0}};
    while (!stack.empty()) {
      const Pending p = stack.back();
      stack.pop_back();
      std::uint32_t ref;
      if (p.temp & kTempLeaf) {
        const auto [first, n] = leaves_[p.temp & ~kTempLeaf];
        const std::size_t block = out.prim_indices.size() / out.leaf_block;
        if (block > BvhRef::kMaxLeafBlock) throw InvalidArgument("BVH: more leaf blocks than a reference can address");
        for (std::uint32_t i = 0; i < n; ++i) out.prim_indices.push_back(refs_[first + i].prim);
        while (out.prim_indices.size() % out.leaf_block != 0) out.prim_indices.push_back(WideBvh::kPadding);
        ref = BvhRef::leaf(static_cast<std::uint32_t>(block), n);
      } else {
        if (out.nodes.size() >= BvhRef::kMaxNodes)
          throw InvalidArgument("BVH: more nodes than a reference can address");
        ref = static_cast<std::uint32_t>(out.nodes.size());
        out.nodes.push_back(nodes_[p.temp]);
        const BvhNode8& node = out.nodes.back();
        for (int k = BvhNode8::kWidth - 1; k >= 0; --k)
          if (node.child[k] != BvhRef::kEmpty) stack.push_back({node.child[k], ref, k});
      }
      if (p.parent == kNone) out.root = ref;
      else out.nodes[p.parent].child[p.slot] = ref;
    }
  }

  std::vector<Ref>& refs_;
  const BvhBuildConfig& c_;
  const BvhClipFunction& clip_;
  bool spatial_ = false;
  float min_overlap_ = 0.0f;
  tbb::concurrent_vector<BvhNode8> nodes_;
  tbb::concurrent_vector<std::pair<std::uint32_t, std::uint32_t>> leaves_;
};

}  // namespace

WideBvh buildWideBvh(std::span<const Box> prim_bounds, const BvhBuildConfig& config, const BvhClipFunction& clip) {
  config.validate();
  if (prim_bounds.size() > std::size_t{BvhRef::kMaxLeafBlock})
    throw InvalidArgument("BVH: " + std::to_string(prim_bounds.size()) + " primitives, more than the encoding holds (" +
                          std::to_string(BvhRef::kMaxLeafBlock) + ")");
  // The valid boxes as references, in input order: chunks counted, then filled, in parallel; the
  // chunks' bounds merged in order.
  const std::size_t count = prim_bounds.size();
  const std::size_t chunks = (count + kRefChunk - 1) / kRefChunk;
  std::vector<std::uint32_t> first(chunks + 1, 0u);
  std::vector<VBox> chunk_bounds(chunks), chunk_centroids(chunks);
  auto valid = [&](std::size_t i) { return !prim_bounds[i].empty() && prim_bounds[i].finite(); };
  auto forChunks = [&](const auto& body) {
    if (chunks <= 1 || config.parallel_threshold == 0) {
      for (std::size_t c = 0; c < chunks; ++c) body(c);
    } else {
      tbb::parallel_for(std::size_t{0}, chunks, body);
    }
  };
  forChunks([&](std::size_t c) {
    std::uint32_t n = 0;
    for (std::size_t i = c * kRefChunk, e = std::min(count, i + kRefChunk); i < e; ++i) n += valid(i) ? 1 : 0;
    first[c + 1] = n;
  });
  for (std::size_t c = 0; c < chunks; ++c) first[c + 1] += first[c];
  const std::uint32_t n = first[chunks];
  std::uint32_t room = 0;
  if (clip && config.spatial_split_alpha > 0.0f)
    room = static_cast<std::uint32_t>(
        std::min<double>(std::floor(double{config.spatial_split_budget} * n), double{BvhRef::kMaxLeafBlock} - n));
  std::vector<Ref> refs(std::size_t{n} + room);
  forChunks([&](std::size_t c) {
    Ref* out = refs.data() + first[c];
    VBox box, cent;
    for (std::size_t i = c * kRefChunk, e = std::min(count, i + kRefChunk); i < e; ++i) {
      if (!valid(i)) continue;
      *out = Ref::make(prim_bounds[i], static_cast<std::uint32_t>(i));
      box.extend(out->vlo(), out->vhi());
      cent.extendPoint(out->centroid2());
      ++out;
    }
    chunk_bounds[c] = box;
    chunk_centroids[c] = cent;
  });
  VBox bounds, centroids;
  for (std::size_t c = 0; c < chunks; ++c) {
    bounds.extend(chunk_bounds[c]);
    centroids.extend(chunk_centroids[c]);
  }
  Builder builder(refs, config, clip);
  return builder.run(Range{0, n, n + room, bounds.box(), centroids.box()});
}

namespace {

// What computeOrder and updateOrder both see of a node: twice each child's centre (in double, so
// that boxes up to float's range neither overflow nor tie by rounding) and the number of used slots.
struct NodeCentres {
  double centre[BvhNode8::kWidth][3];
  int used = 0;

  explicit NodeCentres(const BvhNode8& node) {
    for (int k = 0; k < BvhNode8::kWidth; ++k) {
      used += node.child[k] != BvhRef::kEmpty;
      for (int a = 0; a < 3; ++a) centre[k][a] = double{node.lo[a][k]} + double{node.hi[a][k]};
    }
  }
  // Slot k's coordinate along the diagonal of `octant` (0-3): the orders sort by it, descending.
  [[nodiscard]] double key(int k, int octant) const {
    double v = 0.0;
    for (int a = 0; a < 3; ++a) v += (octant >> a & 1) ? -centre[k][a] : centre[k][a];
    return v;
  }
};

// The packed orders from the slots of octants 0-3 by rank (`slot(octant, rank)`, empty slots
// first): octant o's opposite 7 - o projects the centres on the opposite diagonal, so it takes the
// used slots in reverse order (ties too), after the empty ones, which come first in every order.
template <class Slot>
void packOrders(std::uint32_t (&order)[BvhNode8::kWidth], int empty, const Slot& slot) {
  std::fill(std::begin(order), std::end(order), 0u);
  constexpr int kWidth = BvhNode8::kWidth;
  for (int octant = 0; octant < 4; ++octant) {
    for (int rank = 0; rank < kWidth; ++rank) {
      const auto k = static_cast<std::uint32_t>(slot(octant, rank));
      order[rank] |= k << (3 * octant);
      order[rank < empty ? rank : empty + kWidth - 1 - rank] |= k << (3 * (7 - octant));
    }
  }
}

}  // namespace

void BvhNode8::computeOrder() {
  const NodeCentres c(*this);
  // Per octant 0-3, descending key along the octant's diagonal, empty slots first (key +inf): an
  // insertion sort, stable (equal keys keep slot order); refits call this for nodes whose order
  // changed.
  int slots[4][kWidth];
  for (int octant = 0; octant < 4; ++octant) {
    double key[kWidth];
    int* slot = slots[octant];
    for (int k = 0; k < kWidth; ++k) {
      const double v = child[k] != BvhRef::kEmpty ? c.key(k, octant) : std::numeric_limits<double>::infinity();
      int i = k;
      for (; i > 0 && key[i - 1] < v; --i) {
        key[i] = key[i - 1];
        slot[i] = slot[i - 1];
      }
      key[i] = v;
      slot[i] = k;
    }
  }
  packOrders(order, kWidth - c.used, [&](int octant, int rank) { return slots[octant][rank]; });
}

void BvhNode8::updateOrder() {
  // The order stands when, for octants 0-3, the empty slots come first in slot order and the used
  // ones follow by strictly decreasing (key, -slot), which is the one order computeOrder's stable
  // sort gives. Octants 4-7 are then derived as computeOrder derives them.
  const NodeCentres c(*this);
  const int empty = kWidth - c.used;
  for (int octant = 0; octant < 4; ++octant) {
    double prev_key = 0.0;
    int prev_slot = 0;
    for (int rank = 0; rank < kWidth; ++rank) {
      const int k = orderedSlot(octant, rank);
      if (rank < empty) {
        if (k != c.used + rank) return computeOrder();
        continue;
      }
      if (k >= c.used) return computeOrder();
      const double v = c.key(k, octant);
      if (rank > empty && !(prev_key > v || (prev_key == v && prev_slot < k))) return computeOrder();
      prev_key = v;
      prev_slot = k;
    }
  }
  int slots[4][kWidth];
  for (int octant = 0; octant < 4; ++octant)
    for (int rank = 0; rank < kWidth; ++rank) slots[octant][rank] = orderedSlot(octant, rank);
  packOrders(order, empty, [&](int octant, int rank) { return slots[octant][rank]; });
}

bool BvhNode8::orderValid() const {
  for (int rank = 0; rank < kWidth; ++rank)
    if (order[rank] >> 24 != 0) return false;
  for (int octant = 0; octant < 8; ++octant) {
    unsigned seen = 0;
    for (int rank = 0; rank < kWidth; ++rank) seen |= 1u << orderedSlot(octant, rank);
    if (seen != 0xFFu) return false;
  }
  return true;
}

double WideBvh::sahCost(const BvhBuildConfig& config) const {
  if (root == BvhRef::kEmpty || bounds.empty()) return 0.0;
  // In double: float areas of boxes wider than about 1.8e19 overflow to inf (and inf / inf is NaN).
  auto area = [](const Box& b) {
    const glm::dvec3 e = glm::dvec3(b.hi) - glm::dvec3(b.lo);
    return 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
  };
  if (!(area(bounds) > 0.0)) return 0.0;
  const double inv_root = 1.0 / area(bounds);
  auto blocks = [&](std::uint32_t n) { return static_cast<double>((n + leaf_block - 1) / leaf_block); };
  if (BvhRef::isLeaf(root)) return config.intersection_cost * blocks(BvhRef::leafCount(root));
  double cost = config.traversal_cost;  // the root, entered by every ray that hits the bounds
  for (const BvhNode8& node : nodes) {
    for (int k = 0; k < BvhNode8::kWidth; ++k) {
      const std::uint32_t c = node.child[k];
      if (c == BvhRef::kEmpty) continue;
      const double p = area(node.childBox(k)) * inv_root;
      cost +=
          BvhRef::isLeaf(c) ? p * config.intersection_cost * blocks(BvhRef::leafCount(c)) : p * config.traversal_cost;
    }
  }
  return cost;
}

namespace detail {
void bvhParallelFor(int count, void* context, void (*fn)(void* context, int i)) {
  tbb::parallel_for(0, count, [&](int i) { fn(context, i); });
}
}  // namespace detail

void refitWideBvh(WideBvh& bvh, std::span<const Box> prim_bounds) {
  refitWideBvhWith(bvh, [&](std::uint32_t prim) {
    if (prim >= prim_bounds.size()) throw InvalidArgument("refitWideBvh: primitive index beyond the boxes given");
    return prim_bounds[prim];
  });
}

}  // namespace duplex
