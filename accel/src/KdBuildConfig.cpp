// Names and printing of the kd-tree build configuration (KdBuildConfig.h).

#include "duplex/accel/KdBuildConfig.h"

#include "duplex/accel/Error.h"

#include <ostream>
#include <string>

namespace duplex {

std::string_view toString(KdHeuristic h) {
  switch (h) {
    case KdHeuristic::Sah: return "sah";
    case KdHeuristic::Median: return "median";
    case KdHeuristic::SpatialMiddle: return "middle";
  }
  return "unknown";
}

KdHeuristic parseKdHeuristic(std::string_view name) {
  if (name == "sah") return KdHeuristic::Sah;
  if (name == "median") return KdHeuristic::Median;
  if (name == "middle") return KdHeuristic::SpatialMiddle;
  throw InvalidArgument("unknown kd-tree heuristic '" + std::string(name) + "' (expected sah, median or middle)");
}

std::ostream& operator<<(std::ostream& os, const KdBuildConfig& c) {
  return os << "KdBuildConfig{" << toString(c.heuristic) << ", Ct=" << c.traversal_cost
            << ", Ci=" << c.intersection_cost << ", empty_bonus=" << c.empty_bonus << ", max_depth=" << c.max_depth
            << ", leaf=" << c.max_leaf_size << ", clip=" << c.clip_primitives
            << ", exact_sweep_max=" << c.exact_sweep_max << ", refine_max=" << c.refine_max << "}";
}

}  // namespace duplex
