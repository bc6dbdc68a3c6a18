// The data-agnostic wide BVH builder (WideBvh.h) over boxes: every tree goes through the invariant
// checker (BvhChecks.h) for each preset and several configurations, over uniform, clustered,
// identical, huge and tiny boxes, with unusable (empty, NaN, infinite) boxes mixed in; the build
// does not depend on the parallel threshold; a refit after moving the boxes; the SAH cost; the
// configuration's parser and printer.

#include "BvhChecks.h"
#include "TestSupport.h"

#include "duplex/accel/BvhBuildConfig.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/WideBvh.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

/// Boxes of size up to `size` with centres uniform in [0, extent)^3, scaled by `scale`.
std::vector<Box> uniformBoxes(std::size_t n, std::uint64_t seed, float extent = 100.0f, float size = 2.0f,
                              float scale = 1.0f) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> c(0.0f, extent), s(0.0f, size);
  std::vector<Box> out;
  for (std::size_t i = 0; i < n; ++i) {
    const glm::vec3 lo = draw3(c, rng);
    out.emplace_back(lo * scale, (lo + draw3(s, rng)) * scale);
  }
  return out;
}

/// A few tight clusters far apart, and a scattering of large boxes across them.
std::vector<Box> clusteredBoxes(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> g(0.0f, 0.5f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const glm::vec3 centres[4] = {{0, 0, 0}, {1000, 0, 0}, {0, 5000, -20}, {-300, 40, 9000}};
  std::vector<Box> out;
  for (std::size_t i = 0; i < n; ++i) {
    if (i % 50 == 0) {  // long boxes spanning clusters
      const float x = 1000.0f * u(rng);
      const float z = 9000.0f * u(rng);
      out.emplace_back(glm::vec3(-300.0f, 0.0f, 0.0f), glm::vec3(x, 10.0f, z));
      continue;
    }
    const glm::vec3 p = centres[i % 4] + draw3(g, rng);
    out.emplace_back(p, p + glm::vec3(0.01f + 0.1f * u(rng)));
  }
  return out;
}

/// `boxes` with unusable boxes inserted every few entries: empty, NaN and infinite.
std::vector<Box> withUnusable(std::vector<Box> boxes) {
  std::vector<Box> out;
  int k = 0;
  for (const Box& b : boxes) {
    out.push_back(b);
    if (out.size() % 7 != 0) continue;
    switch (k++ % 6) {
      case 0: out.push_back(Box()); break;
      case 1: out.emplace_back(glm::vec3(kNaN, 0, 0), glm::vec3(1, 1, 1)); break;
      case 2: out.emplace_back(glm::vec3(0, 0, 0), glm::vec3(1, kNaN, 1)); break;
      case 3: out.emplace_back(glm::vec3(-kInf, 0, 0), glm::vec3(1, 1, 1)); break;
      case 4: out.emplace_back(glm::vec3(0, 0, 0), glm::vec3(1, 1, kInf)); break;
      default: out.emplace_back(glm::vec3(2, 0, 0), glm::vec3(1, 1, 1)); break;  // lo > hi
    }
  }
  return out;
}

/// Splits a box primitive: its part inside `box` below and above `pos` (the spatial splits).
BvhClipFunction boxClip(const std::vector<Box>& boxes) {
  return [&boxes](std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper) {
    const Box b = intersection(boxes[prim], box);
    lower = b;
    upper = b;
    lower.hi[axis] = std::min(lower.hi[axis], pos);
    upper.lo[axis] = std::max(upper.lo[axis], pos);
    if (lower.empty()) lower = Box();
    if (upper.empty()) upper = Box();
  };
}

struct NamedBoxes {
  std::string name;
  std::vector<Box> boxes;
};

std::vector<NamedBoxes> boxSets() {
  std::vector<NamedBoxes> sets;
  sets.push_back({"uniform", uniformBoxes(3000, 1)});
  sets.push_back({"clustered", clusteredBoxes(3000, 2)});
  sets.push_back({"identical", std::vector<Box>(500, Box(glm::vec3(1, 2, 3), glm::vec3(1.5f, 2.5f, 3.5f)))});
  sets.push_back({"identical_points", std::vector<Box>(100, Box(glm::vec3(-4.0f), glm::vec3(-4.0f)))});
  sets.push_back({"one", {Box(glm::vec3(0.0f), glm::vec3(1.0f))}});
  sets.push_back({"two", {Box(glm::vec3(0.0f), glm::vec3(1.0f)), Box(glm::vec3(5.0f), glm::vec3(6.0f))}});
  sets.push_back({"flat", [] {
                    auto b = uniformBoxes(800, 3);
                    for (Box& x : b) x.lo.z = x.hi.z = 7.0f;
                    return b;
                  }()});
  sets.push_back({"with_unusable", withUnusable(uniformBoxes(1000, 4))});
  sets.push_back(
      {"only_unusable", {Box(), Box(glm::vec3(kNaN), glm::vec3(kNaN)), Box(glm::vec3(-kInf), glm::vec3(kInf))}});
  sets.push_back({"empty", {}});
  sets.push_back({"huge", uniformBoxes(1000, 5, 100.0f, 2.0f, 1e35f)});
  sets.push_back({"tiny", uniformBoxes(1000, 6, 100.0f, 2.0f, 1e-35f)});
  sets.push_back({"far_from_origin", [] {
                    auto b = uniformBoxes(1000, 7, 1.0f, 0.01f);
                    for (Box& x : b) {
                      x.lo += glm::vec3(1e5f);
                      x.hi += glm::vec3(1e5f);
                    }
                    return b;
                  }()});
  return sets;
}

struct NamedConfig {
  std::string name;
  BvhBuildConfig config;
};

std::vector<NamedConfig> configs() {
  std::vector<NamedConfig> out;
  for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium, BvhPreset::High})
    out.push_back({std::string(toString(p)), BvhBuildConfig::preset(p)});
  auto with = [&](const std::string& name, auto mutate) {
    BvhBuildConfig c;
    mutate(c);
    out.push_back({name, c});
  };
  with("bins2", [](BvhBuildConfig& c) { c.bins = 2; });
  with("bins256", [](BvhBuildConfig& c) { c.bins = BvhBuildConfig::kMaxBins; });
  with("leaf1", [](BvhBuildConfig& c) { c.max_leaf_size = 1; });
  with("leaf16", [](BvhBuildConfig& c) { c.max_leaf_size = 16; });
  with("leaf16_cheap_traversal", [](BvhBuildConfig& c) {
    c.max_leaf_size = 16;
    c.traversal_cost = 0.0f;
  });
  with("costly_traversal", [](BvhBuildConfig& c) { c.traversal_cost = 50.0f; });
  with("serial", [](BvhBuildConfig& c) { c.parallel_threshold = 0; });
  with("parallel16", [](BvhBuildConfig& c) { c.parallel_threshold = 16; });
  return out;
}

