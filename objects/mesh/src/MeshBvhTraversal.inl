// The mesh BVH traversal, included by MeshBvh.cpp once per instruction set inside a namespace and
// a `#pragma GCC target` region that define `BoxRay`, `Node::push` (the node's 8 child boxes
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

// The closest hit below `cur` (a node or leaf of the ray's traversal) closer than t_best: lowers
// t_best and records the hit in `best`, and returns whether it did. The single-ray traversal runs
// it from the root; the packet traversal from the node where a packet's rays have thinned out.
template <int kOct>
inline bool closestSubtree(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray, float& t_best,
                           ClosestHit& best) {
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  bool found = false;
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
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

template <int kOct>
inline bool intersectKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray, Hit& hit) {
  float t_best = std::min(hit.t, ray_os.tfar);
  ClosestHit best;
  if (!closestSubtree<kOct>(bvh, bvh.root, ray, t_best, best)) return false;
  fillHit(best, t_best, hit);
  return true;
}

// Whether anything below `cur` blocks the ray within [tnear, t_far].
template <int kOct>
inline bool occludedSubtree(const MeshBvhView& bvh, std::uint32_t cur, const MeshRay& ray, float t_far) {
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
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

template <int kOct>
inline bool occludedKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray) {
  return occludedSubtree<kOct>(bvh, bvh.root, ray, ray_os.tfar);
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
  if (!prepareMeshRay(ray_os, ray)) return false;
  return byOctant(octantOf(ray), [&](auto oct) { return intersectKernel<oct.value>(bvh, ray_os, ray, hit); });
}

inline bool occludedEntry(const MeshBvhView& bvh, const Ray& ray_os) {
  if (bvh.root == BvhRef::kEmpty) return false;
  MeshRay ray;
  if (!prepareMeshRay(ray_os, ray)) return false;
  return byOctant(octantOf(ray), [&](auto oct) { return occludedKernel<oct.value>(bvh, ray_os, ray); });
}

inline void forEachLeafEntry(const MeshBvhView& bvh, const Ray& ray_os, MeshBvhLeafVisitor visit, void* context) {
  if (bvh.root == BvhRef::kEmpty) return;
  MeshRay ray;
  if (!prepareMeshRay(ray_os, ray)) return;
  byOctant(octantOf(ray), [&](auto oct) { forEachLeafKernel<oct.value>(bvh, ray_os, ray, visit, context); });
}

// ---- Packets: PV::kWidth rays of one octant through the tree together ----
//
// Per node, each child's box is tested against every active ray of the packet (SIMD over the rays,
// PV), with each lane's operations exactly those of Node::push for that ray alone; children that
// some ray enters are pushed in the node's order for the octant with the lanes that enter them and
// their entry distances. So every ray meets the nodes and leaves it would meet alone, in the same
// order, with the same best distance at each: the results are the single-ray path's bit for bit,
// ties included. Leaves run the single-ray leaf test per active lane, and a subtree reached by at
// most PV::kFallback rays is finished ray by ray by the single-ray walk (a diverged packet costs
// the single path's price, not more).

struct PacketRays {
  alignas(64) float o[3][PV::kWidth];
  alignas(64) float inv[3][PV::kWidth];
  alignas(64) float tnear[PV::kWidth];
  alignas(64) float t_best[PV::kWidth];  // closest hit so far (any hit: tfar)
  // The watertight test's constants (WatertightRay4): origin in the ray's permuted order, shear.
  alignas(64) float wo[3][PV::kWidth];
  alignas(64) float ws[3][PV::kWidth];  // sx, sy, sz
  alignas(64) float wtnear[PV::kWidth];
};

// ---- Leaves, one triangle against the packet's rays ----
//
// The rays of `lanes` share the watertight test's axis permutation (kx, ky, kz), so each triangle's
// rows are the same for all of them: one triangle is tested against every ray at once, each lane
// computing exactly the operations of the single-ray test (intersectWatertight4v, in the same
// order). The leaf's triangles are taken in the single path's groups (Leaf::kGroupBlocks blocks:
// the 8-lane test of two blocks, or one block), and per ray each group is settled as the single path
// settles it: the closest of its triangles decided in float (the first of equal t), then the
// triangles with an edge function exactly zero one by one through the scalar test, with t_max
// updated in between. So every ray records the hit the single path records, bit for bit.

