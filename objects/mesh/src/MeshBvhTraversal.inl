// The mesh BVH traversal, included by MeshBvh.cpp once per instruction set inside a namespace and
// a target region (SimdTarget.h) that define `BoxRay`, `Node::push` (the node's 8 child boxes
// against the ray; the children entered are pushed on the stack) and `Leaf` (the triangles of a
// leaf, with per-ray constants Leaf::RayConstants). No include guard: it is meant to be compiled
// several times.
//
// Every child the ray enters goes on the stack in the node's order for the ray's octant, nearest
// on top (BvhNode8::order): no sort per ray, and one pop gives the next node. Closest hit: a popped
// entry behind the closest hit found by then is dropped. Any hit and all leaves: no culling.

// Node::push writes 8 lanes at the stack top whatever the count: 7 pending children per level
// (WideBvh::kMaxDepth levels) plus one 8-lane write fit.
constexpr int kStackSize = 7 * WideBvh::kMaxDepth + 8;

namespace walk {  // qualified calls: no argument-dependent lookup into another ISA's copy
// The walk from `cur` with the stack holding `sp` entries: the closest hit closer than t_best
// lowers t_best and is recorded in `best`; returns whether one was found.
template <int kOct>
[[gnu::always_inline]] inline bool closestLoop(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray,
                                               const BoxRay& box_ray, std::uint32_t* refs, float* dists, int sp,
                                               float& t_best, ClosestHit& best) {
  const Leaf::RayConstants leaf_ray(ray);
  bool found = false;
  while (true) {
    if (BvhRef::isInner(cur)) {
      sp += Node::template push<kOct>(bvh.nodes[cur], box_ray, t_best, refs + sp, dists + sp);
    } else if (Leaf::closest(ray, leaf_ray, bvh.blocks + BvhRef::leafBlock(cur), BvhRef::leafCount(cur), t_best,
                             best)) {
      found = true;
    }
    // Pop the next child not behind the closest hit.
    do {
      if (sp == 0) return found;
      --sp;
    } while (dists[sp] > t_best);
    cur = refs[sp];
  }
}

}  // namespace walk

// The closest hit below `cur` (a node or leaf of the ray's traversal) closer than t_best: lowers
// t_best and records the hit in `best`, and returns whether it did. The packet traversal runs it
// from the node where a packet's rays have thinned out, with rays prepared in full.
template <int kOct>
inline bool closestSubtree(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray, float& t_best,
                           ClosestHit& best) {
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  return walk::closestLoop<kOct>(bvh, cur, ray, BoxRay(ray.kd), refs, dists, 0, t_best, best);
}

namespace walk {
// The inner nodes of the walk from `cur` up to the first leaf the ray reaches (left in `cur`, the
// stack as the walk leaves it); false when the ray reaches none. kCull: pop as the closest-hit
// walk does (entries behind t_best dropped), else as the any-hit walk (none dropped). The
// single-ray entries walk so before they set up the triangle test (prepareWatertight).
template <int kOct, bool kCull>
[[gnu::always_inline]] inline bool toFirstLeaf(const MeshBvhView& bvh, std::uint32_t& cur, const BoxRay& box_ray,
                                               std::uint32_t* refs, float* dists, int& sp, float t_best) {
  while (BvhRef::isInner(cur)) {
    sp += Node::template push<kOct>(bvh.nodes[cur], box_ray, t_best, refs + sp, dists + sp);
    do {
      if (sp == 0) return false;
      --sp;
    } while (kCull && dists[sp] > t_best);
    cur = refs[sp];
  }
  return true;
}

}  // namespace walk

// The single-ray closest hit: `ray` holds the box part only (prepareBvhRay); its triangle part is
// set up from `ray_os` at the first leaf.
template <int kOct>
inline bool intersectKernel(const MeshBvhView& bvh, const Ray& ray_os, MeshRay& ray, Hit& hit) {
  float t_best = std::min(hit.t, ray_os.tfar);
  const BoxRay box_ray(ray.kd);
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  if (!walk::toFirstLeaf<kOct, true>(bvh, cur, box_ray, refs, dists, sp, t_best)) return false;
  prepareWatertight<Leaf::kUsesRay4>(ray_os, ray);
  ClosestHit best;
  if (!walk::closestLoop<kOct>(bvh, cur, ray, box_ray, refs, dists, sp, t_best, best)) return false;
  fillHit(best, t_best, hit);
  return true;
}

