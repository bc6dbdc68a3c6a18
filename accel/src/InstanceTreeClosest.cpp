// InstanceTree::closestPoint (TopLevel::closestPoint): the nearest surface point of the blocking
// instances to a world point. The kd-tree is walked with each cell's box, the cell holding the
// point first, cells farther than the best distance so far skipped; each instance is asked once
// (Object::closestPoint, in world distance), after its own world box passed the same test.

#include "duplex/accel/InstanceTree.h"
#include "duplex/accel/TopLevel.h"

#include "InstanceTreeState.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace duplex {

using namespace toplevel_detail;

namespace {

// Distance from p to box b (0 inside), world space, in double.
double boxDistance(const glm::dvec3& p, const Box& b) { return std::sqrt(distanceSquared(b, p)); }

// The instance slots asked by the current query (kept in the QueryContext: no allocation after
// the first query of a thread).
struct AskedSlots {
  std::vector<std::uint32_t> slots;
};

const int kAskedSlotsKey = 0;

}  // namespace

void InstanceTree::closestPoint(const glm::dvec3& point_ws, ClosestPoint& best, QueryContext& ctx,
                                std::uint32_t mask) const {
  if (tree_.empty() || !std::isfinite(point_ws.x) || !std::isfinite(point_ws.y) || !std::isfinite(point_ws.z)) return;
  const Record* records = state_->records.data();
  const Box* boxes = state_->boxes.data();
  std::vector<std::uint32_t>& asked = ctx.cached<AskedSlots>(&kAskedSlotsKey, [] { return AskedSlots{}; }).slots;
  asked.clear();
  struct Entry {
    std::uint32_t node;
    Box cell;
  };
  std::vector<Entry> stack{{0u, tree_.bounds}};
  while (!stack.empty()) {
    const Entry e = stack.back();
    stack.pop_back();
    if (!(boxDistance(point_ws, e.cell) < best.distance)) continue;
    const KdNode& n = tree_.nodes[e.node];
    if (n.isJump()) {
      stack.push_back({n.jumpTarget(), e.cell});
      continue;
    }
    if (n.isLeaf()) {
      for (std::uint32_t k = 0; k < n.primCount(); ++k) {
        const std::uint32_t slot = tree_.prim_indices[n.primOffset() + k];
        const Record& rec = records[slot];
        if ((rec.mask & mask) == 0 || rec.role != ObjectRole::Surface) continue;
        if (std::find(asked.begin(), asked.end(), slot) != asked.end()) continue;
        if (!(boxDistance(point_ws, boxes[slot]) < best.distance)) continue;
        asked.push_back(slot);
        const PointQuery q = PointQuery::make(point_ws, rec.object_from_world.inverse(), rec.object_from_world);
        if (rec.object->closestPoint(q, best, ctx)) best.instance_id = rec.id;
      }
      continue;
    }
    const int axis = n.axis();
    const auto [lower, upper] = childCells(n, e.cell);
    // The side holding the point on top, so that it is searched first.
    if (point_ws[axis] < double{n.split()}) {
      stack.push_back({n.upperChild(), upper});
      stack.push_back({e.node + 1, lower});
    } else {
      stack.push_back({e.node + 1, lower});
      stack.push_back({n.upperChild(), upper});
    }
  }
}

ClosestPoint TopLevel::closestPoint(const glm::dvec3& point_ws, double max_distance, QueryContext& ctx,
                                    std::uint32_t mask) const {
  ClosestPoint best;
  if (!(max_distance >= 0.0)) return best;  // NaN or negative: nothing can be within it
  // Objects report points strictly closer than best.distance: one step beyond makes the maximum
  // inclusive.
  best.distance = std::nextafter(max_distance, std::numeric_limits<double>::infinity());
  blocking_.closestPoint(point_ws, best, ctx, mask);
  if (!best.valid()) best = ClosestPoint{};  // distance +inf, nothing found
  return best;
}

}  // namespace duplex
