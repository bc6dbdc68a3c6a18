// The crossing query of light transport (TopLevel::intersectWithCrossings): one closest-hit
// traversal of the top level that also collects sensor crossings and the media the ray passes.
//
// Sensors live in a tree of their own (TopLevel::crossing_, an InstanceTree): the first traversal, of the other
// instances, finds the closest blocking hit and the media; the second walks the sensors' tree only
// up to that hit (a sensor behind a wall costs nothing): through a uniform grid over the sensors'
// boxes (CrossingGrid.h, TopLevelConfig::crossing_grid) or else their shallow kd-tree, whose leaves'
// boxes are tested 16, 8 or 4 at a time from a leaf-ordered copy (LeafBoxes.h,
// TopLevelConfig::crossing_build). A flat sensor whose plane the ray plainly misses is dropped by a
// float test with rounding bounds (Object::flatCrossings, FlatPlane.h); any other whose box the ray
// meets is asked for its crossings up to the hit, once (mailbox, then a check of the crossings
// kept), and they are inserted in order.
// Media met along the way are kept and their transmittance is applied segment by segment between
// the sorted crossings, so each medium is integrated once over [tnear, t_hit].

#include "duplex/accel/TopLevel.h"

#include "InstanceTreeState.h"

#include <algorithm>

namespace duplex {

using namespace toplevel_detail;

namespace {

// Per-thread scratch lists (kept in the QueryContext: no allocation per ray): the media a ray met,
// and one sensor's crossings.
struct CrossingScratch {
  std::vector<const Record*> media;
  std::vector<Hit> hits;
  std::vector<std::uint32_t> grid_runs, grid_met;  // the grid walk's cells and met entries
};
const char kScratchKey = 0;

// A prefetch the optimiser keeps: GCC deletes a loop whose only statements are
// __builtin_prefetch calls (they have no side effect it must preserve).
inline void prefetchLine(const char* p) {
#if defined(DUPLEX_LEAF_BOXES_X86)
  asm volatile("prefetcht0 %0" : : "m"(*p));
#else
  __builtin_prefetch(p);
#endif
}

}  // namespace

SegmentEnd TopLevel::intersectWithCrossings(const Ray& ray_ws, std::vector<Crossing>& crossings, QueryContext& ctx,
                                            const CrossingQuery& query) const {
  ++ctx.stats.rays;
  crossings.clear();
  SegmentEnd end;
  const KdTree& tree = blocking_.tree_;
  const bool have_crossing = crossing_ && !crossing_->tree_.empty();
  if (!isQueryable(ray_ws) || (tree.empty() && !have_crossing)) return end;
  const WorldRay w = fromFloat(ray_ws);
  const Record* records = blocking_.state_->records.data();
  const SlotFilter* filters = blocking_.state_->filters.data();
  const Box* boxes = blocking_.state_->boxes.data();
  CrossingScratch& scratch_lists = ctx.cached<CrossingScratch>(&kScratchKey, [] { return CrossingScratch{}; });
  std::vector<const Record*>& media = scratch_lists.media;
  std::vector<Hit>& scratch = scratch_lists.hits;
  media.clear();
  Hit best;
  best.t = ray_ws.tfar;
  std::uint32_t best_id = kInvalidId;
  const Record* winner = nullptr;
  // A sensor's crossings within [tnear, t_reach] (world t), inserted in order (t, then instance
  // id): a ray meets few sensors, so keeping the list sorted costs less than sorting it. An
  // instance in many leaves may come back after the mailbox forgot it; it is asked once.
  auto addCrossings = [&](const Record& rec, float t_reach) {
    if (std::any_of(crossings.begin(), crossings.end(), [&](const Crossing& c) { return c.hit.instance_id == rec.id; }))
      return;
    Ray ray_os = toObject(rec, w);
    ray_os.tfar = t_reach;
    scratch.clear();
    rec.object->intersectAll(ray_os, scratch, ctx);
    for (Hit& h : scratch) {
      if (!(h.t <= t_reach)) continue;
      h.instance_id = rec.id;
      h.ng = normalToWorld(rec, h.ng);
      const auto at = std::upper_bound(crossings.begin(), crossings.end(), h, [](const Hit& a, const Crossing& b) {
        return a.t < b.hit.t || (a.t == b.hit.t && a.instance_id < b.hit.instance_id);
      });
      crossings.insert(at, {h, 1.0f});
    }
  };
  Mailbox mailbox;
  const KdRay kray(ray_ws);
  float t_best = ray_ws.tfar;
  if (!tree.empty())
    traverseKdTree<false>(tree, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t) {
      bool found = false;
      for (std::uint32_t i = begin; i < begin + count; ++i) {
        const std::uint32_t slot = tree.prim_indices[i];
        // Surfaces and media only: sensors live in the sensors' level, walked below.
        const SlotFilter f = filters[slot];
        const std::uint32_t role_mask = f.role == ObjectRole::Surface  ? query.surface_mask
                                        : f.role == ObjectRole::Medium ? query.medium_mask
                                                                       : 0u;
        const float t_reach = f.role == ObjectRole::Surface ? t : t * (1.0f + kCrossingSlack);
        if ((f.mask & role_mask) == 0 || !meetsBox(kray, boxes[slot], t_reach) || mailbox.seen(slot)) continue;
        const Record& rec = records[slot];
        ++ctx.stats.instance_visits;
        if (rec.role == ObjectRole::Surface) {
          if (closerHit(rec, toObject(rec, w), best, t, best_id, ctx)) {
            winner = &rec;
            found = true;
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

  // The sensors' level, up to the blocking hit. A leaf's boxes are read from the leaf-ordered copy
  // (one contiguous run, four boxes per test) and tested first: most references a ray meets are
  // missed, and a miss then reads nothing else (filter, mailbox and record come after).
  if (have_crossing && query.crossing_mask != 0) {
    const InstanceTree::State& ss = *crossing_->state_;
    const KdTree& s_tree = crossing_->tree_;
    const std::uint32_t* s_prims = s_tree.prim_indices.data();
    const Record* s_records = ss.records.data();
    const SlotFilter* s_filters = ss.filters.data();
    const Box* s_boxes = ss.boxes.data();
    const LeafBoxes* leaf_boxes = ss.leaf_boxes.count == s_tree.prim_indices.size() ? &ss.leaf_boxes : nullptr;
    Mailbox s_mailbox;
    // Flat sensors' planes, when they describe this level's slots (refreshed with the leaf boxes).
    const FlatPlane* flat = leaf_boxes && ss.flat.size() == ss.records.size() ? ss.flat.data() : nullptr;
    const PlaneRay plane_ray(ray_ws);
    // A met reference: its filter, the mailbox (a sensor listed in several cells or leaves is
    // plane-tested and asked once), the plane test, then the object.
    auto visit = [&](std::uint32_t slot) {
      const SlotFilter f = s_filters[slot];
      if ((f.mask & query.crossing_mask) == 0 || f.role != ObjectRole::Crossing || s_mailbox.seen(slot)) return;
      if (flat && flat[slot].valid() && plainlyMisses(flat[slot], plane_ray, t_keep)) {
        ++ctx.stats.crossing_plane_misses;
        return;
      }
      ++ctx.stats.instance_visits;
      addCrossings(s_records[slot], t_keep);
    };
    // The grid's entries carry their plane record, slot and mask in one cache line (grid_planes):
    // the same steps as visit() from one read; entries without a record take visit().
    const FlatPlane* grid_planes =
        flat && ss.grid_planes.size() == ss.grid.slots.size() ? ss.grid_planes.data() : nullptr;
    auto visitEntry = [&](std::uint32_t entry) {
      if (!grid_planes || !grid_planes[entry].valid()) return visit(ss.grid.slots[entry]);
      const FlatPlane& p = grid_planes[entry];
      if ((p.mask & query.crossing_mask) == 0 || s_mailbox.seen(p.slot())) return;
      if (plainlyMisses(p, plane_ray, t_keep)) {
        ++ctx.stats.crossing_plane_misses;
        return;
      }
      ++ctx.stats.instance_visits;
      addCrossings(s_records[p.slot()], t_keep);
    };
    // Before the met entries are plane-tested: ask for the records of their sensors (~120 bytes,
    // two or three lines), which addCrossings reads for those the plane test keeps. Found from the
    // entry's slot (a dense array, in cache) rather than from the plane record, whose own load
    // is still under way, so the two misses overlap instead of following each other.
    auto prefetchRecords = [&](const std::uint32_t* met, std::uint32_t n) {
      const std::uint32_t* entry_slots = ss.grid.slots.data();
      for (std::uint32_t k = 0; k < n; ++k) {
        const char* rec = reinterpret_cast<const char*>(s_records + entry_slots[met[k]]);
        prefetchLine(rec);
        prefetchLine(rec + 64);
        prefetchLine(rec + sizeof(Record) - 1);
      }
    };
    const bool by_grid = leaf_boxes && config().crossing_grid && ss.grid.usable() &&
                         ss.grid.forEachMet(kray, ray_ws.dir, t_keep, scratch_lists.grid_runs, scratch_lists.grid_met,
                                            visitEntry, grid_planes, prefetchRecords);
    float t_limit = t_keep;
    if (!by_grid)
      (void)traverseKdTree<false>(s_tree, kray, t_limit, [&](std::uint32_t begin, std::uint32_t count, float&) {
        if (leaf_boxes) {
          leaf_boxes->forEachMet(kray, begin, count, t_keep, [&](std::uint32_t i) { visit(s_prims[i]); });
        } else {
          for (std::uint32_t i = begin; i < begin + count; ++i)
            if (meetsBox(kray, s_boxes[s_prims[i]], t_keep)) visit(s_prims[i]);
        }
        return false;
      });
  }

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
    for (Crossing& c : crossings) c.transmittance = segment(c.hit.t);
    end.transmittance = segment(t_end);
  }
  return end;
}

}  // namespace duplex
