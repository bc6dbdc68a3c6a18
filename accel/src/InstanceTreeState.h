#pragma once
// Private to accel/src: an instance tree's records and the per-ray helpers every top-level query
// shares. Queries beyond the basic ones (crossings, transmittance) live in their own .cpp files and
// include this header.

#include "duplex/accel/Affine.h"
#include "duplex/accel/Box.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/InstanceTree.h"
#include "FlatPlane.h"
#include "LeafBoxes.h"
#include "CrossingGrid.h"
#include "WideTop.h"

#include <glm/matrix.hpp>

#include <emmintrin.h>

#include <algorithm>
#include <cstddef>
#include <limits>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace duplex {

namespace toplevel_detail {

inline std::string describeInstance(const InstanceDesc& d) {
  std::string s = "instance " + std::to_string(d.id);
  if (d.object) s += " (object '" + d.object->name() + "')";
  return s;
}

// Throws InvalidArgument for a configuration out of range (InstanceTree.cpp).
void validateConfig(const TopLevelConfig& c);

// Sorts hits by t, ties by instance id, then primitive id (the order intersectAll reports).
inline void sortHits(std::vector<Hit>& hits) {
  std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
    if (a.t != b.t) return a.t < b.t;
    if (a.instance_id != b.instance_id) return a.instance_id < b.instance_id;
    return a.prim_id < b.prim_id;
  });
}

// What traversal reads for an instance: one record, no pointer chase but the object.
struct Record {
  const Object* object = nullptr;
  Affine object_from_world;
  std::uint32_t id = kInvalidId;
  std::uint32_t mask = 0;
  ObjectRole role = ObjectRole::Surface;
  bool identity = false;  // skip the transform for instances placed as authored
  ObjectRayEntry entry;   // the object's direct entry (Object::rayEntry), fetched once per edit
};

// The part of a record every reference test reads first, kept in its own dense array (8 bytes
// per slot): with many instances (10,000 sensors) the records (~120 bytes each) fall out of the
// cache, and rejecting a reference by role or mask must not cost a miss on its record.
struct SlotFilter {
  std::uint32_t mask = 0;  // 0 for a free slot: no query matches it
  ObjectRole role = ObjectRole::Surface;
};

inline SlotFilter filterOf(const Record& r) { return {r.mask, r.role}; }

struct Prepared {
  Record record;
  std::shared_ptr<const Object> owner;
  Box box;
};

inline constexpr std::uint32_t kNoJump = 0xFFFFFFFFu;

// A leaf reached by routing a box, with the cell it covers.
struct LeafVisit {
  std::uint32_t node;
  Box cell;
  std::uint32_t depth;  // inner nodes above it (jumps do not count: they use no stack)
  Box root;             // the root bounds the cell was derived from
  // The innermost jump node on the path (a subtree that a commit built locally), its cell and
  // depth; kNoJump when the leaf belongs to the last full build.
  std::uint32_t jump = kNoJump;
  Box jump_cell;
  std::uint32_t jump_depth = 0;
  std::uint32_t frontier = kNoJump;  // the frontier subtree it belongs to (InstanceTree::State::frontiers)
};

// A subtree of the last full build that is rebuilt on its own once edits changed a good part of
// its references: the nodes where a walk from the root first meets a subtree of at most
// max(256, references / 64) references (leaves included).
struct Frontier {
  std::uint32_t node;  // stays valid: frontier nodes are never garbage (a rebuild makes them jumps)
  Box cell;            // derived from `root`
  Box root;
  std::uint32_t depth;  // inner nodes above it
  std::uint32_t refs;   // references after its last build
  std::uint32_t edits;  // references added or removed in it since
};

// The world ray as the caller gave it: float for the top-level traversal; the double ray when the
// caller gave one (picking far from the origin), from which transformed instances take their
// object-space rays. A float query converts to double only when it enters a transformed instance.
struct WorldRay {
  Ray f;
  const RayD* d = nullptr;
};

inline WorldRay fromFloat(const Ray& r) { return {r, nullptr}; }

// `r` must outlive the result.
inline WorldRay fromDouble(const RayD& r) {
  Ray f;
  f.origin = glm::vec3(r.origin);
  f.dir = glm::vec3(r.dir);
  f.tnear = static_cast<float>(r.tnear);
  f.tfar = static_cast<float>(r.tfar);
  return {f, &r};
}

