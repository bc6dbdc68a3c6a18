// InstanceTree::intersectPacket / occludedPacket (TopLevel's packet queries): up to kMaxPacketRays
// world rays through the tree together, each instance reached asked once for the sub-packet of
// rays that reach it (Object::intersectPacket, rays in object space). With the wide form (the
// default), its packet walk (InstanceTreeWide.inl); otherwise the kd-tree's, below.
//
// The classic packet kd-tree walk (one split plane against every ray of the packet), kept equal to
// traverseKdTreeClipped ray for ray: the rays of a packet share their direction signs (they are
// grouped by octant), so near and far child are the same for all of them; each ray keeps its own
// interval [lo, hi] and best distance, and goes to the near child, the far child or both by
// exactly the comparisons of the single-ray walk. The packet descends near first, and a far child
// waits on the stack with the rays that go there and their intervals, so every ray visits the
// leaves it would visit alone, in the same order, with the same best distance (the single walk's
// shortcuts past empty leaves skip only visits that do nothing). A leaf asks each instance for the
// rays that pass the same filter, box test and mailbox (one per ray) as intersectImpl's leaf step.
// So the hits are those of intersect() bit for bit, ties between instances included.

#include "duplex/accel/InstanceTree.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/Object.h"
#include "duplex/accel/TopLevel.h"

#include "InstanceTreeState.h"
#include "InstanceTreeWide.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

