#pragma once
// Front-to-back traversal of a KdWideTree (two binary levels per step, SSE2). Private to the
// objects library: MeshObject's closest-hit and any-hit queries use it.
//
// It visits the cells of the binary tree with the binary traversal's intervals (KdTraversal.h): the
// three plane distances of a node are computed together, the four child intervals with min / max
// of the widened distances (no branch per child), and the children the ray meets are pushed far to
// near, so the nearest is popped next. Exactness rules, as in the binary traversal:
// - a zero direction component has 1/dir = +-inf: the ray never crosses that axis' planes; a ray
//   in a plane gets a NaN distance, which min / max ignore (SSE's min / max return their second
//   operand when the first is NaN), so both sides keep the full interval;
// - bounds are widened by kKdPlaneSlack, exactly as the binary traversal widens them;
// - leaves are tested over [tnear, t_best]; a child whose interval starts behind t_best is not
//   pushed, and a popped one is dropped.
// A child is visited when its (widened) interval is not empty: where the binary traversal decides
// by the unwidened plane distance this may visit a cell the binary one skips, never the reverse.

#include "KdWideTree.h"

#include "duplex/accel/KdTraversal.h"

#include <emmintrin.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex::detail {

/// Stack entries: a wide node pushes at most three children besides the one it continues with, and
/// the binary depth (at most kKdStackSize - 1) halves; a push writes one entry past what it keeps.
inline constexpr int kKdWideStackSize = 3 * (kKdStackSize / 2 + 1) + 1;

/// Front-to-back order of the four children for the sign bits of 1/dir on a node's three axes (bit k
/// set: plane k's axis has a negative direction): the memory index of the child of rank r (0 the
/// nearest) in bits 2r, 2r + 1. The near half of plane 0 first, within each half its near quarter.
inline constexpr std::uint8_t kdWideOrder(unsigned signs) {
  const unsigned n0 = signs & 1u, n1 = signs >> 1 & 1u, n2 = signs >> 2 & 1u;
  const unsigned first = 2 * n0 + (n0 != 0 ? n2 : n1);
  const unsigned third = 2 * (1 - n0) + (n0 != 0 ? n1 : n2);
  return static_cast<std::uint8_t>(first | (first ^ 1u) << 2 | third << 4 | (third ^ 1u) << 6);
}

/// kdWideOrder for the 8 sign patterns, and a node's mask of non-empty children (bit = memory index)
/// permuted to rank order, for each sign pattern and mask.
struct KdWideOrderTable {
  std::uint8_t order[8];
  std::uint8_t rank_mask[8][16];
  constexpr KdWideOrderTable() : order{}, rank_mask{} {
    for (unsigned s = 0; s < 8; ++s) {
      order[s] = kdWideOrder(s);
      for (unsigned m = 0; m < 16; ++m) {
        unsigned r_mask = 0;
        for (unsigned r = 0; r < 4; ++r) r_mask |= (m >> (order[s] >> (2 * r) & 3u) & 1u) << r;
        rank_mask[s][m] = static_cast<std::uint8_t>(r_mask);
      }
    }
  }
};
inline constexpr KdWideOrderTable kKdWideOrder{};
// Signs 011 (plane 0 and the lower half's plane negative): children 2, 3, 1, 0 front to back.
static_assert(kKdWideOrder.order[3] == (2 | 3 << 2 | 1 << 4 | 0 << 6) && kKdWideOrder.rank_mask[3][0b0010] == 0b0100);

