#pragma once
// Private to accel/src: the exact event sweeps of the kd-tree build (after Wald & Havran). A
// node's events are the bounds of its references (clipped to the node) on one axis; a sweep over
// them finds the plane of least SAH cost. By node size:
//  - the faces of a single reference (KdTreeBuilder.cpp, findSahSplit);
//  - sweepSmall: up to kSmallSweep references without planar ones, every candidate on SSE lanes;
//  - sweepSorted: the merge of sorted start, end and planar lists (small nodes and windows);
//  - sweepEvents: the events of a window around a binned plane (the refinement), collected and
//    sorted first, in parallel chunks for a large node (KdEventSweep.cpp).
// The small-node sweeps are defined here, so that the split search inlines them.

#include "KdBuildRefs.h"
#include "KdSah.h"
#include "RadixSortFloats.h"

#include <emmintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>

namespace duplex::kd_detail {

// From this many events a radix sort beats std::sort.
constexpr std::size_t kRadixSortMin = 32;

// Sorts a few events in place: an inline insertion sort, where std::sort's calls and checks cost
// more than the sorting of 1-8 values (the top level sorts nine such lists per node).
inline void sortFew(float* v, std::size_t n) {
  for (std::size_t i = 1; i < n; ++i) {
    const float x = v[i];
    std::size_t j = i;
    for (; j > 0 && x < v[j - 1]; --j) v[j] = v[j - 1];
    v[j] = x;
  }
}

// Sorts events: few inline, many by radix.
inline void sortEvents(float* v, std::size_t n) {
  if (n <= 16) sortFew(v, n);
  else if (n < kRadixSortMin) std::sort(v, v + n);
  else radixSortFloats(v, n);
}

// The sorted events (clipped bounds) of every axis of a small node's references, for the full sweep
// of nodes up to KdBuildConfig::exact_sweep_max references. An empty-space cut moves no reference
// and lies at their extent, so the events stay those of the node inside the cut: a chain of cuts
// (the many tiny nodes of a top level) sorts them once.
struct SmallEvents {
  static constexpr std::size_t kMax = 32;
  bool valid = false;
  // Per axis: whether the lists are sorted. sweepSmall needs no order (ties go to the lowest plane
  // explicitly), so the lists are sorted only for an axis that sweepSorted merges: most nodes of a
  // top level (1-8 boxes, no planar one) never sort, where sorting nine lists per node was a
  // visible part of paper-2's top-level build.
  bool sorted[3] = {false, false, false};
  std::uint8_t n_starts[3], n_ends[3], n_planars[3];
  float starts[3][kMax], ends[3][kMax], planars[3][kMax];
};

// The exact sweep of a node of at most kSmallSweep references with no planar one on `axis`,
// without the merge's branches: every start and end is a candidate plane, its counts below and
// above are compares against all events (SSE, four candidates at a time), its cost splitCost4's.
// The least cost wins, on ties the lowest plane: what the merge in order (sweepSorted) picks,
// since a plane listed twice has the same counts and cost both times.
inline constexpr std::size_t kSmallSweep = 8;
inline Split sweepSmall(const SahCost& sah, const NodeGeometry& g, int axis, const SmallEvents& e, std::size_t n) {
  const float* starts = e.starts[axis];  // padded to kSmallSweep with +inf
  const float* ends = e.ends[axis];      // padded with -inf
  const __m128 lo = _mm_set1_ps(g.lo[axis]), hi = _mm_set1_ps(g.hi[axis]);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  __m128 best_cost = inf, best_pos = inf;
  __m128i best_lower = _mm_setzero_si128(), best_upper = _mm_setzero_si128();
  const std::size_t quads = (n + 3) / 4;
  for (std::size_t q = 0; q < 2 * quads; ++q) {
    const __m128 p = _mm_loadu_ps(q < quads ? starts + 4 * q : ends + 4 * (q - quads));
    // lo < p below, hi > p above; compare masks are -1, so subtracting counts.
    __m128i nl = _mm_setzero_si128(), nu = _mm_setzero_si128();
    for (std::size_t j = 0; j < n; ++j) {
      nl = _mm_sub_epi32(nl, _mm_castps_si128(_mm_cmplt_ps(_mm_set1_ps(starts[j]), p)));
      nu = _mm_sub_epi32(nu, _mm_castps_si128(_mm_cmpgt_ps(_mm_set1_ps(ends[j]), p)));
    }
    const __m128 c = sah.splitCost4(g, axis, p, nl, nu);
    // Planes strictly inside the node (the padding is not); a NaN cost never wins.
    const __m128 keep = _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(p, lo), _mm_cmplt_ps(p, hi)), _mm_cmpord_ps(c, c));
    const __m128 take = _mm_and_ps(
        keep, _mm_or_ps(_mm_cmplt_ps(c, best_cost), _mm_and_ps(_mm_cmpeq_ps(c, best_cost), _mm_cmplt_ps(p, best_pos))));
    const __m128i take_i = _mm_castps_si128(take);
    best_cost = _mm_or_ps(_mm_and_ps(take, c), _mm_andnot_ps(take, best_cost));
    best_pos = _mm_or_ps(_mm_and_ps(take, p), _mm_andnot_ps(take, best_pos));
    best_lower = _mm_or_si128(_mm_and_si128(take_i, nl), _mm_andnot_si128(take_i, best_lower));
    best_upper = _mm_or_si128(_mm_and_si128(take_i, nu), _mm_andnot_si128(take_i, best_upper));
  }
  alignas(16) float cost[4], pos[4];
  alignas(16) std::int32_t lower[4], upper[4];
  _mm_store_ps(cost, best_cost);
  _mm_store_ps(pos, best_pos);
  _mm_store_si128(reinterpret_cast<__m128i*>(lower), best_lower);
  _mm_store_si128(reinterpret_cast<__m128i*>(upper), best_upper);
  Split best;
  for (int k = 0; k < 4; ++k)
    if (cost[k] < best.cost ||
        (cost[k] == best.cost && cost[k] < std::numeric_limits<float>::infinity() && pos[k] < best.pos))
      best = {axis, pos[k], cost[k], true, static_cast<std::size_t>(lower[k]), static_cast<std::size_t>(upper[k]),
              true};
  return best;
}

