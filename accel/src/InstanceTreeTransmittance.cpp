// InstanceTree::transmittance (TopLevel::transmittance): shadow and sensor rays through fog. One front-to-back
// traversal of the top-level tree over the whole segment (media anywhere on it count), ending at the first blocking
// surface (transmittance 0). Each instance is asked once however many leaves hold it: a medium
// counted twice would square its transmittance, so the mailbox of the closest-hit query (which may
// forget) is not enough; the instances seen are kept in a per-thread list.

#include "duplex/accel/InstanceTree.h"

#include "InstanceTreeState.h"

#include <algorithm>
#include <vector>

namespace duplex {

using namespace toplevel_detail;

namespace {

// The per-thread list of instance slots seen by the current ray (kept in the QueryContext so that
// a query allocates nothing after the first).
struct SeenSlots {
  std::vector<std::uint32_t> slots;
};

const int kSeenSlotsKey = 0;

}  // namespace

float InstanceTree::transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask) const {
  ++ctx.stats.rays;
  if (!isQueryable(ray_ws) || tree_.empty()) return 1.0f;
  const WorldRay w = fromFloat(ray_ws);
  const Record* records = state_->records.data();
  const SlotFilter* filters = state_->filters.data();
  const Box* boxes = state_->boxes.data();
  std::vector<std::uint32_t>& seen = ctx.cached<SeenSlots>(&kSeenSlotsKey, [] { return SeenSlots{}; }).slots;
  seen.clear();
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;  // never lowered: every leaf along the segment
  double product = 1.0;
  const bool blocked = traverseKdTree<true>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
    for (std::uint32_t i = begin; i < begin + count; ++i) {
      const std::uint32_t slot = tree_.prim_indices[i];
      const SlotFilter f = filters[slot];
      if ((f.mask & mask) == 0 || f.role == ObjectRole::Crossing || !meetsBox(kray, boxes[slot], ray_ws.tfar) ||
          std::find(seen.begin(), seen.end(), slot) != seen.end())
        continue;
      const Record& rec = records[slot];
      seen.push_back(slot);
      ++ctx.stats.instance_visits;
      const Ray ray_os = toObject(rec, w);
      if (rec.role == ObjectRole::Surface) {
        if (rec.object->occluded(ray_os, ctx)) return true;
      } else {
        product *= rec.object->transmittance(ray_os, ctx);
        if (product == 0.0) return true;
      }
    }
    return false;
  });
  return blocked ? 0.0f : static_cast<float>(product);
}

}  // namespace duplex
