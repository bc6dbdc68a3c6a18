// Kd-tree construction: binned SAH with exact empty-space cuts, exact events where they matter,
// perfect splits, TBB subtree tasks and parallel partitions.
//
// Cost model of the build. A kd-tree with empty-space cuts is deep (koala: 26 levels for 100k
// triangles, half the inner nodes cut off empty space), so passes over a level's references are
// what a build costs; three per level (binning, collecting the exact events near the binned plane,
// the partition) would be too many. So:
//  - The partition of a node bins its children on the fly (the child boxes are known before the
//    partition) and keeps their exact extent (min / max of the clipped bounds), so binning costs
//    no pass of its own.
//  - Empty-space cuts are taken at that exact extent: no reference moves, none is clipped, the
//    bins stay valid, so a chain of up to six such cuts costs no pass at all.
//  - The binned plane is refined to the best exact event in the two bins around it (one pass that
//    collects the few events there; KdBuildConfig::refine_max bounds the node size), so the plane
//    sits on a primitive bound as in Wald & Havran's event sweep. Only nodes of at most
//    exact_sweep_max references sweep every event, and a single reference has only its faces.
//  - Subtrees are TBB tasks. The passes over a large node's references (preparation, binning, the
//    refinement's event collection, the partition) run in parallel chunks whose results are
//    combined in order, so the tree depends neither on the thread count nor on the chunking.

#include "duplex/accel/KdTreeBuilder.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "RadixSortFloats.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_group.h>

#include <emmintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace duplex {

namespace {

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

struct Subtree {
  std::vector<KdNode> nodes;
  std::vector<std::uint32_t> prims;
};

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

constexpr int kMaxBins = 32;

// Set bits of a 4-bit mask (SSE2 has no population count).
constexpr std::uint8_t kBitCount4[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};

int binsFor(std::size_t n) { return n < 64 ? 8 : (n < 1024 ? 16 : kMaxBins); }

// j / count for j = 0 .. count (count 8, 16 or 32) and a padding entry, as Bins::boundary computes
// it, so a boundary can be formed without a division per candidate.
const float* binFractions(int count) {
  struct Table {
    float f[3][kMaxBins + 2];
    Table() {
      for (int t = 0; t < 3; ++t)
        for (int j = 0; j < kMaxBins + 2; ++j) f[t][j] = static_cast<float>(j) / static_cast<float>(8 << t);
    }
  };
  static const Table table;
  return table.f[count == 8 ? 0 : count == 16 ? 1 : 2];
}

// From this many events a radix sort beats std::sort.
constexpr std::size_t kRadixSortMin = 32;

// Sorts a few events in place: an inline insertion sort, where std::sort's calls and checks cost
// more than the sorting of 1-8 values (the top level sorts nine such lists per node).
void sortFew(float* v, std::size_t n) {
  for (std::size_t i = 1; i < n; ++i) {
    const float x = v[i];
    std::size_t j = i;
    for (; j > 0 && x < v[j - 1]; --j) v[j] = v[j - 1];
    v[j] = x;
  }
}

// Sorts events: few inline, many by radix.
void sortEvents(float* v, std::size_t n) {
  if (n <= 16) sortFew(v, n);
  else if (n < kRadixSortMin) std::sort(v, v + n);
  else kd_detail::radixSortFloats(v, n);
}

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

// Counts of reference starts and ends per bin on each axis, over a frame (a box containing every
// counted reference). Bin boundary j of an axis is frame_lo + (frame_hi - frame_lo) * j / count.
struct Bins {
  int count = 0;
  float frame_lo[3] = {}, frame_hi[3] = {};
  __m128 sse_lo, sse_scale, sse_max;
  std::uint32_t start[3][kMaxBins], end[3][kMaxBins];

  void init(const float lo[3], const float hi[3], int bins) {
    count = bins;
    float scale[3];
    for (int k = 0; k < 3; ++k) {
      frame_lo[k] = lo[k];
      frame_hi[k] = hi[k];
      scale[k] = hi[k] > lo[k] ? static_cast<float>(bins) / (hi[k] - lo[k]) : 0.0f;
    }
    sse_lo = _mm_setr_ps(lo[0], lo[1], lo[2], 0.0f);
    sse_scale = _mm_setr_ps(scale[0], scale[1], scale[2], 0.0f);  // the fourth lane bins to 0
    sse_max = _mm_set1_ps(static_cast<float>(bins - 1));
    std::fill_n(&start[0][0], 3 * kMaxBins, 0u);
    std::fill_n(&end[0][0], 3 * kMaxBins, 0u);
  }
  // Bin indices of the three axes at once. Clamping in float before the conversion keeps values
  // outside the frame (rounding at its faces) and the ignored fourth lane defined.
  void add(__m128 rlo, __m128 rhi) { addWith(rlo, rhi, sse_lo, sse_scale, sse_max); }
  // add() with the frame's constants passed in (a pass keeps them in registers).
  void addWith(__m128 rlo, __m128 rhi, __m128 frame_lo, __m128 scale, __m128 last_bin) {
    alignas(16) std::int32_t b0[4], b1[4];
    const __m128 f0 = _mm_mul_ps(_mm_sub_ps(rlo, frame_lo), scale);
    const __m128 f1 = _mm_mul_ps(_mm_sub_ps(rhi, frame_lo), scale);
    _mm_store_si128(reinterpret_cast<__m128i*>(b0),
                    _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f0, _mm_setzero_ps()), last_bin)));
    _mm_store_si128(reinterpret_cast<__m128i*>(b1),
                    _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f1, _mm_setzero_ps()), last_bin)));
    for (int k = 0; k < 3; ++k) {
      ++start[k][b0[k]];
      ++end[k][b1[k]];
    }
  }
  void merge(const Bins& o) {
    for (int k = 0; k < 3; ++k)
      for (int j = 0; j < count; ++j) {
        start[k][j] += o.start[k][j];
        end[k][j] += o.end[k][j];
      }
  }
  [[nodiscard]] float boundary(int axis, int j) const {
    return frame_lo[axis] + (frame_hi[axis] - frame_lo[axis]) * (static_cast<float>(j) / static_cast<float>(count));
  }
};

