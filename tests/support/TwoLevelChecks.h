#pragma once
/// \file TwoLevelChecks.h
/// References for two-level queries: a brute force over instances (each instance's own bottom-level
/// query on the object-space ray the top level computes), exact hit comparison, and the invariant
/// checker of incrementally updated top-level trees (jumps, garbage, free slots).

#include "duplex/accel/Affine.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/accel/KdTree.h"

#include "TestSupport.h"

#include <gtest/gtest.h>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace duplex::test {

/// A random rotation, non-uniform scale in [0.3, 1.5] and translation in a cube of side `spread`
/// around the origin.
inline Affine randomPlacement(std::mt19937_64& rng, double spread) {
  std::uniform_real_distribution<double> u(-1.0, 1.0), s(0.3, 1.5);
  // One draw per statement: the order in which a call's arguments are evaluated is unspecified
  // (GCC and clang differ), and every compiler must build the same scenes. The order is the one
  // GCC gave the nested calls this replaces (last argument first), so the scenes stay as they were.
  glm::dvec3 axis, scale, shift;
  for (int k = 2; k >= 0; --k) axis[k] = u(rng);
  axis.z += 1e-3;
  for (int k = 2; k >= 0; --k) shift[k] = u(rng);
  for (int k = 2; k >= 0; --k) scale[k] = s(rng);
  const double angle = 3.14159 * u(rng);
  return Affine::fromRowMajor3x4(rotationScaleTranslation(axis, angle, scale, 0.5 * spread * shift));
}

/// A vector of three draws of `d`, drawn z, y, x in separate statements (see randomPlacement).
inline glm::dvec3 randomStep(std::mt19937_64& rng, std::uniform_real_distribution<double>& d) {
  glm::dvec3 v;
  for (int k = 2; k >= 0; --k) v[k] = d(rng);
  return v;
}

/// The live instances as the test believes them to be.
using Model = std::map<std::uint32_t, InstanceDesc>;

/// Brute force: every live instance whose mask meets `mask`, the same object-space ray the top level
/// computes (double transform from the float world ray), the object's own closest-hit query.
inline Hit bruteIntersect(const Model& model, const Ray& ray, std::uint32_t mask) {
  Hit best;
  best.t = ray.tfar;
  QueryContext ctx;
  std::uint32_t winner = kInvalidId;
  glm::dmat3 normal(1.0);
  for (const auto& [id, d] : model) {
    if ((d.mask & mask) == 0) continue;
    Ray ray_os = d.world_from_object.inverse().apply(ray);
    ray_os.tfar = best.t;
    Hit h = best;
    if (d.object->intersect(ray_os, h, ctx) && (winner == kInvalidId || h.t < best.t)) {
      best = h;
      winner = id;
      const glm::dmat3& l = d.world_from_object.linear;
      normal = glm::determinant(l) * glm::transpose(glm::inverse(l));
    }
  }
  if (winner == kInvalidId) return Hit{};
  best.instance_id = winner;
  best.ng = glm::mat3(normal) * best.ng;
  return best;
}

/// Same t bit for bit; a different (instance, primitive) only as an exact tie.
inline ::testing::AssertionResult sameHit(const Hit& a, const Hit& b) {
  if (a.valid() != b.valid() || (a.valid() && a.t != b.t)) return ::testing::AssertionFailure() << a << " vs " << b;
  return ::testing::AssertionSuccess();
}

/// Whether two hits agree bit for bit: t, u, v, ids and normal (packets against single rays).
inline bool sameHitBits(const Hit& a, const Hit& b) {
  return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 && std::memcmp(&a.u, &b.u, sizeof(float)) == 0 &&
         std::memcmp(&a.v, &b.v, sizeof(float)) == 0 && a.prim_id == b.prim_id && a.instance_id == b.instance_id &&
         std::memcmp(&a.ng, &b.ng, sizeof(glm::vec3)) == 0;
}

