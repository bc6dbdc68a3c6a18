// The wide BVH builder (WideBvh.h): top-down binned SAH that fills each 8-wide node directly.
//
// A node starts with its whole range as one child; the child of largest surface area that the SAH
// (or the leaf size) wants split is split in two, until the node has 8 children or none wants a
// split. This is the tree a greedy largest-area-first collapse of the binary SAH tree would give,
// without building the binary tree first. Children that are not leaves become nodes the same way,
// as TBB tasks when they are large. Nodes are written to a temporary pool in completion order and
// then laid out depth-first in one serial pass, so that the result does not depend on the thread
// count or the scheduling.

#include "duplex/accel/WideBvh.h"

#include "duplex/accel/Check.h"
#include "duplex/accel/Error.h"

#include <tbb/blocked_range.h>
#include <tbb/concurrent_vector.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace duplex {

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Below this many wide levels the SAH chooses the splits; deeper (a pathological distribution
// splitting off one primitive at a time) nodes split at the object median, which bounds the depth
// the traversal stack must hold.
constexpr int kSahDepth = 40;
// Ranges of at least this many references are binned in parallel chunks.
constexpr std::uint32_t kParallelBinning = 1u << 15;

struct Ref {
  Box box;
  std::uint32_t prim;
};

struct Bin {
  Box box;
  Box centroids;
  std::uint32_t count = 0;
};

// A range of the reference array with its bounds and centroid bounds.
struct Range {
  std::uint32_t begin = 0, end = 0;
  Box box, centroids;
  [[nodiscard]] std::uint32_t size() const { return end - begin; }
};

// The best split of a range: references whose centroid falls in bins [0, bin] of `bins` bins go
// left, unless axis is -1 (split at the middle index). The sides' bounds come from the bins.
struct Split {
  int axis = -1;
  std::uint32_t bins = 0, bin = 0;
  float cost = kInf;
  Box left_box, left_centroids, right_box, right_centroids;
};

// Bins of the three axes, k per axis: bin(a, b).
struct BinSet {
  std::uint32_t k = 0;
  std::vector<Bin> bins;
  explicit BinSet(std::uint32_t k_) : k(k_), bins(3 * std::size_t{k_}) {}
  Bin& bin(int a, std::uint32_t b) { return bins[a * k + b]; }
  [[nodiscard]] const Bin& bin(int a, std::uint32_t b) const { return bins[a * k + b]; }
  void merge(const BinSet& o) {
    for (std::size_t i = 0; i < bins.size(); ++i) {
      bins[i].box.extend(o.bins[i].box);
      bins[i].centroids.extend(o.bins[i].centroids);
      bins[i].count += o.bins[i].count;
    }
  }
};

class Builder {
 public:
  Builder(std::vector<Ref>& refs, const BvhBuildConfig& config) : refs_(refs), c_(config) {}

  WideBvh run(const Box& bounds, const Box& centroids) {
    WideBvh out;
    out.leaf_block = c_.leaf_block;
    out.bounds = bounds;
    if (refs_.empty()) return out;
    Range root{0, static_cast<std::uint32_t>(refs_.size()), bounds, centroids};
    const Split split = findSplit(root, 0);
    std::uint32_t temp_root;
    if (wantsLeaf(root, split)) temp_root = makeLeaf(root);
    else temp_root = buildNode(root, split, 0);
    layout(temp_root, out);
    return out;
  }

 private:
  static constexpr std::uint32_t kTempLeaf = 0x80000000u;

  [[nodiscard]] float blocks(std::uint32_t n) const {
    return static_cast<float>((n + c_.leaf_block - 1) / c_.leaf_block);
  }
  [[nodiscard]] float leafCost(std::uint32_t n) const { return c_.intersection_cost * blocks(n); }

  [[nodiscard]] bool wantsLeaf(const Range& r, const Split& s) const {
    const std::uint32_t n = r.size();
    if (n <= 1) return true;
    if (n > c_.max_leaf_size) return false;
    return leafCost(n) <= s.cost;
  }

  // The bin of centroid coordinate c on `axis` of range r with k bins; the partition uses the same
  // expression, so that it sends every reference where the binning counted it.
  static std::uint32_t binIndex(const Range& r, std::uint32_t k, int axis, float c) {
    const float ext = r.centroids.hi[axis] - r.centroids.lo[axis];
    const float scale = static_cast<float>(k) * (1.0f - 1e-6f) / ext;
    return std::min(k - 1, static_cast<std::uint32_t>(std::max(0.0f, (c - r.centroids.lo[axis]) * scale)));
  }

  // Bins the centroids of [first, last) on every axis the centroids extend along.
  void binRange(std::uint32_t first, std::uint32_t last, const Range& r, BinSet& out) const {
    bool live[3];
    for (int a = 0; a < 3; ++a) live[a] = r.centroids.hi[a] > r.centroids.lo[a];
    for (std::uint32_t i = first; i < last; ++i) {
      const Ref& ref = refs_[i];
      const glm::vec3 c = ref.box.center();
      for (int a = 0; a < 3; ++a) {
        if (!live[a]) continue;
        Bin& bin = out.bin(a, binIndex(r, out.k, a, c[a]));
        bin.box.extend(ref.box);
        bin.centroids.extend(c);
        ++bin.count;
      }
    }
  }

  Split findSplit(const Range& r, int depth) const {
    Split best;
    const std::uint32_t n = r.size();
    if (n <= 1) return best;
    if (depth >= kSahDepth) return best;  // the object median (axis -1)
    // A node of few references needs no more bins than references.
    const std::uint32_t k = std::min(c_.bins, std::max(2u, n));
    BinSet bins(k);
    if (n >= kParallelBinning && c_.parallel_threshold > 0) {
      bins = tbb::parallel_reduce(
          tbb::blocked_range<std::uint32_t>(r.begin, r.end, 8192), BinSet(k),
          [&](const tbb::blocked_range<std::uint32_t>& sub, BinSet acc) {
            binRange(sub.begin(), sub.end(), r, acc);
            return acc;
          },
          [](BinSet x, const BinSet& y) {
            x.merge(y);
            return x;
          });
    } else {
      binRange(r.begin, r.end, r, bins);
    }
    const float inv_area = r.box.area() > 0.0f ? 1.0f / r.box.area() : 0.0f;
    std::array<float, BvhBuildConfig::kMaxBins> right_cost;
    for (int a = 0; a < 3; ++a) {
      if (!(r.centroids.hi[a] > r.centroids.lo[a])) continue;
      Box acc;
      std::uint32_t count = 0;
      for (std::uint32_t b = k - 1; b > 0; --b) {
        acc.extend(bins.bin(a, b).box);
        count += bins.bin(a, b).count;
        right_cost[b] = acc.area() * blocks(count);
      }
      acc = Box();
      count = 0;
      for (std::uint32_t b = 0; b + 1 < k; ++b) {
        acc.extend(bins.bin(a, b).box);
        count += bins.bin(a, b).count;
        if (count == 0 || count == n) continue;
        const float cost =
            c_.traversal_cost + c_.intersection_cost * (acc.area() * blocks(count) + right_cost[b + 1]) * inv_area;
        if (cost < best.cost) {
          best.axis = a;
          best.bin = b;
          best.cost = cost;
        }
      }
    }
    if (best.axis >= 0) {
      best.bins = k;
      for (std::uint32_t b = 0; b < k; ++b) {
        const Bin& bin = bins.bin(best.axis, b);
        (b <= best.bin ? best.left_box : best.right_box).extend(bin.box);
        (b <= best.bin ? best.left_centroids : best.right_centroids).extend(bin.centroids);
      }
    }
    return best;
  }

  // Splits `r` by `s` into two non-empty ranges with their bounds.
  std::pair<Range, Range> partition(const Range& r, const Split& s) {
    Range left{r.begin, r.begin, Box(), Box()}, right{r.begin, r.end, Box(), Box()};
    if (s.axis >= 0) {
      auto* mid = std::partition(refs_.data() + r.begin, refs_.data() + r.end, [&](const Ref& ref) {
        return binIndex(r, s.bins, s.axis, ref.box.center()[s.axis]) <= s.bin;
      });
      const auto m = static_cast<std::uint32_t>(mid - refs_.data());
      // The binned count decided the cost; the same rule of bin index on the same float makes the
      // partition agree with it, so neither side can be empty.
      DUPLEX_CHECK(m > r.begin && m < r.end);
      left.end = right.begin = m;
      left.box = s.left_box;
      left.centroids = s.left_centroids;
      right.box = s.right_box;
      right.centroids = s.right_centroids;
      return {left, right};
    } else {
      // No axis separates the centroids (or too deep for the SAH): the middle by index, after
      // ordering by centroid on the longest axis so that the halves are spatially coherent.
      const std::uint32_t m = r.begin + r.size() / 2;
      const int axis = r.centroids.longestAxis();
      std::nth_element(refs_.data() + r.begin, refs_.data() + m, refs_.data() + r.end,
                       [axis](const Ref& a, const Ref& b) {
                         return a.box.lo[axis] + a.box.hi[axis] < b.box.lo[axis] + b.box.hi[axis];
                       });
      left.end = right.begin = m;
    }
    for (Range* side : {&left, &right}) {
      for (std::uint32_t i = side->begin; i < side->end; ++i) {
        side->box.extend(refs_[i].box);
        side->centroids.extend(refs_[i].box.center());
      }
    }
    return {left, right};
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
      auto [lo, hi] = partition(children[pick].range, children[pick].split);
      const Split ls = findSplit(lo, depth + 1), hs = findSplit(hi, depth + 1);
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
  tbb::concurrent_vector<BvhNode8> nodes_;
  tbb::concurrent_vector<std::pair<std::uint32_t, std::uint32_t>> leaves_;
};

}  // namespace

WideBvh buildWideBvh(std::span<const Box> prim_bounds, const BvhBuildConfig& config, const BvhClipFunction& clip) {
  config.validate();
  if (prim_bounds.size() > std::size_t{BvhRef::kMaxLeafBlock})
    throw InvalidArgument("BVH: " + std::to_string(prim_bounds.size()) + " primitives, more than the encoding holds (" +
                          std::to_string(BvhRef::kMaxLeafBlock) + ")");
  (void)clip;  // spatial splits: see below
  if (config.spatial_split_alpha > 0.0f)
    throw InvalidArgument("BVH: spatial splits (alpha > 0, the high preset) are not available in this build");
  std::vector<Ref> refs;
  refs.reserve(prim_bounds.size());
  Box bounds, centroids;
  for (std::size_t i = 0; i < prim_bounds.size(); ++i) {
    const Box& b = prim_bounds[i];
    if (b.empty() || !b.finite()) continue;
    refs.push_back({b, static_cast<std::uint32_t>(i)});
    bounds.extend(b);
    centroids.extend(b.center());
  }
  Builder builder(refs, config);
  return builder.run(bounds, centroids);
}

double WideBvh::sahCost(const BvhBuildConfig& config) const {
  if (root == BvhRef::kEmpty || bounds.area() <= 0.0f) return 0.0;
  const double inv_root = 1.0 / bounds.area();
  auto blocks = [&](std::uint32_t n) { return static_cast<double>((n + leaf_block - 1) / leaf_block); };
  if (BvhRef::isLeaf(root)) return config.intersection_cost * blocks(BvhRef::leafCount(root));
  double cost = config.traversal_cost;  // the root, entered by every ray that hits the bounds
  for (const BvhNode8& node : nodes) {
    for (int k = 0; k < BvhNode8::kWidth; ++k) {
      const std::uint32_t c = node.child[k];
      if (c == BvhRef::kEmpty) continue;
      const double p = node.childBox(k).area() * inv_root;
      cost +=
          BvhRef::isLeaf(c) ? p * config.intersection_cost * blocks(BvhRef::leafCount(c)) : p * config.traversal_cost;
    }
  }
  return cost;
}

void refitWideBvh(WideBvh& bvh, std::span<const Box> prim_bounds) {
  auto leafBox = [&](std::uint32_t ref) {
    Box b;
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    for (std::uint32_t i = 0; i < BvhRef::leafCount(ref); ++i) {
      const std::uint32_t prim = bvh.prim_indices[first + i];
      if (prim >= prim_bounds.size()) throw InvalidArgument("refitWideBvh: primitive index beyond the boxes given");
      b.extend(prim_bounds[prim]);
    }
    return b;
  };
  if (bvh.root == BvhRef::kEmpty) return;
  if (BvhRef::isLeaf(bvh.root)) {
    bvh.bounds = leafBox(bvh.root);
    return;
  }
  // Children come after their parents: in reverse order every child box is final when read.
  std::vector<Box> node_box(bvh.nodes.size());
  for (std::size_t n = bvh.nodes.size(); n-- > 0;) {
    BvhNode8& node = bvh.nodes[n];
    Box all;
    for (int k = 0; k < BvhNode8::kWidth; ++k) {
      const std::uint32_t c = node.child[k];
      if (c == BvhRef::kEmpty) continue;
      const Box b = BvhRef::isLeaf(c) ? leafBox(c) : node_box[c];
      node.setChild(k, c, b);
      all.extend(b);
    }
    node_box[n] = all;
  }
  bvh.bounds = node_box[0];
}

}  // namespace duplex