/// Builds with the box clip function, so that the high preset's spatial splits can act.
WideBvh buildClipped(const std::vector<Box>& boxes, const BvhBuildConfig& config) {
  return buildWideBvh(boxes, config, boxClip(boxes));
}

::testing::AssertionResult sameTree(const WideBvh& a, const WideBvh& b) {
  if (a.root != b.root) return ::testing::AssertionFailure() << "roots " << a.root << " vs " << b.root;
  if (!(a.bounds == b.bounds)) return ::testing::AssertionFailure() << "bounds " << a.bounds << " vs " << b.bounds;
  if (a.nodes.size() != b.nodes.size())
    return ::testing::AssertionFailure() << a.nodes.size() << " vs " << b.nodes.size() << " nodes";
  for (std::size_t i = 0; i < a.nodes.size(); ++i)
    if (std::memcmp(&a.nodes[i], &b.nodes[i], sizeof(BvhNode8)) != 0)
      return ::testing::AssertionFailure() << "node " << i << " differs";
  if (a.prim_indices != b.prim_indices) return ::testing::AssertionFailure() << "prim_indices differ";
  return ::testing::AssertionSuccess();
}

std::size_t usableCount(const std::vector<Box>& boxes) {
  const auto u = usableBoxes(boxes);
  return static_cast<std::size_t>(std::count(u.begin(), u.end(), 1));
}

// ---------------------------------------------------------------------------------------------

TEST(WideBvhBuild, EveryBoxSetAndConfigPassesTheChecker) {
  const auto sets = boxSets();
  for (const NamedConfig& nc : configs()) {
    SCOPED_TRACE(nc.name);
    for (const NamedBoxes& set : sets) {
      SCOPED_TRACE(set.name);
      WideBvh bvh;
      try {
        bvh = buildClipped(set.boxes, nc.config);
      } catch (const std::exception& e) {
        ADD_FAILURE() << nc.name << " on " << set.name << ": " << e.what();
        continue;
      }
      EXPECT_TRUE(checkBoxBvh(bvh, set.boxes, BvhCheckOptions::of(nc.config))) << nc.config;
      const std::size_t usable = usableCount(set.boxes);
      if (usable == 0) {
        EXPECT_EQ(bvh.root, BvhRef::kEmpty);
        EXPECT_EQ(bvh.sahCost(nc.config), 0.0);
      } else if (usable <= 1) {
        EXPECT_TRUE(BvhRef::isLeaf(bvh.root));
      } else if (usable > 16) {
        EXPECT_TRUE(BvhRef::isInner(bvh.root)) << "more primitives than a leaf holds";
      }
    }
  }
}

