// The generic kd-tree builder (buildKdTree / buildKdTreeOverBoxes) used directly, with the
// invariant checker, and the generic traversal (traverseKdTree) with a box "primitive" against a
// brute force; plus the small value types the builder rests on (Box, KdNode, KdBuildConfig parsing
// and validation). Triangles are clipped with the mesh type's clipTriangleToBox, as MeshObject does.

#include "KdTreeChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdNode.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/TriangleClip.h"
#include "RadixSortFloats.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

KdTree buildOverTriangles(const std::vector<std::array<glm::vec3, 3>>& tris, const KdBuildConfig& config) {
  std::vector<Box> bounds(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i)
    for (const auto& v : tris[i]) bounds[i].extend(v);
  return buildKdTree(
      bounds,
      [&](std::uint32_t prim, const Box& box) {
        return clipTriangleToBox(tris[prim][0], tris[prim][1], tris[prim][2], box);
      },
      config);
}

/// Random boxes in [0, 4]^3: ordinary ones, flat ones (zero extent on one axis), points, and boxes
/// snapped to a coarse grid so that many share faces with each other and with split planes.
std::vector<Box> randomBoxes(std::size_t count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 4.0f), s(0.0f, 0.4f);
  std::vector<Box> boxes;
  for (std::size_t i = 0; i < count; ++i) {
    glm::vec3 lo = draw3(u, rng);
    glm::vec3 hi = lo + draw3(s, rng);
    switch (i % 6) {
      case 1: hi[i % 3] = lo[i % 3]; break;  // flat
      case 2: hi = lo; break;                // point
      case 3:                                // on a grid of step 0.5
        lo = glm::floor(lo * 2.0f) * 0.5f;
        hi = lo + glm::vec3(0.5f * static_cast<float>(1 + rng() % 3));
        break;
      default: break;
    }
    boxes.emplace_back(lo, hi);
  }
  return boxes;
}

// The build's radix sort of event lists (kd_detail::radixSortFloats) against std::sort, bit for bit
// up to the order of -0 and +0 (which compare equal; the radix sort puts -0 first): random lists of
// 32 to 3,000 values mixing signs, zeros of both signs, denormals, infinities, repeated values,
// all-equal lists and values that differ in one byte only. A wrong order would only make the SAH
// choose worse planes (the trees would stay valid), so it is tested here directly.
TEST(KdTreeBuilder, EventRadixSortEqualsStdSort) {
  std::mt19937 rng(77);
  const float specials[] = {0.0f,
                            -0.0f,
                            std::numeric_limits<float>::denorm_min(),
                            -std::numeric_limits<float>::denorm_min(),
                            std::numeric_limits<float>::infinity(),
                            -std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::max(),
                            -std::numeric_limits<float>::max(),
                            1.0f,
                            -1.0f};
  const auto bitsOf = [](const std::vector<float>& v) {
    std::vector<std::uint32_t> b(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) b[i] = std::bit_cast<std::uint32_t>(v[i]);
    return b;
  };
  for (int trial = 0; trial < 600; ++trial) {
    const std::size_t n = 32 + rng() % 2969;
    std::vector<float> v(n);
    const int kind = trial % 4;
    const float base = std::uniform_real_distribution<float>(-100.0f, 100.0f)(rng);
    for (float& x : v) {
      if (kind == 0) x = std::uniform_real_distribution<float>(-1e3f, 1e3f)(rng);
      else if (kind == 1) x = specials[rng() % std::size(specials)];
      else if (kind == 2)
        x = std::bit_cast<float>(std::bit_cast<std::uint32_t>(base) ^ static_cast<std::uint32_t>(rng() & 0xFFu));
      else if (rng() % 3 == 0) x = specials[rng() % std::size(specials)];
      else {
        const float mantissa = float(rng() % 1000) - 500.0f;
        x = std::ldexp(mantissa, int(rng() % 60) - 30);
      }
    }
    if (trial % 50 == 7) std::fill(v.begin(), v.end(), base);
    std::vector<float> expected = v;
    std::sort(expected.begin(), expected.end());
    std::vector<float> got = v;
    kd_detail::radixSortFloats(got.data(), got.size());
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(got[i], expected[i]) << "trial " << trial << ", position " << i;
      if (i > 0 && got[i] == 0.0f && got[i - 1] == 0.0f) {
        ASSERT_FALSE(!std::signbit(got[i - 1]) && std::signbit(got[i])) << "+0 before -0, trial " << trial;
      }
    }
    std::vector<std::uint32_t> a = bitsOf(v), b = bitsOf(got);
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    ASSERT_EQ(a, b) << "not a permutation of the input, trial " << trial;
  }
}