template <class F>
inline void forEachLeafGroup(std::uint32_t count, F&& f) {
  int left = static_cast<int>(count);
  for (int first = 0; left > 0;) {
    const int tris = (PV::kGroupBlocks == 2 && left > 4) ? std::min(left, 8) : std::min(left, 4);
    f(first, tris);
    const int blocks = (tris + 3) / 4;
    first += blocks;
    left -= 4 * blocks;
  }
}

// The edge functions, determinant and scaled distance of triangle `lane` of `b` for every ray of
// the packet; returns the rays decided in float (`fast`) and those with a zero edge function.
struct PacketTri {
  typename PV::V t_num, det, V, W;
  unsigned fast = 0, exact = 0;
};

inline PacketTri packetTriangle(const PacketRays& p, const TriangleBlock4& b, int lane, int kx, int ky, int kz,
                                unsigned lanes) {
  using V = typename PV::V;
  const V ox = PV::load(p.wo[0]), oy = PV::load(p.wo[1]), oz = PV::load(p.wo[2]);
  const V sx = PV::load(p.ws[0]), sy = PV::load(p.ws[1]), sz = PV::load(p.ws[2]);
  const V Az = PV::sub(PV::set1(b.v[kz][lane]), oz);
  const V ax = PV::sub(PV::sub(PV::set1(b.v[kx][lane]), ox), PV::mul(sx, Az));
  const V ay = PV::sub(PV::sub(PV::set1(b.v[ky][lane]), oy), PV::mul(sy, Az));
  const V Bz = PV::sub(PV::set1(b.v[3 + kz][lane]), oz);
  const V bx = PV::sub(PV::sub(PV::set1(b.v[3 + kx][lane]), ox), PV::mul(sx, Bz));
  const V by = PV::sub(PV::sub(PV::set1(b.v[3 + ky][lane]), oy), PV::mul(sy, Bz));
  const V Cz = PV::sub(PV::set1(b.v[6 + kz][lane]), oz);
  const V cx = PV::sub(PV::sub(PV::set1(b.v[6 + kx][lane]), ox), PV::mul(sx, Cz));
  const V cy = PV::sub(PV::sub(PV::set1(b.v[6 + ky][lane]), oy), PV::mul(sy, Cz));
  PacketTri r;
  r.V = PV::sub(PV::mul(ax, cy), PV::mul(ay, cx));
  r.W = PV::sub(PV::mul(bx, ay), PV::mul(by, ax));
  const V U = PV::sub(PV::mul(cx, by), PV::mul(cy, bx));
  const V zero = PV::set1(0.0f);
  r.exact = (PV::eq(U, zero) | PV::eq(r.V, zero) | PV::eq(r.W, zero)) & lanes;
  const unsigned mixed = PV::lt(PV::min(U, PV::min(r.V, r.W)), zero) & PV::gt(PV::max(U, PV::max(r.V, r.W)), zero);
  r.det = PV::add(PV::add(U, r.V), r.W);
  const unsigned candidates = ~(mixed | PV::eq(r.det, zero)) & lanes & ~r.exact;
  if (candidates == 0) return r;
  r.t_num = PV::add(PV::add(PV::mul(U, PV::mul(sz, Az)), PV::mul(r.V, PV::mul(sz, Bz))), PV::mul(r.W, PV::mul(sz, Cz)));
  const V abs_det = PV::abs(r.det);
  const V sT = PV::flipSign(r.t_num, r.det);
  const unsigned outside =
      PV::lt(sT, PV::mul(PV::load(p.wtnear), abs_det)) | PV::gt(sT, PV::mul(PV::load(p.t_best), abs_det));
  r.fast = candidates & ~outside;
  return r;
}