inline Ray toObject(const Record& rec, const WorldRay& w) {
  if (rec.identity) return w.f;
  const glm::dvec3 o = w.d ? w.d->origin : glm::dvec3(w.f.origin);
  const glm::dvec3 d = w.d ? w.d->dir : glm::dvec3(w.f.dir);
  Ray r;
  r.origin = glm::vec3(rec.object_from_world.point(o));
  r.dir = glm::vec3(rec.object_from_world.vector(d));
  r.tnear = w.f.tnear;
  r.tfar = w.f.tfar;
  return r;
}

// The world-space geometric normal of a hit: the cofactor matrix det(L) L^-T of L =
// world_from_object's linear part maps cross(v1 - v0, v2 - v0) of object space exactly to the same
// cross product of the world-space vertices (the inverse transpose alone would lose the scale and
// flip the winding of mirrored instances). With M = L^-1 (which the record holds) it is M^T / det M;
// computed per reported hit rather than stored per instance.
inline glm::vec3 normalToWorld(const Record& rec, const glm::vec3& ng_os) {
  if (rec.identity) return ng_os;
  const glm::dmat3& m = rec.object_from_world.linear;
  return glm::vec3((glm::transpose(m) / glm::determinant(m)) * glm::dvec3(ng_os));
}

// Whether the ray meets `box` within [ray.tnear, t_max]: the instance's own world box, tested
// before its ray transform and bottom-level setup. A leaf cell is usually much larger than the
// boxes it holds (rotated instances, boxes cut by few planes), and most visits end here.
inline bool meetsBox(const KdRay& ray, const Box& box, float t_max) {
  float t0 = ray.tnear, t1 = t_max;
  return clipIntervalToBox(ray, box, t0, t1);
}

// The object-space bound an instance is asked with when the best hit so far is at world t: a few
// ulps beyond t, so that a hit at exactly t (which an object may reject by the rounding of its own
// test when asked with t itself) comes back and the tie rule below decides it.
inline float askBound(float t) {
  constexpr float kSlack = 4.0f * std::numeric_limits<float>::epsilon();
  return t + std::abs(t) * kSlack;
}

// The closest-hit rule between instances: a hit replaces the best one when it is closer, or at the
// same t from an instance of lower id. With it the winner does not depend on the order in which
// instances are visited (the tree's shape, the single or packet walk, the leaf order).
inline bool replacesBest(float t_hit, std::uint32_t id, float t_best, std::uint32_t best_id) {
  return t_hit < t_best || (t_hit == t_best && id < best_id);
}

// Asks blocking instance `rec` for a hit along `ray_os` (the world ray in its object space,
// toObject); on one that replacesBest() (t, best_id: the best so far, kInvalidId for none)
// overwrites `best` (object-space normal, instance id not set), t and best_id and returns true. The
// leaf step of every closest-hit traversal (intersect and the crossing query).
inline bool closerHit(const Record& rec, Ray ray_os, Hit& best, float& t, std::uint32_t& best_id, QueryContext& ctx) {
  ray_os.tfar = askBound(t);
  Hit h;
  h.t = ray_os.tfar;
  const bool hit =
      rec.entry.intersect ? rec.entry.intersect(rec.entry.data, ray_os, h) : rec.object->intersect(ray_os, h, ctx);
  if (!hit || !replacesBest(h.t, rec.id, t, best_id)) return false;
  best = h;
  t = h.t;
  best_id = rec.id;
  return true;
}

// Whether anything of blocking instance `rec` blocks `ray_os` (the world ray in its object space,
// toObject) within [tnear, tfar].
inline bool occludes(const Record& rec, const Ray& ray_os, QueryContext& ctx) {
  return rec.entry.occluded ? rec.entry.occluded(rec.entry.data, ray_os) : rec.object->occluded(ray_os, ctx);
}

// A small mailbox: an instance box usually spans several leaves, and a repeated bottom-level
// traversal of the same instance for the same ray is wasted work. The eight slots are compared at
// once (two vector compares, no branch per slot: how many slots a search compared depended on the
// data and mispredicted).
struct Mailbox {
  alignas(16) std::uint32_t slots[8] = {kInvalidId, kInvalidId, kInvalidId, kInvalidId,
                                        kInvalidId, kInvalidId, kInvalidId, kInvalidId};
  std::uint32_t next = 0;
  bool seen(std::uint32_t slot) {
    const __m128i s = _mm_set1_epi32(static_cast<int>(slot));
    const __m128i a = _mm_cmpeq_epi32(s, _mm_load_si128(reinterpret_cast<const __m128i*>(slots)));
    const __m128i b = _mm_cmpeq_epi32(s, _mm_load_si128(reinterpret_cast<const __m128i*>(slots + 4)));
    if (_mm_movemask_epi8(_mm_or_si128(a, b)) != 0) return true;
    slots[next] = slot;
    next = (next + 1) & 7u;
    return false;
  }
};