TEST(WideBvhBuild, HighPresetSpatialSplits) {
  const auto boxes = clusteredBoxes(3000, 8);
  const BvhBuildConfig high = BvhBuildConfig::preset(BvhPreset::High);
  const WideBvh bvh = buildClipped(boxes, high);
  EXPECT_TRUE(checkBoxBvh(bvh, boxes, BvhCheckOptions::of(high)));
  // Without a clip function the spatial splits are off: every box exactly once.
  const WideBvh plain = buildWideBvh(boxes, high);
  BvhCheckOptions once = BvhCheckOptions::of(high);
  once.spatial_splits = false;
  EXPECT_TRUE(checkBoxBvh(plain, boxes, once));
  // Long overlapping boxes are what spatial splits are for: the SAH must not get worse.
  EXPECT_LE(bvh.sahCost(high), plain.sahCost(high) * (1.0 + 1e-6));
}

TEST(WideBvhBuild, DeepChainStaysWithinMaxDepth) {
  // Boxes at geometrically growing distances: a binned SAH peels off a few at a time, so an
  // unbounded build would nest far deeper than the traversal stack allows.
  std::vector<Box> boxes;
  for (int k = 0; k < 1800; ++k) {
    const float x = std::pow(1.05f, static_cast<float>(k)) * 1e-30f;
    boxes.emplace_back(glm::vec3(x, 0.0f, 0.0f), glm::vec3(x * 1.01f, 1.0f, 1.0f));
  }
  for (const std::uint32_t leaf : {1u, 8u}) {
    BvhBuildConfig c;
    c.max_leaf_size = leaf;
    const WideBvh bvh = buildWideBvh(boxes, c);
    EXPECT_TRUE(checkBoxBvh(bvh, boxes, BvhCheckOptions::of(c))) << c;
  }
}

TEST(WideBvhBuild, IdenticalTreesWhateverTheParallelThreshold) {
  const auto boxes = withUnusable(clusteredBoxes(30000, 9));
  for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium}) {
    SCOPED_TRACE(std::string(toString(p)));
    BvhBuildConfig serial = BvhBuildConfig::preset(p), parallel = serial, fine = serial;
    serial.parallel_threshold = 0;
    fine.parallel_threshold = 64;
    const WideBvh a = buildWideBvh(boxes, serial);
    const WideBvh b = buildWideBvh(boxes, parallel);
    const WideBvh c = buildWideBvh(boxes, fine);
    ASSERT_TRUE(checkBoxBvh(a, boxes, BvhCheckOptions::of(serial)));
    EXPECT_TRUE(sameTree(a, b)) << "serial vs default threshold " << parallel.parallel_threshold;
    EXPECT_TRUE(sameTree(a, c)) << "serial vs threshold 64";
    EXPECT_TRUE(sameTree(a, buildWideBvh(boxes, serial))) << "two serial builds";
  }
}

TEST(WideBvhBuild, InvalidConfigurationThrowsNamingTheParameter) {
  const auto boxes = uniformBoxes(10, 10);
  BvhBuildConfig c;
  c.bins = 1;
  expectErrorNaming<InvalidArgument>([&] { (void)buildWideBvh(boxes, c); }, "bins");
  c = {};
  c.max_leaf_size = 17;
  expectErrorNaming<InvalidArgument>([&] { (void)buildWideBvh(boxes, c); }, "leaf");
  c = {};
  c.leaf_block = 8;
  expectErrorNaming<InvalidArgument>([&] { (void)buildWideBvh(boxes, c); }, "leaf_block");
}