// Closest hits of the rays `lanes` (one permutation) in the leaf `block`, `count` triangles.
inline unsigned packetLeafClosest(const MeshRay* const* rays, unsigned lanes, const TriangleBlock4* block,
                                  std::uint32_t count, PacketRays& p, ClosestHit* best, int kx, int ky, int kz) {
  using V = typename PV::V;
  unsigned found = 0;
  forEachLeafGroup(count, [&](int first, int tris) {
    const TriangleBlock4* g = block + first;
    alignas(64) float best_t[PV::kWidth], best_u[PV::kWidth], best_v[PV::kWidth], best_k[PV::kWidth];
    V bt = PV::set1(std::numeric_limits<float>::infinity()), bu = bt, bv = bt, bk = bt;
    unsigned any_fast = 0;
    unsigned exact[8];
    for (int k = 0; k < tris; ++k) {
      const PacketTri r = packetTriangle(p, g[k >> 2], k & 3, kx, ky, kz, lanes);
      exact[k] = r.exact;
      if (r.fast == 0) continue;
      const V inv = PV::div(PV::set1(1.0f), r.det);  // the single test's final step
      const V t = PV::mul(r.t_num, inv);
      const unsigned better = r.fast & PV::lt(t, bt);  // strictly: the first of equal t wins
      bt = PV::blend(better, t, bt);
      bu = PV::blend(better, PV::mul(r.V, inv), bu);
      bv = PV::blend(better, PV::mul(r.W, inv), bv);
      bk = PV::blend(better, PV::set1(static_cast<float>(k)), bk);
      any_fast |= r.fast;
    }
    if (any_fast != 0) {
      PV::store(best_t, bt);
      PV::store(best_u, bu);
      PV::store(best_v, bv);
      PV::store(best_k, bk);
      for (unsigned l = any_fast; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        const int k = static_cast<int>(best_k[j]);
        p.t_best[j] = best_t[j];
        best[j] = {g + (k >> 2), k & 3, best_u[j], best_v[j]};
      }
      found |= any_fast;
    }
    for (int k = 0; k < tris; ++k) {
      const TriangleBlock4& b = g[k >> 2];
      for (unsigned l = exact[k]; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        float t, u, v;
        if (!intersectWatertight(rays[j]->wray, b.vertex(k & 3, 0), b.vertex(k & 3, 1), b.vertex(k & 3, 2), p.t_best[j],
                                 t, u, v))
          continue;
        p.t_best[j] = t;
        best[j] = {&b, k & 3, u, v};
        found |= 1u << j;
      }
    }
  });
  return found;
}

// The rays of `lanes` (one permutation) that a triangle of the leaf blocks within [tnear, tfar].
inline unsigned packetLeafAny(const MeshRay* const* rays, unsigned lanes, const TriangleBlock4* block,
                              std::uint32_t count, const PacketRays& p, int kx, int ky, int kz) {
  unsigned blocked = 0;
  forEachLeafGroup(count, [&](int first, int tris) {
    const TriangleBlock4* g = block + first;
    for (int k = 0; k < tris && (lanes & ~blocked) != 0; ++k) {
      const PacketTri r = packetTriangle(p, g[k >> 2], k & 3, kx, ky, kz, lanes & ~blocked);
      blocked |= r.fast;
      const TriangleBlock4& b = g[k >> 2];
      for (unsigned l = r.exact & ~blocked; l != 0; l &= l - 1) {
        const int j = std::countr_zero(l);
        float t, u, v;
        if (intersectWatertight(rays[j]->wray, b.vertex(k & 3, 0), b.vertex(k & 3, 1), b.vertex(k & 3, 2), p.t_best[j],
                                t, u, v))
          blocked |= 1u << j;
      }
    }
  });
  return blocked;
}

