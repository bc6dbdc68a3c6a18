#pragma once
/// \file KdTraversal.h
/// Front-to-back kd-tree traversal, shared by the bottom (triangles) and top (instances) levels.
/// The primitive test is a leaf callback, inlined through the template parameter: no virtual call
/// per node or primitive.

#include "duplex/accel/KdTree.h"
#include "duplex/accel/Ray.h"

#include <glm/vec3.hpp>

#include <emmintrin.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>

namespace duplex {

/// Per-ray values the traversal needs, computed once per ray and tree space.
/// Plain arrays rather than glm::vec3: the traversal indexes by a run-time axis, and GLM's
/// operator[] is a switch.
struct KdRay {
  float origin[3];  ///< ray origin, in the tree's space
  /// 1/dir with tiny or zero components replaced by +-inf of the same sign, so that +0 and -0
  /// directions classify as "never crosses" and a ray lying in a split plane visits both sides.
  float inv_dir[3];
  /// All bits set where the direction is negative (sign bit of inv_dir): swaps near and far child
  /// without a branch.
  std::uint32_t neg_mask[3];
  bool zero[3];  ///< axes along which the ray does not move (direction 0 or too small to invert)
  float tnear;   ///< start of the segment, in units of the ray's direction
  float tfar;    ///< end of the segment, in units of the ray's direction

