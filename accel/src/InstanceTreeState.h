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

#include <glm/matrix.hpp>

#include <algorithm>
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

// The world ray in both precisions: float for the top-level traversal, double for the transform
// into object space.
struct WorldRay {
  Ray f;
  RayD d;
};

inline WorldRay fromFloat(const Ray& r) {
  return {r, RayD{glm::dvec3(r.origin), glm::dvec3(r.dir), static_cast<double>(r.tnear), static_cast<double>(r.tfar)}};
}

inline WorldRay fromDouble(const RayD& r) {
  Ray f;
  f.origin = glm::vec3(r.origin);
  f.dir = glm::vec3(r.dir);
  f.tnear = static_cast<float>(r.tnear);
  f.tfar = static_cast<float>(r.tfar);
  return {f, r};
}

inline Ray toObject(const Record& rec, const WorldRay& w) {
  if (rec.identity) return w.f;
  Ray r;
  r.origin = glm::vec3(rec.object_from_world.point(w.d.origin));
  r.dir = glm::vec3(rec.object_from_world.vector(w.d.dir));
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

// Asks blocking instance `rec` for a hit closer than t (world units of w's direction); on one,
// overwrites `best` (object-space normal, instance id not set) and t and returns true. The leaf step
// of every closest-hit traversal (intersect and the crossing query).
inline bool closerHit(const Record& rec, const WorldRay& w, Hit& best, float& t, QueryContext& ctx) {
  Ray ray_os = toObject(rec, w);
  ray_os.tfar = t;
  Hit h = best;
  h.t = t;
  if (!rec.object->intersect(ray_os, h, ctx)) return false;
  best = h;
  t = h.t;
  return true;
}

// A small mailbox: an instance box usually spans several leaves, and a repeated bottom-level
// traversal of the same instance for the same ray is wasted work.
struct Mailbox {
  std::uint32_t slots[8];
  int count = 0, next = 0;
  bool seen(std::uint32_t slot) {
    for (int m = 0; m < count; ++m)
      if (slots[m] == slot) return true;
    slots[next] = slot;
    next = (next + 1) & 7;
    if (count < 8) ++count;
    return false;
  }
};

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
