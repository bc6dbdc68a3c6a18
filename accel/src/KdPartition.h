#pragma once
// Private to accel/src: the partition of a kd-tree node's references into its two children, with
// perfect splits (straddling primitives re-clipped to each child) and the children's extents and
// bins computed on the way, so that binning a child costs no pass of its own.

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "KdBins.h"
#include "KdBuildRefs.h"

namespace duplex::kd_detail {

// What a partition produces for one child: its references (clipped to its box), their exact
// extent, and (when the child is large enough to be binned) their bins over the child's box
// intersected with the parent's extent.
struct Child {
  Box box;
  RefVec refs;
  Extent extent;
  bool binned = false;
  Bins bins;
};

// Splits `refs` into the two children (their boxes set by the caller), binning each child expected
// to be large enough, over its box intersected with the parent's extent (which contains every
// reference of the child). Exactly one of `clip` and `split` is non-null.
void partition(const RefVec& refs, const Split& s, const Extent& parent_extent, Child& lower, Child& upper,
               const KdBuildConfig& config, const KdClipFunction* clip, const KdSplitFunction* split);

}  // namespace duplex::kd_detail