// A ray's values for the instance box tests, as vectors over the three axes (lane 3 unused),
// computed once per ray.
struct BoxTestRay {
  __m128 origin, inv_dir;
  float tnear;
  bool any_zero;  // some direction component is zero: the scalar test's origin-in-slab rule
  const KdRay* kd;
};

// Everything a top-level walk computes once per world ray, in registers: KdRay's values for the kd
// walk (`k`), the box-test vectors (`b`, which points at `k`) and the ray clipped to `root`
// ([tmin, tmax], as clipRayToBox). Returns false for a ray that is not queryable (isQueryable) or
// misses the root box; `k` and `b` are then unspecified. The values are prepareKdRay's and
// clipPreparedRay's (KdTraversal.h), computed without their round trips through memory.
[[gnu::always_inline]] inline bool setupWorldRay(const Ray& ray, const Box& root, KdRay& k, BoxTestRay& b, float& tmin,
                                                 float& tmax) {
  __m128 o, d, inv;
  int zero;
  if (!kd_detail::prepareSse(ray, k, o, d, inv, zero)) return false;
  b.origin = o;
  b.inv_dir = inv;
  b.tnear = ray.tnear;
  b.any_zero = zero != 0;
  b.kd = &k;
  return kd_detail::clipSse(o, d, inv, kd_detail::boxLo(root), kd_detail::boxHi(root), tmin, tmax);
}

// Whether the ray meets `box` within [ray.tnear, t_max], as meetsBox(), the three slabs at once;
// `t_enter` gets the widened entry (the largest entry, widened once: the widening is monotonic,
// so the bounds are clipIntervalToBox's). Rays with a zero direction component take meetsBox's
// scalar rule.
[[gnu::always_inline]] inline bool meetsBoxAt(const BoxTestRay& ray, const Box& box, float t_max, float& t_enter) {
  if (ray.any_zero) {
    float t1 = t_max;
    t_enter = ray.tnear;
    return clipIntervalToBox(*ray.kd, box, t_enter, t1);
  }
  const __m128 t0 = _mm_mul_ps(_mm_sub_ps(kd_detail::boxLo(box), ray.origin), ray.inv_dir);
  const __m128 t1 = _mm_mul_ps(_mm_sub_ps(kd_detail::boxHi(box), ray.origin), ray.inv_dir);
  const __m128 t_in = _mm_min_ps(t1, t0), t_out = _mm_max_ps(t1, t0);
  // The largest entry and smallest exit of lanes 0..2.
  const float enter =
      _mm_cvtss_f32(_mm_max_ss(_mm_max_ss(t_in, _mm_shuffle_ps(t_in, t_in, 1)), _mm_movehl_ps(t_in, t_in)));
  const float leave =
      _mm_cvtss_f32(_mm_min_ss(_mm_min_ss(t_out, _mm_shuffle_ps(t_out, t_out, 1)), _mm_movehl_ps(t_out, t_out)));
  constexpr float kWiden = 2.0f * 3.0f * std::numeric_limits<float>::epsilon();
  t_enter = std::max(ray.tnear, enter - std::abs(enter) * kWiden);
  return t_enter <= std::min(t_max, leave + std::abs(leave) * kWiden);
}

// Calls met(slot, t_enter) for each reference of a leaf whose instance passes `pass(filter)` and
// whose box the ray meets within [ray.tnear, t_max], in leaf order, with the box's widened entry.
template <class Pass, class Met>
[[gnu::always_inline]] inline void forEachMetRef(const BoxTestRay& ray, const std::uint32_t* refs, std::uint32_t count,
                                                 const SlotFilter* filters, const Box* boxes, float t_max, Pass&& pass,
                                                 Met&& met) {
  for (std::uint32_t i = 0; i < count; ++i) {
    const std::uint32_t slot = refs[i];
    float t_enter;
    if (pass(filters[slot]) && meetsBoxAt(ray, boxes[slot], t_max, t_enter)) met(slot, t_enter);
  }
}