// The checker itself: each broken tree is refused with a message naming the violation.
TEST(WideBvhChecker, RefusesBrokenTrees) {
  const auto boxes = uniformBoxes(2000, 15);
  const WideBvh good = buildWideBvh(boxes);
  ASSERT_TRUE(checkBoxBvh(good, boxes));
  ASSERT_GT(good.nodes.size(), 2u);
  // The first leaf slot and the first inner child slot of the tree.
  int leaf_node = -1, leaf_slot = -1;
  for (std::size_t n = 0; n < good.nodes.size() && leaf_node < 0; ++n)
    for (int k = 0; k < good.nodes[n].childCount(); ++k)
      if (BvhRef::isLeaf(good.nodes[n].child[k])) {
        leaf_node = static_cast<int>(n);
        leaf_slot = k;
        break;
      }
  ASSERT_GE(leaf_node, 0);
  const std::uint32_t leaf = good.nodes[leaf_node].child[leaf_slot];
  const std::size_t first = 4 * BvhRef::leafBlock(leaf);
  auto expectRefused = [&](const char* what, const std::string& needle, auto mutate, BvhCheckOptions opt = {}) {
    WideBvh bad = good;
    mutate(bad);
    const auto r = checkBoxBvh(bad, boxes, opt);
    EXPECT_FALSE(r) << what;
    if (!r) {
      EXPECT_NE(std::string(r.message()).find(needle), std::string::npos) << what << ": " << r.message();
    }
  };
  expectRefused("leaf box shrunk", "does not contain",
                [&](WideBvh& b) { b.nodes[leaf_node].hi[0][leaf_slot] -= 0.5f; });
  expectRefused("leaf box grown", "union of its primitives",
                [&](WideBvh& b) { b.nodes[leaf_node].lo[1][leaf_slot] -= 0.5f; });
  expectRefused("child outside parent", "outside the parent",
                [&](WideBvh& b) { b.nodes[1].lo[2][0] = b.bounds.lo.z - 1.0f; });
  expectRefused("primitive referenced twice", "in 2 leaves", [&](WideBvh& b) {
    b.prim_indices[first] =
        b.prim_indices[4 * BvhRef::leafBlock(b.nodes.back().child[b.nodes.back().childCount() - 1])];
  });
  expectRefused("padding not kPadding", "not padding", [&](WideBvh& b) {
    for (std::size_t n = 0; n < b.nodes.size(); ++n)
      for (int k = 0; k < b.nodes[n].childCount(); ++k) {
        const std::uint32_t r = b.nodes[n].child[k];
        if (BvhRef::isLeaf(r) && BvhRef::leafCount(r) % 4 != 0) {
          b.prim_indices[4 * BvhRef::leafBlock(r) + BvhRef::leafCount(r)] = 0;
          return;
        }
      }
  });
  expectRefused(
      "leaf too large", "max_leaf_size", [](WideBvh&) {},
      [] {
        BvhCheckOptions o;
        o.max_leaf_size = 1;
        return o;
      }());
  expectRefused("empty slot box not [+inf, -inf]", "empty slot", [](WideBvh& b) {
    for (BvhNode8& n : b.nodes)
      if (n.childCount() < BvhNode8::kWidth) {
        n.lo[0][BvhNode8::kWidth - 1] = 0.0f;
        return;
      }
  });
  expectRefused("inner node with one child", "1 children", [](WideBvh& b) {
    BvhNode8& n = b.nodes[0];
    const int used = n.childCount();
    for (int k = 1; k < used; ++k) n.setChild(k, BvhRef::kEmpty, Box());
  });
  expectRefused("nodes not depth-first", "depth-first", [](WideBvh& b) {
    // Swap the last two nodes and the references to them.
    const std::uint32_t x = static_cast<std::uint32_t>(b.nodes.size() - 2), y = x + 1;
    std::swap(b.nodes[x], b.nodes[y]);
    for (BvhNode8& n : b.nodes)
      for (std::uint32_t& c : n.child)
        if (c == x) c = y;
        else if (c == y) c = x;
  });
  expectRefused("child order not a permutation", "child order is not a permutation",
                [](WideBvh& b) { b.nodes[0].order[3] = b.nodes[0].order[2]; });
  expectRefused("child order with high bits", "child order is not a permutation",
                [](WideBvh& b) { b.nodes[0].order[0] |= 1u << 30; });
  expectRefused("child order not the boxes'", "differs from the boxes'",
                [](WideBvh& b) { std::swap(b.nodes[0].order[0], b.nodes[0].order[7]); });
  expectRefused("unreachable node", "reached", [](WideBvh& b) { b.nodes.push_back(b.nodes.back()); });
  expectRefused("bounds too large", "union of usable bounds", [](WideBvh& b) { b.bounds.hi.x += 1.0f; });
  std::vector<Box> with_nan = boxes;
  with_nan[good.prim_indices[first]].lo.y = kNaN;
  const auto r = checkBoxBvh(good, with_nan);
  EXPECT_FALSE(r) << "a NaN box referenced";
  EXPECT_NE(std::string(r.message()).find("not usable"), std::string::npos) << r.message();
}