// Sorts one axis' lists of a small node's events, once.
inline void sortSmallEvents(SmallEvents& e, int axis) {
  if (e.sorted[axis]) return;
  sortFew(e.starts[axis], e.n_starts[axis]);
  sortFew(e.ends[axis], e.n_ends[axis]);
  sortFew(e.planars[axis], e.n_planars[axis]);
  e.sorted[axis] = true;
}

// The events of every axis of a small node (every event lies in the node: references are clipped
// to it), in reference order (sortSmallEvents sorts an axis when it is merged).
inline void collectSmallEvents(const RefVec& refs, SmallEvents& e) {
  for (int axis = 0; axis < 3; ++axis) {
    std::uint8_t n_planars = 0;
    std::size_t k = 0;
    for (const PrimRef& r : refs) {
      e.starts[axis][k] = r.lo[axis];
      e.ends[axis][k] = r.hi[axis];
      ++k;
      if (r.lo[axis] == r.hi[axis]) e.planars[axis][n_planars++] = r.lo[axis];
    }
    e.n_starts[axis] = e.n_ends[axis] = static_cast<std::uint8_t>(refs.size());
    e.n_planars[axis] = n_planars;
    e.sorted[axis] = false;
    // Padding that no plane counts: sweepSmall reads kSmallSweep events.
    for (std::size_t j = refs.size(); j < kSmallSweep; ++j) {
      e.starts[axis][j] = std::numeric_limits<float>::infinity();
      e.ends[axis][j] = -std::numeric_limits<float>::infinity();
    }
  }
  e.valid = true;
}

// The sweep over sorted events of `axis` (starts: lower bounds, ends: upper bounds, planars: both)
// inside a window, with `below_window` references starting and `above_window` ending outside it.
Split sweepSorted(const SahCost& sah, const NodeGeometry& g, int axis, const float* starts, std::size_t n_starts,
                  const float* ends, std::size_t n_ends, const float* planars, std::size_t n_planars,
                  std::size_t below_window, std::size_t above_window);

// Exact SAH over the events (clipped bounds) of `axis` that lie in [win_lo, win_hi], after
// Wald & Havran: a primitive counts below a plane p if its lower bound is < p, above if its
// upper bound is > p; a primitive lying in p goes to the cheaper side. `parallel`: a large node
// collects its events in parallel chunks (the same result).
Split sweepEvents(const SahCost& sah, const RefVec& refs, const NodeGeometry& g, int axis, float win_lo, float win_hi,
                  bool parallel);

}  // namespace duplex::kd_detail