namespace walk {
// The any-hit walk from `cur` with the stack holding `sp` entries: whether anything blocks the
// ray within [tnear, t_far].
template <int kOct>
[[gnu::always_inline]] inline bool occludedLoop(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray,
                                                const BoxRay& box_ray, std::uint32_t* refs, float* dists, int sp,
                                                float t_far) {
  const Leaf::RayConstants leaf_ray(ray);
  while (true) {
    if (BvhRef::isInner(cur)) {
      sp += Node::template push<kOct>(bvh.nodes[cur], box_ray, t_far, refs + sp, dists + sp);
    } else if (Leaf::any(ray, leaf_ray, bvh.blocks + BvhRef::leafBlock(cur), BvhRef::leafCount(cur), t_far)) {
      return true;
    }
    if (sp == 0) return false;
    cur = refs[--sp];
  }
}

}  // namespace walk

// Whether anything below `cur` blocks the ray (prepared in full) within [tnear, t_far].
template <int kOct>
inline bool occludedSubtree(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray, float t_far) {
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  return walk::occludedLoop<kOct>(bvh, cur, ray, BoxRay(ray.kd), refs, dists, 0, t_far);
}

// The single-ray any hit, with the triangle part set up at the first leaf as in intersectKernel.
template <int kOct>
inline bool occludedKernel(const MeshBvhView& bvh, const Ray& ray_os, MeshRay& ray) {
  const BoxRay box_ray(ray.kd);
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  if (!walk::toFirstLeaf<kOct, false>(bvh, cur, box_ray, refs, dists, sp, ray_os.tfar)) return false;
  prepareWatertight<Leaf::kUsesRay4>(ray_os, ray);
  return walk::occludedLoop<kOct>(bvh, cur, ray, box_ray, refs, dists, sp, ray_os.tfar);
}

template <int kOct>
inline void forEachLeafKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray, MeshBvhLeafVisitor visit,
                              void* context) {
  const BoxRay box_ray(ray.kd);
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  while (true) {
    if (BvhRef::isInner(cur)) {
      sp += Node::template push<kOct>(bvh.nodes[cur], box_ray, ray_os.tfar, refs + sp, dists + sp);
    } else {
      visit(context, BvhRef::leafBlock(cur), BvhRef::leafCount(cur));
    }
    if (sp == 0) return;
    cur = refs[--sp];
  }
}

// The ray's octant: bit a set when its direction is negative on axis a.
inline int octantOf(const MeshRay& ray) {
  return static_cast<int>((ray.kd.neg_mask[0] & 1u) | (ray.kd.neg_mask[1] & 2u) | (ray.kd.neg_mask[2] & 4u));
}

template <class F>
inline auto byOctant(int octant, F&& f) {
  switch (octant) {
    case 0: return f(std::integral_constant<int, 0>());
    case 1: return f(std::integral_constant<int, 1>());
    case 2: return f(std::integral_constant<int, 2>());
    case 3: return f(std::integral_constant<int, 3>());
    case 4: return f(std::integral_constant<int, 4>());
    case 5: return f(std::integral_constant<int, 5>());
    case 6: return f(std::integral_constant<int, 6>());
    default: return f(std::integral_constant<int, 7>());
  }
}

inline bool intersectEntry(const MeshBvhView& bvh, const Ray& ray_os, Hit& hit) {
  if (bvh.root == BvhRef::kEmpty) return false;
  MeshRay ray;
  int octant;
  if (!prepareBvhRay(ray_os, ray, octant)) return false;
  return byOctant(octant, [&](auto oct) { return intersectKernel<oct.value>(bvh, ray_os, ray, hit); });
}

inline bool occludedEntry(const MeshBvhView& bvh, const Ray& ray_os) {
  if (bvh.root == BvhRef::kEmpty) return false;
  MeshRay ray;
  int octant;
  if (!prepareBvhRay(ray_os, ray, octant)) return false;
  return byOctant(octant, [&](auto oct) { return occludedKernel<oct.value>(bvh, ray_os, ray); });
}

// The direct entries (ObjectRayEntry): `bvh` is the object's MeshBvhView.
inline bool intersectViewEntry(const void* bvh, const Ray& ray_os, Hit& hit) {
  return intersectEntry(*static_cast<const MeshBvhView*>(bvh), ray_os, hit);
}

inline bool occludedViewEntry(const void* bvh, const Ray& ray_os) {
  return occludedEntry(*static_cast<const MeshBvhView*>(bvh), ray_os);
}

