#pragma once
// Private to accel/src: the walks of a blocking instance tree's wide form (WideTop.h), one set per
// instruction set (InstanceTreeWide.cpp), chosen once per process by widestSimdIsa().

#include "duplex/accel/SimdIsa.h"

#include "InstanceTreeState.h"
#include "WideTop.h"

#include <cstddef>
#include <cstdint>
#include <functional>

namespace duplex::toplevel_detail {

// What the walks read of an instance tree, and the instance mask of the query.
struct WideQuery {
  const WideTop* top;
  const Record* records;      // by slot
  const SlotFilter* filters;  // by slot
  std::uint32_t mask;
};

struct WideKernels {
  SimdIsa isa;
  // The closest hit of world ray `ray_f` (`ray_d`: the same ray in double when the caller gave one,
  // else null) among the blocking instances passing the mask, as InstanceTree::intersect: returns
  // false for none (or a ray that is not queryable), else the hit in `out` (world normal, instance id).
  bool (*closest)(const WideQuery& q, const Ray& ray_f, const RayD* ray_d, Hit& out, QueryContext& ctx);
  // Whether any blocking instance passing the mask blocks `ray` within [tnear, tfar].
  bool (*occluded)(const WideQuery& q, const Ray& ray, QueryContext& ctx);
  // closest() / occluded() of rays[0, n) one by one into out[0, n) (a miss: Hit{}; occluded: 1 or
  // 0), with the rays' count not added to ctx.stats.
  void (*closestBatch)(const WideQuery& q, const Ray* rays, std::size_t n, Hit* out, QueryContext& ctx);
  void (*occludedBatch)(const WideQuery& q, const Ray* rays, std::size_t n, std::uint8_t* out, QueryContext& ctx);
  // Packets: the rays `rays[j]` of the lanes `lanes` (all of one octant: the same direction signs,
  // each queryable) walk the form together: each child box is tested against all of them at once,
  // and each instance is asked once with the lanes that reach it (Object::intersectPacket). Closest:
  // returns the lanes with a hit, their winners' records in `winner` and hits in `best` (object-space
  // normal, instance id not set), the same as closest() ray by ray. Any hit: returns the blocked lanes.
  std::uint32_t (*closestPacket)(const WideQuery& q, const Ray* rays, std::uint32_t lanes, Hit* best,
                                 const Record** winner, QueryContext& ctx);
  std::uint32_t (*occludedPacket)(const WideQuery& q, const Ray* rays, std::uint32_t lanes, QueryContext& ctx);
  // The bare walk, for tests: visit(slot, t_best) for each reference met no later than t_best, as
  // the two queries walk (closest: nearest first, stopping behind t_best; any hit: at the first
  // visit returning true).
  bool (*walk)(const WideTop& top, const Ray& ray, bool any_hit, float& t_best,
               const std::function<bool(std::uint32_t, float&)>& visit);
};

// The kernels of the widest instruction set the CPU runs (capped by DUPLEX_ISA).
const WideKernels& wideKernels();

}  // namespace duplex::toplevel_detail