TEST(KdTreeBuilder, EmptyInputGivesEmptyTree) {
  const KdTree a = buildKdTree({}, [](std::uint32_t, const Box& b) { return b; });
  EXPECT_TRUE(a.empty());
  EXPECT_TRUE(a.nodes.empty());
  EXPECT_TRUE(a.prim_indices.empty());
  EXPECT_TRUE(a.bounds.empty());
  const KdTree b = buildKdTreeOverBoxes({});
  EXPECT_TRUE(b.empty());
  EXPECT_TRUE(b.prim_indices.empty());
  EXPECT_EQ(b.stats(1.0f, 1.5f).nodes, 0u);
  EXPECT_TRUE(checkBoxKdTree(a, {}));
  EXPECT_TRUE(checkBoxKdTree(b, {}));
  // Traversal of an empty tree never calls the leaf function.
  const KdRay ray(Ray{});
  float t = kInf;
  bool called = false;
  EXPECT_FALSE(traverseKdTree<false>(a, ray, t, [&](std::uint32_t, std::uint32_t, float&) { return called = true; }));
  EXPECT_FALSE(called);
}

TEST(KdTreeBuilder, OnlyUnusableBoxesGiveEmptyTree) {
  const std::vector<Box> boxes = {
      Box(),                                              // default: empty
      Box(glm::vec3(1.0f), glm::vec3(0.0f)),              // inverted
      Box(glm::vec3(0.0f, kNaN, 0.0f), glm::vec3(1.0f)),  // NaN
      Box(glm::vec3(0.0f), glm::vec3(1.0f, 1.0f, kInf)),  // infinite
      Box(glm::vec3(-kInf), glm::vec3(kInf)),             // infinite
  };
  const KdTree tree = buildKdTreeOverBoxes(boxes);
  EXPECT_TRUE(tree.empty());
  EXPECT_TRUE(tree.prim_indices.empty());
  EXPECT_TRUE(checkBoxKdTree(tree, boxes));
}

TEST(KdTreeBuilder, NaNAndEmptyBoxesAreLeftOut) {
  std::vector<Box> boxes = randomBoxes(300, 5);
  const std::set<std::size_t> bad = {0, 17, 101, 250, 399};
  boxes[0] = Box(glm::vec3(kNaN), glm::vec3(kNaN));
  boxes[17] = Box(glm::vec3(1.0f, 1.0f, kNaN), glm::vec3(2.0f));
  boxes[101] = Box();
  boxes[250] = Box(glm::vec3(0.0f), glm::vec3(kInf));
  boxes[399] = Box(glm::vec3(3.0f), glm::vec3(2.0f));
  for (const ConfigCase& c : allConfigCases()) {
    SCOPED_TRACE(c.name);
    const KdTree tree = buildKdTreeOverBoxes(boxes, c.config);
    EXPECT_TRUE(checkBoxKdTree(tree, boxes, c.config.max_depth));  // also: no reference to a left-out box
    for (const std::uint32_t id : tree.prim_indices)
      EXPECT_EQ(bad.count(id), 0u) << "left-out box " << id << " referenced";
    for (int k = 0; k < 3; ++k) EXPECT_TRUE(std::isfinite(tree.bounds.lo[k]) && std::isfinite(tree.bounds.hi[k]));
  }
}

// A subtree that replaces a cell of an enclosing tree (the incremental top level) is built with
// the cell as its root: the tree's bounds are the cell, the empty margin around the boxes ends in
// empty leaves, and every box is still covered. A root that does not hold every box is refused.
TEST(KdTreeBuilder, GivenRootBoundsFrameTheTree) {
  const std::vector<Box> boxes = randomBoxes(200, 12);
  Box all;
  for (const Box& b : boxes) all.extend(b);
  const glm::vec3 margin = all.extent();
  const Box root(all.lo - margin, all.hi + 2.0f * margin);
  const KdTree tree = buildKdTreeOverBoxes(boxes, KdBuildConfig{}, root);
  EXPECT_TRUE(checkBoxKdTree(tree, boxes, 0, &root));
  for (std::uint32_t i = 0; i < boxes.size(); ++i) {
    const glm::dvec3 lo(boxes[i].lo), hi(boxes[i].hi);
    EXPECT_TRUE(kdcheck_detail::pointCovered(tree, 0.5 * (lo + hi), i)) << "box " << i;
    EXPECT_TRUE(kdcheck_detail::pointCovered(tree, lo, i)) << "box " << i;
    EXPECT_TRUE(kdcheck_detail::pointCovered(tree, hi, i)) << "box " << i;
  }
  // Points of the margin, near the root's corners, lie in leaves without references.
  for (int corner = 0; corner < 8; ++corner) {
    glm::vec3 p;
    for (int k = 0; k < 3; ++k)
      p[k] = (corner >> k) & 1 ? root.hi[k] - 0.01f * margin[k] : root.lo[k] + 0.01f * margin[k];
    std::uint32_t i = 0;
    while (!tree.nodes[i].isLeaf())
      i = p[tree.nodes[i].axis()] < tree.nodes[i].split() ? i + 1 : tree.nodes[i].upperChild();
    EXPECT_EQ(tree.nodes[i].primCount(), 0u) << "corner " << corner;
  }
  // The cost is that of a ray through the root: cutting off the margin costs a few node steps more
  // than the tree over the boxes' own bounds, scaled by the area ratio.
  const KdTree tight = buildKdTreeOverBoxes(boxes);
  EXPECT_TRUE(checkBoxKdTree(tight, boxes));
  const double area_ratio = static_cast<double>(all.area()) / static_cast<double>(root.area());
  const KdBuildConfig costs{};  // weigh both trees by the costs they were built for
  EXPECT_LT(tree.stats(costs.traversal_cost, costs.intersection_cost).sah_cost,
            tight.stats(costs.traversal_cost, costs.intersection_cost).sah_cost * area_ratio + 6.0);
  const Box too_small(all.lo, all.hi - 0.5f * margin);
  expectErrorNaming<InvalidArgument>([&] { (void)buildKdTreeOverBoxes(boxes, KdBuildConfig{}, too_small); },
                                     "root bounds");
  EXPECT_TRUE(buildKdTreeOverBoxes(std::vector<Box>{Box()}, KdBuildConfig{}, root).empty());
}

