// The 8-wide traversal form of an instance kd-tree (WideTop.h, private): its invariants against the
// kd-tree it is derived from, and its walk against a brute force over the boxes.

#include "InstanceTreeWide.h"
#include "WideTop.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <utility>
#include <vector>

namespace duplex::test {
namespace {

using toplevel_detail::kWideNone;
using toplevel_detail::kWideRef;
using toplevel_detail::WideNode;
using toplevel_detail::WideTop;

// Random boxes in [0, 4]^3: ordinary ones, flat ones, points, boxes on a coarse grid (sharing faces
// with each other and with split planes), and a few large ones spanning many leaves.
std::vector<Box> randomBoxes(std::size_t count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 4.0f), s(0.0f, 0.4f);
  std::vector<Box> boxes;
  for (std::size_t i = 0; i < count; ++i) {
    glm::vec3 lo(u(rng), u(rng), u(rng));
    glm::vec3 hi = lo + glm::vec3(s(rng), s(rng), s(rng));
    switch (i % 7) {
      case 1: hi[i % 3] = lo[i % 3]; break;  // flat
      case 2: hi = lo; break;                // a point
      case 3:                                // on a grid of quarter units
        lo = glm::floor(lo * 4.0f) / 4.0f;
        hi = lo + 0.25f;
        break;
      case 4: hi = lo + glm::vec3(2.0f * s(rng) * 5.0f); break;  // large
      default: break;
    }
    boxes.emplace_back(lo, hi);
  }
  return boxes;
}

Box childBox(const WideNode& n, int c) {
  return Box({n.bounds[0][c], n.bounds[2][c], n.bounds[4][c]}, {n.bounds[1][c], n.bounds[3][c], n.bounds[5][c]});
}

bool contains(const Box& outer, const Box& inner) {
  return outer.lo.x <= inner.lo.x && outer.lo.y <= inner.lo.y && outer.lo.z <= inner.lo.z && outer.hi.x >= inner.hi.x &&
         outer.hi.y >= inner.hi.y && outer.hi.z >= inner.hi.z;
}

// Every reference's clipped box, by (slot, box) pairs, found walking the kd-tree with cells.
void kdReferences(const KdTree& tree, const std::vector<Box>& boxes, std::uint32_t index, const Box& cell,
                  std::multiset<std::pair<std::uint32_t, std::vector<float>>>& out) {
  const KdNode& n = tree.nodes[index];
  if (n.isJump()) return kdReferences(tree, boxes, n.jumpTarget(), cell, out);
  if (n.isLeaf()) {
    for (std::uint32_t k = 0; k < n.primCount(); ++k) {
      const std::uint32_t slot = tree.prim_indices[n.primOffset() + k];
      const Box c(glm::max(boxes[slot].lo, cell.lo), glm::min(boxes[slot].hi, cell.hi));
      if (!c.empty()) out.insert({slot, {c.lo.x, c.lo.y, c.lo.z, c.hi.x, c.hi.y, c.hi.z}});
    }
    return;
  }
  const auto [lower, upper] = childCells(n, cell);
  kdReferences(tree, boxes, index + 1, lower, out);
  kdReferences(tree, boxes, n.upperChild(), upper, out);
}

// Checks that every child box contains the boxes below it; collects the references.
Box checkNode(const WideTop& top, std::uint32_t index,
              std::multiset<std::pair<std::uint32_t, std::vector<float>>>& refs, std::size_t& visited) {
  EXPECT_LT(index, top.nodes.size());
  ++visited;
  const WideNode& n = top.nodes[index];
  Box all;
  for (int c = 0; c < 8; ++c) {
    if (!(n.valid & (1u << c))) {
      EXPECT_EQ(n.child[c], kWideNone);
      continue;
    }
    const Box b = childBox(n, c);
    EXPECT_FALSE(b.empty());
    all.extend(b);
    if (n.child[c] & kWideRef) {
      refs.insert({n.child[c] & ~kWideRef, {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z}});
    } else {
      const Box below = checkNode(top, n.child[c], refs, visited);
      EXPECT_TRUE(contains(b, below)) << "child " << c << " of node " << index;
    }
  }
  return all;
}

TEST(WideTop, CoversEveryClippedReferenceUnderBoxesThatContainIt) {
  for (std::uint64_t seed : {1u, 2u, 3u}) {
    const std::vector<Box> boxes = randomBoxes(seed == 3 ? 5 : 600, seed);
    const KdTree tree = buildKdTreeOverBoxes(boxes);
    WideTop top;
    top.build(tree, boxes);
    ASSERT_TRUE(top.usable);
    std::multiset<std::pair<std::uint32_t, std::vector<float>>> expected, found;
    kdReferences(tree, boxes, 0, tree.bounds, expected);
    std::size_t visited = 0;
    checkNode(top, top.root, found, visited);
    EXPECT_EQ(visited, top.nodes.size()) << "every node reachable once";
    // Each clipped reference lies in a reference of the same instance (siblings of one instance
    // are merged into one box), and every reference comes from the kd-tree.
    std::map<std::uint32_t, std::vector<Box>> found_by_slot, expected_by_slot;
    auto toBox = [](const std::vector<float>& b) { return Box({b[0], b[1], b[2]}, {b[3], b[4], b[5]}); };
    for (const auto& [slot, b] : found) found_by_slot[slot].push_back(toBox(b));
    for (const auto& [slot, b] : expected) expected_by_slot[slot].push_back(toBox(b));
    EXPECT_EQ(found_by_slot.size(), expected_by_slot.size()) << "seed " << seed;
    for (const auto& [slot, list] : expected_by_slot) {
      const auto& have = found_by_slot[slot];
      EXPECT_LE(have.size(), list.size()) << "slot " << slot;
      for (const Box& b : list)
        EXPECT_TRUE(std::any_of(have.begin(), have.end(), [&](const Box& h) { return contains(h, b); }))
            << "seed " << seed << ": slot " << slot << "'s clipped box " << b << " is in no reference";
      for (const Box& h : have) {
        Box all;
        for (const Box& b : list) all.extend(b);
        EXPECT_TRUE(contains(all, h)) << "slot " << slot << ": a reference beyond its clipped boxes";
      }
    }
  }
}

TEST(WideTop, EmptyTreeIsNotUsable) {
  WideTop top;
  top.build(KdTree{}, {});
  EXPECT_FALSE(top.usable);
  EXPECT_TRUE(top.nodes.empty());
}

// Every box the ray meets (a brute force with the kd-tree's box clip) is visited, and the
// closest-hit walk visits references in an order that never skips one nearer than the best.
TEST(WideTop, WalkVisitsEveryBoxTheRayMeets) {
  const std::vector<Box> boxes = randomBoxes(800, 7);
  const KdTree tree = buildKdTreeOverBoxes(boxes);
  WideTop top;
  top.build(tree, boxes);
  ASSERT_TRUE(top.usable);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 5.0f), d(-1.0f, 1.0f);
  int rays = 0;
  for (int i = 0; i < 3000; ++i) {
    Ray ray;
    ray.origin = {u(rng), u(rng), u(rng)};
    ray.dir = {d(rng), d(rng), d(rng)};
    if (i % 5 == 0) ray.dir = glm::vec3(2.0f) - ray.origin;                  // through the middle
    if (i % 11 == 0) ray.origin = boxes[i % boxes.size()].lo;                // from a box corner
    if (i % 7 == 0) ray.dir[i % 3] = 0.0f;                                   // in a plane of two axes
    if (i % 13 == 0) ray.dir = glm::vec3(0.0f, 0.0f, -1.0f);                 // along an axis
    if (i % 17 == 0) ray.origin[i % 3] = boxes[i % boxes.size()].hi[i % 3];  // on a box's face plane
    ray.tnear = 0.0f;
    ray.tfar = i % 3 == 0 ? 1.5f : std::numeric_limits<float>::infinity();
    KdRay k;
    if (!prepareKdRay(ray, k)) continue;
    ++rays;
    std::set<std::uint32_t> expected;
    for (std::uint32_t s = 0; s < boxes.size(); ++s) {
      float t0 = ray.tnear, t1 = ray.tfar;
      if (clipIntervalToBox(k, boxes[s], t0, t1)) expected.insert(s);
    }
    const auto& kernels = toplevel_detail::wideKernels();
    std::set<std::uint32_t> visited;
    float t = ray.tfar;
    kernels.walk(top, ray, false, t, [&](std::uint32_t slot, float&) {
      visited.insert(slot);
      return false;
    });
    for (std::uint32_t s : expected) EXPECT_TRUE(visited.count(s)) << "ray " << i << " misses box " << s;
    // Closest-hit culling: with each visit "hitting" at the reference's box entry, the walk ends
    // with the nearest entry of all the boxes the ray meets.
    float best = ray.tfar;
    float nearest = ray.tfar;
    for (std::uint32_t s : expected) {
      float t0 = ray.tnear, t1 = ray.tfar;
      clipIntervalToBox(k, boxes[s], t0, t1);
      nearest = std::min(nearest, t0);
    }
    std::vector<float> entries(boxes.size());
    for (std::uint32_t s = 0; s < boxes.size(); ++s) {
      float t0 = ray.tnear, t1 = ray.tfar;
      entries[s] = clipIntervalToBox(k, boxes[s], t0, t1) ? t0 : std::numeric_limits<float>::infinity();
    }
    kernels.walk(top, ray, false, best, [&](std::uint32_t slot, float& t_best) {
      if (!(entries[slot] < t_best)) return false;
      t_best = entries[slot];
      return true;
    });
    EXPECT_EQ(best, nearest) << "ray " << i;
    // Any hit: the walk stops at the first visit that reports one, and finds one whenever the ray
    // meets some box.
    float t_any = ray.tfar;
    int visits = 0;
    const bool any = kernels.walk(top, ray, true, t_any, [&](std::uint32_t, float&) { return ++visits, true; });
    EXPECT_TRUE(any || expected.empty()) << "ray " << i;
    EXPECT_LE(visits, 1);
  }
  EXPECT_GT(rays, 2900);
}

}  // namespace
}  // namespace duplex::test