/// Structure and coverage of the (possibly incrementally updated) tree: nodes reached once, jumps
/// in range, leaf ranges inside the index list, every referenced slot live, every live box that
/// meets a leaf cell (after shrinking by a relative 1e-6) referenced by it, no slot twice in a leaf.
inline ::testing::AssertionResult checkIncrementalTree(const TopLevel& top, const Model& model) {
  const KdTree& tree = top.tree();
  if (model.empty()) return ::testing::AssertionSuccess();
  if (tree.empty()) return ::testing::AssertionFailure() << "empty tree for " << model.size() << " instances";
  std::vector<int> reached(tree.nodes.size(), 0);
  std::map<std::uint32_t, std::uint32_t> id_of_slot;
  std::string problems;
  int problem_count = 0;
  auto problem = [&](const std::string& s) {
    if (problem_count++ < 8) problems += "\n  " + s;
  };
  for (const auto& [id, d] : model) {
    (void)d;
    if (!top.contains(id)) problem("instance " + std::to_string(id) + " missing");
  }
  for (const auto& [id, d] : model) {
    (void)d;
    const Box b = top.instanceBounds(id);
    if (!(tree.bounds.lo.x <= b.lo.x && tree.bounds.lo.y <= b.lo.y && tree.bounds.lo.z <= b.lo.z &&
          tree.bounds.hi.x >= b.hi.x && tree.bounds.hi.y >= b.hi.y && tree.bounds.hi.z >= b.hi.z))
      problem("instance " + std::to_string(id) + " sticks out of the root bounds");
  }
  std::vector<std::pair<std::uint32_t, Box>> stack{{0u, tree.bounds}};
  while (!stack.empty()) {
    auto [i, cell] = stack.back();
    stack.pop_back();
    if (i >= tree.nodes.size()) {
      problem("node index " + std::to_string(i) + " out of range");
      continue;
    }
    if (reached[i]++) problem("node " + std::to_string(i) + " reached twice");
    const KdNode& n = tree.nodes[i];
    if (n.isJump()) {
      stack.emplace_back(n.jumpTarget(), cell);
      continue;
    }
    if (!n.isLeaf()) {
      const auto [lower, upper] = childCells(n, cell);
      stack.emplace_back(n.upperChild(), upper);
      stack.emplace_back(i + 1, lower);
      continue;
    }
    if (static_cast<std::size_t>(n.primOffset()) + n.primCount() > tree.prim_indices.size()) {
      problem("leaf range out of the index list at node " + std::to_string(i));
      continue;
    }
    std::set<std::uint32_t> ids;
    for (std::uint32_t k = 0; k < n.primCount(); ++k) {
      const std::uint32_t slot = tree.prim_indices[n.primOffset() + k];
      const std::uint32_t id = top.idAt(slot);
      if (!model.count(id)) {
        problem("leaf " + std::to_string(i) + " references slot " + std::to_string(slot) + " of a dead instance");
        continue;
      }
      if (!ids.insert(id).second)
        problem("leaf " + std::to_string(i) + " holds instance " + std::to_string(id) + " twice");
    }
    for (const auto& [id, d] : model) {
      const Box b = top.instanceBounds(id);
      Box s = intersection(b, cell);
      // Relative to the extent and to the coordinates' magnitude (a box touching the cell from
      // outside must not count, and 1e-6 of a small extent can vanish in a large coordinate's ulp).
      const glm::vec3 shrink = 1e-6f * (cell.extent() + glm::max(glm::abs(cell.lo), glm::abs(cell.hi)));
      s.lo += shrink;
      s.hi -= shrink;
      if (!s.empty() && !ids.count(id))
        problem("instance " + std::to_string(id) + " meets leaf " + std::to_string(i) + " but is not referenced");
    }
  }
  // Subtrees replaced by local rebuilds stay in the node array until the next compaction, and the
  // top level counts them; any other unreached node is a leak.
  const std::size_t unreached = static_cast<std::size_t>(std::count(reached.begin(), reached.end(), 0));
  if (unreached != top.stats().garbage_nodes)
    problem(std::to_string(unreached) + " nodes unreachable, " + std::to_string(top.stats().garbage_nodes) +
            " counted as garbage by the top level");
  if (problem_count == 0) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << problem_count << " problem(s):" << problems;
}

}  // namespace duplex::test