  /// Uninitialised; for callers that compute the same values themselves (MeshObject's per-ray
  /// setup does it with SSE, together with the triangle test's constants).
  KdRay() = default;
  /// The values for ray `r`, given in the tree's space.
  explicit KdRay(const Ray& r) : origin{r.origin.x, r.origin.y, r.origin.z}, tnear(r.tnear), tfar(r.tfar) {
    const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
    for (int k = 0; k < 3; ++k) {
      const float inv = 1.0f / d[k];
      zero[k] = !std::isfinite(inv);  // |d| so small that 1/d overflows behaves like 0
      inv_dir[k] = zero[k] ? std::copysign(std::numeric_limits<float>::infinity(), d[k]) : inv;
      neg_mask[k] = std::signbit(inv_dir[k]) ? ~std::uint32_t{0} : 0u;
    }
  }
};

/// Clips the interval [tmin, tmax] (in and out) of the ray to `box`. Axes with zero direction only
/// test the origin against the slab (closed: a ray in a face plane is inside). Entry and exit are
/// widened by 6 ulp-style steps (Ize 2013) so that rounding never culls a hit on the box boundary.
/// Entry and exit per axis come from min / max rather than a compare and swap: the order is a coin
/// flip for random directions, and a branch on it mispredicts every other ray.
inline bool clipIntervalToBox(const KdRay& ray, const Box& box, float& tmin, float& tmax) {
  if (!(tmin <= tmax)) return false;
  constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
  const float lo[3] = {box.lo.x, box.lo.y, box.lo.z};
  const float hi[3] = {box.hi.x, box.hi.y, box.hi.z};
  for (int k = 0; k < 3; ++k) {
    if (ray.zero[k]) {
      if (ray.origin[k] < lo[k] || ray.origin[k] > hi[k]) return false;
      continue;
    }
    const float t0 = (lo[k] - ray.origin[k]) * ray.inv_dir[k];
    const float t1 = (hi[k] - ray.origin[k]) * ray.inv_dir[k];
    const float t_in = std::min(t0, t1), t_out = std::max(t0, t1);
    tmin = std::max(tmin, t_in - std::abs(t_in) * kWiden);
    tmax = std::min(tmax, t_out + std::abs(t_out) * kWiden);
  }
  return tmin <= tmax;
}

/// Clips the ray's [tnear, tfar] to `box` (see clipIntervalToBox).
inline bool clipRayToBox(const KdRay& ray, const Box& box, float& tmin, float& tmax) {
  tmin = ray.tnear;
  tmax = ray.tfar;
  return clipIntervalToBox(ray, box, tmin, tmax);
}

namespace kd_detail {
// isQueryable(ray) with one branch, from o = (origin, tnear) and d = (dir, tfar) as loaded from the
// ray: origin and direction finite (|x| < inf is false for NaN and inf), some direction component
// non-zero, tnear <= tfar.
[[gnu::always_inline]] inline bool queryableSse(__m128 o, __m128 d, const Ray& ray) {
  const __m128 sign_bit = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const int finite = _mm_movemask_ps(
      _mm_and_ps(_mm_cmplt_ps(_mm_andnot_ps(sign_bit, o), inf), _mm_cmplt_ps(_mm_andnot_ps(sign_bit, d), inf)));
  const int nonzero = _mm_movemask_ps(_mm_cmpneq_ps(d, _mm_setzero_ps()));
  return !(((finite & 7) != 7) | ((nonzero & 7) == 0) | !(ray.tnear <= ray.tfar));
}

// prepareKdRay, with the vectors it computed for callers that go on in registers: o = (origin,
// tnear), d = (dir, tfar), inv = 1 / dir (lane 3: 1 / tfar, unused), zero = KdRay::zero as bits.
[[gnu::always_inline]] inline bool prepareSse(const Ray& ray, KdRay& k, __m128& o, __m128& d, __m128& inv, int& zero) {
  static_assert(offsetof(KdRay, inv_dir) == 12 && offsetof(KdRay, neg_mask) == 24 && offsetof(KdRay, zero) == 36 &&
                    offsetof(KdRay, tnear) == 40,
                "KdRay's arrays are written with 16-byte stores, each overlapping the next field");
  // Ray is {ox, oy, oz, tnear, dx, dy, dz, tfar}: two unaligned loads.
  o = _mm_loadu_ps(&ray.origin.x);
  d = _mm_loadu_ps(&ray.dir.x);
  const __m128 sign_bit = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  if (!queryableSse(o, d, ray)) return false;
  // 1/d is already +-inf with the sign of d for a zero (or denormal) component, which is what
  // KdRay stores for them.
  inv = _mm_div_ps(_mm_set1_ps(1.0f), d);
  zero = _mm_movemask_ps(_mm_cmpeq_ps(_mm_andnot_ps(sign_bit, inv), inf)) & 7;
  // In field order, each 16-byte store's fourth lane is overwritten by the next store.
  _mm_storeu_ps(k.origin, o);
  _mm_storeu_ps(k.inv_dir, inv);
  _mm_storeu_si128(reinterpret_cast<__m128i*>(k.neg_mask), _mm_srai_epi32(_mm_castps_si128(inv), 31));
  k.zero[0] = (zero & 1) != 0;
  k.zero[1] = (zero & 2) != 0;
  k.zero[2] = (zero & 4) != 0;
  k.tnear = ray.tnear;
  k.tfar = ray.tfar;
  return true;
}
}  // namespace kd_detail

/// Fills `k` with the values KdRay(ray) holds, computed with SSE in one pass (one vector division
/// instead of three scalar ones, one branch for the validity checks): returns false, leaving `k`
/// unspecified, when the ray is not queryable (isQueryable in Ray.h). `ray` and `k` are in the same
/// space (the tree's). The top level and the mesh queries both set their rays up this way.
[[gnu::always_inline]] inline bool prepareKdRay(const Ray& ray, KdRay& k) {
  __m128 o, d, inv;
  int zero;
  return kd_detail::prepareSse(ray, k, o, d, inv, zero);
}

namespace kd_detail {
// The clip of clipPreparedRay from vectors: o = (origin, tnear), d = (dir, tfar), inv = 1 / dir
// (lane 3 unused), the box's lo and hi in lanes 0..2 (lane 3 unused).
[[gnu::always_inline]] inline bool clipSse(__m128 o, __m128 d, __m128 inv, __m128 lo, __m128 hi, float& tmin,
                                           float& tmax) {
  const __m128 sign_bit = _mm_set1_ps(-0.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128 zero_dir = _mm_cmpeq_ps(_mm_andnot_ps(sign_bit, inv), inf);
  // clipIntervalToBox's rules: per axis the entry and exit are widened, and a widened value that is
  // NaN (an infinite distance) is ignored, as std::max / std::min ignore it there; SSE's max / min
  // return their second operand when either is NaN. An axis with zero direction only tests the
  // origin against the closed slab.
  const __m128 outside = _mm_or_ps(_mm_cmplt_ps(o, lo), _mm_cmpgt_ps(o, hi));
  if ((_mm_movemask_ps(_mm_and_ps(zero_dir, outside)) & 7) != 0) return false;
  const __m128 t0 = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
  const __m128 t1 = _mm_mul_ps(_mm_sub_ps(hi, o), inv);
  // std::min(t0, t1) is t1 < t0 ? t1 : t0, as _mm_min_ps(t1, t0).
  const __m128 t_in = _mm_min_ps(t1, t0);
  const __m128 t_out = _mm_max_ps(t1, t0);
  constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
  const __m128 widen = _mm_set1_ps(kWiden);
  __m128 w_in = _mm_sub_ps(t_in, _mm_mul_ps(_mm_andnot_ps(sign_bit, t_in), widen));
  __m128 w_out = _mm_add_ps(t_out, _mm_mul_ps(_mm_andnot_ps(sign_bit, t_out), widen));
  // Zero-direction lanes do not limit the interval (-inf / +inf are neutral below).
  w_in = _mm_or_ps(_mm_and_ps(zero_dir, _mm_xor_ps(inf, sign_bit)), _mm_andnot_ps(zero_dir, w_in));
  w_out = _mm_or_ps(_mm_and_ps(zero_dir, inf), _mm_andnot_ps(zero_dir, w_out));
  // max(tnear, w) per lane (a NaN w gives tnear), then the largest of lanes 0..2; min likewise.
  const __m128 m_in = _mm_max_ps(w_in, _mm_shuffle_ps(o, o, _MM_SHUFFLE(3, 3, 3, 3)));
  const __m128 m_out = _mm_min_ps(w_out, _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 3, 3, 3)));
  tmin = _mm_cvtss_f32(_mm_max_ss(_mm_max_ss(m_in, _mm_shuffle_ps(m_in, m_in, 1)), _mm_movehl_ps(m_in, m_in)));
  tmax = _mm_cvtss_f32(_mm_min_ss(_mm_min_ss(m_out, _mm_shuffle_ps(m_out, m_out, 1)), _mm_movehl_ps(m_out, m_out)));
  return tmin <= tmax;
}

// A box's corners as vectors (lane 3 unused): Box is {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z}, and
// loads at lo.x and lo.z stay inside it.
[[gnu::always_inline]] inline __m128 boxLo(const Box& box) { return _mm_loadu_ps(&box.lo.x); }
[[gnu::always_inline]] inline __m128 boxHi(const Box& box) {
  const __m128 b = _mm_loadu_ps(&box.lo.z);
  return _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 3, 2, 1));
}
}  // namespace kd_detail