TEST(KdTreeBuilder, SingleBoxIsOneLeaf) {
  const std::vector<Box> boxes = {Box(glm::vec3(1.0f, 2.0f, 3.0f), glm::vec3(2.0f, 4.0f, 3.5f))};
  const KdTree tree = buildKdTreeOverBoxes(boxes);
  ASSERT_TRUE(checkBoxKdTree(tree, boxes));
  ASSERT_EQ(tree.nodes.size(), 1u);
  EXPECT_TRUE(tree.nodes[0].isLeaf());
  EXPECT_EQ(tree.bounds, boxes[0]);
  const KdTreeStats st = tree.stats(1.0f, 1.5f);
  EXPECT_EQ(st.leaves, 1u);
  EXPECT_EQ(st.references, 1u);
  EXPECT_DOUBLE_EQ(st.sah_cost, 1.5);  // one leaf of one primitive: Ci * 1
}

class KdTreeBuilderConfigs : public ::testing::TestWithParam<ConfigCase> {};

TEST_P(KdTreeBuilderConfigs, RandomTriangles) {
  const auto tris = randomTriangles(GetParam().config.heuristic == KdHeuristic::Sah ? 2500 : 800, 31);
  const KdTree tree = buildOverTriangles(tris, GetParam().config);
  EXPECT_TRUE(checkTriangleKdTree(tree, tris, std::vector<char>(tris.size(), 1), GetParam().config.max_depth));
}

/// Box count for a heuristic: the simple heuristics split overlapping boxes to the depth limit
/// (see SimpleHeuristicsStopWhenASplitSeparatesNothing), so their trees grow too fast for big inputs.
std::size_t boxCount(const KdBuildConfig& c, std::size_t sah_count) {
  return c.heuristic == KdHeuristic::Sah ? sah_count : 300;
}

TEST_P(KdTreeBuilderConfigs, RandomBoxes) {
  const auto boxes = randomBoxes(boxCount(GetParam().config, 2500), 32);
  const KdTree tree = buildKdTreeOverBoxes(boxes, GetParam().config);
  EXPECT_TRUE(checkBoxKdTree(tree, boxes, GetParam().config.max_depth));
}

TEST_P(KdTreeBuilderConfigs, IdenticalBoxes) {
  // Copies of one box and a few others: no split can separate the copies.
  std::vector<Box> boxes(GetParam().config.heuristic == KdHeuristic::Sah ? 300 : 12,
                         Box(glm::vec3(1.0f), glm::vec3(2.0f)));
  boxes.emplace_back(glm::vec3(5.0f), glm::vec3(6.0f));
  boxes.emplace_back(glm::vec3(-3.0f), glm::vec3(-2.5f));
  const KdTree tree = buildKdTreeOverBoxes(boxes, GetParam().config);
  EXPECT_TRUE(checkBoxKdTree(tree, boxes, GetParam().config.max_depth));
}

TEST_P(KdTreeBuilderConfigs, CoplanarTrianglesOnSplitCandidates) {
  // Triangles lying in a few shared axis planes (planar events), including the planes of other
  // triangles' bounds: the planar-left/right choice must keep them referenced.
  std::vector<std::array<glm::vec3, 3>> tris;
  for (int level = 0; level < 5; ++level)
    for (int i = 0; i < 40; ++i) {
      const float z = 0.25f * static_cast<float>(level);
      const float x = 0.1f * static_cast<float>(i % 10), y = 0.1f * static_cast<float>(i / 10);
      tris.push_back({glm::vec3(x, y, z), glm::vec3(x + 0.1f, y, z), glm::vec3(x, y + 0.1f, z)});
      tris.push_back({glm::vec3(x, y, z), glm::vec3(x, y + 0.1f, z + 0.25f), glm::vec3(x + 0.05f, y, z + 0.25f)});
    }
  const KdTree tree = buildOverTriangles(tris, GetParam().config);
  EXPECT_TRUE(checkTriangleKdTree(tree, tris, std::vector<char>(tris.size(), 1), GetParam().config.max_depth));
}

INSTANTIATE_TEST_SUITE_P(AllHeuristics, KdTreeBuilderConfigs, ::testing::ValuesIn(allConfigCases()),
                         [](const auto& info) { return info.param.name; });

