// The wide walks, included by InstanceTreeWide.cpp once per instruction set inside a namespace
// that defines `WideRay`, `setupRay(ray, WideRay&) -> queryable`,
// `wideHits(ray, node, t_max, t_enter[8]) -> mask`, `packetChildHits(packet, node, child, lanes,
// key) -> lanes` and `objectRay(record, world_ray)` (toObject's values, InstanceTreeState.h) for
// that set.

// Walks the form front to back: nodes and references in the order of their box entry, each node's
// children sorted nearest first (for AnyHit, in any order). Calls visit(slot, t_best) for each
// reference whose clipped box the ray meets no later than t_best; visit returns whether it found a
// hit (lowering t_best for a closest-hit walk). With AnyHit the walk returns at the first such
// visit. Returns whether any visit found a hit.
template <bool AnyHit, class Visit>
inline bool walk(const WideTop& top, const WideRay& r, float& t_best, Visit&& visit) {
  struct Entry {
    std::uint32_t child;
    float t;
  };
  Entry stack[kWideStackSize];
  int depth = 0;
  const WideNode* nodes = top.nodes.data();
  std::uint32_t cur = top.root;
  float cur_t = r.tnear;
  bool found = false;
  while (true) {
    if (cur & kWideRef) {
      if (cur_t <= t_best && visit(cur & ~kWideRef, t_best)) {
        found = true;
        if constexpr (AnyHit) return true;
      }
    } else {
      alignas(32) float t_enter[8];
      std::uint32_t mask = wideHits(r, nodes[cur], t_best, t_enter);
      if (mask != 0) {
        const WideNode& node = nodes[cur];
        const int first = std::countr_zero(mask);
        mask &= mask - 1;
        if (mask == 0) {  // one child met: no sorting, no push
          cur = node.child[first];
          cur_t = t_enter[first];
          continue;
        }
        // Several: pushed sorted by entry, the nearest last (popped, that is taken, at once).
        const int base = depth;
        stack[depth++] = {node.child[first], t_enter[first]};
        do {
          const int c = std::countr_zero(mask);
          mask &= mask - 1;
          const Entry e{node.child[c], t_enter[c]};
          int j = depth++;
          if constexpr (!AnyHit) {
            for (; j > base && stack[j - 1].t < e.t; --j) stack[j] = stack[j - 1];
          }
          stack[j] = e;
        } while (mask != 0);
        --depth;
        cur = stack[depth].child;
        cur_t = stack[depth].t;
        continue;
      }
    }
    // The next entry that can still hold a closer hit.
    do {
      if (depth == 0) return found;
      --depth;
      cur = stack[depth].child;
      cur_t = stack[depth].t;
    } while (cur_t > t_best);
  }
}

// A blocking instance the query's mask selects, not asked before for this ray.
inline bool selected(const WideQuery& q, std::uint32_t slot, Mailbox& mailbox) {
  const SlotFilter f = q.filters[slot];
  return (f.mask & q.mask) != 0 && f.role == ObjectRole::Surface && !mailbox.seen(slot);
}

bool closestEntry(const WideQuery& q, const Ray& ray_f, const RayD* ray_d, Hit& out, QueryContext& ctx) {
  WideRay r;
  if (!setupRay(ray_f, r)) return false;
  const WorldRay w{ray_f, ray_d};
  float t_best = ray_f.tfar;
  std::uint32_t best_id = kInvalidId;
  const Record* winner = nullptr;
  Mailbox mailbox;
  Hit best;
  walk<false>(*q.top, r, t_best, [&](std::uint32_t slot, float& t) {
    if (!selected(q, slot, mailbox)) return false;
    ++ctx.stats.instance_visits;
    const Record& rec = q.records[slot];
    if (!closerHit(rec, objectRay(rec, w), best, t, best_id, ctx)) return false;
    winner = &rec;
    return true;
  });
  if (!winner) return false;
  out = best;
  out.instance_id = winner->id;
  out.ng = normalToWorld(*winner, best.ng);
  return true;
}