/// clipRayToBox(k, box, tmin, tmax) for a ray `k` that prepareKdRay filled from `ray`, the three
/// slabs at once with SSE: the same interval (only the sign of a zero bound may differ, which no
/// comparison sees) and the same answer.
[[gnu::always_inline]] inline bool clipPreparedRay(const Ray& ray, const KdRay& k, const Box& box, float& tmin,
                                                   float& tmax) {
  return kd_detail::clipSse(_mm_loadu_ps(&ray.origin.x), _mm_loadu_ps(&ray.dir.x),
                            _mm_setr_ps(k.inv_dir[0], k.inv_dir[1], k.inv_dir[2], 0.0f), kd_detail::boxLo(box),
                            kd_detail::boxHi(box), tmin, tmax);
}

/// A leaf without primitives (not a jump: a jump's count field is all ones).
inline bool isEmptyLeaf(const KdNode& node) { return node.isEmptyLeaf(); }

/// Relative slack in t when deciding whether a ray meets a child cell (see traverseKdTree).
inline constexpr float kKdPlaneSlack = 8.0f * std::numeric_limits<float>::epsilon();

/// Maximal stack depth; the builder bounds the depth well below it.
inline constexpr int kKdStackSize = 64;

/// Visits the leaves pierced by the ray front to back and calls
///   bool leaf(std::uint32_t prim_begin, std::uint32_t prim_count, float& t_best)
/// where [prim_begin, prim_begin + prim_count) indexes tree.prim_indices (or any array laid out in
/// the same order). The callback tests its primitives against [ray.tnear, t_best] and lowers
/// t_best on a closer hit; it returns true when it found a hit. With AnyHit the traversal returns
/// at the first such leaf. Returns whether any leaf reported a hit. `t_best` starts at ray.tfar.
///
/// A leaf's primitives are tested over the whole ray, not only the leaf's interval; traversal
/// ends when the next node starts behind t_best. That is what keeps hits on split planes and
/// straddling primitives exact.
template <bool AnyHit, class LeafFn>
inline bool traverseKdTree(const KdTree& tree, const KdRay& ray, float& t_best, LeafFn&& leaf);