// What a partition produces for one child: its references (clipped to its box), their exact
// extent, and (when the child is large enough to be binned) their bins over the child's box
// intersected with the parent's extent.
struct Child {
  Box box;
  RefVec refs;
  Extent extent;
  bool binned = false;
  Bins bins;
};

// SAH cost terms of one node: the surface area of a child is 2 (ab + len (a + b)) where a, b are
// the node's extents on the other two axes and len its extent on the split axis.
struct NodeGeometry {
  float lo[3], hi[3];
  float ab[3], a_plus_b[3];
  float inv_half_area;
  explicit NodeGeometry(const Box& box) {
    lo[0] = box.lo.x, lo[1] = box.lo.y, lo[2] = box.lo.z;
    hi[0] = box.hi.x, hi[1] = box.hi.y, hi[2] = box.hi.z;
    const float e[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    for (int axis = 0; axis < 3; ++axis) {
      const float a = e[(axis + 1) % 3], b = e[(axis + 2) % 3];
      ab[axis] = a * b;
      a_plus_b[axis] = a + b;
    }
    const float half_area = e[0] * e[1] + e[1] * e[2] + e[2] * e[0];
    inv_half_area = half_area > 0.0f ? 1.0f / half_area : 0.0f;
  }
};

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

class Builder {
 public:
  // Exactly one of `clip` and `split` is non-null.
  Builder(const KdClipFunction* clip, const KdSplitFunction* split, const KdBuildConfig& config, int max_depth)
      : clip_(clip), split_(split), cfg_(config), max_depth_(max_depth) {}

  // Builds the subtree of a node with references `refs` (clipped to `box`), their exact extent
  // `extent`, and optionally their bins (`bins`, may be null), appending it to `out`.
  void build(RefVec&& refs, Box box, const Bins* bins, const Extent& extent, int depth, int bad_refines,
             Subtree& out) const {
    // Nodes whose upper child is an empty leaf still to be written after their lower subtree.
    std::array<std::uint32_t, 64> pending;  // depth <= 60
    int n_pending = 0;
    Bins own;            // bins made here when the parent did not bin this node (or they are too coarse)
    SmallEvents events;  // valid while `refs` stay (empty-space cuts)
    for (;;) {
      const std::size_t n = refs.size();
      Split split;
      if (n > 0 && depth < max_depth_) {
        if (cfg_.heuristic == KdHeuristic::Sah) {
          split = findSahSplit(refs, box, bins, own, extent, events);
          const float leaf_cost = cfg_.intersection_cost * static_cast<float>(n);
          if (split.axis >= 0 && split.cost > leaf_cost) ++bad_refines;
          // As in pbrt: accept a few splits that look worse than a leaf, since later splits may
          // pay for them, but stop when the estimate is clearly hopeless.
          if ((split.cost > 4.0f * leaf_cost && n < 16) || bad_refines >= 3) split.axis = -1;
        } else if (n > cfg_.max_leaf_size) {
          split = findSimpleSplit(refs, box);
        }
      }
      if (split.axis < 0) {
        makeLeaf(refs, out);
        break;
      }
      const std::size_t self = out.nodes.size();
      out.nodes.push_back(KdNode::inner(split.axis, split.pos, 0));

      if (split.exact && (split.n_lower == 0 || split.n_upper == 0)) {
        // Empty-space cut: every reference lies on one side (planar ones go there too), so none
        // moves or is clipped and the bins remain those of the remaining node.
        if (split.n_lower == 0) {
          out.nodes.push_back(KdNode::leaf(static_cast<std::uint32_t>(out.prims.size()), 0));
          out.nodes[self].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
          box.lo[split.axis] = split.pos;
        } else {
          pending[static_cast<std::size_t>(n_pending++)] = static_cast<std::uint32_t>(self);
          box.hi[split.axis] = split.pos;
        }
        ++depth;
        continue;
      }

      Child lower, upper;
      lower.box = box;
      upper.box = box;
      lower.box.hi[split.axis] = split.pos;
      upper.box.lo[split.axis] = split.pos;
      partition(refs, split, extent, lower, upper);
      RefVec().swap(refs);  // release before recursing

      if (cfg_.parallel_threshold > 0 && n >= cfg_.parallel_threshold) {
        Subtree lo_tree, hi_tree;
        tbb::task_group tasks;
        tasks.run([&] { buildChild(lower, depth + 1, bad_refines, lo_tree); });
        buildChild(upper, depth + 1, bad_refines, hi_tree);
        tasks.wait();
        append(lo_tree, out);
        out.nodes[self].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
        append(hi_tree, out);
      } else {
        buildChild(lower, depth + 1, bad_refines, out);
        out.nodes[self].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
        buildChild(upper, depth + 1, bad_refines, out);
      }
      break;
    }
    while (n_pending > 0) {
      const std::uint32_t node = pending[static_cast<std::size_t>(--n_pending)];
      out.nodes[node].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
      out.nodes.push_back(KdNode::leaf(static_cast<std::uint32_t>(out.prims.size()), 0));
    }
  }

