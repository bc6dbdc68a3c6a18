// The exact event sweeps of the kd-tree build over many events (see KdEventSweep.h).

#include "KdEventSweep.h"

#include "duplex/accel/Check.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <emmintrin.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace duplex::kd_detail {

namespace {

// Set bits of a 4-bit mask (SSE2 has no population count).
constexpr std::uint8_t kBitCount4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

// What collectWindow found: events stored, and references starting below (lo < win_lo) and
// ending above (hi > win_hi) the window.
struct WindowEvents {
  std::size_t n_starts = 0, n_ends = 0, n_planars = 0, below = 0, above = 0;
};

// The events of references [first, last) on `axis` inside [win_lo, win_hi]: lower bounds to
// `starts`, upper bounds to `ends`, bounds of references lying in a plane to `planars`, each in
// reference order (each array has room for last - first values).
WindowEvents collectWindow(const PrimRef* first, const PrimRef* last, int axis, float win_lo, float win_hi,
                           float* starts, float* ends, float* planars) {
  std::size_t n_starts = 0, n_ends = 0, n_planars = 0;
  std::size_t below_window = 0, above_window = 0;
  // Without branches: whether a bound falls into the window is a coin flip per reference, and
  // mispredicted branches here cost more than the stores (every slot written lies below n). Four
  // references at a time: the six comparisons of each are SSE compares and bit masks; only the
  // compaction stores stay scalar (the same events, in the same order, as one at a time).
  const __m128 lo4 = _mm_set1_ps(win_lo), hi4 = _mm_set1_ps(win_hi);
  const PrimRef* r = first;
  const PrimRef* const end4 = r + (static_cast<std::size_t>(last - first) & ~std::size_t{3});
  for (; r != end4; r += 4) {
    const float a[4] = {r[0].lo[axis], r[1].lo[axis], r[2].lo[axis], r[3].lo[axis]};
    const float b[4] = {r[0].hi[axis], r[1].hi[axis], r[2].hi[axis], r[3].hi[axis]};
    const __m128 va = _mm_loadu_ps(a), vb = _mm_loadu_ps(b);
    const auto a_in = static_cast<unsigned>(_mm_movemask_ps(_mm_and_ps(_mm_cmpge_ps(va, lo4), _mm_cmple_ps(va, hi4))));
    const auto b_in = static_cast<unsigned>(_mm_movemask_ps(_mm_and_ps(_mm_cmpge_ps(vb, lo4), _mm_cmple_ps(vb, hi4))));
    const unsigned planar = a_in & static_cast<unsigned>(_mm_movemask_ps(_mm_cmpeq_ps(va, vb)));
    below_window += kBitCount4[_mm_movemask_ps(_mm_cmplt_ps(va, lo4))];
    above_window += kBitCount4[_mm_movemask_ps(_mm_cmpgt_ps(vb, hi4))];
    for (unsigned k = 0; k < 4; ++k) {
      starts[n_starts] = a[k];
      n_starts += (a_in >> k) & 1u;
      ends[n_ends] = b[k];
      n_ends += (b_in >> k) & 1u;
    }
    // References lying in a plane of the axis are rare in most meshes, so this branch is
    // predictable where the stores it skips would be wasted.
    if (planar != 0) {
      for (unsigned k = 0; k < 4; ++k) {
        planars[n_planars] = a[k];
        n_planars += (planar >> k) & 1u;
      }
    }
  }
  for (; r != last; ++r) {
    const float a = r->lo[axis], b = r->hi[axis];
    const bool a_in = (a >= win_lo) & (a <= win_hi);
    below_window += a < win_lo;
    starts[n_starts] = a;
    n_starts += a_in;
    above_window += b > win_hi;
    ends[n_ends] = b;
    n_ends += (b >= win_lo) & (b <= win_hi);
    planars[n_planars] = a;
    n_planars += a_in & (a == b);
  }
  return {n_starts, n_ends, n_planars, below_window, above_window};
}

// sweepEvents of a large node: the events collected in parallel chunks, concatenated in chunk
// order (the serial pass's lists exactly), the start and end lists sorted side by side.
Split sweepEventsChunked(const SahCost& sah, const RefVec& refs, const NodeGeometry& g, int axis, float win_lo,
                         float win_hi, bool parallel) {
  const std::size_t n = refs.size(), chunks = passChunkCount(n, parallel);
  // Not the thread-local scratch: while this thread waits for the chunks it may run another
  // subtree's build, which would use (and could reallocate) that scratch.
  std::vector<float, UninitAllocator<float>> events(3 * n);
  float* const starts = events.data();
  float* const ends = starts + n;
  float* const planars = starts + 2 * n;
  std::vector<WindowEvents> parts(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    const std::size_t begin = c * kPassChunk, end = std::min(n, begin + kPassChunk);
    parts[c] = collectWindow(refs.data() + begin, refs.data() + end, axis, win_lo, win_hi, starts + begin, ends + begin,
                             planars + begin);
  });
  WindowEvents w;
  for (std::size_t c = 0; c < chunks; ++c) {
    // Each chunk's events start at its first reference's slot, at or after where they go.
    const std::size_t begin = c * kPassChunk;
    std::copy_n(starts + begin, parts[c].n_starts, starts + w.n_starts);
    std::copy_n(ends + begin, parts[c].n_ends, ends + w.n_ends);
    std::copy_n(planars + begin, parts[c].n_planars, planars + w.n_planars);
    w.n_starts += parts[c].n_starts;
    w.n_ends += parts[c].n_ends;
    w.n_planars += parts[c].n_planars;
    w.below += parts[c].below;
    w.above += parts[c].above;
  }
  DUPLEX_DCHECK(w.n_starts <= n && w.n_ends <= n && w.n_planars <= n);
  tbb::parallel_invoke([&] { sortEvents(starts, w.n_starts); }, [&] { sortEvents(ends, w.n_ends); });
  sortEvents(planars, w.n_planars);
  return sweepSorted(sah, g, axis, starts, w.n_starts, ends, w.n_ends, planars, w.n_planars, w.below, w.above);
}

}  // namespace

