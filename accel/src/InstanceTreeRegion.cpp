// Region queries of the top level (TopLevel::instancesInRegion, TopLevel::trianglesInRegion): the
// kd-tree is walked with each cell's box, cells the region excludes skipped; each instance whose
// own world box passes is then judged by its box or, for a geometric mode, by its object in object
// space (the region transformed by the instance's transform).

#include "duplex/accel/InstanceTree.h"
#include "duplex/accel/TopLevel.h"

#include "InstanceTreeState.h"

#include <algorithm>
#include <vector>

namespace duplex {

using namespace toplevel_detail;

std::vector<std::uint32_t> InstanceTree::slotsInRegion(const ConvexRegion& region, std::uint32_t mask) const {
  std::vector<std::uint32_t> slots;
  if (tree_.empty()) return slots;
  std::vector<std::pair<std::uint32_t, Box>> stack{{0u, tree_.bounds}};
  while (!stack.empty()) {
    const auto [i, cell] = stack.back();
    stack.pop_back();
    if (region.excludes(cell)) continue;
    const KdNode& n = tree_.nodes[i];
    if (n.isJump()) {
      stack.emplace_back(n.jumpTarget(), cell);
      continue;
    }
    if (n.isLeaf()) {
      for (std::uint32_t k = 0; k < n.primCount(); ++k) slots.push_back(tree_.prim_indices[n.primOffset() + k]);
      continue;
    }
    const auto [lower, upper] = childCells(n, cell);
    stack.emplace_back(n.upperChild(), upper);
    stack.emplace_back(i + 1, lower);
  }
  std::sort(slots.begin(), slots.end());
  slots.erase(std::unique(slots.begin(), slots.end()), slots.end());
  std::erase_if(slots, [&](std::uint32_t slot) {
    return (state_->records[slot].mask & mask) == 0 || region.excludes(state_->boxes[slot]);
  });
  return slots;
}

void InstanceTree::appendInRegion(const ConvexRegion& region, std::uint32_t mask, RegionMode mode,
                                  std::vector<std::uint32_t>& out) const {
  for (const std::uint32_t slot : slotsInRegion(region, mask)) {
    const Record& rec = state_->records[slot];
    bool selected = true;
    // A world box inside the region decides both geometric modes (its object's bounds hold all of
    // its geometry); otherwise the object is asked, and a type without a region test is judged by
    // its box: it meets the region, but is not known to lie inside it.
    if (mode != RegionMode::Boxes && !region.containsBox(state_->boxes[slot]))
      selected = rec.object->inRegion(region.transformed(rec.object_from_world.inverse()), mode)
                     .value_or(mode == RegionMode::Touching);
    if (selected) out.push_back(rec.id);
  }
}

void InstanceTree::appendTrianglesInRegion(const ConvexRegion& region, std::uint32_t mask,
                                           std::vector<InstanceTriangle>& out) const {
  std::vector<RegionTriangle> tris;
  // By instance id, each instance's triangles by prim id (as the object lists them).
  std::vector<std::uint32_t> slots = slotsInRegion(region, mask);
  std::sort(slots.begin(), slots.end(),
            [&](std::uint32_t x, std::uint32_t y) { return state_->records[x].id < state_->records[y].id; });
  for (const std::uint32_t slot : slots) {
    const Record& rec = state_->records[slot];
    const Affine world_from_object = rec.object_from_world.inverse();
    tris.clear();
    if (!rec.object->trianglesInRegion(region.transformed(world_from_object), tris)) continue;
    for (const RegionTriangle& t : tris) {
      InstanceTriangle& w = out.emplace_back();
      w.instance_id = rec.id;
      w.prim_id = t.prim_id;
      w.vertex = t.vertex;
      for (int k = 0; k < 3; ++k) w.position_ws[k] = world_from_object.point(glm::dvec3(t.position_os[k]));
    }
  }
}

std::vector<std::uint32_t> TopLevel::instancesInRegion(std::span<const glm::dvec4> planes, std::uint32_t mask,
                                                       RegionMode mode) const {
  const ConvexRegion region(planes);
  std::vector<std::uint32_t> out;
  if (crossing_) crossing_->appendInRegion(region, mask, mode, out);
  blocking_.appendInRegion(region, mask, mode, out);
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<InstanceTriangle> TopLevel::trianglesInRegion(std::span<const glm::dvec4> planes,
                                                          std::uint32_t mask) const {
  const ConvexRegion region(planes);
  std::vector<InstanceTriangle> out;
  if (crossing_) crossing_->appendTrianglesInRegion(region, mask, out);
  const auto middle = static_cast<std::ptrdiff_t>(out.size());
  blocking_.appendTrianglesInRegion(region, mask, out);
  // Both runs are ordered; an id lives in one tree only, so merging by id keeps each instance whole.
  std::inplace_merge(
      out.begin(), out.begin() + middle, out.end(),
      [](const InstanceTriangle& a, const InstanceTriangle& b) { return a.instance_id < b.instance_id; });
  return out;
}

}  // namespace duplex