namespace duplex {

using namespace toplevel_detail;

namespace {
constexpr int kLanes = kMaxPacketRays;
// Octant groups of at most this many rays go the single-ray way: the packet walk's bookkeeping
// per node costs more than two or three rays save (random rays: one or two per octant).
constexpr int kMinPacket = 3;
}  // namespace

// A packet's rays by their index in the caller's packet.
struct InstanceTree::PacketState {
  KdRay kray[kLanes];
  BoxTestRay box_ray[kLanes];  // each ray's instance box test (points into kray)
  WorldRay w[kLanes];
  float t[kLanes];                        // best distance so far (closest hit), tfar (any hit)
  float t_enter[kLanes], t_exit[kLanes];  // the ray's segment in the tree's bounds
  Hit best[kLanes];
  std::uint32_t best_id[kLanes];  // the instance of best (kInvalidId: none yet), for the tie rule
  const Record* winner[kLanes];
  Mailbox mailbox[kLanes];
};

namespace {
struct Interval {
  float lo[kLanes], hi[kLanes];
};
}  // namespace

template <bool AnyHit>
std::uint32_t InstanceTree::packetWalk(PacketState& p, std::uint32_t lanes, std::uint32_t octant, QueryContext& ctx,
                                       std::uint32_t mask) const {
  const auto widen_up = [](float t) { return t + std::abs(t) * kKdPlaneSlack; };
  const auto widen_down = [](float t) { return t - std::abs(t) * kKdPlaneSlack; };
  const Record* records = state_->records.data();
  const SlotFilter* filters = state_->filters.data();
  const Box* boxes = state_->boxes.data();
  const KdNode* nodes = tree_.nodes.data();
  struct Entry {
    std::uint32_t node;
    std::uint32_t lanes;
    Interval iv;
  };
  std::array<Entry, kKdStackSize> stack;
  int top = 0;
  Interval iv;
  for (std::uint32_t l = lanes; l != 0; l &= l - 1) {
    const int j = std::countr_zero(l);
    iv.lo[j] = widen_down(p.t_enter[j]);
    iv.hi[j] = widen_up(p.t_exit[j]);
  }
  std::uint32_t done = 0;  // any hit: blocked lanes; closest hit: lanes that found something
  std::uint32_t index = 0;
  std::uint32_t m = lanes;
  Ray rays_os[kLanes];
  Hit hits_os[kLanes];
  while (true) {
    const KdNode node = nodes[index];
    if (!node.isLeaf()) {
      const int axis = node.axis();
      const std::uint32_t lower = index + 1, upper = node.upperChild();
      const std::uint32_t swap = (octant >> axis & 1u) != 0 ? lower ^ upper : 0u;
      const std::uint32_t near_child = lower ^ swap, far_child = upper ^ swap;
      std::uint32_t near_m = 0, far_m = 0;
      Entry far;  // lanes and intervals are written for the rays that go far, and only those are read
      far.node = far_child;
      for (std::uint32_t l = m; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        const float t_plane = (node.split() - p.kray[j].origin[axis]) * p.kray[j].inv_dir[axis];
        if (t_plane > iv.hi[j]) {
          near_m |= 1u << j;
        } else if (t_plane < iv.lo[j]) {
          far_m |= 1u << j;
          far.iv.lo[j] = iv.lo[j];
          far.iv.hi[j] = iv.hi[j];
        } else {
          near_m |= 1u << j;
          far_m |= 1u << j;
          far.iv.lo[j] = std::max(iv.lo[j], widen_down(t_plane));
          far.iv.hi[j] = iv.hi[j];
          iv.hi[j] = std::min(iv.hi[j], widen_up(t_plane));
        }
      }
      if (near_m == 0) {
        index = far_child;
        m = far_m;
        iv = far.iv;
        continue;
      }
      if (far_m != 0) {
        far.lanes = far_m;
        stack[static_cast<std::size_t>(top++)] = far;
      }
      index = near_child;
      m = near_m;
      continue;
    }
    if (node.isJump()) {
      index = node.jumpTarget();
      continue;
    }
    for (std::uint32_t i = node.primOffset(); i < node.primOffset() + node.primCount(); ++i) {
      const std::uint32_t slot = tree_.prim_indices[i];
      const SlotFilter f = filters[slot];
      if ((f.mask & mask) == 0 || f.role != ObjectRole::Surface) continue;
      std::uint32_t sub = 0;
      for (std::uint32_t l = m & ~(AnyHit ? done : 0u); l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        float t_enter;
        if (meetsBoxAt(p.box_ray[j], boxes[slot], p.t[j], t_enter) && !p.mailbox[j].seen(slot)) sub |= 1u << j;
      }
      if (sub == 0) continue;
      const Record& rec = records[slot];
      ctx.stats.instance_visits += static_cast<std::uint64_t>(std::popcount(sub));
      for (std::uint32_t l = sub; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        rays_os[j] = toObject(rec, p.w[j]);
        if constexpr (!AnyHit) {
          // As closerHit (InstanceTreeState.h): asked a few ulps beyond the best hit, decided by replacesBest.
          rays_os[j].tfar = askBound(p.t[j]);
          hits_os[j] = Hit{};
          hits_os[j].t = rays_os[j].tfar;
        }
      }
      if constexpr (AnyHit) {
        done |= rec.object->occludedPacket(rays_os, sub, ctx);
        if ((done & lanes) == lanes) return done;
      } else {
        const std::uint32_t found = rec.object->intersectPacket(rays_os, hits_os, sub, ctx);
        for (std::uint32_t l = found; l != 0; l &= l - 1) {
          const int j = std::countr_zero(l);
          if (!replacesBest(hits_os[j].t, rec.id, p.t[j], p.best_id[j])) continue;
          p.best[j] = hits_os[j];
          p.t[j] = hits_os[j].t;
          p.best_id[j] = rec.id;
          p.winner[j] = &rec;
          done |= 1u << j;
        }
      }
    }
    // The next entry with a ray that can still find a closer hit (any hit: is not blocked yet).
    do {
      if (top == 0) return done;
      const Entry& e = stack[static_cast<std::size_t>(--top)];
      index = e.node;
      m = e.lanes & ~(AnyHit ? done : 0u);
      for (std::uint32_t l = m; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        if (e.iv.lo[j] > p.t[j]) m &= ~(1u << j);
      }
      if (m != 0) iv = e.iv;
    } while (m == 0);
  }
}

template <bool AnyHit>
std::uint32_t InstanceTree::packetQuery(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                        std::uint32_t mask) const {
  const int n = static_cast<int>(rays_ws.size());
  std::uint32_t result = 0;
  ctx.stats.rays += static_cast<std::uint64_t>(n);
  if (tree_.empty()) return 0;
  // A ray alone (or one of at most kMinPacket) in its octant, or every ray of a packet spread over
  // more than kMaxPacketOctants octants (incoherent: random directions), goes the single path (identical
  // results, no packet set-up). The octant is the sign bits of the direction, as KdRay's.
  auto single = [&](int i) {
    const Ray& r = rays_ws[static_cast<std::size_t>(i)];
    --ctx.stats.rays;  // counted above
    if constexpr (AnyHit) {
      if (occluded(r, ctx, mask)) result |= 1u << i;
    } else {
      hits[static_cast<std::size_t>(i)] = intersect(r, ctx, mask);
      if (hits[static_cast<std::size_t>(i)].valid()) result |= 1u << i;
    }
  };
  std::uint32_t by_octant[8] = {};
  for (int i = 0; i < n; ++i) {
    const Ray& r = rays_ws[static_cast<std::size_t>(i)];
    if (!isQueryable(r)) continue;
    by_octant[static_cast<int>(std::signbit(r.dir.x)) | static_cast<int>(std::signbit(r.dir.y)) << 1 |
              static_cast<int>(std::signbit(r.dir.z)) << 2] |= 1u << i;
  }
  int octants = 0;
  for (const std::uint32_t lanes : by_octant) octants += lanes != 0 ? 1 : 0;
  if (octants > kMaxPacketOctants) {
    for (const std::uint32_t lanes : by_octant)
      for (std::uint32_t l = lanes; l != 0; l &= l - 1) single(std::countr_zero(l));
    return result;
  }
  if (state_->wide.usable) {
    // The wide form's packet walk (InstanceTreeWide.inl), one octant at a time.
    const State& s = *state_;
    const WideQuery q{&s.wide, s.records.data(), s.filters.data(), mask};
    const WideKernels& kernels = wideKernels();
    const Ray* rays = rays_ws.data();  // lanes index the span: only its first n rays are read
    for (const std::uint32_t lanes : by_octant) {
      if (lanes == 0) continue;
      if (std::popcount(lanes) <= kMinPacket) {
        for (std::uint32_t l = lanes; l != 0; l &= l - 1) single(std::countr_zero(l));
        continue;
      }
      if constexpr (AnyHit) {
        result |= kernels.occludedPacket(q, rays, lanes, ctx);
      } else {
        Hit best[kMaxPacketRays];
        const Record* winner[kMaxPacketRays];
        for (std::uint32_t l = kernels.closestPacket(q, rays, lanes, best, winner, ctx); l != 0; l &= l - 1) {
          const int i = std::countr_zero(l);
          Hit h = best[i];
          h.instance_id = winner[i]->id;
          h.ng = normalToWorld(*winner[i], h.ng);
          hits[static_cast<std::size_t>(i)] = h;
          result |= 1u << i;
        }
      }
    }
    return result;
  }
  // The rays that miss the root box have their (miss) result already.
  PacketState p;
  for (std::uint32_t& lanes : by_octant) {
    for (std::uint32_t l = lanes; l != 0; l &= l - 1) {
      const int i = std::countr_zero(l);
      if (!setupWorldRay(rays_ws[static_cast<std::size_t>(i)], tree_.bounds, p.kray[i], p.box_ray[i], p.t_enter[i],
                         p.t_exit[i]))
        lanes &= ~(1u << i);
    }
  }
  for (std::uint32_t octant = 0; octant < 8; ++octant) {
    const std::uint32_t lanes = by_octant[octant];
    if (lanes == 0) continue;
    if (std::popcount(lanes) <= kMinPacket) {
      for (std::uint32_t l = lanes; l != 0; l &= l - 1) single(std::countr_zero(l));
      continue;
    }
    for (std::uint32_t l = lanes; l != 0; l &= l - 1) {
      const int i = std::countr_zero(l);
      const Ray& r = rays_ws[static_cast<std::size_t>(i)];
      p.w[i] = fromFloat(r);
      p.t[i] = r.tfar;
      p.best[i] = Hit{};
      p.best[i].t = r.tfar;
      p.winner[i] = nullptr;
      p.best_id[i] = kInvalidId;
      p.mailbox[i] = Mailbox{};
    }
    const std::uint32_t done = packetWalk<AnyHit>(p, lanes, octant, ctx, mask);
    if constexpr (AnyHit) {
      result |= done & lanes;
    } else {
      for (std::uint32_t l = lanes; l != 0; l &= l - 1) {
        const int i = std::countr_zero(l);
        if (p.winner[i] == nullptr) continue;
        Hit h = p.best[i];
        h.instance_id = p.winner[i]->id;
        h.ng = normalToWorld(*p.winner[i], h.ng);
        hits[static_cast<std::size_t>(i)] = h;
        result |= 1u << i;
      }
    }
  }
  return result;
}

std::uint32_t InstanceTree::intersectPacket(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                            std::uint32_t mask) const {
  if (!packetSizeOk(rays_ws.size(), hits.size()))
    throwPacketSizeError("InstanceTree::intersectPacket", rays_ws.size(), hits.size());
  for (std::size_t i = 0; i < rays_ws.size(); ++i) hits[i] = Hit{};
  return packetQuery<false>(rays_ws, hits, ctx, mask);
}

std::uint32_t InstanceTree::occludedPacket(std::span<const Ray> rays_ws, QueryContext& ctx, std::uint32_t mask) const {
  if (!packetSizeOk(rays_ws.size(), rays_ws.size()))
    throwPacketSizeError("InstanceTree::occludedPacket", rays_ws.size(), rays_ws.size());
  return packetQuery<true>(rays_ws, {}, ctx, mask);
}

std::uint32_t TopLevel::intersectPacket(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                        std::uint32_t mask) const {
  return blocking_.intersectPacket(rays_ws, hits, ctx, mask);
}

std::uint32_t TopLevel::occludedPacket(std::span<const Ray> rays_ws, QueryContext& ctx, std::uint32_t mask) const {
  return blocking_.occludedPacket(rays_ws, ctx, mask);
}

}  // namespace duplex