// The closest-hit leaf step: the leaf's instances whose box the ray meets, visited in the order of
// their box entry (the nearest first, so that its hit culls the others), skipping those whose box
// starts behind the best hit and those the mailbox has seen. `visit(slot)` asks the instance and
// returns whether it found a closer hit (lowering t).
template <class Pass, class Visit>
inline bool closestInLeaf(const BoxTestRay& ray, const std::uint32_t* refs, std::uint32_t count,
                          const SlotFilter* filters, const Box* boxes, float& t, Mailbox& mailbox, Pass&& pass,
                          Visit&& visit) {
  constexpr std::uint32_t kChunk = 16;  // met references sorted at a time (leaves are far smaller)
  bool found = false;
  for (std::uint32_t begin = 0; begin < count; begin += kChunk) {
    std::uint32_t met_slot[kChunk];
    float met_t[kChunk];
    std::uint32_t n = 0;
    forEachMetRef(ray, refs + begin, std::min(kChunk, count - begin), filters, boxes, t, pass,
                  [&](std::uint32_t slot, float t_enter) {
                    // Insertion by entry distance (a leaf meets few boxes; equal entries keep leaf order).
                    std::uint32_t j = n++;
                    for (; j > 0 && met_t[j - 1] > t_enter; --j) {
                      met_t[j] = met_t[j - 1];
                      met_slot[j] = met_slot[j - 1];
                    }
                    met_t[j] = t_enter;
                    met_slot[j] = slot;
                  });
    for (std::uint32_t j = 0; j < n && met_t[j] <= t; ++j) {
      if (mailbox.seen(met_slot[j])) continue;
      if (visit(met_slot[j])) found = true;
    }
  }
  return found;
}

}  // namespace toplevel_detail

struct InstanceTree::State {
  using Record = toplevel_detail::Record;
  using LeafVisit = toplevel_detail::LeafVisit;
  using Prepared = toplevel_detail::Prepared;
  std::vector<Record> records;                       // by slot; tree indices are slots
  std::vector<toplevel_detail::SlotFilter> filters;  // by slot: filterOf(records[slot])
  std::vector<std::shared_ptr<const Object>> owners;
  std::vector<Box> boxes;  // world box by slot; empty for a free slot
  std::vector<std::uint32_t> free_slots;
  std::unordered_map<std::uint32_t, std::uint32_t> slot_of_id;

  // Edits recorded since the last commit, in call order; nullopt = removal.
  std::vector<std::pair<std::uint32_t, std::optional<Prepared>>> pending;
  std::unordered_map<std::uint32_t, std::size_t> pending_index;

  std::size_t garbage = 0;  // dead entries in tree.prim_indices
  double sah_cost = 0.0;
  double fresh_cost = 0.0;
  std::size_t fresh_count = 0;
  std::uint64_t commits = 0, full_rebuilds = 0, subtree_rebuilds = 0;
  std::size_t last_edits = 0;
  bool last_full = false;

  std::size_t fresh_nodes = 0, fresh_refs = 0;  // of the last full build
  bool cost_stale = false;     // sah_cost is an estimate (root bounds changed): recompute when it matters
  bool boundary_left = false;  // a box on a root face moved or vanished: the root may shrink
  bool needs_rebuild = false;  // a commit failed half way: the records are ahead of the tree

  std::vector<LeafVisit> scratch_old, scratch_new;

  // Blocking trees only: the 8-wide traversal form of the tree (WideTop.h), refreshed after every
  // commit and build: what lies on the paths of the boxes an incremental commit edited
  // (`wide_edited`: the old and new world boxes of the instances it moved, added or removed), or
  // all of it after a full build or a compaction (`wide_full`).
  toplevel_detail::WideTop wide;
  std::vector<Box> wide_edited;
  bool wide_full = false;

