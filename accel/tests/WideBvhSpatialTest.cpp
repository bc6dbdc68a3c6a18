// The wide BVH builder's spatial splits (the High preset) and its determinism: primitives are
// line segments, whose exact clip is simple, so that coverage can be checked point by point.

#include "TestSupport.h"

#include "duplex/accel/WideBvh.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <vector>

namespace duplex {
namespace {

struct Segment {
  glm::vec3 a, b;
  // Exactly a at 0 and b at 1.
  [[nodiscard]] glm::vec3 at(float t) const { return (1.0f - t) * a + t * b; }
};

Box segmentBox(const Segment& s) {
  Box box;
  box.extend(s.a);
  box.extend(s.b);
  return box;
}

// Diagonal segments of up to `length` in a unit cube: their boxes overlap much more than the
// segments do, which is where spatial splits pay.
std::vector<Segment> diagonalSegments(std::size_t n, unsigned seed, float length = 0.1f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Segment> out;
  for (std::size_t i = 0; i < n; ++i) {
    const glm::vec3 p = test::draw3(u, rng);
    const glm::vec3 d = test::draw3(u, rng) - 0.5f;
    out.push_back({p - length * d, p + length * d});
  }
  return out;
}

// The part of segment s inside `box` (closed), split at `pos` on `axis`: the bounds of each part,
// widened by kSlack (far above the rounding of the end points, far below the cube) and limited to
// the box and to its side of the plane.
BvhClipFunction segmentClip(const std::vector<Segment>& segs) {
  return [&segs](std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper) {
    const Segment& s = segs[prim];
    lower = upper = Box();
    double t0 = 0.0, t1 = 1.0;
    for (int k = 0; k < 3; ++k) {
      const double a = s.a[k], d = double(s.b[k]) - a;
      if (d == 0.0) {
        if (a < box.lo[k] || a > box.hi[k]) return;
        continue;
      }
      double ta = (box.lo[k] - a) / d, tb = (box.hi[k] - a) / d;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    if (t0 > t1) return;
    const double a = s.a[axis], d = double(s.b[axis]) - a;
    const double tp = d == 0.0 ? (a <= pos ? 2.0 : -1.0) : (pos - a) / d;
    auto part = [&](double from, double to, Box& out) {
      if (from > to) return;
      constexpr float kSlack = 1e-5f;
      for (double t : {from, to}) {
        const glm::vec3 p = s.at(float(t));
        out.extend(p - kSlack);
        out.extend(p + kSlack);
      }
      out = intersection(out, box);
    };
    const bool lower_first = d >= 0.0;
    const double lo_end = std::clamp(tp, t0, t1);
    if (d == 0.0) {
      part(t0, t1, a <= pos ? lower : upper);
    } else if (lower_first) {
      part(t0, lo_end, lower);
      part(lo_end, t1, upper);
    } else {
      part(lo_end, t1, lower);
      part(t0, lo_end, upper);
    }
    if (!lower.empty()) lower.hi[axis] = std::min(lower.hi[axis], pos);
    if (!upper.empty()) upper.lo[axis] = std::max(upper.lo[axis], pos);
  };
}

// Calls f(prim, leaf box) for every leaf entry of the tree.
template <class F>
void forEachLeafEntry(const WideBvh& bvh, F&& f) {
  auto leaf = [&](std::uint32_t ref, const Box& box) {
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    for (std::uint32_t i = 0; i < BvhRef::leafCount(ref); ++i) f(bvh.prim_indices[first + i], box);
  };
  if (BvhRef::isLeaf(bvh.root)) leaf(bvh.root, bvh.bounds);
  for (const BvhNode8& node : bvh.nodes)
    for (int k = 0; k < BvhNode8::kWidth; ++k)
      if (BvhRef::isLeaf(node.child[k])) leaf(node.child[k], node.childBox(k));
}

std::size_t leafEntries(const WideBvh& bvh) {
  std::size_t n = 0;
  forEachLeafEntry(bvh, [&](std::uint32_t, const Box&) { ++n; });
  return n;
}

BvhBuildConfig high() { return BvhBuildConfig::preset(BvhPreset::High); }

TEST(WideBvhSpatial, EveryPointOfEverySegmentIsInALeafReferencingIt) {
  const auto segs = diagonalSegments(3000, 5);
  std::vector<Box> boxes;
  for (const Segment& s : segs) boxes.push_back(segmentBox(s));
  const WideBvh bvh = buildWideBvh(boxes, high(), segmentClip(segs));
  std::vector<std::vector<Box>> leaves(segs.size());
  forEachLeafEntry(bvh, [&](std::uint32_t prim, const Box& box) {
    ASSERT_LT(prim, segs.size());
    leaves[prim].push_back(box);
  });
  std::size_t duplicated = 0;
  for (std::size_t i = 0; i < segs.size(); ++i) {
    ASSERT_FALSE(leaves[i].empty()) << "segment " << i << " not referenced";
    duplicated += leaves[i].size() > 1 ? 1 : 0;
    for (int j = 0; j <= 64; ++j) {
      const glm::vec3 p = segs[i].at(float(j) / 64.0f);
      const bool covered = std::any_of(leaves[i].begin(), leaves[i].end(), [&](const Box& b) {
        return p.x >= b.lo.x && p.x <= b.hi.x && p.y >= b.lo.y && p.y <= b.hi.y && p.z >= b.lo.z && p.z <= b.hi.z;
      });
      ASSERT_TRUE(covered) << "segment " << i << " point " << j << " in no leaf referencing it";
    }
  }
  EXPECT_GT(duplicated, segs.size() / 20) << "spatial splits should duplicate some long segments";
}

TEST(WideBvhSpatial, DuplicatesStayWithinTheBudgetAndLowerTheSah) {
  const auto segs = diagonalSegments(4000, 9);
  std::vector<Box> boxes;
  for (const Segment& s : segs) boxes.push_back(segmentBox(s));
  const WideBvh medium = buildWideBvh(boxes, BvhBuildConfig::preset(BvhPreset::Medium), segmentClip(segs));
  EXPECT_EQ(leafEntries(medium), segs.size());
  for (const float budget : {0.05f, 0.5f}) {
    BvhBuildConfig c = high();
    c.spatial_split_budget = budget;
    const WideBvh bvh = buildWideBvh(boxes, c, segmentClip(segs));
    const std::size_t entries = leafEntries(bvh);
    EXPECT_GT(entries, segs.size()) << "budget " << budget;
    EXPECT_LE(entries, segs.size() + std::size_t(budget * segs.size())) << "budget " << budget;
    EXPECT_LT(bvh.sahCost(c), medium.sahCost(c)) << "budget " << budget;
  }
  // No clip function: no spatial splits, whatever the config says.
  const WideBvh unclipped = buildWideBvh(boxes, high());
  EXPECT_EQ(leafEntries(unclipped), segs.size());
}

void expectSameTree(const WideBvh& a, const WideBvh& b) {
  ASSERT_EQ(a.root, b.root);
  ASSERT_EQ(a.nodes.size(), b.nodes.size());
  EXPECT_EQ(0, std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode8)));
  EXPECT_EQ(a.prim_indices, b.prim_indices);
  EXPECT_EQ(a.bounds, b.bounds);
}

TEST(WideBvhSpatial, TreeDoesNotDependOnThreadsOrTheParallelThreshold) {
  // Large enough for parallel binning and subtree tasks.
  const auto segs = diagonalSegments(60000, 3, 0.02f);
  std::vector<Box> boxes;
  for (const Segment& s : segs) boxes.push_back(segmentBox(s));
  for (const BvhPreset preset : {BvhPreset::Medium, BvhPreset::High}) {
    SCOPED_TRACE(std::string(toString(preset)));
    BvhBuildConfig parallel = BvhBuildConfig::preset(preset), serial = parallel;
    serial.parallel_threshold = 0;
    parallel.parallel_threshold = 256;
    const BvhClipFunction clip = segmentClip(segs);
    WideBvh one, two;
    tbb::task_arena(1).execute([&] { one = buildWideBvh(boxes, serial, clip); });
    tbb::task_arena(2).execute([&] { two = buildWideBvh(boxes, parallel, clip); });
    const WideBvh dflt = buildWideBvh(boxes, BvhBuildConfig::preset(preset), clip);
    expectSameTree(one, two);
    expectSameTree(one, dflt);
    if (preset == BvhPreset::High) {
      EXPECT_GT(leafEntries(one), segs.size()) << "no spatial split was exercised";
    }
  }
}

}  // namespace
}  // namespace duplex