// A split that sends every primitive of a node to both children separates nothing: it only
// doubles the references below it. Overlapping primitives (instances placed at one spot, big boxes
// over small ones) must not make the tree grow exponentially up to the depth limit.
TEST(KdTreeBuilder, SimpleHeuristicsStopWhenASplitSeparatesNothing) {
  std::vector<Box> boxes(24, Box(glm::vec3(1.0f), glm::vec3(2.0f)));
  boxes.emplace_back(glm::vec3(5.0f), glm::vec3(6.0f));
  for (const KdHeuristic h : {KdHeuristic::Sah, KdHeuristic::Median, KdHeuristic::SpatialMiddle}) {
    SCOPED_TRACE(toString(h));
    KdBuildConfig c;
    c.heuristic = h;
    const KdTree tree = buildKdTreeOverBoxes(boxes, c);
    ASSERT_TRUE(checkBoxKdTree(tree, boxes));
    // Primitive sets of every subtree (post-order over the depth-first array).
    std::vector<std::set<std::uint32_t>> prims(tree.nodes.size());
    std::size_t useless = 0;
    for (std::size_t i = tree.nodes.size(); i-- > 0;) {
      const KdNode& n = tree.nodes[i];
      if (n.isLeaf()) {
        prims[i].insert(tree.prim_indices.begin() + n.primOffset(),
                        tree.prim_indices.begin() + n.primOffset() + n.primCount());
        continue;
      }
      prims[i] = prims[i + 1];
      prims[i].insert(prims[n.upperChild()].begin(), prims[n.upperChild()].end());
      if (prims[i + 1] == prims[i] && prims[n.upperChild()] == prims[i] && prims[i].size() > 1) ++useless;
    }
    EXPECT_EQ(useless, 0u) << "inner nodes whose two children both hold all of the node's primitives (of "
                           << tree.nodes.size() << " nodes)";
    EXPECT_LE(tree.prim_indices.size(), 4 * boxes.size()) << "references for " << boxes.size() << " boxes";
  }
}

TEST(KdTreeBuilder, ExplicitDepthLimitIsHonoured) {
  const auto boxes = randomBoxes(3000, 8);
  for (const int depth : {1, 3, 7}) {
    KdBuildConfig c;
    c.max_depth = depth;
    const KdTree tree = buildKdTreeOverBoxes(boxes, c);
    EXPECT_TRUE(checkBoxKdTree(tree, boxes, depth));
    EXPECT_LE(tree.stats(1.0f, 1.5f).max_depth, static_cast<std::uint32_t>(depth));
  }
}

/// Every node's fields, so that two trees can be compared node for node.
std::vector<std::array<std::uint32_t, 3>> nodeFields(const KdTree& tree) {
  std::vector<std::array<std::uint32_t, 3>> out;
  for (const KdNode& n : tree.nodes)
    out.push_back(n.isLeaf() ? std::array<std::uint32_t, 3>{3u, n.primOffset(), n.primCount()}
                             : std::array<std::uint32_t, 3>{static_cast<std::uint32_t>(n.axis()),
                                                            std::bit_cast<std::uint32_t>(n.split()), n.upperChild()});
  return out;
}

TEST(KdTreeBuilder, ParallelBuildEqualsSerialBuild) {
  // 70,000 small triangles: the root's partition runs in parallel chunks (from 65,536 references)
  // and subtrees run as tasks. Chunks are concatenated in order and their bins summed, so the tree
  // must be the serial one, node for node.
  std::mt19937_64 rng(123);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), d(-0.01f, 0.01f);
  std::vector<std::array<glm::vec3, 3>> tris;
  while (tris.size() < 70000) {
    const glm::vec3 c = draw3(u, rng) * glm::vec3(1.0f, 1.0f, 0.2f);
    tris.push_back({c, c + draw3(d, rng), c + draw3(d, rng)});
  }
  KdBuildConfig serial;
  serial.parallel_threshold = 0;
  KdBuildConfig parallel;
  parallel.parallel_threshold = 512;
  const KdTree a = buildOverTriangles(tris, serial);
  KdTree b;
  tbb::task_arena arena(4);
  arena.execute([&] { b = buildOverTriangles(tris, parallel); });
  EXPECT_EQ(nodeFields(a), nodeFields(b));
  EXPECT_EQ(a.prim_indices, b.prim_indices);
  EXPECT_GT(a.nodes.size(), 10000u);
}

