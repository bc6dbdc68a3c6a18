#pragma once
/// \file KdTreeBuilder.h
/// One kd-tree builder for both levels: it sees primitives only through their bounds and a
/// clipping function.

#include "duplex/accel/Box.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"

#include <cstdint>
#include <functional>
#include <span>

namespace duplex {

/// Bounds of primitive `prim` clipped to `box` (same space as the primitive bounds). Must return a
/// box contained in `box`, and may return an empty box when the primitive does not meet `box`.
/// Called from several threads at once. Triangles pass exact clipping (clipTriangleToBox), boxes
/// pass plain box intersection.
using KdClipFunction = std::function<Box(std::uint32_t prim, const Box& box)>;

/// Builds a kd-tree over `prim_bounds.size()` primitives. Primitives with empty or non-finite
/// bounds are left out (the caller filters degenerate geometry before). With no usable primitive
/// the tree is empty (no nodes). Throws InvalidArgument for more than 2^30 primitives.
///
/// Algorithm: top-down, per node binned SAH (32 bins per axis) over the primitives' clipped bounds,
/// then the exact candidate planes (clipped bound values) in the two bins around the best bin
/// boundary are swept to place the plane exactly where Wald & Havran's event sweep would put it,
/// within that window. O(N) per node, O(N log N) overall. Straddling primitives are re-clipped to
/// each child ("perfect splits"). Subtrees run as TBB tasks.
[[nodiscard]] KdTree buildKdTree(std::span<const Box> prim_bounds, const KdClipFunction& clip,
                                 const KdBuildConfig& config = {});

/// Convenience for box primitives (the top level): clipping is box intersection.
[[nodiscard]] KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config = {});

}  // namespace duplex