// The per-octant child orders (BvhNode8::order): for rays of every octant, ranks go from the
// farthest box centre along the octant's diagonal to the nearest, empty slots first.
TEST(WideBvhNode, ChildOrderRunsFarToNearAlongEachOctant) {
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> u(-100.0f, 100.0f);
  for (int used = 2; used <= BvhNode8::kWidth; ++used) {
    BvhNode8 node;
    for (int k = 0; k < BvhNode8::kWidth; ++k) node.setChild(k, BvhRef::kEmpty, Box());
    for (int k = 0; k < used; ++k) {
      const glm::vec3 c = draw3(u, rng);
      node.setChild(k, static_cast<std::uint32_t>(k + 1), Box(c - glm::vec3(1.0f), c + glm::vec3(2.0f)));
    }
    node.computeOrder();
    ASSERT_TRUE(node.orderValid());
    for (int octant = 0; octant < 8; ++octant) {
      const glm::dvec3 dir((octant & 1) ? -1.0 : 1.0, (octant & 2) ? -1.0 : 1.0, (octant & 4) ? -1.0 : 1.0);
      auto along = [&](int slot) {
        const Box b = node.childBox(slot);
        return glm::dot(glm::dvec3(b.lo) + glm::dvec3(b.hi), dir);
      };
      for (int rank = 0; rank < BvhNode8::kWidth; ++rank) {
        const int slot = node.orderedSlot(octant, rank);
        if (rank < BvhNode8::kWidth - used) {
          EXPECT_EQ(node.child[slot], BvhRef::kEmpty) << "octant " << octant << " rank " << rank;
        } else if (rank > BvhNode8::kWidth - used) {
          EXPECT_GE(along(node.orderedSlot(octant, rank - 1)), along(slot)) << "octant " << octant << " rank " << rank;
        }
      }
    }
  }
  BvhNode8 bad;
  for (int k = 0; k < BvhNode8::kWidth; ++k) bad.setChild(k, BvhRef::kEmpty, Box());
  bad.computeOrder();
  EXPECT_TRUE(bad.orderValid());
  bad.order[5] = bad.order[4];
  EXPECT_FALSE(bad.orderValid());
}

// The orders are those of a stable sort by descending key (what the traversal's tie-breaking
// among equally distant hits follows): checked against an insertion sort on nodes with many equal
// centres, negative zeros and empty slots.
TEST(WideBvhNode, ChildOrderIsAStableSortOfTheKeys) {
  std::mt19937 rng(47);
  std::uniform_int_distribution<int> coarse(-2, 2);  // few distinct centres: many ties
  std::uniform_int_distribution<int> count(2, BvhNode8::kWidth);
  for (int trial = 0; trial < 2000; ++trial) {
    const int used = count(rng);
    BvhNode8 node;
    for (int k = 0; k < BvhNode8::kWidth; ++k) node.setChild(k, BvhRef::kEmpty, Box());
    for (int k = 0; k < used; ++k) {
      glm::vec3 c = draw3(coarse, rng);
      for (int a = 0; a < 3; ++a)
        if (c[a] == 0.0f && (rng() & 1)) c[a] = -0.0f;
      node.setChild(k, static_cast<std::uint32_t>(k + 1), Box(c, c));
    }
    node.computeOrder();
    ASSERT_TRUE(node.orderValid());
    for (int octant = 0; octant < 8; ++octant) {
      // Octants 4-7 are the reverses of 3-0 among the used slots.
      const int base = octant < 4 ? octant : 7 - octant;
      double key[BvhNode8::kWidth];
      int slot[BvhNode8::kWidth];
      for (int k = 0; k < BvhNode8::kWidth; ++k) {
        double v = std::numeric_limits<double>::infinity();
        if (k < used) {
          v = 0.0;
          for (int a = 0; a < 3; ++a) {
            const double c = double{node.lo[a][k]} + double{node.hi[a][k]};
            v += (base >> a & 1) ? -c : c;
          }
        }
        int i = k;
        for (; i > 0 && key[i - 1] < v; --i) {
          key[i] = key[i - 1];
          slot[i] = slot[i - 1];
        }
        key[i] = v;
        slot[i] = k;
      }
      const int empty = BvhNode8::kWidth - used;
      for (int rank = 0; rank < BvhNode8::kWidth; ++rank) {
        const int expected = octant < 4 || rank < empty ? slot[rank] : slot[empty + BvhNode8::kWidth - 1 - rank];
        ASSERT_EQ(node.orderedSlot(octant, rank), expected) << "trial " << trial << " octant " << octant;
      }
    }
  }
}

