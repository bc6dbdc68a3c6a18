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

template <int kOct>
inline bool intersectKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray, Hit& hit) {
  float t_best = std::min(hit.t, ray_os.tfar);
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  ClosestHit best;
  bool found = false;
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
  while (true) {
    if (BvhRef::isInner(cur)) {
      sp += Node::template push<kOct>(bvh.nodes[cur], box_ray, t_best, refs + sp, dists + sp);
    } else if (Leaf::closest(ray, leaf_ray, bvh.blocks + BvhRef::leafBlock(cur), BvhRef::leafCount(cur), t_best,
                             best)) {
      found = true;
    }
    // Pop the next child not behind the closest hit.
    do {
      if (sp == 0) {
        if (!found) return false;
        fillHit(best, t_best, hit);
        return true;
      }
      --sp;
    } while (dists[sp] > t_best);
    cur = refs[sp];
  }
}

template <int kOct>
inline bool occludedKernel(const MeshBvhView& bvh, const Ray& ray_os, const MeshRay& ray) {
  const float t_far = ray_os.tfar;
  const BoxRay box_ray(ray.kd);
  const Leaf::RayConstants leaf_ray(ray);
  alignas(32) std::uint32_t refs[kStackSize];
  alignas(32) float dists[kStackSize];
  int sp = 0;
  std::uint32_t cur = bvh.root;
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