inline void forEachLeafEntry(const MeshBvhView& bvh, const Ray& ray_os, MeshBvhLeafVisitor visit, void* context) {
  if (bvh.root == BvhRef::kEmpty) return;
  MeshRay ray;
  int octant;
  if (!prepareBvhRay(ray_os, ray, octant)) return;  // the leaves are the visitor's: no triangle set-up
  byOctant(octant, [&](auto oct) { forEachLeafKernel<oct.value>(bvh, ray_os, ray, visit, context); });
}

// ---- Packets: PV::kWidth rays of one octant through the tree together ----
//
// Per node, each child's box is tested against every active ray of the packet (SIMD over the rays,
// PV), with each lane's operations exactly those of Node::push for that ray alone; children that
// some ray enters are pushed in the node's order for the octant with the lanes that enter them and
// their entry distances. So every ray meets the nodes and leaves it would meet alone, in the same
// order, with the same best distance at each: the results are the single-ray path's bit for bit,
// ties included. Before the per-ray tests, one test of all 8 children against the bounds of the
// packet's rays (PacketBounds) drops the children no ray can enter, so that a coherent packet pays
// the per-ray tests only for the one to three children it meets. Leaves run the single-ray leaf
// test per active lane, and a subtree reached by at most PV::kFallback rays is finished ray by ray
// by the single-ray walk (a diverged packet costs the single path's price, not more).

struct PacketRays {
  alignas(64) float o[3][PV::kWidth];
  alignas(64) float inv[3][PV::kWidth];
  alignas(64) float tnear[PV::kWidth];
  alignas(64) float t_best[PV::kWidth];  // closest hit so far (any hit: tfar)
  PacketBounds bounds;                   // of the lanes in use
};

// The largest t_best of the lanes `active`: no ray of them looks further.
inline float packetReach(const PacketRays& p, unsigned active) {
  float t = -std::numeric_limits<float>::infinity();
  for (; active != 0; active &= active - 1) t = std::max(t, p.t_best[std::countr_zero(active)]);
  return t;
}

// The lanes of `active` that enter child slot k of `node` (as Node::push's box test), and their
// widened entry distances in `tn_out`.
template <int kOct>
inline unsigned packetEnters(const BvhNode8& node, int k, const PacketRays& p, unsigned active,
                             typename PV::V& tn_out) {
  using V = typename PV::V;
  const float* base = &node.lo[0][0] + k;
  V tn = PV::load(p.tnear), tf = PV::load(p.t_best);
  auto slab = [&](auto axis) {
    constexpr int a = decltype(axis)::value;
    const V o = PV::load(p.o[a]), inv = PV::load(p.inv[a]);
    const V n = PV::mul(PV::sub(PV::set1(base[nearRow<kOct, a>()]), o), inv);
    const V f = PV::mul(PV::sub(PV::set1(base[farRow<kOct, a>()]), o), inv);
    tn = PV::max(n, tn);
    tf = PV::min(f, tf);
  };
  slab(std::integral_constant<int, 2>());
  slab(std::integral_constant<int, 1>());
  slab(std::integral_constant<int, 0>());
  const V widen = PV::set1(kBoxWiden);
  tf = PV::add(tf, PV::mul(PV::abs(tf), widen));
  tn_out = PV::sub(tn, PV::mul(PV::abs(tn), widen));
  return PV::le(tn_out, tf) & active;
}

// Packet stack: 7 pending children per level at most, as the single-ray stack.
constexpr int kPacketStackSize = 7 * WideBvh::kMaxDepth + 1;