// updateOrder keeps an order only where computeOrder would give it: after small and large moves
// of the boxes (ties included), and from orders that are any permutation or not valid at all.
TEST(WideBvhNode, UpdatedOrderEqualsTheComputedOne) {
  std::mt19937 rng(53);
  std::uniform_int_distribution<int> coarse(-3, 3);
  std::uniform_int_distribution<int> count(2, BvhNode8::kWidth);
  std::uniform_real_distribution<float> jitter(-1.5f, 1.5f);
  int kept = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const int used = count(rng);
    BvhNode8 node;
    for (int k = 0; k < BvhNode8::kWidth; ++k) node.setChild(k, BvhRef::kEmpty, Box());
    auto place = [&](bool move) {
      for (int k = 0; k < used; ++k) {
        glm::vec3 c = move ? node.childBox(k).lo : draw3(coarse, rng);
        if (move && trial % 3 != 0) {  // a third keeps ties
          c.x += jitter(rng);
          c.z += jitter(rng);
        }
        node.setChild(k, static_cast<std::uint32_t>(k + 1), Box(c, c + glm::vec3(1.0f)));
      }
    };
    place(false);
    node.computeOrder();
    if (trial % 5 == 0) {  // an order of another node: any permutation, or garbage
      std::uint32_t word = static_cast<std::uint32_t>(rng());
      for (std::uint32_t& o : node.order) o = trial % 10 == 0 ? word++ : o ^ (word & 0x00FFFFFFu);
    }
    place(true);
    BvhNode8 updated = node, computed = node;
    updated.updateOrder();
    computed.computeOrder();
    ASSERT_TRUE(std::equal(std::begin(updated.order), std::end(updated.order), std::begin(computed.order)))
        << "trial " << trial;
    kept += std::equal(std::begin(node.order), std::end(node.order), std::begin(computed.order));
  }
  EXPECT_GT(kept, 300);  // the check's fast path is exercised
}

// ---------------------------------------------------------------------------------------------

TEST(WideBvhRefit, UnmovedBoxesGiveTheSameTree) {
  for (const NamedBoxes& set : boxSets()) {
    SCOPED_TRACE(set.name);
    const WideBvh built = buildWideBvh(set.boxes);
    WideBvh refit = built;
    refitWideBvh(refit, set.boxes);
    EXPECT_TRUE(sameTree(built, refit));
  }
}

TEST(WideBvhRefit, MovedBoxesKeepTheTopologyAndGetTightBoxes) {
  for (const NamedBoxes& set : boxSets()) {
    if (usableCount(set.boxes) == 0) continue;
    SCOPED_TRACE(set.name);
    const WideBvh built = buildWideBvh(set.boxes);
    std::mt19937_64 rng(11);
    std::normal_distribution<float> g(0.0f, 1.0f);
    const auto usable = usableBoxes(set.boxes);
    std::vector<Box> moved = set.boxes;
    const glm::vec3 e = built.bounds.extent();
    const float step = std::max(1e-30f, 0.2f * std::max({e.x, e.y, e.z}));
    for (std::size_t i = 0; i < moved.size(); ++i) {
      if (!usable[i]) continue;
      const glm::vec3 d = step * draw3(g, rng);
      const glm::vec3 grow = std::abs(g(rng)) * 0.1f * moved[i].extent();
      moved[i] = Box(moved[i].lo + d - grow, moved[i].hi + d + grow);
    }
    WideBvh refit = built;
    refitWideBvh(refit, moved);
    // Same topology: references and leaf ranges untouched.
    EXPECT_EQ(refit.root, built.root);
    EXPECT_EQ(refit.prim_indices, built.prim_indices);
    ASSERT_EQ(refit.nodes.size(), built.nodes.size());
    for (std::size_t n = 0; n < built.nodes.size(); ++n)
      for (int k = 0; k < BvhNode8::kWidth; ++k) EXPECT_EQ(refit.nodes[n].child[k], built.nodes[n].child[k]);
    // Every box holds the moved boxes exactly (the tight checker), parents hold children.
    EXPECT_TRUE(checkBoxBvh(refit, moved));
    // Moving back restores the original.
    refitWideBvh(refit, set.boxes);
    EXPECT_TRUE(sameTree(built, refit));
  }
}

TEST(WideBvhRefit, IndexBeyondTheBoxesThrows) {
  const auto boxes = uniformBoxes(100, 12);
  WideBvh bvh = buildWideBvh(boxes);
  const std::vector<Box> fewer(boxes.begin(), boxes.begin() + 50);
  expectErrorNaming<InvalidArgument>([&] { refitWideBvh(bvh, fewer); }, "refitWideBvh");
}

// ---------------------------------------------------------------------------------------------