  // Crossing trees only (InstanceTree::Kind::Crossing): the boxes in leaf order (LeafBoxes.h), refreshed after every
  // commit and build (O(references)); a count that differs from tree.prim_indices (a failed commit) means "not
  // available", and the crossing query reads `boxes` by slot instead. With them, a uniform grid over the same boxes
  // (CrossingGrid.h), refreshed at the same times.
  toplevel_detail::LeafBoxes leaf_boxes;
  toplevel_detail::CrossingGrid grid;
  std::vector<toplevel_detail::FlatPlane> flat;  // by slot: the flat instances' planes (FlatPlane.h)
  // By grid entry (grid.slots order): the same records, so that an entry whose box a ray meets is
  // filtered, mailboxed and plane-tested from one cache line (slot and mask packed in the record)
  // instead of three random reads (entry slot, filter, plane).
  std::vector<toplevel_detail::FlatPlane> grid_planes;
  void refreshLeafBoxes(const KdTree& tree) {
    leaf_boxes.refresh(boxes, tree.prim_indices);
    flat.assign(records.size(), {});
    for (std::size_t slot = 0; slot < records.size(); ++slot) {
      const Record& rec = records[slot];
      if (!rec.object || boxes[slot].empty()) continue;
      if (const std::optional<FlatCrossings> f = rec.object->flatCrossings())
        flat[slot] = toplevel_detail::FlatPlane(rec.identity ? Affine::identity() : rec.object_from_world, *f,
                                                static_cast<std::uint32_t>(slot),
                                                rec.role == ObjectRole::Crossing ? rec.mask : 0u);
    }
    // A flat slot's rectangle |x| <= w/2, |y| <= h/2 of its object's plane z = 0, in world space.
    grid.refresh(boxes, [&](std::uint32_t slot, toplevel_detail::FlatQuad& q) {
      const toplevel_detail::FlatPlane& f = flat[slot];
      if (!f.valid()) return false;
      const Record& rec = records[slot];
      const Affine world_from_object = rec.identity ? Affine::identity() : rec.object_from_world.inverse();
      const double w = f.half_width, h = f.half_height;
      const glm::dvec3 local[4] = {{-w, -h, 0.0}, {w, -h, 0.0}, {w, h, 0.0}, {-w, h, 0.0}};
      for (int c = 0; c < 4; ++c) {
        q.corner[c] = world_from_object.point(local[c]);
        if (!(std::isfinite(q.corner[c].x) && std::isfinite(q.corner[c].y) && std::isfinite(q.corner[c].z)))
          return false;
      }
      return true;
    });
    grid_planes.clear();
    if (grid.usable()) {
      grid_planes.resize(grid.slots.size());
      for (std::size_t e = 0; e < grid.slots.size(); ++e) grid_planes[e] = flat[grid.slots[e]];
    }
  }

  std::size_t garbage_nodes = 0;  // nodes no longer reachable (replaced local subtrees)
  std::vector<toplevel_detail::Frontier> frontiers;
  std::vector<std::uint32_t> frontier_of;        // by node index (nodes of the last full build): frontier or kNoJump
  std::vector<std::uint32_t> touched_frontiers;  // frontiers edited in this commit (repeats)
  double frontier_credit = 0.0;                  // references of frontier rebuild work the edits have paid for
  void countEdit(const LeafVisit& v) {
    if (v.frontier == toplevel_detail::kNoJump) return;
    ++frontiers[v.frontier].edits;
    touched_frontiers.push_back(v.frontier);
  }
  // Finds the frontiers of a freshly built tree (InstanceTreeRefine.cpp).
  void markFrontiers(const KdTree& tree);
  // Rebuilds the touched frontiers whose edits exceed a fraction of their references; returns them.
  std::vector<std::uint32_t> rebuildEditedFrontiers(InstanceTree& top);
  // Jump subtrees that lost references in this commit (visits of their leaves), and the references
  // each jump subtree lost since it was built (cleared by full builds and compaction).
  std::vector<LeafVisit> touched_jumps;
  std::unordered_map<std::uint32_t, std::uint32_t> jump_losses;

  // Re-splits grown leaves by local builds, after rebuilding the small jump subtrees in
  // touched_jumps over their current references (InstanceTreeRefine.cpp); returns whether the tree
  // changed.
  bool refineLeaves(InstanceTree& top, std::vector<LeafVisit>& grown_leaves);
  // Rebuilds the jump subtrees of touched_jumps that hold at most kMaxJumpRebuild references;
  // returns the jump nodes whose subtrees are gone (rebuilt, or inside a rebuilt one).
  // Visits of rebuilt frontiers (`rebuilt_frontiers`) are skipped.
  std::vector<std::uint32_t> rebuildTouchedJumps(InstanceTree& top,
                                                 const std::vector<std::uint32_t>& rebuilt_frontiers);
};

}  // namespace duplex