// Closest hits of the lanes `active` of `p` (rays[j]: lane j's prepared ray); lowers p.t_best and
// records in best[j]; returns the lanes that found a hit.
template <int kOct>
inline unsigned intersectPacketKernel(const MeshBvhView& bvh, const MeshRay* const* rays, unsigned active,
                                      PacketRays& p, ClosestHit* best) {
  std::uint32_t refs[kPacketStackSize];
  unsigned masks[kPacketStackSize];
  alignas(64) float dists[kPacketStackSize][PV::kWidth];
  unsigned found = 0;
  int sp = 0;
  std::uint32_t cur = bvh.root;
  unsigned m = active;
  float reach = packetReach(p, active);
  while (true) {
    if (std::popcount(m) <= PV::kFallback) {
      for (unsigned lanes = m; lanes != 0; lanes &= lanes - 1) {
        const int j = std::countr_zero(lanes);
        if (closestSubtree<kOct>(bvh, cur, *rays[j], p.t_best[j], best[j])) {
          found |= 1u << j;
          reach = packetReach(p, active);
        }
      }
    } else if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      for (unsigned ranks = Node::template frustum<kOct>(node, p.bounds, reach); ranks != 0; ranks &= ranks - 1) {
        const int k = node.orderedSlot(kOct, std::countr_zero(ranks));
        typename PV::V tn;
        const unsigned enter = packetEnters<kOct>(node, k, p, m, tn);
        if (enter == 0) continue;
        refs[sp] = node.child[k];
        masks[sp] = enter;
        PV::store(dists[sp], tn);
        ++sp;
      }
    } else {
      const TriangleBlock4* blocks = bvh.blocks + BvhRef::leafBlock(cur);
      const std::uint32_t count = BvhRef::leafCount(cur);
      const unsigned lowered = Leaf::closestLanes(rays, m, blocks, count, p.t_best, best);
      found |= lowered;
      if (lowered != 0) reach = packetReach(p, active);
    }
    // Pop the next child with a lane not behind its closest hit.
    do {
      if (sp == 0) return found;
      --sp;
      m = masks[sp] & ~PV::gt(PV::load(dists[sp]), PV::load(p.t_best));
    } while (m == 0);
    cur = refs[sp];
  }
}

// The lanes of `active` that something blocks within [tnear, p.t_best] (tfar).
template <int kOct>
inline unsigned occludedPacketKernel(const MeshBvhView& bvh, const MeshRay* const* rays, unsigned active,
                                     const PacketRays& p) {
  std::uint32_t refs[kPacketStackSize];
  unsigned masks[kPacketStackSize];
  unsigned blocked = 0;
  int sp = 0;
  std::uint32_t cur = bvh.root;
  unsigned m = active;
  const float reach = packetReach(p, active);
  while (true) {
    if (std::popcount(m) <= PV::kFallback) {
      for (unsigned lanes = m; lanes != 0; lanes &= lanes - 1) {
        const int j = std::countr_zero(lanes);
        if (occludedSubtree<kOct>(bvh, cur, *rays[j], p.t_best[j])) blocked |= 1u << j;
      }
    } else if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      for (unsigned ranks = Node::template frustum<kOct>(node, p.bounds, reach); ranks != 0; ranks &= ranks - 1) {
        const int k = node.orderedSlot(kOct, std::countr_zero(ranks));
        typename PV::V tn;
        const unsigned enter = packetEnters<kOct>(node, k, p, m, tn);
        if (enter == 0) continue;
        refs[sp] = node.child[k];
        masks[sp] = enter;
        ++sp;
      }
    } else {
      const TriangleBlock4* blocks = bvh.blocks + BvhRef::leafBlock(cur);
      const std::uint32_t count = BvhRef::leafCount(cur);
      for (unsigned lanes = m; lanes != 0; lanes &= lanes - 1) {
        const int j = std::countr_zero(lanes);
        if (Leaf::any(*rays[j], Leaf::RayConstants(*rays[j]), blocks, count, p.t_best[j])) blocked |= 1u << j;
      }
      if (blocked == active) return blocked;
    }
    do {
      if (sp == 0) return blocked;
      m = masks[--sp] & ~blocked;
    } while (m == 0);
    cur = refs[sp];
  }
}