/// The SAH cost from its definition in WideBvh.h, computed in a separate pass in double.
double sahFromDefinition(const WideBvh& bvh, const BvhBuildConfig& c) {
  if (bvh.root == BvhRef::kEmpty) return 0.0;
  auto area = [](const Box& b) {
    const glm::dvec3 e = glm::dvec3(b.hi) - glm::dvec3(b.lo);
    return 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
  };
  const double root_area = area(bvh.bounds);
  auto blocks = [&](std::uint32_t n) { return std::ceil(double(n) / bvh.leaf_block); };
  if (BvhRef::isLeaf(bvh.root)) return c.intersection_cost * blocks(BvhRef::leafCount(bvh.root));
  double cost = c.traversal_cost;
  for (const BvhNode8& node : bvh.nodes)
    for (int k = 0; k < node.childCount(); ++k) {
      const double p = area(node.childBox(k)) / root_area;
      cost += BvhRef::isLeaf(node.child[k]) ? p * c.intersection_cost * blocks(BvhRef::leafCount(node.child[k]))
                                            : p * c.traversal_cost;
    }
  return cost;
}

TEST(WideBvhSah, PositiveBoundedAndAsDefined) {
  for (const NamedBoxes& set : boxSets()) {
    if (set.name == "huge") continue;  // HugeCoordinatesGiveAFiniteCost
    SCOPED_TRACE(set.name);
    for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium}) {
      const BvhBuildConfig c = BvhBuildConfig::preset(p);
      const WideBvh bvh = buildWideBvh(set.boxes, c);
      const double cost = bvh.sahCost(c);
      const std::size_t n = usableCount(set.boxes);
      if (n == 0) {
        EXPECT_EQ(cost, 0.0);
        continue;
      }
      if (!(bvh.bounds.area() > 0.0f)) continue;  // identical points: no area to weigh by
      EXPECT_GT(cost, 0.0);
      EXPECT_TRUE(std::isfinite(cost));
      EXPECT_NEAR(cost, sahFromDefinition(bvh, c), 1e-6 * cost);
      // Every term's probability is at most 1: the cost is at most that of visiting everything.
      const double everything = c.traversal_cost * (1.0 + double(bvh.nodes.size()) * BvhNode8::kWidth) +
                                c.intersection_cost * double(bvh.prim_indices.size()) / bvh.leaf_block;
      EXPECT_LE(cost, everything * (1.0 + 1e-6));
      // The root's leaves cost at least one block test for a ray through the root.
      EXPECT_GE(cost, c.intersection_cost * (1.0 - 1e-6));
    }
  }
  // Small spread boxes: far cheaper than a single leaf of everything.
  const auto boxes = uniformBoxes(20000, 13, 100.0f, 0.5f);
  const BvhBuildConfig c;
  const double cost = buildWideBvh(boxes, c).sahCost(c);
  EXPECT_LT(cost, 0.02 * c.intersection_cost * 20000 / 4);
}

TEST(WideBvhSah, HugeCoordinatesGiveAFiniteCost) {
  // Extents near 1e37: a box's surface area overflows float, but the cost is a ratio of areas and
  // stays finite (and as defined, computed in double).
  const auto boxes = uniformBoxes(1000, 5, 100.0f, 2.0f, 1e35f);
  const BvhBuildConfig c;
  const WideBvh bvh = buildWideBvh(boxes, c);
  ASSERT_TRUE(checkBoxBvh(bvh, boxes, BvhCheckOptions::of(c)));
  const double cost = bvh.sahCost(c);
  EXPECT_TRUE(std::isfinite(cost)) << cost;
  EXPECT_NEAR(cost, sahFromDefinition(bvh, c), 1e-4 * sahFromDefinition(bvh, c));
}

// ---------------------------------------------------------------------------------------------

TEST(BvhBuildConfigText, PresetsAndRoundTrips) {
  for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium, BvhPreset::High}) {
    EXPECT_EQ(parseBvhPreset(toString(p)), p);
    const BvhBuildConfig c = BvhBuildConfig::preset(p);
    EXPECT_NO_THROW(c.validate());
    EXPECT_EQ(BvhBuildConfig::parse(toString(p)), c) << toString(p);
    EXPECT_EQ(BvhBuildConfig::parse(c.toString()), c) << c.toString();
    std::ostringstream os;
    os << c;
    EXPECT_EQ(os.str(), c.toString());
  }
  EXPECT_EQ(BvhBuildConfig::preset(BvhPreset::Medium), BvhBuildConfig{});
  EXPECT_GT(BvhBuildConfig::preset(BvhPreset::High).spatial_split_alpha, 0.0f);
  EXPECT_EQ(BvhBuildConfig::preset(BvhPreset::Fast).spatial_split_alpha, 0.0f);
  // Awkward values print and parse back exactly.
  std::mt19937_64 rng(14);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int i = 0; i < 200; ++i) {
    BvhBuildConfig c;
    c.bins = 2 + static_cast<std::uint32_t>(rng() % (BvhBuildConfig::kMaxBins - 1));
    c.traversal_cost = u(rng) * 10.0f;
    c.intersection_cost = 1e-7f + u(rng) * 1e3f;
    c.max_leaf_size = 1 + static_cast<std::uint32_t>(rng() % 16);
    c.spatial_split_alpha = i % 3 == 0 ? 0.0f : u(rng) * 1e-3f;
    c.spatial_split_budget = u(rng) * 4.0f;
    c.parallel_threshold = static_cast<std::uint32_t>(rng());
    ASSERT_EQ(BvhBuildConfig::parse(c.toString()), c) << c.toString();
  }
}