Split sweepEvents(const SahCost& sah, const RefVec& refs, const NodeGeometry& g, int axis, float win_lo, float win_hi,
                  bool parallel) {
  const std::size_t n = refs.size();
  if (passChunkCount(n, parallel) > 1) return sweepEventsChunked(sah, refs, g, axis, win_lo, win_hi, parallel);
  // Scratch for the three event lists: on the stack for small nodes (the many tiny nodes of a
  // top level), per thread otherwise (allocation dominated). Nothing here waits for other tasks,
  // so no other build can run on this thread and reuse the scratch meanwhile.
  constexpr std::size_t kStack = 32;
  float stack_events[3 * kStack];
  float* events = stack_events;
  if (n > kStack) {
    thread_local std::vector<float> scratch;
    if (scratch.size() < 3 * n) scratch.resize(3 * n);
    events = scratch.data();
  }
  float* const starts = events;
  float* const ends = events + n;
  float* const planars = events + 2 * n;
  const WindowEvents w = collectWindow(refs.data(), refs.data() + n, axis, win_lo, win_hi, starts, ends, planars);
  sortEvents(starts, w.n_starts);
  sortEvents(ends, w.n_ends);
  sortEvents(planars, w.n_planars);
  return sweepSorted(sah, g, axis, starts, w.n_starts, ends, w.n_ends, planars, w.n_planars, w.below, w.above);
}

Split sweepSorted(const SahCost& sah, const NodeGeometry& g, int axis, const float* starts, std::size_t n_starts,
                  const float* ends, std::size_t n_ends, const float* planars, std::size_t n_planars,
                  std::size_t below_window, std::size_t above_window) {
  Split best;
  if (n_starts == 0 && n_ends == 0) return best;
  const float lo = g.lo[axis], hi = g.hi[axis];
  std::size_t i_start = 0, i_end = 0, i_planar = 0;
  // Merge the two sorted lists; each distinct value is one candidate plane.
  while (i_start < n_starts || i_end < n_ends) {
    const float p = i_end >= n_ends       ? starts[i_start]
                    : i_start >= n_starts ? ends[i_end]
                                          : std::min(starts[i_start], ends[i_end]);
    while (i_planar < n_planars && planars[i_planar] < p) ++i_planar;
    std::size_t n_planar = 0;
    while (i_planar + n_planar < n_planars && planars[i_planar + n_planar] == p) ++n_planar;
    const std::size_t n_lower = below_window + i_start;  // lo < p
    while (i_end < n_ends && ends[i_end] <= p) ++i_end;
    const std::size_t n_upper = above_window + (n_ends - i_end);  // hi > p
    if (p > lo && p < hi) {
      const float cost_l = sah.splitCost(g, axis, p, n_lower + n_planar, n_upper);
      if (cost_l < best.cost) best = {axis, p, cost_l, true, n_lower + n_planar, n_upper, true};
      if (n_planar > 0) {
        const float cost_u = sah.splitCost(g, axis, p, n_lower, n_upper + n_planar);
        if (cost_u < best.cost) best = {axis, p, cost_u, false, n_lower, n_upper + n_planar, true};
      }
    }
    while (i_start < n_starts && starts[i_start] <= p) ++i_start;
  }
  return best;
}

}  // namespace duplex::kd_detail
