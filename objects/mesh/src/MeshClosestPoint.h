#pragma once
// The closest-point search of the mesh BVH in object space (MeshObject::closestPoint under a
// similarity transform), one kernel per instruction set chosen once per process (SimdIsa.h).
// Private to the objects library: MeshObject calls it, the tests reach every path through
// DUPLEX_ISA.

#include "duplex/accel/SimdIsa.h"
#include "duplex/accel/WideBvh.h"
#include "TriangleBlock4.h"

#include <glm/vec3.hpp>

namespace duplex::detail {

/// The search's state (object space, squared distances in the object's units squared).
struct ClosestPointSearch {
  /// In: the squared radius of the search (+inf: unbounded); out: lowered to the squared distance
  /// of the point found, if any was closer.
  double best2 = 0.0;
  /// Out: the triangle of the point found (block and lane), null when none was within the radius.
  const TriangleBlock4* block = nullptr;
  int lane = 0;
  glm::dvec3 point{0.0};  ///< out: the point found
};

/// Searches `bvh` (its leaves' triangles in `blocks`, block k holding prim_indices[4k, 4k + 4))
/// for the triangle point nearest to `p` (object space) closer than sqrt(s.best2). Every path
/// computes the same doubles as the scalar reference (closestPointOnTriangle, squared box
/// distances without fused multiply-add) and visits in the same order, so that the result does
/// not depend on the instruction set.
using MeshClosestPointKernel = void (*)(const WideBvh& bvh, const TriangleBlock4* blocks, const glm::dvec3& p,
                                        ClosestPointSearch& s);

/// The kernel of widestSimdIsa().
MeshClosestPointKernel meshClosestPointKernel();
/// The kernel of `isa`, which the CPU must support.
MeshClosestPointKernel meshClosestPointKernel(SimdIsa isa);

}  // namespace duplex::detail
