// The partition of a kd-tree node's references (see KdPartition.h).

#include "KdPartition.h"

#include "duplex/accel/Check.h"

#include <tbb/parallel_for.h>

#include <emmintrin.h>

#include <algorithm>
#include <cstddef>
#include <vector>

namespace duplex::kd_detail {

namespace {

// What every partition pass reads besides the references.
struct PartitionInputs {
  const KdBuildConfig& config;
  const KdClipFunction* clip;
  const KdSplitFunction* split;
};

// One child's side of a partition pass: its references (written at `next`, into storage sized
// for every reference the pass can send there), extent and bins.
struct Sink {
  PrimRef* next;
  ExtentAcc extent;
  Bins* bins;  // null: not binned
  // The bins' frame constants, copied once per pass: read through `bins` they would be reloaded
  // per reference behind the may_alias stores.
  __m128 bin_lo = _mm_setzero_ps(), bin_scale = _mm_setzero_ps(), bin_max = _mm_setzero_ps();
  // Called by partitionRange before its first put() (the only caller of put()).
  void cacheFrame() {
    if (bins) bin_lo = bins->sse_lo, bin_scale = bins->sse_scale, bin_max = bins->sse_max;
  }
  // kBinned: bins != null, decided once per pass rather than per reference.
  template <bool kBinned>
  void put(const PrimRef& r) {
    const __m128 lo = r.loadLo(), hi = r.loadHi();
    // 28 bytes in two overlapping 16-byte stores: lo (and hi[0]) at 0, hi and the id at 12.
    _mm_storeu_ps(next->lo, lo);
    _mm_storeu_ps(next->hi, hi);
    ++next;
    extent.add(lo, hi);
    if constexpr (kBinned) bins->addWith(lo, hi, bin_lo, bin_scale, bin_max);
  }
};

template <bool kLowerBinned, bool kUpperBinned>
void partitionRange(const PartitionInputs& in, const RefVec& refs, std::size_t begin, std::size_t end, const Split& s,
                    const Box& lower_box, const Box& upper_box, Sink& lower_out, Sink& upper_out) {
  const int axis = s.axis;
  const float pos = s.pos;
  // The sinks' state and the input in locals: put()'s 16-byte stores may alias anything (the
  // intrinsics' vector types are may_alias), so through the references every reference would
  // reload and store the output pointers and extents, a chain through memory per reference.
  Sink lower = lower_out, upper = upper_out;
  lower.cacheFrame();
  upper.cacheFrame();
  const PrimRef* data = refs.data();
  const bool planar_left = s.planar_left;
  for (std::size_t i = begin; i < end; ++i) {
    const PrimRef& r = data[i];
    const float a = r.lo[axis], b = r.hi[axis];
    if (b <= pos) {
      // Below the plane, or lying in it.
      if (a == pos && !planar_left) upper.put<kUpperBinned>(r);
      else lower.put<kLowerBinned>(r);
    } else if (a >= pos) {
      upper.put<kUpperBinned>(r);
    } else {
      // Straddles the plane. If the clipped part turns out empty on one side the primitive only
      // touched the plane there and is dropped there; the plain box intersection is the
      // fallback when clipping is off.
      const Box bounds = r.box();
      Box parts[2];
      if (in.config.clip_primitives && in.split) {
        (*in.split)(r.id, bounds, axis, pos, parts[0], parts[1]);
      } else {
        for (int side = 0; side < 2; ++side) {
          const Box bounded = intersection(bounds, side == 0 ? lower_box : upper_box);
          parts[side] = in.config.clip_primitives ? (*in.clip)(r.id, bounded) : bounded;
        }
      }
      if (!parts[0].empty()) lower.put<kLowerBinned>(PrimRef(parts[0], r.id));
      if (!parts[1].empty()) upper.put<kUpperBinned>(PrimRef(parts[1], r.id));
    }
  }
  lower_out = lower;
  upper_out = upper;
}

// Sends refs[begin, end) to the children's sinks; straddling primitives are re-clipped to each
// child ("perfect splits").
void partitionRange(const PartitionInputs& in, const RefVec& refs, std::size_t begin, std::size_t end, const Split& s,
                    const Box& lower_box, const Box& upper_box, Sink& lower, Sink& upper) {
  const int binned = (lower.bins ? 1 : 0) | (upper.bins ? 2 : 0);
  switch (binned) {
    case 0: return partitionRange<false, false>(in, refs, begin, end, s, lower_box, upper_box, lower, upper);
    case 1: return partitionRange<true, false>(in, refs, begin, end, s, lower_box, upper_box, lower, upper);
    case 2: return partitionRange<false, true>(in, refs, begin, end, s, lower_box, upper_box, lower, upper);
    default: return partitionRange<true, true>(in, refs, begin, end, s, lower_box, upper_box, lower, upper);
  }
}

}  // namespace

void partition(const RefVec& refs, const Split& s, const Extent& parent_extent, Child& lower, Child& upper,
               const KdBuildConfig& config, const KdClipFunction* clip, const KdSplitFunction* split) {
  const PartitionInputs in{config, clip, split};
  const bool sah = config.heuristic == KdHeuristic::Sah;
  for (Child* c : {&lower, &upper}) {
    const std::size_t expected = c == &lower ? s.n_lower : s.n_upper;
    c->binned = sah && expected > config.exact_sweep_max;
    if (c->binned) {
      float lo[3], hi[3];
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::max(c->box.lo[k], parent_extent.lo[k]);
        hi[k] = std::min(c->box.hi[k], parent_extent.hi[k]);
      }
      c->bins.init(lo, hi, binsFor(expected));
    }
  }
  const std::size_t n = refs.size();
  const std::size_t chunks = passChunkCount(n, config.parallel_threshold > 0);
  if (chunks == 1) {
    // A child receives each reference of the node at most once.
    lower.refs.resize(n);
    upper.refs.resize(n);
    Sink lo{lower.refs.data(), {}, lower.binned ? &lower.bins : nullptr};
    Sink hi{upper.refs.data(), {}, upper.binned ? &upper.bins : nullptr};
    partitionRange(in, refs, 0, n, s, lower.box, upper.box, lo, hi);
    lower.refs.resize(static_cast<std::size_t>(lo.next - lower.refs.data()));
    upper.refs.resize(static_cast<std::size_t>(hi.next - upper.refs.data()));
    lower.extent = lo.extent.extent();
    upper.extent = hi.extent.extent();
    return;
  }
  // Large node: chunks in parallel, each with its own output and bins, then concatenated.
  struct ChunkOut {
    RefVec refs[2];
    ExtentAcc extent[2];
    Bins bins[2];
  };
  std::vector<ChunkOut> parts(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    ChunkOut& p = parts[c];
    const std::size_t begin = c * kPassChunk, end = std::min(n, begin + kPassChunk);
    Sink sinks[2];
    for (int side = 0; side < 2; ++side) {
      const Child& child = side == 0 ? lower : upper;
      if (child.binned) p.bins[side] = child.bins;  // zeroed counts, same frame
      p.refs[side].resize(end - begin);
      sinks[side] = {p.refs[side].data(), {}, child.binned ? &p.bins[side] : nullptr};
    }
    partitionRange(in, refs, begin, end, s, lower.box, upper.box, sinks[0], sinks[1]);
    for (int side = 0; side < 2; ++side) {
      DUPLEX_DCHECK(sinks[side].next <= p.refs[side].data() + (end - begin));
      p.refs[side].resize(static_cast<std::size_t>(sinks[side].next - p.refs[side].data()));
      p.extent[side] = sinks[side].extent;
    }
  });
  for (int side = 0; side < 2; ++side) {
    Child& child = side == 0 ? lower : upper;
    std::vector<std::size_t> offset(chunks + 1, 0);
    for (std::size_t c = 0; c < chunks; ++c) offset[c + 1] = offset[c] + parts[c].refs[side].size();
    child.refs.resize(offset[chunks]);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::copy(parts[c].refs[side].begin(), parts[c].refs[side].end(),
                child.refs.begin() + static_cast<std::ptrdiff_t>(offset[c]));
    });
    ExtentAcc e;
    for (std::size_t c = 0; c < chunks; ++c) {
      e.merge(parts[c].extent[side]);
      if (child.binned) child.bins.merge(parts[c].bins[side]);
    }
    child.extent = e.extent();
  }
}

}  // namespace duplex::kd_detail