bool occludedEntry(const WideQuery& q, const Ray& ray, QueryContext& ctx) {
  WideRay r;
  if (!setupRay(ray, r)) return false;
  const WorldRay w = fromFloat(ray);
  float t_best = ray.tfar;
  Mailbox mailbox;
  return walk<true>(*q.top, r, t_best, [&](std::uint32_t slot, float&) {
    if (!selected(q, slot, mailbox)) return false;
    ++ctx.stats.instance_visits;
    return occludes(q.records[slot], objectRay(q.records[slot], w), ctx);
  });
}

// Sub-packets of at most this many lanes enter an object through its single-ray entry.
constexpr int kAloneLanes = 4;

// The largest / smallest value of a row of kMaxPacketRays lanes.
inline float rowMax(const float* row) {
  __m128 r = _mm_max_ps(_mm_max_ps(_mm_load_ps(row), _mm_load_ps(row + 4)),
                        _mm_max_ps(_mm_load_ps(row + 8), _mm_load_ps(row + 12)));
  r = _mm_max_ps(r, _mm_shuffle_ps(r, r, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm_cvtss_f32(_mm_max_ps(r, _mm_shuffle_ps(r, r, _MM_SHUFFLE(2, 3, 0, 1))));
}

inline float rowMin(const float* row) {
  __m128 r = _mm_min_ps(_mm_min_ps(_mm_load_ps(row), _mm_load_ps(row + 4)),
                        _mm_min_ps(_mm_load_ps(row + 8), _mm_load_ps(row + 12)));
  r = _mm_min_ps(r, _mm_shuffle_ps(r, r, _MM_SHUFFLE(1, 0, 3, 2)));
  return _mm_cvtss_f32(_mm_min_ps(r, _mm_shuffle_ps(r, r, _MM_SHUFFLE(2, 3, 0, 1))));
}

// `rays` are the caller's world rays (float; lanes index them). An instance placed as authored
// (Record::identity) is asked with them as they are: its object space is world space, so the
// rays need no copy, and for a closest-hit query the best distance so far goes in the hit's t, which
// bounds an object's search as the ray's tfar does (Object::intersect), without touching the ray.
template <bool AnyHit>
std::uint32_t packetWalk(const WideQuery& q, PacketRays& p, const Ray* rays, std::uint32_t lanes, Hit* best,
                         std::uint32_t* best_id, const Record** winner, QueryContext& ctx) {
  struct Entry {
    const WideNode* parent;
    std::uint32_t child;  // index in parent
    std::uint32_t lanes;
    float key;
  };
  Entry stack[kWideStackSize];
  int depth = 0;
  Mailbox mailbox[kMaxPacketRays];
  Ray rays_os[kMaxPacketRays];
  Hit hits_os[kMaxPacketRays];
  // Object rays are read up to the highest lane in use.
  const std::size_t span = static_cast<std::size_t>(32 - std::countl_zero(lanes));
  const WideNode* nodes = q.top->nodes.data();
  std::uint32_t done = 0;  // any hit: blocked lanes; closest hit: lanes that found something
  std::uint32_t cur = q.top->root;
  std::uint32_t m = lanes;
  // The furthest any lane still looks (unused lanes hold -inf).
  float reach = rowMax(p.t);
  while (true) {
    if (cur & kWideRef) {
      const std::uint32_t slot = cur & ~kWideRef;
      const SlotFilter f = q.filters[slot];
      std::uint32_t sub = 0;
      if ((f.mask & q.mask) != 0 && f.role == ObjectRole::Surface)
        for (std::uint32_t l = m; l != 0; l &= l - 1) {
          const int j = std::countr_zero(l);
          if (!mailbox[j].seen(slot)) sub |= 1u << j;
        }
      if (sub != 0) {
        const Record& rec = q.records[slot];
        ctx.stats.instance_visits += static_cast<std::uint64_t>(std::popcount(sub));
        const Ray* ask = rays;
        if (!rec.identity) {
          for (std::uint32_t l = sub; l != 0; l &= l - 1) {
            const int j = std::countr_zero(l);
            rays_os[j] = objectRay(rec, fromFloat(rays[j]));
          }
          ask = rays_os;
        }
        if constexpr (!AnyHit) {
          // As closerHit (InstanceTreeState.h): asked a few ulps beyond the best hit, decided by replacesBest.
          for (std::uint32_t l = sub; l != 0; l &= l - 1) {
            const int j = std::countr_zero(l);
            hits_os[j].t = askBound(p.t[j]);
            if (!rec.identity) rays_os[j].tfar = hits_os[j].t;
          }
        }
        // A sub-packet of a few lanes costs less through the single-ray entry (an object's
        // packet set-up is paid per visit, its savings per lane).
        const bool alone = std::popcount(sub) <= kAloneLanes && rec.entry.intersect && rec.entry.occluded;
        if constexpr (AnyHit) {
          if (alone) {
            for (std::uint32_t l = sub; l != 0; l &= l - 1) {
              const int j = std::countr_zero(l);
              if (rec.entry.occluded(rec.entry.data, ask[j])) done |= 1u << j;
            }
          } else {
            done |= rec.object->occludedPacket({ask, span}, sub, ctx);
          }
          if ((done & lanes) == lanes) return done;
        } else {
          std::uint32_t found = 0;
          if (alone) {
            for (std::uint32_t l = sub; l != 0; l &= l - 1) {
              const int j = std::countr_zero(l);
              if (rec.entry.intersect(rec.entry.data, ask[j], hits_os[j])) found |= 1u << j;
            }
          } else {
            found = rec.object->intersectPacket({ask, span}, {hits_os, span}, sub, ctx);
          }
          for (std::uint32_t l = found; l != 0; l &= l - 1) {
            const int j = std::countr_zero(l);
            if (!replacesBest(hits_os[j].t, rec.id, p.t[j], best_id[j])) continue;
            best[j] = hits_os[j];
            p.t[j] = hits_os[j].t;
            best_id[j] = rec.id;
            winner[j] = &rec;
            done |= 1u << j;
          }
          if (found != 0) reach = rowMax(p.t);
        }
      }
    } else {
      const WideNode& node = nodes[cur];
      Entry met[8];
      int n = 0;
      for (std::uint32_t v = packetBoundsHits(p, node, reach); v != 0; v &= v - 1) {
        const int c = std::countr_zero(v);
        float key;
        const std::uint32_t hit = packetChildHits(p, node, c, m, key);
        if (hit == 0) continue;
        Entry e{&node, static_cast<std::uint32_t>(c), hit, key};
        int j = n++;
        if constexpr (!AnyHit) {
          for (; j > 0 && met[j - 1].key < key; --j) met[j] = met[j - 1];
        }
        met[j] = e;
      }
      if (n != 0) {
        for (int i = 0; i + 1 < n; ++i) stack[depth++] = met[i];
        cur = node.child[met[n - 1].child];
        m = met[n - 1].lanes;
        continue;
      }
    }
    // The next entry with lanes that still reach its box.
    while (true) {
      if (depth == 0) return done;
      const Entry e = stack[--depth];
      std::uint32_t want = e.lanes;
      if constexpr (AnyHit) want &= ~done;
      if (want == 0) continue;
      float key;
      want = packetChildHits(p, *e.parent, static_cast<int>(e.child), want, key);
      if (want == 0) continue;
      cur = e.parent->child[e.child];
      m = want;
      break;
    }
  }
}

// Fills the packet rows of the lanes, four rays at a time: each ray is two 4-float vectors
// (origin, tnear) and (direction, tfar), transposed into rows. Unused lanes repeat the first lane's
// ray, so that the bounds are reductions over whole rows and no ray past the caller's is read, and
// never meet a box (tnear +inf, t -inf).
inline void setupPacket(const Ray* rays, std::uint32_t lanes, PacketRays& p) {
  const int first = std::countr_zero(lanes);
  const __m128 one = _mm_set1_ps(1.0f);
  const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
  const __m128i bit = _mm_setr_epi32(1, 2, 4, 8);
  for (int k = 0; k < kMaxPacketRays; k += 4) {
    const std::uint32_t want = lanes >> k & 0xFu;
    __m128 o[4], d[4];
    for (int i = 0; i < 4; ++i) {
      const Ray& r = rays[(want >> i & 1u) != 0 ? k + i : first];
      o[i] = _mm_loadu_ps(&r.origin.x);
      d[i] = _mm_loadu_ps(&r.dir.x);
    }
    _MM_TRANSPOSE4_PS(o[0], o[1], o[2], o[3]);
    _MM_TRANSPOSE4_PS(d[0], d[1], d[2], d[3]);
    const __m128 used =
        _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_and_si128(_mm_set1_epi32(static_cast<int>(want)), bit), bit));
    for (int a = 0; a < 3; ++a) {
      _mm_store_ps(p.org[a] + k, o[a]);
      // +-inf for a zero (or denormal) component, as prepareKdRay's.
      _mm_store_ps(p.inv[a] + k, _mm_div_ps(one, d[a]));
    }
    _mm_store_ps(p.tnear + k, _mm_or_ps(_mm_and_ps(used, o[3]), _mm_andnot_ps(used, inf)));
    _mm_store_ps(p.t + k, _mm_or_ps(_mm_and_ps(used, d[3]), _mm_andnot_ps(used, _mm_xor_ps(inf, _mm_set1_ps(-0.0f)))));
  }
  for (int a = 0; a < 3; ++a) p.near_row[a] = 2 * a + (std::signbit(p.inv[a][first]) ? 1 : 0);
  for (int a = 0; a < 3; ++a) {
    const bool neg = (p.near_row[a] & 1) != 0;
    const float o_lo = rowMin(p.org[a]), o_hi = rowMax(p.org[a]);
    p.near_o[a] = neg ? o_lo : o_hi;
    p.far_o[a] = neg ? o_hi : o_lo;
    p.inv_lo[a] = rowMin(p.inv[a]);
    p.inv_hi[a] = rowMax(p.inv[a]);
  }
  p.t_lo = rowMin(p.tnear);
}

std::uint32_t closestPacketEntry(const WideQuery& q, const Ray* rays, std::uint32_t lanes, Hit* best,
                                 const Record** winner, QueryContext& ctx) {
  PacketRays p;
  setupPacket(rays, lanes, p);
  std::uint32_t best_id[kMaxPacketRays];
  for (std::uint32_t l = lanes; l != 0; l &= l - 1) {
    const int j = std::countr_zero(l);
    best_id[j] = kInvalidId;
    winner[j] = nullptr;
  }
  return packetWalk<false>(q, p, rays, lanes, best, best_id, winner, ctx);
}

std::uint32_t occludedPacketEntry(const WideQuery& q, const Ray* rays, std::uint32_t lanes, QueryContext& ctx) {
  PacketRays p;
  setupPacket(rays, lanes, p);
  return packetWalk<true>(q, p, rays, lanes, nullptr, nullptr, nullptr, ctx) & lanes;
}

bool walkEntry(const WideTop& top, const Ray& ray, bool any_hit, float& t_best,
               const std::function<bool(std::uint32_t, float&)>& visit) {
  WideRay r;
  if (!setupRay(ray, r)) return false;
  return any_hit ? walk<true>(top, r, t_best, visit) : walk<false>(top, r, t_best, visit);
}
