// Kd-tree construction: binned SAH refined to exact events, perfect splits, TBB subtree tasks.
//
// Why binned + refinement rather than the full Wald & Havran event sweep: the sweep needs the
// events of all three axes kept sorted through every split (three event lists per node, merged on
// each partition), which costs memory traffic and is hard to run in parallel. Binning is one
// streaming pass per node; the refinement then sweeps only the exact events that fall into the two
// bins around the best bin boundary, so the chosen plane sits on a primitive bound just like in
// the exact sweep whenever the exact optimum lies in that window (almost always: the binned cost
// is a close upper envelope of the exact one). Both are O(N log N) overall.

#include "duplex/accel/KdTreeBuilder.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"

#include <tbb/task_group.h>

#include <emmintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

namespace duplex {

namespace {

// Bounds as plain arrays: the builder indexes by a run-time axis everywhere, and GLM's
// operator[] is a switch.
struct PrimRef {
  float lo[3], hi[3];  // primitive bounds clipped to the current node
  std::uint32_t id;

  PrimRef(const Box& b, std::uint32_t i) : lo{b.lo.x, b.lo.y, b.lo.z}, hi{b.hi.x, b.hi.y, b.hi.z}, id(i) {}
  [[nodiscard]] Box box() const { return Box({lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}); }
};

struct Subtree {
  std::vector<KdNode> nodes;
  std::vector<std::uint32_t> prims;
};

struct Split {
  int axis = -1;
  float pos = 0.0f;
  float cost = std::numeric_limits<float>::infinity();
  bool planar_left = true;  // primitives lying in the plane go to the lower child
};

constexpr int kBins = 32;

class Builder {
 public:
  Builder(const KdClipFunction& clip, const KdBuildConfig& config, int max_depth)
      : clip_(clip), cfg_(config), max_depth_(max_depth) {}

