// The closest-point search of the mesh BVH (MeshClosestPoint.h), included by MeshClosestPoint.cpp
// once per instruction set inside a namespace and a target region (SimdTarget.h) that define `D4`:
// four doubles per value (V) and the operations below. No include guard: it is compiled several
// times.
//
// The boxes of a node's 8 children and of a block's 4 triangles are measured 4 lanes at a time, each
// lane with exactly the double operations of the scalar search this replaces (std::max(a, b) is
// (a < b) ? b : a, which is D4::max(b, a) whatever the operands, NaN and signed zeros included), so
// the distances, the pruning and the visit order are those of the scalar search bit for bit. The
// exact point-triangle distance stays scalar, in double (closestPointOnTriangle), for the triangles
// whose box may hold a point closer than the best.

// Per lane std::max(std::max(lo - p, p - hi), 0.0): the gap between p and [lo, hi] on one axis.
[[gnu::always_inline]] inline D4::V gap(D4::V lo, D4::V hi, D4::V p) {
  return D4::max(D4::zero(), D4::max(D4::sub(p, hi), D4::sub(lo, p)));
}

// Per lane (gx^2 + gy^2) + gz^2: the squared distance from p to four boxes (the scalar sum from 0).
[[gnu::always_inline]] inline D4::V squaredDistance(const D4::V (&lo)[3], const D4::V (&hi)[3], const D4::V (&p)[3]) {
  D4::V s = D4::zero();
  for (int a = 0; a < 3; ++a) {
    const D4::V g = gap(lo[a], hi[a], p[a]);
    s = D4::add(s, D4::mul(g, g));
  }
  return s;
}

inline void closestPointKernel(const WideBvh& bvh, const TriangleBlock4* blocks, const glm::dvec3& p,
                               ClosestPointSearch& s) {
  if (bvh.root == BvhRef::kEmpty) return;
  // Boxes are pruned against the best squared distance grown by a relative 1e-10, so that the
  // rounding of a box's distance never prunes the box of a triangle that ties the best.
  constexpr double kSlack = 1.0 + 1e-10;
  double best2 = s.best2;  // +inf for an unbounded query
  double prune2 = best2 * kSlack;
  const D4::V pv[3] = {D4::set1(p.x), D4::set1(p.y), D4::set1(p.z)};
  struct Entry {
    std::uint32_t ref;
    double d2;  // squared object-space distance from p to the entry's box
  };
  // Bounded: a path holds at most 7 pending siblings per level.
  Entry stack[1 + (BvhNode8::kWidth - 1) * WideBvh::kMaxDepth];
  std::size_t size = 0;
  stack[size++] = {bvh.root, distanceSquared(bvh.bounds, p)};
  while (size > 0) {
    const Entry e = stack[--size];
    if (!(e.d2 < prune2)) continue;
    if (BvhRef::isLeaf(e.ref)) {
      const TriangleBlock4* block = blocks + BvhRef::leafBlock(e.ref);
      for (int left = static_cast<int>(BvhRef::leafCount(e.ref)); left > 0; left -= 4, ++block) {
        // Each triangle's box: min and max of its vertices per axis (in float: the same values).
        D4::V lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
          const __m128 x0 = _mm_load_ps(block->v[a]), x1 = _mm_load_ps(block->v[3 + a]),
                       x2 = _mm_load_ps(block->v[6 + a]);
          lo[a] = D4::fromFloats(_mm_min_ps(_mm_min_ps(x2, x1), x0));  // std::min(x0, std::min(x1, x2))
          hi[a] = D4::fromFloats(_mm_max_ps(_mm_max_ps(x2, x1), x0));
        }
        const D4::V box2v = squaredDistance(lo, hi, pv);
        alignas(32) double box2[4];
        D4::store(box2, box2v);
        // Lanes whose box is nearer than the best when the block starts; the best may improve
        // within the block, so each is checked again.
        for (unsigned lanes = D4::lt(box2v, D4::set1(prune2)) & static_cast<unsigned>(kLeafLaneMask[std::min(left, 4)]);
             lanes != 0; lanes &= lanes - 1) {
          const int k = std::countr_zero(lanes);
          if (!(box2[k] < prune2)) continue;
          const glm::dvec3 c = closestPointOnTriangle(p, glm::dvec3(block->vertex(k, 0)),
                                                      glm::dvec3(block->vertex(k, 1)), glm::dvec3(block->vertex(k, 2)));
          const glm::dvec3 off = c - p;
          const double d2 = glm::dot(off, off);
          if (!(d2 < best2)) continue;
          best2 = d2;
          prune2 = d2 * kSlack;
          s.block = block;
          s.lane = k;
          s.point = c;
        }
      }
      continue;
    }
    const BvhNode8& node = bvh.nodes[e.ref];
    // The 8 children's squared distances; unused slots ([+inf, -inf]) get +inf and are never kept.
    alignas(32) double d[BvhNode8::kWidth];
    unsigned keep = 0;
    for (int h = 0; h < BvhNode8::kWidth; h += 4) {
      D4::V lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = D4::fromFloats(_mm_load_ps(&node.lo[a][h]));
        hi[a] = D4::fromFloats(_mm_load_ps(&node.hi[a][h]));
      }
      const D4::V d2 = squaredDistance(lo, hi, pv);
      D4::store(d + h, d2);
      keep |= D4::lt(d2, D4::set1(prune2)) << h;
    }
    std::pair<double, std::uint32_t> order[BvhNode8::kWidth];
    int n = 0;
    for (; keep != 0; keep &= keep - 1) {
      const int k = std::countr_zero(keep);
      order[n++] = {d[k], node.child[k]};
    }
    for (int i = 1; i < n; ++i)  // descending by distance (at most 8): the nearest ends on top
      for (int j = i; j > 0 && order[j - 1].first < order[j].first; --j) std::swap(order[j - 1], order[j]);
    for (int i = 0; i < n; ++i) stack[size++] = {order[i].second, order[i].first};
  }
  s.best2 = best2;
}

inline void closestPointEntry(const WideBvh& bvh, const TriangleBlock4* blocks, const glm::dvec3& p,
                              ClosestPointSearch& s) {
  closestPointKernel(bvh, blocks, p, s);
}
