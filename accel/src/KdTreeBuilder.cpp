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
//
// This file drives the build (the recursion, the split search, leaves and subtrees); the parts it
// uses live apart: KdBins.h (binning), KdSah.h (SAH costs), KdEventSweep.h/.cpp (exact sweeps),
// KdPartition.h/.cpp (the partition), KdBuildConfig.cpp (names and printing of the configuration).

#include "duplex/accel/KdTreeBuilder.h"

#include "duplex/accel/Check.h"
#include "duplex/accel/Error.h"
#include "KdBins.h"
#include "KdBuildRefs.h"
#include "KdEventSweep.h"
#include "KdPartition.h"
#include "KdSah.h"

#include <tbb/task_group.h>

#include <emmintrin.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace duplex {

namespace {

using namespace kd_detail;

struct Subtree {
  std::vector<KdNode> nodes;
  std::vector<std::uint32_t> prims;
};

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
          DUPLEX_DCHECK(n_pending < static_cast<int>(pending.size()));
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
      partition(refs, split, extent, lower, upper, cfg_, clip_, split_);
      // A child receives each reference at most once (its storage is sized for that).
      DUPLEX_DCHECK(lower.refs.size() <= n && upper.refs.size() <= n);
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
  [[nodiscard]] bool parallelPasses() const { return cfg_.parallel_threshold > 0; }

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
      const __m128 c = sah_.splitCost4(g, axis, p, nl, nu);
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
          const float cost = sah_.splitCost(g, axis, r.lo[axis], 0, 1);
          if (cost < best.cost) best = {axis, r.lo[axis], cost, false, 0, 1, true};
        }
        if (r.hi[axis] < g.hi[axis] && r.hi[axis] > g.lo[axis]) {
          const float cost = sah_.splitCost(g, axis, r.hi[axis], 1, 0);
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
        const Split s = small ? sweepSmall(sah_, g, axis, events, n)
                        : n <= SmallEvents::kMax
                            ? sweepSorted(sah_, g, axis, events.starts[axis], events.n_starts[axis], events.ends[axis],
                                          events.n_ends[axis], events.planars[axis], events.n_planars[axis], 0, 0)
                            : sweepEvents(sah_, refs, g, axis, g.lo[axis], g.hi[axis], parallelPasses());
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
      binRefs(refs, own, parallelPasses());
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
        const float cost = sah_.splitCost(g, axis, extent.lo[axis], 0, n);
        if (cost < best.cost) best = {axis, extent.lo[axis], cost, false, 0, n, true}, best_bin = -1;
      }
      if (extent.hi[axis] < hi && extent.hi[axis] > lo) {
        const float cost = sah_.splitCost(g, axis, extent.hi[axis], n, 0);
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
    const Split refined = sweepEvents(sah_, refs, g, axis, win_lo, win_hi, parallelPasses());
    return refined.axis >= 0 ? refined : best;
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

  const KdClipFunction* clip_;
  const KdSplitFunction* split_;
  const KdBuildConfig& cfg_;
  SahCost sah_{cfg_};
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
  DUPLEX_CHECK(total <= n);
  refs.resize(total);
}

}  // namespace

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
  // The root first: a leaf, or an inner node with both subtrees after it.
  DUPLEX_CHECK(!out.nodes.empty() && (out.nodes.front().isLeaf() || out.nodes.size() >= 3));
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