// Runs `packet(kx, ky, kz, lanes)` on each set of at least PV::kLeafMinRays rays of `m` that share
// the watertight permutation, and `single(j)` on the others.
template <class Packet, class Single>
inline void forEachPermutation(const MeshRay* const* rays, unsigned m, Packet&& packet, Single&& single) {
  while (m != 0) {
    const WatertightRay& w0 = rays[std::countr_zero(m)]->wray;
    unsigned same = 0;
    for (unsigned l = m; l != 0; l &= l - 1) {
      const WatertightRay& w = rays[std::countr_zero(l)]->wray;
      if (w.kx == w0.kx && w.ky == w0.ky && w.kz == w0.kz) same |= l & (~l + 1);
    }
    m &= ~same;
    if (std::popcount(same) >= PV::kLeafMinRays) {
      packet(w0.kx, w0.ky, w0.kz, same);
    } else {
      for (; same != 0; same &= same - 1) single(std::countr_zero(same));
    }
  }
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
  while (true) {
    if (std::popcount(m) <= PV::kFallback) {
      for (unsigned lanes = m; lanes != 0; lanes &= lanes - 1) {
        const int j = std::countr_zero(lanes);
        if (closestSubtree<kOct>(bvh, cur, *rays[j], p.t_best[j], best[j])) found |= 1u << j;
      }
    } else if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      for (int rank = 0; rank < 8; ++rank) {
        const int k = node.orderedSlot(kOct, rank);
        if (node.child[k] == BvhRef::kEmpty) continue;
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
      forEachPermutation(
          rays, m,
          [&](int kx, int ky, int kz, unsigned same) {
            found |= packetLeafClosest(rays, same, blocks, count, p, best, kx, ky, kz);
          },
          [&](int j) {
            if (Leaf::closest(*rays[j], Leaf::RayConstants(*rays[j]), blocks, count, p.t_best[j], best[j]))
              found |= 1u << j;
          });
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
  while (true) {
    if (std::popcount(m) <= PV::kFallback) {
      for (unsigned lanes = m; lanes != 0; lanes &= lanes - 1) {
        const int j = std::countr_zero(lanes);
        if (occludedSubtree<kOct>(bvh, cur, *rays[j], p.t_best[j])) blocked |= 1u << j;
      }
    } else if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      for (int rank = 0; rank < 8; ++rank) {
        const int k = node.orderedSlot(kOct, rank);
        if (node.child[k] == BvhRef::kEmpty) continue;
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
      forEachPermutation(
          rays, m,
          [&](int kx, int ky, int kz, unsigned same) {
            blocked |= packetLeafAny(rays, same, blocks, count, p, kx, ky, kz);
          },
          [&](int j) {
            if (Leaf::any(*rays[j], Leaf::RayConstants(*rays[j]), blocks, count, p.t_best[j])) blocked |= 1u << j;
          });
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
// and every group of a packet spread over more than 4 octants, goes ray by ray through
// `single(oct, i)` (i: the packet index), since packet setup would cost more than it saves; larger groups go through
// `packet(oct, lanes, p, group)`, where group[j] is the packet index of lane j of `p` and `lanes` the group's lane
// mask. Rays that are not queryable are left out.
template <class Single, class Packet>
inline void forEachPacketGroup(const Ray* rays, unsigned active, MeshRay* prepared, Single&& single, Packet&& packet) {
  unsigned by_octant[8] = {};
  for (unsigned lanes = active; lanes != 0; lanes &= lanes - 1) {
    const int i = std::countr_zero(lanes);
    if (prepareMeshRay(rays[i], prepared[i])) by_octant[octantOf(prepared[i])] |= 1u << i;
  }
  // Rays spread over more than 4 octants (16 random directions cover about 7) are incoherent: ray
  // by ray, at the single path's cost.
  int octants = 0;
  for (const unsigned lanes : by_octant) octants += lanes != 0 ? 1 : 0;
  const int min_packet = octants > 4 ? kMaxPacketRays : PV::kMinPacket;
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
        const WatertightRay& w = prepared[i].wray;
        p.wo[0][j] = w.origin[w.kx];
        p.wo[1][j] = w.origin[w.ky];
        p.wo[2][j] = w.origin[w.kz];
        p.ws[0][j] = w.sx;
        p.ws[1][j] = w.sy;
        p.ws[2][j] = w.sz;
        p.wtnear[j] = w.tnear;
      }
      for (int j = std::popcount(lanes); j < PV::kWidth; ++j) {
        group[j] = group[0];
        for (int a = 0; a < 3; ++a) p.o[a][j] = p.inv[a][j] = p.wo[a][j] = p.ws[a][j] = 0.0f;
        p.tnear[j] = p.t_best[j] = p.wtnear[j] = 0.0f;
      }
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
