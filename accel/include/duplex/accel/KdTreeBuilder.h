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

/// Bounds of primitive `prim` inside `box` (its current bounds, inside the node) on either side of
/// the plane at `pos` on `axis`: `lower` within box's half below the plane, `upper` above; either
/// may be empty. The same contract as two KdClipFunction calls on the halves, in one call (a
/// triangle is clipped once: splitTriangleInBox). Called from several threads at once.
using KdSplitFunction =
    std::function<void(std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper)>;

/// Builds a kd-tree over `prim_bounds.size()` primitives. Primitives with empty or non-finite
/// bounds are left out (the caller filters degenerate geometry before). With no usable primitive
/// the tree is empty (no nodes). Throws InvalidArgument for more than 2^30 primitives, a tree of
/// more than 2^30 nodes, or a configuration outside its ranges (traversal_cost and
/// intersection_cost finite and > 0, empty_bonus in [0, 1), max_depth >= 0); the message names the
/// field and its value.
///
/// Algorithm: top-down SAH. Nodes are binned (8 to 32 bins per axis, counted while the parent is
/// partitioned), with exact empty-space cuts at the references' extent (a chain of them moves no
/// reference); the binned plane is then moved to the best exact event (clipped bound) in the two
/// bins around it, and the smallest nodes sweep all their events (KdBuildConfig::exact_sweep_max,
/// refine_max). O(N) per node, O(N log N) overall. Straddling primitives are re-clipped to each
/// child ("perfect splits"). Partitions of large nodes run in parallel chunks, subtrees as TBB
/// tasks; the tree does not depend on the thread count.
[[nodiscard]] KdTree buildKdTree(std::span<const Box> prim_bounds, const KdClipFunction& clip,
                                 const KdBuildConfig& config = {});

/// The same build with a split function: straddling primitives are clipped once per split
/// instead of once per child. Same tree as with the equivalent clip function.
[[nodiscard]] KdTree buildKdTree(std::span<const Box> prim_bounds, const KdSplitFunction& split,
                                 const KdBuildConfig& config = {});

/// Convenience for box primitives (the top level): clipping is box intersection.
[[nodiscard]] KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config = {});
/// The same with `root_bounds` as the tree's bounds instead of the boxes' (a cell of an enclosing
/// tree that a subtree replaces): the space between them is cut off where the SAH finds it worth
/// it, and the tree's SAH cost is that of a ray through `root_bounds`. Throws InvalidArgument when
/// `root_bounds` is not finite or does not contain every box. No usable box: an empty tree.
[[nodiscard]] KdTree buildKdTreeOverBoxes(std::span<const Box> boxes, const KdBuildConfig& config,
                                          const Box& root_bounds);

}  // namespace duplex