TEST(KdTreeBuilder, ChunkedPassesEqualSerialPassesWithSignedZerosAndSkippedBoxes) {
  // 40,000 boxes: the root's preparation, binning, event collection and partition run in parallel
  // chunks (from 16,384 references) and must give the serial passes' tree bit for bit. Traps for a
  // chunked pass: unusable (NaN, empty) boxes inside chunks, which the preparation skips and whose
  // gaps it must close in order; and the lower bound x = 0 of every second box, stored as -0 in the
  // first half of the input and +0 in the second, so that the exact extent of the lower child (which
  // the serial pass folds with _mm_min_ps, the later of two equal values winning) decides the sign
  // of the empty-space cut at x = 0; a merge of chunk extents that kept the earlier value would
  // give -0 there.
  constexpr std::size_t kCount = 40000;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), s(0.001f, 0.02f);
  std::vector<Box> boxes;
  for (std::size_t i = 0; i < kCount; ++i) {
    if (i % 997 == 13) {
      boxes.push_back(i % 2 ? Box({kNaN, 0.0f, 0.0f}, {1.0f, 1.0f, 1.0f}) : Box());
      continue;
    }
    const float zero = i < kCount / 2 ? -0.0f : 0.0f;
    const glm::vec3 r = draw3(u, rng);
    const glm::vec3 lo = i % 2 == 0 ? glm::vec3(zero, r.y, r.z)                       // x from 0, y in [0, 1]
                                    : glm::vec3(2.0f * r.x - 1.0f, 2.0f + r.y, r.z);  // x from -1, y in [2, 3]
    boxes.emplace_back(lo, lo + draw3(s, rng));
  }
  KdBuildConfig serial;
  serial.intersection_cost = 1.0f;  // as the top level: small leaves, many cuts
  serial.parallel_threshold = 0;
  const KdTree a = buildKdTreeOverBoxes(boxes, serial);
  // The serial tree has the +0 cut (else the trap is not armed) and no -0 split.
  std::size_t plus_zero = 0, minus_zero = 0;
  for (const KdNode& n : a.nodes)
    if (!n.isLeaf() && n.axis() == 0 && n.split() == 0.0f) (std::signbit(n.split()) ? minus_zero : plus_zero) += 1;
  EXPECT_GT(plus_zero, 0u);
  EXPECT_EQ(minus_zero, 0u);
  for (const int threads : {1, 2, 4}) {
    KdBuildConfig parallel = serial;
    parallel.parallel_threshold = KdBuildConfig{}.parallel_threshold;
    KdTree b;
    tbb::task_arena arena(threads);
    arena.execute([&] { b = buildKdTreeOverBoxes(boxes, parallel); });
    EXPECT_EQ(nodeFields(a), nodeFields(b)) << threads << " threads";
    EXPECT_EQ(a.prim_indices, b.prim_indices) << threads << " threads";
    EXPECT_EQ(a.bounds, b.bounds);
  }
}

TEST(KdTreeBuilder, BinningKnobsKeepInvariants) {
  // Exact sweeps everywhere / nowhere, refinement never / only in small nodes.
  const auto tris = randomTriangles(2500, 41);
  const auto boxes = randomBoxes(2500, 42);
  for (const std::uint32_t exact : {0u, 1u, 64u})
    for (const std::uint32_t refine : {0u, 16u}) {
      KdBuildConfig c;
      c.exact_sweep_max = exact;
      c.refine_max = refine;
      SCOPED_TRACE(::testing::Message() << c);
      EXPECT_TRUE(checkTriangleKdTree(buildOverTriangles(tris, c), tris, std::vector<char>(tris.size(), 1)));
      EXPECT_TRUE(checkBoxKdTree(buildKdTreeOverBoxes(boxes, c), boxes));
    }
}

TEST(KdTreeBuilder, InvalidConfigurationThrows) {
  const std::vector<Box> boxes = {Box(glm::vec3(0.0f), glm::vec3(1.0f))};
  // Refused with a message that names the field at fault.
  auto expect_throw = [&](const std::string& field, auto mutate) {
    KdBuildConfig c;
    mutate(c);
    try {
      (void)buildKdTreeOverBoxes(boxes, c);
      ADD_FAILURE() << "no exception for " << c;
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find(field + " must be"), std::string::npos) << e.what();
    }
  };
  expect_throw("traversal_cost", [](KdBuildConfig& c) { c.traversal_cost = 0.0f; });
  expect_throw("traversal_cost", [](KdBuildConfig& c) { c.traversal_cost = kInf; });
  expect_throw("intersection_cost", [](KdBuildConfig& c) { c.intersection_cost = -1.0f; });
  expect_throw("intersection_cost", [](KdBuildConfig& c) { c.intersection_cost = kNaN; });
  expect_throw("empty_bonus", [](KdBuildConfig& c) { c.empty_bonus = 1.0f; });
  expect_throw("empty_bonus", [](KdBuildConfig& c) { c.empty_bonus = -0.1f; });
  expect_throw("max_depth", [](KdBuildConfig& c) { c.max_depth = -1; });
}