// Splits the queryable lanes of a packet (at most kMaxPacketRays rays) by octant and into groups of
// PV::kWidth lanes. A group of at most PV::kMinPacket rays (random rays: one or two per octant),
// and every group of a packet spread over more than kMaxPacketOctants octants, goes ray by ray through
// `single(oct, i)` (i: the packet index), since packet setup would cost more than it saves; larger groups go through
// `packet(oct, lanes, p, group)`, where group[j] is the packet index of lane j of `p` and `lanes` the group's lane
// mask. Rays that are not queryable are left out.
template <class Single, class Packet>
inline void forEachPacketGroup(const Ray* rays, unsigned active, MeshRay* prepared, Single&& single, Packet&& packet) {
  unsigned by_octant[8] = {};
  for (unsigned lanes = active; lanes != 0; lanes &= lanes - 1) {
    const int i = std::countr_zero(lanes);
    if (prepareMeshRay<Leaf::kUsesRay4>(rays[i], prepared[i])) by_octant[octantOf(prepared[i])] |= 1u << i;
  }
  // Incoherent rays (spread over more than kMaxPacketOctants octants): ray by ray, at the single
  // path's cost.
  int octants = 0;
  for (const unsigned lanes : by_octant) octants += lanes != 0 ? 1 : 0;
  const int min_packet = octants > kMaxPacketOctants ? kMaxPacketRays : PV::kMinPacket;
  for (int oct = 0; oct < 8; ++oct) {
    unsigned left = by_octant[oct];
    if (std::popcount(left) <= min_packet) {
      for (; left != 0; left &= left - 1) single(oct, std::countr_zero(left));
      continue;
    }
    while (left != 0) {
      PacketRays p;
      int group[PV::kWidth];
      unsigned lanes = 0;
      for (int j = 0; j < PV::kWidth && left != 0; ++j, left &= left - 1) {
        const int i = std::countr_zero(left);
        group[j] = i;
        lanes |= 1u << j;
        const KdRay& kd = prepared[i].kd;
        for (int a = 0; a < 3; ++a) {
          p.o[a][j] = kd.origin[a];
          p.inv[a][j] = kd.inv_dir[a];
        }
        p.tnear[j] = kd.tnear;
        p.t_best[j] = kd.tfar;
      }
      // Unused lanes repeat lane 0 (lane masks keep them out of every result), so that the
      // bounds below are reductions over whole vectors.
      for (int j = std::popcount(lanes); j < PV::kWidth; ++j) {
        group[j] = group[0];
        for (int a = 0; a < 3; ++a) {
          p.o[a][j] = p.o[a][0];
          p.inv[a][j] = p.inv[a][0];
        }
        p.tnear[j] = p.tnear[0];
        p.t_best[j] = 0.0f;
      }
      PacketBounds& b = p.bounds;
      for (int a = 0; a < 3; ++a) {
        const typename PV::V o = PV::load(p.o[a]), inv = PV::load(p.inv[a]);
        const bool neg = (oct >> a & 1) != 0;
        b.near_o[a] = neg ? PV::hmin(o) : PV::hmax(o);
        b.far_o[a] = neg ? PV::hmax(o) : PV::hmin(o);
        b.inv_lo[a] = PV::hmin(inv);
        b.inv_hi[a] = PV::hmax(inv);
      }
      b.t_lo = PV::hmin(PV::load(p.tnear));
      packet(oct, lanes, p, group);
    }
  }
}

inline unsigned intersectPacketEntry(const MeshBvhView& bvh, const Ray* rays, Hit* hits, unsigned active) {
  if (bvh.root == BvhRef::kEmpty) return 0;
  MeshRay prepared[kMaxPacketRays];
  unsigned found = 0;
  auto single = [&](int oct, int i) {
    if (byOctant(oct, [&](auto o) { return intersectKernel<o.value>(bvh, rays[i], prepared[i], hits[i]); }))
      found |= 1u << i;
  };
  auto packet = [&](int oct, unsigned lanes, PacketRays& p, const int* group) {
    const MeshRay* rs[PV::kWidth];
    ClosestHit best[PV::kWidth];
    for (int j = 0; j < PV::kWidth; ++j) {
      rs[j] = &prepared[group[j]];
      p.t_best[j] = std::min(hits[group[j]].t, rays[group[j]].tfar);
    }
    const unsigned hit_lanes =
        byOctant(oct, [&](auto o) { return intersectPacketKernel<o.value>(bvh, rs, lanes, p, best); });
    for (unsigned l = hit_lanes; l != 0; l &= l - 1) {
      const int j = std::countr_zero(l);
      fillHit(best[j], p.t_best[j], hits[group[j]]);
      found |= 1u << group[j];
    }
  };
  forEachPacketGroup(rays, active, prepared, single, packet);
  return found;
}

inline unsigned occludedPacketEntry(const MeshBvhView& bvh, const Ray* rays, unsigned active) {
  if (bvh.root == BvhRef::kEmpty) return 0;
  MeshRay prepared[kMaxPacketRays];
  unsigned blocked = 0;
  auto single = [&](int oct, int i) {
    if (byOctant(oct, [&](auto o) { return occludedKernel<o.value>(bvh, rays[i], prepared[i]); })) blocked |= 1u << i;
  };
  auto packet = [&](int oct, unsigned lanes, PacketRays& p, const int* group) {
    const MeshRay* rs[PV::kWidth];
    for (int j = 0; j < PV::kWidth; ++j) rs[j] = &prepared[group[j]];
    const unsigned hit_lanes = byOctant(oct, [&](auto o) { return occludedPacketKernel<o.value>(bvh, rs, lanes, p); });
    for (unsigned l = hit_lanes; l != 0; l &= l - 1) blocked |= 1u << group[std::countr_zero(l)];
  };
  forEachPacketGroup(rays, active, prepared, single, packet);
  return blocked;
}
