#pragma once
// Private to accel/src: what every part of the kd-tree build shares (KdTreeBuilder.cpp drives it):
// the primitive references a node holds, the split it chooses, the exact extent of its references,
// and the chunking of passes over a large node's references.

#include "duplex/accel/Box.h"

#include <emmintrin.h>

#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

namespace duplex::kd_detail {

// Bounds as plain arrays: the builder indexes by a run-time axis everywhere, and GLM's
// operator[] is a switch. 28 bytes; the SSE loads of lo[0..3] and hi[0..3] read one float past
// each triple (hi[0], id), which the code ignores.
struct PrimRef {
  float lo[3], hi[3];  // primitive bounds clipped to the current node
  std::uint32_t id;

  PrimRef() = default;
  PrimRef(const Box& b, std::uint32_t i) : lo{b.lo.x, b.lo.y, b.lo.z}, hi{b.hi.x, b.hi.y, b.hi.z}, id(i) {}
  [[nodiscard]] Box box() const { return Box({lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}); }
  [[nodiscard]] __m128 loadLo() const { return _mm_loadu_ps(lo); }  // lane 3: hi[0]
  [[nodiscard]] __m128 loadHi() const { return _mm_loadu_ps(hi); }  // lane 3: the id's bits
};
static_assert(sizeof(PrimRef) == 28);

// Leaves new elements uninitialised, so that a partition can size its output to the most
// references it can receive and write them through a pointer (no capacity check per reference).
template <class T>
struct UninitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitAllocator<U>;
  };
  UninitAllocator() = default;
  template <class U>
  UninitAllocator(const UninitAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

using RefVec = std::vector<PrimRef, UninitAllocator<PrimRef>>;

struct Split {
  int axis = -1;
  float pos = 0.0f;
  float cost = std::numeric_limits<float>::infinity();
  bool planar_left = true;  // primitives lying in the plane go to the lower child
  // References on each side (planar ones on their side); exact when `exact`, else the binned
  // estimate (rounding of bin indices may move a reference between neighbouring bins).
  std::size_t n_lower = 0, n_upper = 0;
  bool exact = false;
};

// Exact extent of a set of references.
struct Extent {
  float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity()};
  float hi[3] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity()};
};

// SSE accumulator of an Extent.
struct ExtentAcc {
  __m128 lo = _mm_set1_ps(std::numeric_limits<float>::infinity());
  __m128 hi = _mm_set1_ps(-std::numeric_limits<float>::infinity());
  void add(__m128 rlo, __m128 rhi) {
    lo = _mm_min_ps(lo, rlo);
    hi = _mm_max_ps(hi, rhi);
  }
  /// Folds in the accumulator of the references that follow this one's, as add() would have.
  void merge(const ExtentAcc& later) { add(later.lo, later.hi); }
  [[nodiscard]] Extent extent() const {
    alignas(16) float l[4], h[4];
    _mm_store_ps(l, lo);
    _mm_store_ps(h, hi);
    Extent e;
    for (int k = 0; k < 3; ++k) e.lo[k] = l[k], e.hi[k] = h[k];
    return e;
  }
};

// Passes over a node's references (the root's preparation and binning, the refinement's event
// collection, the partition) run in parallel chunks of kPassChunk references in nodes of at least
// kParallelPassMin, so that the top levels, which subtree tasks cannot split, keep both threads busy
// (otherwise a mesh's first few levels run on one thread while the other waits). Every chunked pass gives the serial
// pass's result bit for bit: outputs are concatenated in chunk order, bin counts added, and extents merged as the
// serial pass folds them (on equal values, -0 and +0, the later one wins, as _mm_min_ps / _mm_max_ps keep it).
constexpr std::size_t kPassChunk = 8192;
constexpr std::size_t kParallelPassMin = 2 * kPassChunk;

// Chunks of a pass over n references: 1 (serial) below kParallelPassMin or in a serial build.
constexpr std::size_t passChunkCount(std::size_t n, bool parallel) {
  return parallel && n >= kParallelPassMin ? (n + kPassChunk - 1) / kPassChunk : 1;
}

}  // namespace duplex::kd_detail