TEST(BvhBuildConfigText, OverridesApplyToThePreset) {
  BvhBuildConfig fast = BvhBuildConfig::preset(BvhPreset::Fast);
  fast.max_leaf_size = 4;
  EXPECT_EQ(BvhBuildConfig::parse("fast,leaf=4"), fast);
  BvhBuildConfig high = BvhBuildConfig::preset(BvhPreset::High);
  high.spatial_split_alpha = 1e-4f;
  high.spatial_split_budget = 0.3f;
  EXPECT_EQ(BvhBuildConfig::parse("high,alpha=1e-4,budget=0.3"), high);
  BvhBuildConfig bins;
  bins.bins = 16;
  EXPECT_EQ(BvhBuildConfig::parse("bins=16"), bins);
  BvhBuildConfig all;
  all.bins = 64;
  all.traversal_cost = 0.5f;
  all.intersection_cost = 2.0f;
  all.max_leaf_size = 3;
  all.parallel_threshold = 0;
  EXPECT_EQ(BvhBuildConfig::parse("medium,bins=64,ct=0.5,ci=2,leaf=3,parallel=0"), all);
  // A later override wins.
  EXPECT_EQ(BvhBuildConfig::parse("bins=8,bins=16"), bins);
}

TEST(BvhBuildConfigText, ErrorsNameTheBadPart) {
  struct Case {
    const char* text;
    const char* needle;  // what the message must name
  };
  const Case cases[] = {
      {"", "empty"},
      {"medium,", "empty"},
      {",bins=4", "empty"},
      {"medium,,bins=4", "empty"},
      {"ultra", "'ultra'"},
      {"medium,fast", "'fast'"},
      {"bins=4,medium", "'medium'"},
      {"nope=3", "'nope=3'"},
      {"medium,Bins=4", "'Bins=4'"},
      {"bins=x", "'bins=x'"},
      {"bins=", "'bins='"},
      {"bins=-3", "'bins=-3'"},
      {"bins=4 ", "'bins=4 '"},
      {"bins=0x10", "'bins=0x10'"},
      {"ct=nan", "'ct=nan'"},
      {"ci=inf", "'ci=inf'"},
      {"alpha=1e99", "'alpha=1e99'"},
      {"leaf=4.5", "'leaf=4.5'"},
      {"parallel=99999999999", "'parallel=99999999999'"},
      {"bins=1", "bins"},
      {"bins=257", "bins"},
      {"leaf=0", "leaf"},
      {"leaf=17", "leaf"},
      {"ct=-1", "ct"},
      {"ci=0", "ci"},
      {"ci=-2", "ci"},
      {"alpha=-1", "alpha"},
      {"budget=-0.5", "budget"},
      {"budget=5", "budget"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    expectErrorNaming<InvalidArgument>([&] { (void)BvhBuildConfig::parse(c.text); }, c.needle);
  }
  expectErrorNaming<InvalidArgument>([] { (void)parseBvhPreset("Medium"); }, "'Medium'");
  expectErrorNaming<InvalidArgument>([] { (void)parseBvhPreset(""); }, "''");
}

TEST(BvhBuildConfigText, ValidateNamesTheParameter) {
  auto expectBad = [](auto mutate, const std::string& needle) {
    BvhBuildConfig c;
    mutate(c);
    expectErrorNaming<InvalidArgument>([&] { c.validate(); }, needle);
  };
  expectBad([](BvhBuildConfig& c) { c.bins = BvhBuildConfig::kMaxBins + 1; }, "bins");
  expectBad([](BvhBuildConfig& c) { c.traversal_cost = kNaN; }, "ct");
  expectBad([](BvhBuildConfig& c) { c.intersection_cost = kInf; }, "ci");
  expectBad([](BvhBuildConfig& c) { c.max_leaf_size = 0; }, "leaf");
  expectBad([](BvhBuildConfig& c) { c.leaf_block = 0; }, "leaf_block");
  expectBad([](BvhBuildConfig& c) { c.spatial_split_alpha = kInf; }, "alpha");
  expectBad([](BvhBuildConfig& c) { c.spatial_split_budget = kNaN; }, "budget");
}

}  // namespace
}  // namespace duplex::test
