// The mesh BVH traversal, included by MeshBvh.cpp once per instruction set inside a namespace and
// a `#pragma GCC target` region that define `BoxRay`, `Node::test` (the node's 8 child boxes
// against the ray) and `Leaf` (the triangles of a leaf, with per-ray constants
// Leaf::RayConstants). No include guard: it is meant to be compiled several times.
//
// Closest hit: the children whose boxes the ray meets within [tnear, t_best] are visited nearest
// first; the others wait on a stack with their entry distance and are dropped when popped behind
// the closest hit found by then. Any hit: the same without ordering, stopping at the first hit.

struct StackEntry {
  std::uint32_t ref;
  float dist;
};
// 7 pending children per level (WideBvh::kMaxDepth levels) fit.
constexpr int kStackSize = 7 * WideBvh::kMaxDepth + 8;

template <int kOct>
inline bool intersectKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray, Hit& hit) {
  float t_best = std::min(hit.t, ray_os.tfar);
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  ClosestHit best;
  bool found = false;
  StackEntry stack[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  while (true) {
    if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      alignas(32) float dist[8];
      unsigned mask = Node::template test<kOct>(node, box_ray, t_best, dist);
      if (mask != 0) {
        const int a = std::countr_zero(mask);
        mask &= mask - 1;
        if (mask == 0) {
          cur = node.child[a];
          continue;
        }
        const int b = std::countr_zero(mask);
        mask &= mask - 1;
        if (mask == 0) {
          // Two children, the common case below the top levels.
          if (dist[a] <= dist[b]) {
            stack[sp++] = {node.child[b], dist[b]};
            cur = node.child[a];
          } else {
            stack[sp++] = {node.child[a], dist[a]};
            cur = node.child[b];
          }
          continue;
        }
        // Three or more: sorted farthest first onto the stack (insertion sort of at most 8), the
        // nearest is visited now.
        StackEntry e[8];
        int n = 0;
        e[n++] = {node.child[a], dist[a]};
        e[n++] = {node.child[b], dist[b]};
        for (; mask != 0; mask &= mask - 1) {
          const int k = std::countr_zero(mask);
          e[n++] = {node.child[k], dist[k]};
        }
        for (int i = 1; i < n; ++i) {
          const StackEntry x = e[i];
          int j = i;
          for (; j > 0 && e[j - 1].dist < x.dist; --j) e[j] = e[j - 1];
          e[j] = x;
        }
        for (int i = 0; i + 1 < n; ++i) stack[sp++] = e[i];
        cur = e[n - 1].ref;
        continue;
      }
    } else {
      if (Leaf::closest(ray, leaf_ray, bvh.blocks + BvhRef::leafBlock(cur), BvhRef::leafCount(cur), t_best, best))
        found = true;
    }
    // Pop the next child not behind the closest hit.
    while (true) {
      if (sp == 0) {
        if (!found) return false;
        fillHit(best, t_best, hit);
        return true;
      }
      --sp;
      if (stack[sp].dist <= t_best) break;
    }
    cur = stack[sp].ref;
  }
}

template <int kOct>
inline bool occludedKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray) {
  const float t_far = ray_os.tfar;
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  std::uint32_t stack[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  while (true) {
    if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      alignas(32) float dist[8];
      unsigned mask = Node::template test<kOct>(node, box_ray, t_far, dist);
      if (mask != 0) {
        cur = node.child[std::countr_zero(mask)];
        for (mask &= mask - 1; mask != 0; mask &= mask - 1) stack[sp++] = node.child[std::countr_zero(mask)];
        continue;
      }
    } else if (Leaf::any(ray, leaf_ray, bvh.blocks + BvhRef::leafBlock(cur), BvhRef::leafCount(cur), t_far)) {
      return true;
    }
    if (sp == 0) return false;
    cur = stack[--sp];
  }
}

template <int kOct>
inline void forEachLeafKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray, MeshBvhLeafVisitor visit,
                              void* context) {
  const BoxRay box_ray(ray.kd);
  std::uint32_t stack[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  while (true) {
    if (BvhRef::isInner(cur)) {
      const BvhNode8& node = bvh.nodes[cur];
      alignas(32) float dist[8];
      unsigned mask = Node::template test<kOct>(node, box_ray, ray_os.tfar, dist);
      if (mask != 0) {
        cur = node.child[std::countr_zero(mask)];
        for (mask &= mask - 1; mask != 0; mask &= mask - 1) stack[sp++] = node.child[std::countr_zero(mask)];
        continue;
      }
    } else {
      visit(context, BvhRef::leafBlock(cur), BvhRef::leafCount(cur));
    }
    if (sp == 0) return;
    cur = stack[--sp];
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