/// Visits the non-empty leaves of `tree` pierced by the ray front to back and calls
///   bool leaf(std::uint32_t first_block, std::uint32_t blocks, float& t_best)
/// which tests the leaf's blocks over [ray.tnear, t_best], lowers t_best on a closer hit and returns
/// whether it found one. With AnyHit the traversal returns at the first such leaf. Returns whether
/// any leaf reported a hit. `t_best` starts at the caller's limit (at most ray.tfar).
template <bool AnyHit, class LeafFn>
inline bool traverseKdWideTree(const KdWideTree& tree, const KdRay& ray, float& t_best, LeafFn&& leaf) {
  if (tree.root_word == KdWideTree::kEmptyRoot) return false;
  float tmin, tmax;
  if (!clipRayToBox(ray, tree.bounds, tmin, tmax)) return false;

  // Ray values by axis, (origin, 1/dir) in the low lanes, so that each of a node's three axes picks
  // them with one load.
  __m128 origin_inv[3];
  for (int k = 0; k < 3; ++k) origin_inv[k] = _mm_setr_ps(ray.origin[k], ray.inv_dir[k], 0.0f, 0.0f);
  const char* origin_inv_bytes = reinterpret_cast<const char*>(origin_inv);
  struct Entry {
    std::uint32_t word;
    float lo, hi;  // the widened interval of the ray in the child's cell
  };
  Entry stack[kKdWideStackSize];
  Entry* sp = stack;
  const KdWideNode* nodes = tree.nodes.data();
  bool found = false;
  std::uint32_t word = tree.root_word;
  float lo = tmin - std::abs(tmin) * kKdPlaneSlack, hi = tmax + std::abs(tmax) * kKdPlaneSlack;

  static_assert(kKdPlaneSlack == 8.0f * std::numeric_limits<float>::epsilon(), "a power of two: |t| s is exact");
  const __m128 one_plus = _mm_set1_ps(1.0f + kKdPlaneSlack), one_minus = _mm_set1_ps(1.0f - kKdPlaneSlack);
  // Child lanes in rank order: 0, 1 in the near half of plane 0, 2, 3 in the far half; 0, 2 the near
  // quarters of their half. A bound that does not apply to a lane is made NaN (all bits set), which
  // max / min below ignore, just as they ignore the NaN distance of a ray lying in a plane.
  const __m128 not_entered0 = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, 0, 0));  // near half
  const __m128 not_left0 = _mm_castsi128_ps(_mm_setr_epi32(0, 0, -1, -1));     // far half
  const __m128 not_entered1 = _mm_castsi128_ps(_mm_setr_epi32(-1, 0, -1, 0));  // near quarters
  const __m128 not_left1 = _mm_castsi128_ps(_mm_setr_epi32(0, -1, 0, -1));     // far quarters

  while (true) {
    if (!(word & KdWideNode::kLeafBit)) {
      const KdWideNode& node = nodes[word];
      // Distances to the three planes (lane 3 is unused).
      const __m128 oi0 = *reinterpret_cast<const __m128*>(origin_inv_bytes + node.axis16[0]);
      const __m128 oi1 = *reinterpret_cast<const __m128*>(origin_inv_bytes + node.axis16[1]);
      const __m128 oi2 = *reinterpret_cast<const __m128*>(origin_inv_bytes + node.axis16[2]);
      const __m128 oi01 = _mm_unpacklo_ps(oi0, oi1);  // o0, o1, inv0, inv1
      const __m128 o = _mm_shuffle_ps(oi01, oi2, _MM_SHUFFLE(1, 0, 1, 0));
      const __m128 inv = _mm_shuffle_ps(oi01, oi2, _MM_SHUFFLE(1, 1, 3, 2));
      const __m128 d = _mm_sub_ps(_mm_load_ps(node.plane), o);
      const __m128 t = _mm_mul_ps(d, inv);
      // t + |t| s and t - |t| s as one multiply each: |t| s is exact (s is a power of two), so both
      // forms round the same exact value t (1 +- s) once, as the binary traversal's widen_up/_down.
      // The sign of t is that of d * inv, known before the product (t = +-0 or NaN: either factor).
      const __m128 t_negative = _mm_castsi128_ps(_mm_srai_epi32(_mm_castps_si128(_mm_xor_ps(d, inv)), 31));
      const __m128 t_up = _mm_mul_ps(t, _mm_or_ps(_mm_and_ps(t_negative, one_minus), _mm_andnot_ps(t_negative, one_plus)));
      const __m128 t_down = _mm_mul_ps(t, _mm_or_ps(_mm_and_ps(t_negative, one_plus), _mm_andnot_ps(t_negative, one_minus)));
      // All ones where the plane's axis has a negative direction: then the near half of plane 0 is
      // its upper half, whose plane is plane 2.
      const __m128 neg = _mm_castsi128_ps(_mm_srai_epi32(_mm_castps_si128(inv), 31));
      const unsigned signs = static_cast<unsigned>(_mm_movemask_ps(neg)) & 7u;
      const __m128 neg0 = _mm_shuffle_ps(neg, neg, _MM_SHUFFLE(0, 0, 0, 0));
      const __m128 sub_up = _mm_or_ps(_mm_and_ps(neg0, _mm_shuffle_ps(t_up, t_up, _MM_SHUFFLE(1, 1, 2, 2))),
                                      _mm_andnot_ps(neg0, _mm_shuffle_ps(t_up, t_up, _MM_SHUFFLE(2, 2, 1, 1))));
      const __m128 sub_down = _mm_or_ps(_mm_and_ps(neg0, _mm_shuffle_ps(t_down, t_down, _MM_SHUFFLE(1, 1, 2, 2))),
                                        _mm_andnot_ps(neg0, _mm_shuffle_ps(t_down, t_down, _MM_SHUFFLE(2, 2, 1, 1))));
      const __m128 in0 = _mm_or_ps(_mm_shuffle_ps(t_down, t_down, _MM_SHUFFLE(0, 0, 0, 0)), not_entered0);
      const __m128 out0 = _mm_or_ps(_mm_shuffle_ps(t_up, t_up, _MM_SHUFFLE(0, 0, 0, 0)), not_left0);
      const __m128 in1 = _mm_or_ps(sub_down, not_entered1);
      const __m128 out1 = _mm_or_ps(sub_up, not_left1);
      // SSE's max / min return the second operand when the first is NaN: the plane bounds go first.
      const __m128 lo4 = _mm_max_ps(in1, _mm_max_ps(in0, _mm_set1_ps(lo)));
      const __m128 hi4 = _mm_min_ps(out1, _mm_min_ps(out0, _mm_set1_ps(hi)));
      const __m128 met = _mm_and_ps(_mm_cmple_ps(lo4, hi4), _mm_cmple_ps(lo4, _mm_set1_ps(t_best)));
      const unsigned visit = static_cast<unsigned>(_mm_movemask_ps(met)) & kKdWideOrder.rank_mask[signs][node.child_mask];
      if (visit != 0) {
        alignas(16) float lo_r[4], hi_r[4];
        _mm_store_ps(lo_r, lo4);
        _mm_store_ps(hi_r, hi4);
        const unsigned order = kKdWideOrder.order[signs];
        // The others met, farthest first (every slot is written, only those met are kept), so that
        // nearer ones are popped first; the step continues with the nearest.
        const unsigned others = visit & (visit - 1);
        for (unsigned r = 3; r >= 1; --r) {
          *sp = {node.child[order >> (2 * r) & 3u], lo_r[r], hi_r[r]};
          sp += others >> r & 1u;
        }
        const auto r = static_cast<unsigned>(std::countr_zero(visit));
        word = node.child[order >> (2 * r) & 3u];
        lo = lo_r[r];
        hi = hi_r[r];
        continue;
      }
    } else {
      std::uint32_t first = word & KdWideNode::kOffsetMask;
      std::uint32_t blocks = word >> KdWideNode::kOffsetBits & KdWideNode::kMaxCount;
      if (blocks == 0) [[unlikely]] {
        const auto& big = tree.big_leaves[first];
        first = big.first;
        blocks = big.second;
      }
      if (leaf(first, blocks, t_best)) {
        found = true;
        if constexpr (AnyHit) return true;
      }
    }
    // The next node that can still hold a closer hit.
    do {
      if (sp == stack) return found;
      --sp;
      word = sp->word;
      lo = sp->lo;
      hi = sp->hi;
    } while (lo > t_best);
  }
}

}  // namespace duplex::detail