 private:
  [[nodiscard]] std::size_t passChunks(std::size_t n) const { return passChunkCount(n, cfg_.parallel_threshold > 0); }

  // Bins every reference into `bins` (initialised, counts zero): chunks bin into copies whose
  // counts are added.
  void binRefs(const RefVec& refs, Bins& bins) const {
    const std::size_t n = refs.size(), chunks = passChunks(n);
    if (chunks == 1) {
      for (const PrimRef& r : refs) bins.add(r.loadLo(), r.loadHi());
      return;
    }
    std::vector<Bins> parts(chunks, bins);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      const std::size_t end = std::min(n, (c + 1) * kPassChunk);
      for (std::size_t i = c * kPassChunk; i < end; ++i) parts[c].add(refs[i].loadLo(), refs[i].loadHi());
    });
    for (const Bins& part : parts) bins.merge(part);
  }

  void buildChild(Child& c, int depth, int bad_refines, Subtree& out) const {
    build(std::move(c.refs), c.box, c.binned ? &c.bins : nullptr, c.extent, depth, bad_refines, out);
  }

  static void makeLeaf(const RefVec& refs, Subtree& out) {
    out.nodes.push_back(
        KdNode::leaf(static_cast<std::uint32_t>(out.prims.size()), static_cast<std::uint32_t>(refs.size())));
    for (const PrimRef& r : refs) out.prims.push_back(r.id);
  }

  // Moves a subtree built with local offsets to the end of `out`, fixing its indices.
  static void append(const Subtree& sub, Subtree& out) {
    const auto node_base = static_cast<std::uint32_t>(out.nodes.size());
    const auto prim_base = static_cast<std::uint32_t>(out.prims.size());
    out.nodes.reserve(out.nodes.size() + sub.nodes.size());
    for (KdNode node : sub.nodes) {
      // Masks instead of a branch (leaves and inner nodes alternate unpredictably).
      const std::uint32_t leaf = 0u - static_cast<std::uint32_t>(node.isLeaf());
      node.setPrimOffset(node.primOffset() + (prim_base & leaf));
      node.setUpperChild(node.upperChild() + (node_base & ~leaf));
      out.nodes.push_back(node);
    }
    out.prims.insert(out.prims.end(), sub.prims.begin(), sub.prims.end());
  }

  float splitCost(const NodeGeometry& g, int axis, float pos, std::size_t n_lower, std::size_t n_upper) const {
    const float p_lower = (g.ab[axis] + (pos - g.lo[axis]) * g.a_plus_b[axis]) * g.inv_half_area;
    const float p_upper = (g.ab[axis] + (g.hi[axis] - pos) * g.a_plus_b[axis]) * g.inv_half_area;
    float cost = cfg_.traversal_cost + cfg_.intersection_cost * (p_lower * static_cast<float>(n_lower) +
                                                                 p_upper * static_cast<float>(n_upper));
    if (n_lower == 0 || n_upper == 0) cost *= 1.0f - cfg_.empty_bonus;
    return cost;
  }

  // Bins are too coarse for the node when its references span less than half of them on each
  // axis: a chain of empty-space cuts shrank the node inside its parent's frame.
  static bool tooCoarse(const Bins& b, const Extent& e) {
    for (int k = 0; k < 3; ++k) {
      const float w = b.frame_hi[k] - b.frame_lo[k];
      if (w > 0.0f && (e.hi[k] - e.lo[k]) >= 0.5f * w) return false;
    }
    return true;
  }

  // Index of the first least entry of cost[0 .. count) (count a multiple of 4; no NaN), without
  // the data-dependent branches of a scan.
  static int firstMinimum(const float* cost, int count) {
    __m128 least = _mm_load_ps(cost);
    for (int j = 4; j < count; j += 4) least = _mm_min_ps(least, _mm_load_ps(cost + j));
    least = _mm_min_ps(least, _mm_shuffle_ps(least, least, _MM_SHUFFLE(2, 3, 0, 1)));
    least = _mm_min_ps(least, _mm_shuffle_ps(least, least, _MM_SHUFFLE(1, 0, 3, 2)));
    std::uint32_t mask = 0;
    for (int j = 0; j < count; j += 4)
      mask |= static_cast<std::uint32_t>(_mm_movemask_ps(_mm_cmpeq_ps(_mm_load_ps(cost + j), least))) << j;
    return std::countr_zero(mask);
  }

  // splitCost of four planes `p` on `axis` with references `nl` below and `nu` above, on SSE lanes:
  // splitCost's operations in the same order, so the same results bit for bit.
  __m128 splitCost4(const NodeGeometry& g, int axis, __m128 p, __m128i nl, __m128i nu) const {
    const __m128 lo = _mm_set1_ps(g.lo[axis]), hi = _mm_set1_ps(g.hi[axis]);
    const __m128 ab = _mm_set1_ps(g.ab[axis]), a_plus_b = _mm_set1_ps(g.a_plus_b[axis]);
    const __m128 inv_half_area = _mm_set1_ps(g.inv_half_area);
    const __m128 ct = _mm_set1_ps(cfg_.traversal_cost), ci = _mm_set1_ps(cfg_.intersection_cost);
    const __m128 p_lower = _mm_mul_ps(_mm_add_ps(ab, _mm_mul_ps(_mm_sub_ps(p, lo), a_plus_b)), inv_half_area);
    const __m128 p_upper = _mm_mul_ps(_mm_add_ps(ab, _mm_mul_ps(_mm_sub_ps(hi, p), a_plus_b)), inv_half_area);
    const __m128 c = _mm_add_ps(ct, _mm_mul_ps(ci, _mm_add_ps(_mm_mul_ps(p_lower, _mm_cvtepi32_ps(nl)),
                                                              _mm_mul_ps(p_upper, _mm_cvtepi32_ps(nu)))));
    const __m128i zero = _mm_setzero_si128();
    const __m128 one_empty = _mm_castsi128_ps(_mm_or_si128(_mm_cmpeq_epi32(nl, zero), _mm_cmpeq_epi32(nu, zero)));
    const __m128 bonus = _mm_set1_ps(1.0f - cfg_.empty_bonus);
    return _mm_or_ps(_mm_and_ps(one_empty, _mm_mul_ps(c, bonus)), _mm_andnot_ps(one_empty, c));
  }

  // Costs of the bin boundaries j = 1 .. count - 1 of `axis` into cost[j - 1], with their planes and
  // reference counts below / above: splitCost's operations in the same order on four lanes (the
  // same results, bit for bit), +inf for planes outside the node or straddled by all n references
  // (they separate nothing). The bin counts are the hot part of a build's SAH evaluation.
  void binnedCosts(const NodeGeometry& g, const Bins& b, int axis, std::int32_t n, float* pos, std::int32_t* n_lower,
                   std::int32_t* n_upper, float* cost) const {
    const int m = b.count - 1;  // candidates; count is 8, 16 or 32, so m + 1 is a multiple of 4
    std::int32_t below = 0, above = n;
    for (int j = 0; j < m; ++j) {
      below += static_cast<std::int32_t>(b.start[axis][j]);
      above -= static_cast<std::int32_t>(b.end[axis][j]);
      n_lower[j] = below;
      n_upper[j] = above;
    }
    n_lower[m] = n;  // padding lane: straddled by all, so +inf
    n_upper[m] = n;
    const float* frac = binFractions(b.count);
    const __m128 frame_lo = _mm_set1_ps(b.frame_lo[axis]);
    const __m128 frame_w = _mm_set1_ps(b.frame_hi[axis] - b.frame_lo[axis]);
    const __m128 lo = _mm_set1_ps(g.lo[axis]), hi = _mm_set1_ps(g.hi[axis]);
    const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
    const __m128i all = _mm_set1_epi32(n);
    for (int j = 0; j <= m; j += 4) {
      // boundary(axis, j + 1): frame_lo + (frame_hi - frame_lo) * ((j + 1) / count).
      const __m128 p = _mm_add_ps(frame_lo, _mm_mul_ps(frame_w, _mm_loadu_ps(frac + j + 1)));
      _mm_store_ps(pos + j, p);
      const __m128i nl = _mm_load_si128(reinterpret_cast<const __m128i*>(n_lower + j));
      const __m128i nu = _mm_load_si128(reinterpret_cast<const __m128i*>(n_upper + j));
      const __m128 c = splitCost4(g, axis, p, nl, nu);
      const __m128 inside = _mm_and_ps(_mm_cmpgt_ps(p, lo), _mm_cmplt_ps(p, hi));
      const __m128 separates = _mm_castsi128_ps(
          _mm_andnot_si128(_mm_and_si128(_mm_cmpeq_epi32(nl, all), _mm_cmpeq_epi32(nu, all)), _mm_set1_epi32(-1)));
      const __m128 keep = _mm_and_ps(inside, separates);
      _mm_store_ps(cost + j, _mm_or_ps(_mm_and_ps(keep, c), _mm_andnot_ps(keep, inf)));
    }
  }

  Split findSahSplit(const RefVec& refs, const Box& box, const Bins*& bins, Bins& own, const Extent& extent,
                     SmallEvents& events) const {
    const NodeGeometry g(box);
    if (!(g.inv_half_area > 0.0f)) return {};
    const std::size_t n = refs.size();
    if (n == 1) {
      // One reference (most top-level leaves): the only useful planes are its faces.
      const PrimRef& r = refs[0];
      Split best;
      for (int axis = 0; axis < 3; ++axis) {
        if (r.lo[axis] > g.lo[axis] && r.lo[axis] < g.hi[axis]) {
          const float cost = splitCost(g, axis, r.lo[axis], 0, 1);
          if (cost < best.cost) best = {axis, r.lo[axis], cost, false, 0, 1, true};
        }
        if (r.hi[axis] < g.hi[axis] && r.hi[axis] > g.lo[axis]) {
          const float cost = splitCost(g, axis, r.hi[axis], 1, 0);
          if (cost < best.cost) best = {axis, r.hi[axis], cost, true, 1, 0, true};
        }
      }
      return best;
    }
    if (n <= cfg_.exact_sweep_max) {
      if (n <= SmallEvents::kMax && !events.valid) collectSmallEvents(refs, events);
      Split best;
      for (int axis = 0; axis < 3; ++axis) {
        if (!(g.hi[axis] > g.lo[axis])) continue;
        const bool small = n <= kSmallSweep && events.n_planars[axis] == 0;
        if (!small && n <= SmallEvents::kMax) sortSmallEvents(events, axis);
        const Split s = small ? sweepSmall(g, axis, events, n)
                        : n <= SmallEvents::kMax
                            ? sweepSorted(g, axis, events.starts[axis], events.n_starts[axis], events.ends[axis],
                                          events.n_ends[axis], events.planars[axis], events.n_planars[axis], 0, 0)
                            : sweepEvents(refs, g, axis, g.lo[axis], g.hi[axis]);
        if (s.cost < best.cost) best = s;
      }
      return best;
    }
    if (bins == nullptr || tooCoarse(*bins, extent)) {
      // Over the references' extent (inside the box), so that every bin can hold a plane.
      float lo[3], hi[3];
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::max(g.lo[k], extent.lo[k]);
        hi[k] = std::min(g.hi[k], extent.hi[k]);
      }
      own.init(lo, hi, binsFor(n));
      binRefs(refs, own);
      bins = &own;
    }
    const Bins& b = *bins;

    Split best;
    int best_bin = -1;  // bin boundary of the best split; -1 for an empty-space cut at the extent
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = g.lo[axis], hi = g.hi[axis];
      if (!(hi > lo)) continue;
      // Empty-space cuts at the exact extent: no reference below (above) the plane, and those
      // lying in it go to the occupied side.
      if (extent.lo[axis] > lo && extent.lo[axis] < hi) {
        const float cost = splitCost(g, axis, extent.lo[axis], 0, n);
        if (cost < best.cost) best = {axis, extent.lo[axis], cost, false, 0, n, true}, best_bin = -1;
      }
      if (extent.hi[axis] < hi && extent.hi[axis] > lo) {
        const float cost = splitCost(g, axis, extent.hi[axis], n, 0);
        if (cost < best.cost) best = {axis, extent.hi[axis], cost, true, n, 0, true}, best_bin = -1;
      }
      // The bin boundaries j = 1 .. count - 1, costed four at a time (binnedCosts), then scanned in
      // order as before, so ties resolve the same way.
      alignas(16) float pos[kMaxBins], cost[kMaxBins];
      alignas(16) std::int32_t n_lower[kMaxBins], n_upper[kMaxBins];
      binnedCosts(g, b, axis, static_cast<std::int32_t>(n), pos, n_lower, n_upper, cost);
      // The first boundary of least cost, as a scan in order with a strict comparison would find.
      const int i = firstMinimum(cost, b.count);
      if (cost[i] < best.cost) {
        best = {axis, pos[i], cost[i], true, static_cast<std::size_t>(n_lower[i]), static_cast<std::size_t>(n_upper[i]),
                false};
        best_bin = i + 1;
      }
    }
    if (best.axis < 0 || best_bin < 0 || n > cfg_.refine_max) return best;

    // Exact events in the window of the two bins around the chosen boundary: the plane then sits
    // on a primitive bound, as in an exact sweep, whenever the exact optimum lies in the window.
    const int axis = best.axis;
    const float win_lo = std::max(g.lo[axis], b.boundary(axis, best_bin - 1));
    const float win_hi = std::min(g.hi[axis], b.boundary(axis, best_bin + 1));
    // When no event falls into the window the binned plane stays (it separates some references:
    // planes that separate nothing are no candidates).
    const Split refined = sweepEvents(refs, g, axis, win_lo, win_hi);
    return refined.axis >= 0 ? refined : best;
  }

  // Exact SAH over the events (clipped bounds) of `axis` that lie in [win_lo, win_hi], after
  // Wald & Havran: a primitive counts below a plane p if its lower bound is < p, above if its
  // upper bound is > p; a primitive lying in p goes to the cheaper side.
  Split sweepEvents(const RefVec& refs, const NodeGeometry& g, int axis, float win_lo, float win_hi) const {
    const std::size_t n = refs.size();
    if (passChunks(n) > 1) return sweepEventsChunked(refs, g, axis, win_lo, win_hi);
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
    return sweepSorted(g, axis, starts, w.n_starts, ends, w.n_ends, planars, w.n_planars, w.below, w.above);
  }

  // sweepEvents of a large node: the events collected in parallel chunks, concatenated in chunk
  // order (the serial pass's lists exactly), the start and end lists sorted side by side.
  Split sweepEventsChunked(const RefVec& refs, const NodeGeometry& g, int axis, float win_lo, float win_hi) const {
    const std::size_t n = refs.size(), chunks = passChunks(n);
    // Not the thread-local scratch: while this thread waits for the chunks it may run another
    // subtree's build, which would use (and could reallocate) that scratch.
    std::vector<float, UninitAllocator<float>> events(3 * n);
    float* const starts = events.data();
    float* const ends = starts + n;
    float* const planars = starts + 2 * n;
    std::vector<WindowEvents> parts(chunks);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      const std::size_t begin = c * kPassChunk, end = std::min(n, begin + kPassChunk);
      parts[c] = collectWindow(refs.data() + begin, refs.data() + end, axis, win_lo, win_hi, starts + begin,
                               ends + begin, planars + begin);
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
    tbb::parallel_invoke([&] { sortEvents(starts, w.n_starts); }, [&] { sortEvents(ends, w.n_ends); });
    sortEvents(planars, w.n_planars);
    return sweepSorted(g, axis, starts, w.n_starts, ends, w.n_ends, planars, w.n_planars, w.below, w.above);
  }

  // What collectWindow found: events stored, and references starting below (lo < win_lo) and
  // ending above (hi > win_hi) the window.
  struct WindowEvents {
    std::size_t n_starts = 0, n_ends = 0, n_planars = 0, below = 0, above = 0;
  };

  // The events of references [first, last) on `axis` inside [win_lo, win_hi]: lower bounds to
  // `starts`, upper bounds to `ends`, bounds of references lying in a plane to `planars`, each in
  // reference order (each array has room for last - first values).
  static WindowEvents collectWindow(const PrimRef* first, const PrimRef* last, int axis, float win_lo, float win_hi,
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
      const auto a_in =
          static_cast<unsigned>(_mm_movemask_ps(_mm_and_ps(_mm_cmpge_ps(va, lo4), _mm_cmple_ps(va, hi4))));
      const auto b_in =
          static_cast<unsigned>(_mm_movemask_ps(_mm_and_ps(_mm_cmpge_ps(vb, lo4), _mm_cmple_ps(vb, hi4))));
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

  // The exact sweep of a node of at most kSmallSweep references with no planar one on `axis`,
  // without the merge's branches: every start and end is a candidate plane, its counts below and
  // above are compares against all events (SSE, four candidates at a time), its cost splitCost4's.
  // The least cost wins, on ties the lowest plane: what the merge in order (sweepSorted) picks,
  // since a plane listed twice has the same counts and cost both times.
  static constexpr std::size_t kSmallSweep = 8;
  Split sweepSmall(const NodeGeometry& g, int axis, const SmallEvents& e, std::size_t n) const {
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
      const __m128 c = splitCost4(g, axis, p, nl, nu);
      // Planes strictly inside the node (the padding is not); a NaN cost never wins.
      const __m128 keep = _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(p, lo), _mm_cmplt_ps(p, hi)), _mm_cmpord_ps(c, c));
      const __m128 take = _mm_and_ps(
          keep,
          _mm_or_ps(_mm_cmplt_ps(c, best_cost), _mm_and_ps(_mm_cmpeq_ps(c, best_cost), _mm_cmplt_ps(p, best_pos))));
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
  static void sortSmallEvents(SmallEvents& e, int axis) {
    if (e.sorted[axis]) return;
    sortFew(e.starts[axis], e.n_starts[axis]);
    sortFew(e.ends[axis], e.n_ends[axis]);
    sortFew(e.planars[axis], e.n_planars[axis]);
    e.sorted[axis] = true;
  }

  // The events of every axis of a small node (every event lies in the node: references are clipped
  // to it), in reference order (sortSmallEvents sorts an axis when it is merged).
  static void collectSmallEvents(const RefVec& refs, SmallEvents& e) {
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
  Split sweepSorted(const NodeGeometry& g, int axis, const float* starts, std::size_t n_starts, const float* ends,
                    std::size_t n_ends, const float* planars, std::size_t n_planars, std::size_t below_window,
                    std::size_t above_window) const {
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
        const float cost_l = splitCost(g, axis, p, n_lower + n_planar, n_upper);
        if (cost_l < best.cost) best = {axis, p, cost_l, true, n_lower + n_planar, n_upper, true};
        if (n_planar > 0) {
          const float cost_u = splitCost(g, axis, p, n_lower, n_upper + n_planar);
          if (cost_u < best.cost) best = {axis, p, cost_u, false, n_lower, n_upper + n_planar, true};
        }
      }
      while (i_start < n_starts && starts[i_start] <= p) ++i_start;
    }
    return best;
  }

  // Median / spatial-middle plane, on the longest axis where both children get fewer references
  // than the node: otherwise the split only duplicates references (overlapping boxes would then
  // grow the tree to the depth limit). The SAH rejects such splits by cost; these heuristics need
  // the explicit check.
  Split findSimpleSplit(const RefVec& refs, const Box& box) const {
    const glm::vec3 e = box.extent();
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return e[a] > e[b]; });
    for (const int axis : order) {
      const float lo = box.lo[axis], hi = box.hi[axis];
      float pos = 0.5f * (lo + hi);
      if (cfg_.heuristic == KdHeuristic::Median) {
        std::vector<float> c(refs.size());
        for (std::size_t i = 0; i < refs.size(); ++i) c[i] = 0.5f * (refs[i].lo[axis] + refs[i].hi[axis]);
        auto mid = c.begin() + static_cast<std::ptrdiff_t>(c.size() / 2);
        std::nth_element(c.begin(), mid, c.end());
        pos = *mid;
        if (!(pos > lo && pos < hi)) pos = 0.5f * (lo + hi);
      }
      if (!(pos > lo && pos < hi)) continue;
      std::size_t n_lower = 0, n_upper = 0;
      for (const PrimRef& r : refs) {
        n_lower += (r.lo[axis] < pos || (r.lo[axis] == pos && r.hi[axis] == pos)) ? 1 : 0;
        n_upper += r.hi[axis] > pos ? 1 : 0;
      }
      if (n_lower == refs.size() || n_upper == refs.size()) continue;
      return {axis, pos, 0.0f, true, n_lower, n_upper, true};
    }
    return {};
  }

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

  // Sends refs[begin, end) to the children's sinks; straddling primitives are re-clipped to each
  // child ("perfect splits").
  void partitionRange(const RefVec& refs, std::size_t begin, std::size_t end, const Split& s, const Box& lower_box,
                      const Box& upper_box, Sink& lower, Sink& upper) const {
    const int binned = (lower.bins ? 1 : 0) | (upper.bins ? 2 : 0);
    switch (binned) {
      case 0: return partitionRange<false, false>(refs, begin, end, s, lower_box, upper_box, lower, upper);
      case 1: return partitionRange<true, false>(refs, begin, end, s, lower_box, upper_box, lower, upper);
      case 2: return partitionRange<false, true>(refs, begin, end, s, lower_box, upper_box, lower, upper);
      default: return partitionRange<true, true>(refs, begin, end, s, lower_box, upper_box, lower, upper);
    }
  }

  template <bool kLowerBinned, bool kUpperBinned>
  void partitionRange(const RefVec& refs, std::size_t begin, std::size_t end, const Split& s, const Box& lower_box,
                      const Box& upper_box, Sink& lower_out, Sink& upper_out) const {
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
        if (cfg_.clip_primitives && split_) {
          (*split_)(r.id, bounds, axis, pos, parts[0], parts[1]);
        } else {
          for (int side = 0; side < 2; ++side) {
            const Box bounded = intersection(bounds, side == 0 ? lower_box : upper_box);
            parts[side] = cfg_.clip_primitives ? (*clip_)(r.id, bounded) : bounded;
          }
        }
        if (!parts[0].empty()) lower.put<kLowerBinned>(PrimRef(parts[0], r.id));
        if (!parts[1].empty()) upper.put<kUpperBinned>(PrimRef(parts[1], r.id));
      }
    }
    lower_out = lower;
    upper_out = upper;
  }

  // Splits `refs` into the two children, binning each child expected to be large enough, over its
  // box intersected with the parent's extent (which contains every reference of the child).
  void partition(const RefVec& refs, const Split& s, const Extent& parent_extent, Child& lower, Child& upper) const {
    const bool sah = cfg_.heuristic == KdHeuristic::Sah;
    for (Child* c : {&lower, &upper}) {
      const std::size_t expected = c == &lower ? s.n_lower : s.n_upper;
      c->binned = sah && expected > cfg_.exact_sweep_max;
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
    const std::size_t chunks = passChunks(n);
    if (chunks == 1) {
      // A child receives each reference of the node at most once.
      lower.refs.resize(n);
      upper.refs.resize(n);
      Sink lo{lower.refs.data(), {}, lower.binned ? &lower.bins : nullptr};
      Sink hi{upper.refs.data(), {}, upper.binned ? &upper.bins : nullptr};
      partitionRange(refs, 0, n, s, lower.box, upper.box, lo, hi);
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
      partitionRange(refs, begin, end, s, lower.box, upper.box, sinks[0], sinks[1]);
      for (int side = 0; side < 2; ++side) {
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

  const KdClipFunction* clip_;
  const KdSplitFunction* split_;
  const KdBuildConfig& cfg_;
  int max_depth_;
};

bool finiteBox(const Box& b) {
  // x - x is 0 for a finite x and NaN for an infinite or NaN one; the sum of six such is 0 only
  // when all six are finite (one test instead of six branches per primitive).
  const float zero = (b.lo.x - b.lo.x) + (b.lo.y - b.lo.y) + (b.lo.z - b.lo.z) + (b.hi.x - b.hi.x) + (b.hi.y - b.hi.y) +
                     (b.hi.z - b.hi.z);
  return zero == 0.0f && !b.empty();
}

// The references of the primitives with finite, non-empty bounds, in primitive order, and the
// union of those bounds (`bounds` starts empty). A parallel build of many primitives fills chunks
// side by side, then closes the gaps left by skipped primitives and extends the bounds chunk by
// chunk in order, which gives the serial loop's result (Box::extend keeps the earlier of equal values).
void prepareRefs(std::span<const Box> prim_bounds, bool parallel, RefVec& refs, Box& bounds) {
  const std::size_t n = prim_bounds.size();
  const std::size_t chunks = passChunkCount(n, parallel);
  refs.resize(n);
  std::vector<std::size_t> kept(chunks);
  std::vector<Box> chunk_bounds(chunks);
  const auto fill = [&](std::size_t c) {
    const std::size_t begin = c * kPassChunk, end = chunks == 1 ? n : std::min(n, begin + kPassChunk);
    PrimRef* const first = refs.data() + begin;
    PrimRef* out = first;
    Box b;
    for (std::size_t i = begin; i < end; ++i) {
      if (!finiteBox(prim_bounds[i])) continue;
      *out++ = PrimRef(prim_bounds[i], static_cast<std::uint32_t>(i));
      b.extend(prim_bounds[i]);
    }
    kept[c] = static_cast<std::size_t>(out - first);
    chunk_bounds[c] = b;
  };
  if (chunks == 1) fill(0);
  else tbb::parallel_for(std::size_t{0}, chunks, fill);
  std::size_t total = 0;
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::size_t begin = c * kPassChunk;
    if (begin != total) std::copy_n(refs.data() + begin, kept[c], refs.data() + total);
    total += kept[c];
    bounds.extend(chunk_bounds[c]);
  }
  refs.resize(total);
}

}  // namespace

std::string_view toString(KdHeuristic h) {
  switch (h) {
    case KdHeuristic::Sah: return "sah";
    case KdHeuristic::Median: return "median";
    case KdHeuristic::SpatialMiddle: return "middle";
  }
  return "unknown";
}

KdHeuristic parseKdHeuristic(std::string_view name) {
  if (name == "sah") return KdHeuristic::Sah;
  if (name == "median") return KdHeuristic::Median;
  if (name == "middle") return KdHeuristic::SpatialMiddle;
  throw InvalidArgument("unknown kd-tree heuristic '" + std::string(name) + "' (expected sah, median or middle)");
}

std::ostream& operator<<(std::ostream& os, const KdBuildConfig& c) {
  return os << "KdBuildConfig{" << toString(c.heuristic) << ", Ct=" << c.traversal_cost
            << ", Ci=" << c.intersection_cost << ", empty_bonus=" << c.empty_bonus << ", max_depth=" << c.max_depth
            << ", leaf=" << c.max_leaf_size << ", clip=" << c.clip_primitives
            << ", exact_sweep_max=" << c.exact_sweep_max << ", refine_max=" << c.refine_max << "}";
}

namespace {

// `root`: the root box (null: the primitives' bounds); it must contain them.
KdTree build(std::span<const Box> prim_bounds, const KdClipFunction* clip, const KdSplitFunction* split,
             const KdBuildConfig& config, const Box* root = nullptr) {
  if (prim_bounds.size() > KdNode::kMaxIndex)
    throw InvalidArgument("kd-tree build: " + std::to_string(prim_bounds.size()) +
                          " primitives exceed the limit of 2^30");
  // Name the field and the value: a bad cost usually comes from a command-line flag or a caller's
  // arithmetic, and "invalid configuration" alone does not say which.
  auto refuse = [&config](const char* field, const char* rule, double value) {
    std::ostringstream os;
    os << "kd-tree build: " << field << " must be " << rule << " (got " << value << "; configuration " << config << ")";
    throw InvalidArgument(os.str());
  };
  if (!(config.traversal_cost > 0.0f && std::isfinite(config.traversal_cost)))
    refuse("traversal_cost", "finite and > 0", config.traversal_cost);
  if (!(config.intersection_cost > 0.0f && std::isfinite(config.intersection_cost)))
    refuse("intersection_cost", "finite and > 0", config.intersection_cost);
  if (!(config.empty_bonus >= 0.0f && config.empty_bonus < 1.0f))
    refuse("empty_bonus", "in [0, 1)", config.empty_bonus);
  if (config.max_depth < 0) refuse("max_depth", ">= 0 (0: automatic)", config.max_depth);

  KdTree tree;
  RefVec refs;
  prepareRefs(prim_bounds, config.parallel_threshold > 0, refs, tree.bounds);
  if (refs.empty()) return tree;

  int max_depth = config.max_depth;
  if (max_depth == 0)
    max_depth = static_cast<int>(std::lround(8.0 + 1.3 * std::log2(static_cast<double>(refs.size()))));
  max_depth = std::min(max_depth, 60);  // traversal stack holds 64 entries

  Builder builder(clip, split, config, max_depth);
  Extent extent;  // the references' exact extent; the root box unless one is given
  for (int k = 0; k < 3; ++k) extent.lo[k] = tree.bounds.lo[k], extent.hi[k] = tree.bounds.hi[k];
  if (root) tree.bounds = *root;
  Subtree out;
  out.nodes.reserve(refs.size() * 2);
  out.prims.reserve(refs.size() * 2);
  builder.build(std::move(refs), tree.bounds, nullptr, extent, 0, 0, out);
  if (out.nodes.size() > KdNode::kMaxIndex || out.prims.size() > 0xFFFFFFFFu)
    throw InvalidArgument("kd-tree build: tree exceeds 2^30 nodes");
  tree.nodes = std::move(out.nodes);
  tree.prim_indices = std::move(out.prims);
  tree.nodes.shrink_to_fit();
  tree.prim_indices.shrink_to_fit();
  return tree;
}

}  // namespace

KdTree buildKdTree(std::span<const Box> prim_bounds, const KdClipFunction& clip, const KdBuildConfig& config) {
  return build(prim_bounds, &clip, nullptr, config);
}

KdTree buildKdTree(std::span<const Box> prim_bounds, const KdSplitFunction& split, const KdBuildConfig& config) {
  return build(prim_bounds, nullptr, &split, config);
}

KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config) {
  // Clipping a box primitive to a node is plain intersection; `box` is already that.
  return buildKdTree(
      boxes, [](std::uint32_t, const Box& box) { return box; }, config);
}

KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config, const Box& root_bounds) {
  Box all;
  for (const Box& b : boxes)
    if (finiteBox(b)) all.extend(b);
  if (all.empty()) return {};
  if (!finiteBox(root_bounds) ||
      !(root_bounds.lo.x <= all.lo.x && root_bounds.lo.y <= all.lo.y && root_bounds.lo.z <= all.lo.z &&
        root_bounds.hi.x >= all.hi.x && root_bounds.hi.y >= all.hi.y && root_bounds.hi.z >= all.hi.z))
    throw InvalidArgument("kd-tree build: the given root bounds do not contain every box");
  const KdClipFunction clip = [](std::uint32_t, const Box& box) { return box; };
  return build(boxes, &clip, nullptr, config, &root_bounds);
}

}  // namespace duplex