TEST(KdBuildConfig, HeuristicNamesRoundTrip) {
  for (const KdHeuristic h : {KdHeuristic::Sah, KdHeuristic::Median, KdHeuristic::SpatialMiddle})
    EXPECT_EQ(parseKdHeuristic(toString(h)), h);
  EXPECT_EQ(parseKdHeuristic("sah"), KdHeuristic::Sah);
  EXPECT_EQ(parseKdHeuristic("median"), KdHeuristic::Median);
  EXPECT_EQ(parseKdHeuristic("middle"), KdHeuristic::SpatialMiddle);
  try {
    (void)parseKdHeuristic("bvh");
    ADD_FAILURE() << "parseKdHeuristic(\"bvh\") did not throw";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("bvh"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Generic traversal with boxes as primitives: the leaf callback computes the exact entry distance
// of the ray into each referenced box (double slabs) and lowers t_best; the result must be the
// brute-force nearest box entry, and an any-hit query must agree with "some box is hit".

/// The ray's parameter interval inside the box in double, clipped to [tnear, tfar]; false when it
/// misses.
bool boxInterval(const Ray& r, const Box& b, double& t0, double& t1) {
  t0 = r.tnear;
  t1 = r.tfar;
  for (int k = 0; k < 3; ++k) {
    const double o = r.origin[k], d = r.dir[k], lo = b.lo[k], hi = b.hi[k];
    if (d == 0.0) {
      if (o < lo || o > hi) return false;
      continue;
    }
    double a = (lo - o) / d, c = (hi - o) / d;
    if (a > c) std::swap(a, c);
    t0 = std::max(t0, a);
    t1 = std::min(t1, c);
  }
  return t0 <= t1;
}

/// Entry t of the ray into the box, or NaN when it misses.
double boxEntry(const Ray& r, const Box& b) {
  double t0, t1;
  return boxInterval(r, b, t0, t1) ? t0 : std::numeric_limits<double>::quiet_NaN();
}

/// Whether the ray runs through the box over a positive length (not only touching it at one
/// parameter, e.g. starting on its face and leaving at once: such contacts are optional).
bool boxPierced(const Ray& r, const Box& b) {
  double t0, t1;
  return boxInterval(r, b, t0, t1) && t1 - t0 > 1e-6 * (1.0 + std::abs(t0));
}

TEST(KdTraversal, NearestBoxAgreesWithBruteForce) {
  const auto boxes = randomBoxes(300, 44);
  Box all;
  for (const Box& b : boxes) all.extend(b);
  for (const ConfigCase& c : allConfigCases()) {
    SCOPED_TRACE(c.name);
    const KdTree tree = buildKdTreeOverBoxes(boxes, c.config);
    ASSERT_TRUE(checkBoxKdTree(tree, boxes, c.config.max_depth));
    std::vector<Ray> rays = randomRays(enlarged(all, 0.5f), 1500, 9);
    // Axis-parallel rays, some with -0 components, and rays with limited [tnear, tfar].
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<float> u(-1.0f, 5.0f);
    for (int i = 0; i < 600; ++i) {
      Ray r;
      r.origin = draw3(u, rng);
      const int axis = i % 3;
      r.dir = glm::vec3(i % 2 ? -0.0f : 0.0f, (i / 2) % 2 ? -0.0f : 0.0f, (i / 4) % 2 ? -0.0f : 0.0f);
      r.dir[axis] = (i / 3) % 2 ? 1.0f : -1.0f;
      if (i % 5 == 0) r.origin = glm::floor(r.origin * 2.0f) * 0.5f;  // on grid planes, shared with boxes
      rays.push_back(r);
    }
    for (std::size_t i = 0; i < 600; ++i) {
      Ray r = rays[i];
      r.tnear = 0.5f;
      r.tfar = 2.0f + static_cast<float>(i % 3);
      rays.push_back(r);
    }
    std::size_t failures = 0, hits = 0;
    for (const Ray& ray : rays) {
      // best_any: nearest entry over all boxes; best_pierced: over boxes the ray runs through.
      double best_any = std::numeric_limits<double>::infinity(), best_pierced = best_any;
      for (const Box& b : boxes) {
        const double t = boxEntry(ray, b);
        if (std::isnan(t)) continue;
        best_any = std::min(best_any, t);
        if (boxPierced(ray, b)) best_pierced = std::min(best_pierced, t);
      }
      const KdRay kray(ray);
      float t_best = ray.tfar;
      double best_kd = std::numeric_limits<double>::infinity();
      const bool found =
          traverseKdTree<false>(tree, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
            bool any = false;
            for (std::uint32_t k = begin; k < begin + count; ++k) {
              const double t = boxEntry(ray, boxes[tree.prim_indices[k]]);
              if (!std::isnan(t) && t <= t_max) {
                best_kd = std::min(best_kd, t);
                float f = static_cast<float>(best_kd);  // rounded up, so no closer box is culled
                if (static_cast<double>(f) < best_kd) f = std::nextafter(f, kInf);
                t_max = f;
                any = true;
              }
            }
            return any;
          });
      float t_any = ray.tfar;
      const bool any_hit =
          traverseKdTree<true>(tree, kray, t_any, [&](std::uint32_t begin, std::uint32_t count, float&) {
            for (std::uint32_t k = begin; k < begin + count; ++k)
              if (!std::isnan(boxEntry(ray, boxes[tree.prim_indices[k]]))) return true;
            return false;
          });
      const bool must_hit = std::isfinite(best_pierced), may_hit = std::isfinite(best_any);
      hits += must_hit;
      const double tol = 1e-6 * (1.0 + std::abs(best_any));
      bool ok = found == std::isfinite(best_kd) && (!must_hit || found) && (may_hit || !found) &&
                (!must_hit || any_hit) && (may_hit || !any_hit);
      if (found) ok = ok && best_kd >= best_any - tol && (!must_hit || best_kd <= best_pierced + tol);
      if (!ok && failures++ < 8)
        ADD_FAILURE() << ray << ": traversal nearest " << best_kd << " (found " << found << ", any-hit " << any_hit
                      << ") vs brute force " << best_pierced << " (touching included: " << best_any << ")";
    }
    EXPECT_EQ(failures, 0u);
    EXPECT_GT(hits, rays.size() / 5);
  }
}

TEST(KdTraversal, ZeroDirectionComponentsAndSplitPlanes) {
  // Rays lying exactly in split planes must still find every box they touch.
  const auto boxes = randomBoxes(800, 45);
  const KdTree tree = buildKdTreeOverBoxes(boxes);
  ASSERT_TRUE(checkBoxKdTree(tree, boxes));
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<float> u(-0.5f, 4.5f);
  std::size_t checked = 0, failures = 0;
  for (std::uint32_t i = 0; i < tree.nodes.size() && checked < 3000; ++i) {
    const KdNode& n = tree.nodes[i];
    if (n.isLeaf()) continue;
    for (int rep = 0; rep < 4; ++rep, ++checked) {
      Ray r;
      r.origin = draw3(u, rng);
      r.origin[n.axis()] = n.split();
      r.dir = glm::normalize(draw3(u, rng) - 2.0f);
      r.dir[n.axis()] = rep % 2 ? -0.0f : 0.0f;
      std::set<std::uint32_t> expected, visited;
      for (std::uint32_t b = 0; b < boxes.size(); ++b)
        if (boxPierced(r, boxes[b])) expected.insert(b);
      const KdRay kray(r);
      float t_best = r.tfar;
      (void)traverseKdTree<false>(tree, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
        for (std::uint32_t k = begin; k < begin + count; ++k) visited.insert(tree.prim_indices[k]);
        return false;
      });
      for (const std::uint32_t b : expected)
        if (!visited.count(b) && failures++ < 8)
          ADD_FAILURE() << r << " in the split plane of node " << i << " never visits box " << b << " " << boxes[b];
    }
  }
  EXPECT_EQ(failures, 0u);
  EXPECT_GT(checked, 100u);
}

// ---------------------------------------------------------------------------------------------
// The checker itself must be able to fail: corrupt valid trees and expect a report.

TEST(KdTreeChecks, CheckerCatchesCorruptedTrees) {
  const auto tris = randomTriangles(600, 90);
  const std::vector<char> usable(tris.size(), 1);
  const KdTree good = buildOverTriangles(tris, {});
  ASSERT_TRUE(checkTriangleKdTree(good, tris, usable));
  ASSERT_GT(good.nodes.size(), 3u);
  std::uint32_t inner = 0, leaf = 0;
  while (good.nodes[inner].isLeaf()) ++inner;
  while (!good.nodes[leaf].isLeaf() || good.nodes[leaf].primCount() < 2) ++leaf;
  const KdNode& in = good.nodes[inner];
  const KdNode& lf = good.nodes[leaf];

  auto expect_caught = [&](const char* what, auto corrupt, const std::vector<char>& use) {
    KdTree bad = good;
    corrupt(bad);
    EXPECT_FALSE(checkTriangleKdTree(bad, tris, use)) << "checker missed: " << what;
  };
  expect_caught(
      "a reference replaced by a duplicate",
      [&](KdTree& t) { t.prim_indices[lf.primOffset()] = t.prim_indices[lf.primOffset() + 1]; }, usable);
  expect_caught(
      "split moved outside the node",
      [&](KdTree& t) { t.nodes[inner] = KdNode::inner(in.axis(), t.bounds.hi[in.axis()] + 1.0f, in.upperChild()); },
      usable);
  expect_caught(
      "split moved inside the node",
      [&](KdTree& t) {
        const Box b = good.nodeBox(inner);
        t.nodes[inner] = KdNode::inner(in.axis(), 0.5f * (in.split() + b.lo[in.axis()]), in.upperChild());
      },
      usable);
  expect_caught(
      "upper child pointing back", [&](KdTree& t) { t.nodes[inner].setUpperChild(inner); }, usable);
  expect_caught(
      "upper child out of range",
      [&](KdTree& t) { t.nodes[inner].setUpperChild(static_cast<std::uint32_t>(t.nodes.size())); }, usable);
  expect_caught(
      "leaf range past the index list",
      [&](KdTree& t) { t.nodes[leaf].setPrimOffset(static_cast<std::uint32_t>(t.prim_indices.size())); }, usable);
  expect_caught(
      "reference to an unknown primitive", [&](KdTree& t) { t.prim_indices[0] = 100000; }, usable);
  expect_caught(
      "bounds shrunk", [&](KdTree& t) { t.bounds.hi.x -= 0.01f; }, usable);
  std::vector<char> one_unusable = usable;
  one_unusable[good.prim_indices[0]] = 0;
  expect_caught(
      "reference to an unusable primitive", [](KdTree&) {}, one_unusable);
  EXPECT_FALSE(checkTriangleKdTree(good, tris, usable, 3)) << "checker missed a tree deeper than max_depth";

  // Box trees: drop a box from one leaf.
  const auto boxes = randomBoxes(300, 91);
  const KdTree box_tree = buildKdTreeOverBoxes(boxes);
  ASSERT_TRUE(checkBoxKdTree(box_tree, boxes));
  KdTree bad = box_tree;
  for (std::uint32_t i = 0; i < bad.nodes.size(); ++i)
    if (bad.nodes[i].isLeaf() && bad.nodes[i].primCount() >= 2) {
      bad.prim_indices[bad.nodes[i].primOffset()] = bad.prim_indices[bad.nodes[i].primOffset() + 1];
      break;
    }
  EXPECT_FALSE(checkBoxKdTree(bad, boxes)) << "checker missed a box dropped from a leaf";
}

// ---------------------------------------------------------------------------------------------

TEST(KdNode, EncodesInnerAndLeafFields) {
  for (const int axis : {0, 1, 2}) {
    const KdNode n = KdNode::inner(axis, -3.25f, KdNode::kMaxIndex);
    EXPECT_FALSE(n.isLeaf());
    EXPECT_EQ(n.axis(), axis);
    EXPECT_EQ(n.split(), -3.25f);
    EXPECT_EQ(n.upperChild(), KdNode::kMaxIndex);
    KdNode m = n;
    m.setUpperChild(12345);
    EXPECT_EQ(m.upperChild(), 12345u);
    EXPECT_EQ(m.axis(), axis);
    EXPECT_EQ(m.split(), -3.25f);
  }
  KdNode leaf = KdNode::leaf(0xFFFFFFF0u, KdNode::kMaxIndex);
  EXPECT_TRUE(leaf.isLeaf());
  EXPECT_EQ(leaf.primOffset(), 0xFFFFFFF0u);
  EXPECT_EQ(leaf.primCount(), KdNode::kMaxIndex);
  leaf.setPrimOffset(7);
  EXPECT_EQ(leaf.primOffset(), 7u);
  EXPECT_EQ(leaf.primCount(), KdNode::kMaxIndex);
  EXPECT_TRUE(KdNode::leaf(3, 0).isLeaf());
  EXPECT_EQ(KdNode::leaf(3, 0).primCount(), 0u);
}

TEST(Box, BasicOperations) {
  Box b;
  EXPECT_TRUE(b.empty());
  EXPECT_EQ(b.area(), 0.0f);
  b.extend(glm::vec3(1.0f, 2.0f, 3.0f));
  EXPECT_FALSE(b.empty());  // a point box is not empty
  EXPECT_EQ(b.area(), 0.0f);
  b.extend(Box(glm::vec3(0.0f), glm::vec3(2.0f, 3.0f, 4.0f)));
  EXPECT_EQ(b, Box(glm::vec3(0.0f), glm::vec3(2.0f, 3.0f, 4.0f)));
  EXPECT_FLOAT_EQ(b.area(), 2.0f * (2 * 3 + 3 * 4 + 4 * 2));
  EXPECT_EQ(b.longestAxis(), 2);
  EXPECT_EQ(Box(glm::vec3(0.0f), glm::vec3(1.0f)).longestAxis(), 0);  // ties: x first
  EXPECT_EQ(Box(glm::vec3(0.0f), glm::vec3(1.0f, 2.0f, 2.0f)).longestAxis(), 1);
  EXPECT_TRUE(b.contains(glm::vec3(2.0f, 3.0f, 4.0f)));  // closed
  EXPECT_FALSE(b.contains(glm::vec3(2.0f, 3.0f, 4.0001f)));
  EXPECT_TRUE(b.overlaps(Box(glm::vec3(2.0f, 0.0f, 0.0f), glm::vec3(5.0f))));  // touching counts
  EXPECT_TRUE(intersection(b, Box(glm::vec3(3.0f), glm::vec3(5.0f))).empty());
  EXPECT_EQ(intersection(b, Box(glm::vec3(1.0f), glm::vec3(5.0f))), Box(glm::vec3(1.0f), glm::vec3(2.0f, 3.0f, 4.0f)));
}

// ---------------------------------------------------------------------------------------------

TEST(KdTreeBuilder, SplitFunctionBuildsAValidTree) {
  // The one-clip-per-split path (what meshes use) against the invariant checker, for every config.
  const auto tris = randomTriangles(2500, 43);
  std::vector<Box> bounds(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i)
    for (const auto& v : tris[i]) bounds[i].extend(v);
  for (const ConfigCase& c : allConfigCases()) {
    SCOPED_TRACE(c.name);
    const KdTree tree = buildKdTree(
        bounds,
        [&](std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper) {
          splitTriangleInBox(tris[prim][0], tris[prim][1], tris[prim][2], box, axis, pos, lower, upper);
        },
        c.config);
    EXPECT_TRUE(checkTriangleKdTree(tree, tris, std::vector<char>(tris.size(), 1), c.config.max_depth));
  }
}

}  // namespace
}  // namespace duplex::test