  void build(std::vector<PrimRef>&& refs, const Box& box, int depth, int bad_refines, Subtree& out) const {
    const std::size_t n = refs.size();
    Split split;
    if (n > 0 && depth < max_depth_) {
      if (cfg_.heuristic == KdHeuristic::Sah) {
        split = findSahSplit(refs, box);
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
      return;
    }

    Box lower_box = box, upper_box = box;
    lower_box.hi[split.axis] = split.pos;
    upper_box.lo[split.axis] = split.pos;
    std::vector<PrimRef> lower, upper;
    partition(refs, split, lower_box, upper_box, lower, upper);
    std::vector<PrimRef>().swap(refs);  // release before recursing

    const std::size_t self = out.nodes.size();
    out.nodes.push_back(KdNode::inner(split.axis, split.pos, 0));
    if (cfg_.parallel_threshold > 0 && n >= cfg_.parallel_threshold) {
      Subtree lo_tree, hi_tree;
      tbb::task_group tasks;
      tasks.run([&] { build(std::move(lower), lower_box, depth + 1, bad_refines, lo_tree); });
      build(std::move(upper), upper_box, depth + 1, bad_refines, hi_tree);
      tasks.wait();
      append(lo_tree, out);
      out.nodes[self].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
      append(hi_tree, out);
    } else {
      build(std::move(lower), lower_box, depth + 1, bad_refines, out);
      out.nodes[self].setUpperChild(static_cast<std::uint32_t>(out.nodes.size()));
      build(std::move(upper), upper_box, depth + 1, bad_refines, out);
    }
  }

 private:
  static void makeLeaf(const std::vector<PrimRef>& refs, Subtree& out) {
    out.nodes.push_back(KdNode::leaf(static_cast<std::uint32_t>(out.prims.size()), static_cast<std::uint32_t>(refs.size())));
    for (const PrimRef& r : refs) out.prims.push_back(r.id);
  }

  // Moves a subtree built with local offsets to the end of `out`, fixing its indices.
  static void append(const Subtree& sub, Subtree& out) {
    const auto node_base = static_cast<std::uint32_t>(out.nodes.size());
    const auto prim_base = static_cast<std::uint32_t>(out.prims.size());
    out.nodes.reserve(out.nodes.size() + sub.nodes.size());
    for (KdNode node : sub.nodes) {
      if (node.isLeaf())
        node.setPrimOffset(node.primOffset() + prim_base);
      else
        node.setUpperChild(node.upperChild() + node_base);
      out.nodes.push_back(node);
    }
    out.prims.insert(out.prims.end(), sub.prims.begin(), sub.prims.end());
  }

  // SAH cost terms of one node: the surface area of a child is 2 (ab + len (a + b)) where a, b
  // are the node's extents on the other two axes and len its extent on the split axis.
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

  float splitCost(const NodeGeometry& g, int axis, float pos, std::size_t n_lower, std::size_t n_upper) const {
    const float p_lower = (g.ab[axis] + (pos - g.lo[axis]) * g.a_plus_b[axis]) * g.inv_half_area;
    const float p_upper = (g.ab[axis] + (g.hi[axis] - pos) * g.a_plus_b[axis]) * g.inv_half_area;
    float cost = cfg_.traversal_cost +
                 cfg_.intersection_cost * (p_lower * static_cast<float>(n_lower) + p_upper * static_cast<float>(n_upper));
    if (n_lower == 0 || n_upper == 0) cost *= 1.0f - cfg_.empty_bonus;
    return cost;
  }

  // Nodes this small are swept exactly on all axes; binning would cost more than it saves.
  static constexpr std::size_t kExactSweepMax = 12;

  Split findSahSplit(const std::vector<PrimRef>& refs, const Box& box) const {
    const NodeGeometry g(box);
    if (!(g.inv_half_area > 0.0f)) return {};
    if (refs.size() <= kExactSweepMax) {
      Split best;
      for (int axis = 0; axis < 3; ++axis) {
        if (!(g.hi[axis] > g.lo[axis])) continue;
        const Split s = sweepEvents(refs, g, axis, g.lo[axis], g.hi[axis]);
        if (s.cost < best.cost) best = s;
      }
      return best;
    }

    // 1. Binned estimate on every axis with a positive extent, one pass over the references.
    // Fewer bins for smaller nodes: the window refinement below recovers the exact plane, and
    // evaluating 3 x 31 candidates dominated the build time of the many mid-sized nodes.
    const int bins = refs.size() < 64 ? 8 : (refs.size() < 1024 ? 16 : kBins);
    float scale[3];
    for (int axis = 0; axis < 3; ++axis)
      scale[axis] = g.hi[axis] > g.lo[axis] ? static_cast<float>(bins) / (g.hi[axis] - g.lo[axis]) : 0.0f;
    std::array<std::array<std::uint32_t, kBins>, 3> starts_bin{}, ends_bin{};
    // Bin indices of the three axes at once (SSE2): this loop runs over every reference of every
    // node and was a fifth of the build. Clamping in float before the conversion also keeps
    // out-of-range values (rounding at the box faces) defined.
    const __m128 node_lo = _mm_setr_ps(g.lo[0], g.lo[1], g.lo[2], 0.0f);
    const __m128 node_scale = _mm_setr_ps(scale[0], scale[1], scale[2], 0.0f);
    const __m128 max_bin = _mm_set1_ps(static_cast<float>(bins - 1));
    alignas(16) std::int32_t b0[4], b1[4];
    for (const PrimRef& r : refs) {
      // lo[0..2] then hi[0]; hi[0..2] then the id: the fourth lanes are scaled by 0 and ignored.
      const __m128 lo = _mm_loadu_ps(r.lo);
      const __m128 hi = _mm_loadu_ps(r.hi);
      const __m128 f0 = _mm_mul_ps(_mm_sub_ps(lo, node_lo), node_scale);
      const __m128 f1 = _mm_mul_ps(_mm_sub_ps(hi, node_lo), node_scale);
      _mm_store_si128(reinterpret_cast<__m128i*>(b0),
                      _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f0, _mm_setzero_ps()), max_bin)));
      _mm_store_si128(reinterpret_cast<__m128i*>(b1),
                      _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f1, _mm_setzero_ps()), max_bin)));
      for (int axis = 0; axis < 3; ++axis) {
        ++starts_bin[axis][b0[axis]];
        ++ends_bin[axis][b1[axis]];
      }
    }
    Split best;
    int best_bin = -1;
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = g.lo[axis], hi = g.hi[axis];
      if (!(hi > lo)) continue;
      std::size_t n_lower = 0, n_upper = refs.size();
      for (int j = 1; j < bins; ++j) {
        n_lower += starts_bin[axis][j - 1];
        n_upper -= ends_bin[axis][j - 1];
        const float pos = lo + (hi - lo) * (static_cast<float>(j) / static_cast<float>(bins));
        if (!(pos > lo && pos < hi)) continue;
        const float cost = splitCost(g, axis, pos, n_lower, n_upper);
        if (cost < best.cost) {
          best = {axis, pos, cost, true};
          best_bin = j;
        }
      }
    }
    if (best.axis < 0) return best;

    // 2. Exact events in the window of the two bins around the chosen boundary. Only primitive
    // bounds are candidates (the SAH optimum lies on one): a bin boundary that is not an event
    // would let empty-space splits go on forever around a single primitive. When no event falls
    // into the window, the whole axis is swept.
    const int axis = best.axis;
    const float lo = g.lo[axis], hi = g.hi[axis];
    const float win_lo = std::max(lo, lo + (hi - lo) * (static_cast<float>(best_bin - 1) / static_cast<float>(bins)));
    const float win_hi = std::min(hi, lo + (hi - lo) * (static_cast<float>(best_bin + 1) / static_cast<float>(bins)));
    Split refined = sweepEvents(refs, g, axis, win_lo, win_hi);
    if (refined.axis < 0) refined = sweepEvents(refs, g, axis, lo, hi);
    return refined;
  }

  // Exact SAH over the events (clipped bounds) of `axis` that lie in [win_lo, win_hi], after
  // Wald & Havran: a primitive counts below a plane p if its lower bound is < p, above if its
  // upper bound is > p; a primitive lying in p goes to the cheaper side.
  Split sweepEvents(const std::vector<PrimRef>& refs, const NodeGeometry& g, int axis, float win_lo, float win_hi) const {
    std::size_t below_window = 0, above_window = 0;  // lo < win_lo, hi > win_hi
    // Per-thread scratch: this runs once or three times per node, and allocation dominated.
    thread_local std::vector<float> starts, ends, planars;
    starts.clear();
    ends.clear();
    planars.clear();
    for (const PrimRef& r : refs) {
      const float a = r.lo[axis], b = r.hi[axis];
      if (a < win_lo) ++below_window; else if (a <= win_hi) starts.push_back(a);
      if (b > win_hi) ++above_window; else if (b >= win_lo) ends.push_back(b);
      if (a == b && a >= win_lo && a <= win_hi) planars.push_back(a);
    }
    Split best;
    if (starts.empty() && ends.empty()) return best;
    std::sort(starts.begin(), starts.end());
    std::sort(ends.begin(), ends.end());
    std::sort(planars.begin(), planars.end());
    const float lo = g.lo[axis], hi = g.hi[axis];
    std::size_t i_start = 0, i_end = 0, i_planar = 0;
    // Merge the two sorted lists; each distinct value is one candidate plane.
    while (i_start < starts.size() || i_end < ends.size()) {
      const float p = i_end >= ends.size() ? starts[i_start]
                      : i_start >= starts.size() ? ends[i_end]
                                                 : std::min(starts[i_start], ends[i_end]);
      while (i_planar < planars.size() && planars[i_planar] < p) ++i_planar;
      std::size_t n_planar = 0;
      while (i_planar + n_planar < planars.size() && planars[i_planar + n_planar] == p) ++n_planar;
      const std::size_t n_lower = below_window + i_start;                // lo < p
      while (i_end < ends.size() && ends[i_end] <= p) ++i_end;
      const std::size_t n_upper = above_window + (ends.size() - i_end);  // hi > p
      if (p > lo && p < hi) {
        const float cost_l = splitCost(g, axis, p, n_lower + n_planar, n_upper);
        const float cost_u = splitCost(g, axis, p, n_lower, n_upper + n_planar);
        if (cost_l < best.cost) best = {axis, p, cost_l, true};
        if (cost_u < best.cost) best = {axis, p, cost_u, false};
      }
      while (i_start < starts.size() && starts[i_start] <= p) ++i_start;
    }
    return best;
  }

  // Median / spatial-middle plane, on the longest axis where both children get fewer references
  // than the node: otherwise the split only duplicates references (overlapping boxes would then
  // grow the tree to the depth limit). The SAH rejects such splits by cost; these heuristics need
  // the explicit check.
  Split findSimpleSplit(const std::vector<PrimRef>& refs, const Box& box) const {
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
      return {axis, pos, 0.0f, true};
    }
    return {};
  }

  void partition(const std::vector<PrimRef>& refs, const Split& s, const Box& lower_box, const Box& upper_box,
                 std::vector<PrimRef>& lower, std::vector<PrimRef>& upper) const {
    lower.reserve(refs.size());
    upper.reserve(refs.size());
    const int axis = s.axis;
    for (const PrimRef& r : refs) {
      const float a = r.lo[axis], b = r.hi[axis];
      if (a == s.pos && b == s.pos) {
        (s.planar_left ? lower : upper).push_back(r);
        continue;
      }
      const bool to_lower = a < s.pos, to_upper = b > s.pos;
      if (to_lower && !to_upper) {
        lower.push_back(r);
      } else if (to_upper && !to_lower) {
        upper.push_back(r);
      } else {
        // Straddles the plane: re-clip to each child (perfect split). If the clipped part turns
        // out empty on one side the primitive only touched the plane there and is dropped there;
        // the plain box intersection is the fallback when clipping is off.
        for (int side = 0; side < 2; ++side) {
          const Box& child = side == 0 ? lower_box : upper_box;
          const Box bounded = intersection(r.box(), child);
          const Box clipped = cfg_.clip_primitives ? clip_(r.id, bounded) : bounded;
          if (clipped.empty()) continue;
          (side == 0 ? lower : upper).emplace_back(clipped, r.id);
        }
      }
    }
  }

  const KdClipFunction& clip_;
  const KdBuildConfig& cfg_;
  int max_depth_;
};

