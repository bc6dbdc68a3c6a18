#pragma once
// Queries of the mesh BVH (objects space): the traversal kernels, one per instruction set, chosen
// once per process (SimdIsa.h). Private to the objects library: MeshObject calls them, the tests and
// benchmarks reach every path through meshBvhKernels(isa).

#include "duplex/accel/Box.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/accel/WideBvh.h"
#include "TriangleBlock4.h"

#include <cstdint>

namespace duplex::detail {

/// What the kernels read: the BVH's nodes and root, and the leaf blocks (block k holds the BVH's
/// prim_indices[4k, 4k + 4)).
struct MeshBvhView {
  const BvhNode8* nodes = nullptr;
  std::uint32_t root = BvhRef::kEmpty;
  Box bounds;
  const TriangleBlock4* blocks = nullptr;
};

/// Called for every leaf a ray's traversal reaches: (first block, triangle count); returns nothing:
/// the all-hits query visits every leaf the ray's segment crosses.
using MeshBvhLeafVisitor = void (*)(void* context, std::uint32_t block, std::uint32_t count);

/// One instruction set's kernels. The results do not depend on it except for the choice among
/// triangles hit at exactly the same distance.
struct MeshBvhKernels {
  SimdIsa isa;
  /// Closest hit of `ray` (object space) closer than hit.t: fills `hit` and returns true.
  bool (*intersect)(const MeshBvhView& bvh, const Ray& ray, Hit& hit);
  /// Whether anything blocks `ray` within [tnear, tfar].
  bool (*occluded)(const MeshBvhView& bvh, const Ray& ray);
  /// Every leaf whose box the ray's segment meets (no culling by hits).
  void (*forEachLeaf)(const MeshBvhView& bvh, const Ray& ray, MeshBvhLeafVisitor visit, void* context);
  /// Closest hits of the lanes `active` (bit i: rays[i], i < kMaxPacketRays; object space), each
  /// exactly as intersect(rays[i], hits[i]); returns the lanes that found a hit. Traced in packets
  /// of packet_width rays of one octant.
  unsigned (*intersectPacket)(const MeshBvhView& bvh, const Ray* rays, Hit* hits, unsigned active);
  /// The lanes of `active` that occluded(rays[i]) would report blocked.
  unsigned (*occludedPacket)(const MeshBvhView& bvh, const Ray* rays, unsigned active);
  /// Rays traced together: 4 (SSE2), 8 (AVX2), 16 (AVX-512).
  int packet_width;
  /// intersect and occluded with the view passed as ObjectRayEntry::data (MeshObject::rayEntry).
  bool (*intersect_view)(const void* bvh, const Ray& ray, Hit& hit);
  bool (*occluded_view)(const void* bvh, const Ray& ray);
};

/// The kernels of widestSimdIsa().
const MeshBvhKernels& meshBvhKernels();
/// The kernels of `isa`, which the CPU must support (tests and benchmarks run every path).
const MeshBvhKernels& meshBvhKernels(SimdIsa isa);

}  // namespace duplex::detail
