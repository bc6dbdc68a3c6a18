// The crossing query of light transport (TopLevel::intersectWithCrossings): one closest-hit
// traversal of the top level that also collects sensor crossings and the media the ray passes.
//
// Sensors never lower t_best, so the traversal visits exactly the leaves a closest-hit query
// visits. A sensor instance met in a leaf is asked for its crossing up to the current t_best (t
// only decreases, so a crossing beyond it is beyond the final hit too); each instance is asked
// once (mailbox, then a check of the crossings kept). After the traversal the crossings beyond
// the final hit are dropped and the rest sorted. Media met along the way are kept and their
// transmittance is applied segment by segment between the sorted crossings, so each medium is
// integrated once over [tnear, t_hit].

#include "TopLevelState.h"

#include <algorithm>

namespace duplex {

using namespace toplevel_detail;

namespace {

// Per-thread scratch lists (kept in the QueryContext: no allocation per ray): the media a ray met,
// and one sensor's crossings.
struct CrossingScratch {
  std::vector<const Record*> media;
  std::vector<Hit> hits;
};
const char kScratchKey = 0;

}  // namespace

SegmentEnd TopLevel::intersectWithCrossings(const Ray& ray_ws, std::vector<SensorCrossing>& crossings, QueryContext& ctx,
                                            const CrossingQuery& query) const {
  ++ctx.stats.rays;
  crossings.clear();
  SegmentEnd end;
  if (!isQueryable(ray_ws) || tree_.empty()) return end;
  const WorldRay w = fromFloat(ray_ws);
  const Record* records = state_->records.data();
  const SlotFilter* filters = state_->filters.data();
  const Box* boxes = state_->boxes.data();
  CrossingScratch& scratch_lists = ctx.cached<CrossingScratch>(&kScratchKey, [] { return CrossingScratch{}; });
  std::vector<const Record*>& media = scratch_lists.media;
  std::vector<Hit>& scratch = scratch_lists.hits;
  media.clear();
  Hit best;
  best.t = ray_ws.tfar;
  const Record* winner = nullptr;
  Mailbox mailbox;
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;
  traverseKdTree<false>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t) {
    bool found = false;
    for (std::uint32_t i = begin; i < begin + count; ++i) {
      const std::uint32_t slot = tree_.prim_indices[i];
      const SlotFilter f = filters[slot];
      const std::uint32_t role_mask = f.role == ObjectRole::Surface  ? query.surface_mask
                                      : f.role == ObjectRole::Sensor ? query.sensor_mask
                                                                     : query.medium_mask;
      const float t_reach = f.role == ObjectRole::Surface ? t : t * (1.0f + kCrossingSlack);
      if ((f.mask & role_mask) == 0 || !meetsBox(kray, boxes[slot], t_reach) || mailbox.seen(slot)) continue;
      const Record& rec = records[slot];
      ++ctx.stats.instance_visits;
      if (rec.role == ObjectRole::Surface) {
        Ray ray_os = toObject(rec, w);
        ray_os.tfar = t;
        Hit h = best;
        h.t = t;
        if (rec.object->intersect(ray_os, h, ctx)) {
          best = h;
          t = h.t;
          winner = &rec;
          found = true;
        }
      } else if (rec.role == ObjectRole::Sensor) {
        // The mailbox holds 8 slots: an instance in many leaves may come back; ask it once.
        if (std::any_of(crossings.begin(), crossings.end(), [&](const SensorCrossing& c) { return c.hit.instance_id == rec.id; }))
          continue;
        Ray ray_os = toObject(rec, w);
        ray_os.tfar = t_reach;
        scratch.clear();
        rec.object->intersectAll(ray_os, scratch, ctx);
        for (Hit& h : scratch) {
          h.instance_id = rec.id;
          h.ng = normalToWorld(rec, h.ng);
          crossings.push_back({h, 1.0f});
        }
      } else if (std::find(media.begin(), media.end(), &rec) == media.end()) {
        media.push_back(&rec);
      }
    }
    return found;
  });

  if (winner) {
    best.instance_id = winner->id;
    best.ng = normalToWorld(*winner, best.ng);
    end.hit = best;
  }
  const float t_end = winner ? best.t : ray_ws.tfar;
  const float t_keep = t_end * (1.0f + kCrossingSlack);
  crossings.erase(std::remove_if(crossings.begin(), crossings.end(),
                                 [&](const SensorCrossing& c) { return !(c.hit.t <= t_keep); }),
                  crossings.end());
  std::sort(crossings.begin(), crossings.end(), [](const SensorCrossing& a, const SensorCrossing& b) {
    if (a.hit.t != b.hit.t) return a.hit.t < b.hit.t;
    return a.hit.instance_id < b.hit.instance_id;
  });

  // Media: the product of each medium's transmittance over consecutive segments
  // [tnear, t_1], [t_1, t_2], ..., [t_k, t_end] (transmittance is multiplicative along a ray).
  if (!media.empty()) {
    float running = 1.0f;
    float t0 = ray_ws.tnear;
    auto segment = [&](float t1) {
      if (running > 0.0f && t1 > t0) {
        for (const Record* m : media) {
          Ray ray_os = toObject(*m, w);
          ray_os.tnear = t0;
          ray_os.tfar = t1;
          running *= m->object->transmittance(ray_os, ctx);
        }
      }
      t0 = std::max(t0, t1);
      return running;
    };
    for (SensorCrossing& c : crossings) c.transmittance = segment(c.hit.t);
    end.transmittance = segment(t_end);
  }
  return end;
}

}  // namespace duplex