bool finiteBox(const Box& b) {
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(b.lo[k]) || !std::isfinite(b.hi[k])) return false;
  return !b.empty();
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
  return os << "KdBuildConfig{" << toString(c.heuristic) << ", Ct=" << c.traversal_cost << ", Ci=" << c.intersection_cost
            << ", empty_bonus=" << c.empty_bonus << ", max_depth=" << c.max_depth << ", leaf=" << c.max_leaf_size
            << ", clip=" << c.clip_primitives << "}";
}

KdTree buildKdTree(std::span<const Box> prim_bounds, const KdClipFunction& clip, const KdBuildConfig& config) {
  if (prim_bounds.size() > KdNode::kMaxIndex)
    throw InvalidArgument("kd-tree build: " + std::to_string(prim_bounds.size()) + " primitives exceed the limit of 2^30");
  if (!(config.traversal_cost > 0.0f) || !(config.intersection_cost > 0.0f) || !(config.empty_bonus >= 0.0f) ||
      !(config.empty_bonus < 1.0f) || config.max_depth < 0)
    throw InvalidArgument("kd-tree build: invalid configuration");

  KdTree tree;
  std::vector<PrimRef> refs;
  refs.reserve(prim_bounds.size());
  for (std::size_t i = 0; i < prim_bounds.size(); ++i) {
    if (!finiteBox(prim_bounds[i])) continue;
    refs.emplace_back(prim_bounds[i], static_cast<std::uint32_t>(i));
    tree.bounds.extend(prim_bounds[i]);
  }
  if (refs.empty()) return tree;

  int max_depth = config.max_depth;
  if (max_depth == 0)
    max_depth = static_cast<int>(std::lround(8.0 + 1.3 * std::log2(static_cast<double>(refs.size()))));
  max_depth = std::min(max_depth, 60);  // traversal stack holds 64 entries

  Builder builder(clip, config, max_depth);
  Subtree out;
  out.nodes.reserve(refs.size() * 2);
  out.prims.reserve(refs.size() * 2);
  builder.build(std::move(refs), tree.bounds, 0, 0, out);
  if (out.nodes.size() > KdNode::kMaxIndex || out.prims.size() > 0xFFFFFFFFu)
    throw InvalidArgument("kd-tree build: tree exceeds 2^30 nodes");
  tree.nodes = std::move(out.nodes);
  tree.prim_indices = std::move(out.prims);
  tree.nodes.shrink_to_fit();
  tree.prim_indices.shrink_to_fit();
  return tree;
}

KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config) {
  // Clipping a box primitive to a node is plain intersection; `box` is already that.
  return buildKdTree(boxes, [](std::uint32_t, const Box& box) { return box; }, config);
}

}  // namespace duplex
