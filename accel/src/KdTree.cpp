#include "duplex/accel/KdTree.h"

#include <algorithm>
#include <functional>

namespace duplex {

KdTreeStats KdTree::stats(float traversal_cost, float intersection_cost) const {
  KdTreeStats s;
  s.nodes = static_cast<std::uint32_t>(nodes.size());
  s.bytes = nodes.size() * sizeof(KdNode) + prim_indices.size() * sizeof(std::uint32_t);
  if (nodes.empty()) return s;
  const double root_area = std::max(1e-30, static_cast<double>(bounds.area()));
  // Depth-first walk carrying each node's box; the SAH cost weighs every node by the probability
  // that a ray through the root box also passes through it.
  std::function<void(std::uint32_t, const Box&, std::uint32_t)> walk = [&](std::uint32_t i, const Box& box,
                                                                           std::uint32_t depth) {
    const KdNode& n = nodes[i];
    if (n.isJump()) {
      walk(n.jumpTarget(), box, depth);
      return;
    }
    const double p = box.area() / root_area;
    s.max_depth = std::max(s.max_depth, depth);
    if (n.isLeaf()) {
      ++s.leaves;
      if (n.primCount() == 0) ++s.empty_leaves;
      s.references += n.primCount();
      s.sah_cost += p * intersection_cost * n.primCount();
      return;
    }
    ++s.inner_nodes;
    s.sah_cost += p * traversal_cost;
    const auto [lower, upper] = childCells(n, box);
    walk(i + 1, lower, depth + 1);
    walk(n.upperChild(), upper, depth + 1);
  };
  walk(0, bounds, 0);
  const std::uint32_t filled = s.leaves - s.empty_leaves;
  s.avg_leaf_size = filled ? static_cast<double>(s.references) / filled : 0.0;
  return s;
}

Box KdTree::nodeBox(std::uint32_t index) const {
  if (nodes.empty()) return {};
  // Depth-first search from the root (jumps make "index < upperChild" unusable as a guide).
  std::vector<std::pair<std::uint32_t, Box>> stack{{0u, bounds}};
  while (!stack.empty()) {
    const auto [i, box] = stack.back();
    stack.pop_back();
    if (i == index) return box;
    const KdNode& n = nodes[i];
    if (n.isJump()) {
      stack.emplace_back(n.jumpTarget(), box);
      continue;
    }
    if (n.isLeaf()) continue;
    const auto [lower, upper] = childCells(n, box);
    stack.emplace_back(n.upperChild(), upper);
    stack.emplace_back(i + 1, lower);
  }
  return {};
}

}  // namespace duplex