/// traverseKdTree for a ray already clipped to tree.bounds: [tmin, tmax] is what clipRayToBox
/// returned for it (tmin <= tmax).
template <bool AnyHit, class LeafFn>
inline bool traverseKdTreeClipped(const KdTree& tree, const KdRay& ray, float tmin, float tmax, float& t_best,
                                  LeafFn&& leaf) {
  if (tree.nodes.empty()) return false;

  // The current cell's interval [lo, hi] is kept widened by the slack: closed intervals with a few
  // ulps of slack, because a ray through a vertex that lies on split planes touches the cells
  // meeting there at a single point, and the t of two planes at that point differ by rounding.
  // Skipping such a cell can skip every triangle around the vertex, so a child is dropped only
  // when the plane is clearly outside the interval. Widening is monotonic, so a bound cut at a
  // plane is simply the widened plane distance (no exact copy of the interval is needed).
  auto widen_up = [](float t) { return t + std::abs(t) * kKdPlaneSlack; };
  auto widen_down = [](float t) { return t - std::abs(t) * kKdPlaneSlack; };
  struct Entry {
    std::uint32_t node;
    float lo, hi;
  };
  Entry stack[kKdStackSize];
  int top = 0;
  const KdNode* nodes = tree.nodes.data();
  std::uint32_t index = 0;
  bool found = false;
  float lo = widen_down(tmin), hi = widen_up(tmax);

  while (true) {
    const KdNode node = nodes[index];
    if (!node.isLeaf()) {
      const int axis = node.axis();
      const float t_plane = (node.split() - ray.origin[axis]) * ray.inv_dir[axis];
      // The near child is the one the ray is in before it crosses the plane; with a zero
      // direction the infinite inverse makes t_plane +-inf (or NaN on the plane: every comparison
      // below is false, and min / max keep the full interval: both children).
      // Branch free: a negative direction swaps the children by xor.
      const std::uint32_t lower = index + 1;
      const std::uint32_t upper = node.upperChild();
      const std::uint32_t swap = (lower ^ upper) & ray.neg_mask[axis];
      const std::uint32_t near_child = lower ^ swap;
      if (t_plane > hi) {
        index = near_child;
      } else if (t_plane < lo) {
        index = upper ^ swap;  // the far child
      } else {
        // Both. An empty leaf child (most leaves a random ray meets are empty) is dropped here
        // rather than pushed, popped and visited: the lower child is usually in the same cache
        // line, and the upper one is needed soon anyway.
        const std::uint32_t far_child = upper ^ swap;
        const float far_lo = std::max(lo, widen_down(t_plane));
        if (isEmptyLeaf(nodes[far_child])) {
          index = near_child;
          hi = std::min(hi, widen_up(t_plane));
        } else if (isEmptyLeaf(nodes[near_child])) {
          if (far_lo > t_best) goto pop;
          index = far_child;
          lo = far_lo;
        } else {
          stack[top++] = {far_child, far_lo, hi};
          index = near_child;
          hi = std::min(hi, widen_up(t_plane));
        }
      }
      continue;
    }

    if (node.isJump()) {  // incrementally updated trees only: same cell, same interval
      index = node.jumpTarget();
      continue;
    }
    if (node.primCount() != 0 && leaf(node.primOffset(), node.primCount(), t_best)) {
      found = true;
      if constexpr (AnyHit) return true;
    }
  pop:
    // The next node that can still hold a closer hit.
    do {
      if (top == 0) return found;
      --top;
      index = stack[top].node;
      lo = stack[top].lo;
      hi = stack[top].hi;
    } while (lo > t_best);
  }
}

template <bool AnyHit, class LeafFn>
inline bool traverseKdTree(const KdTree& tree, const KdRay& ray, float& t_best, LeafFn&& leaf) {
  float tmin, tmax;
  if (tree.nodes.empty() || !clipRayToBox(ray, tree.bounds, tmin, tmax)) return false;
  return traverseKdTreeClipped<AnyHit>(tree, ray, tmin, tmax, t_best, std::forward<LeafFn>(leaf));
}

}  // namespace duplex
