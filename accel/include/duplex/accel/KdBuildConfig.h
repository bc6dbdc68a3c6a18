#pragma once
/// \file KdBuildConfig.h
/// Parameters of the kd-tree build, with the defaults we ship and why.

#include <cstdint>
#include <ostream>
#include <string_view>

namespace duplex {

/// How split planes are chosen.
enum class KdHeuristic {
  /// Surface area heuristic: 8 to 32 bins per axis plus exact empty-space cuts, the binned plane
  /// refined to the exact primitive bounds inside the best bins (see KdTreeBuilder.cpp). Best
  /// trees, slowest build.
  Sah,
  /// Plane at the median primitive centroid on the longest axis; leaves of max_leaf_size.
  Median,
  /// Plane at the middle of the node's longest axis; leaves of max_leaf_size.
  SpatialMiddle,
};

/// The name parseKdHeuristic() reads: "sah", "median" or "middle".
std::string_view toString(KdHeuristic h);
/// Parses "sah", "median", "middle"; throws InvalidArgument otherwise.
KdHeuristic parseKdHeuristic(std::string_view name);

/// Build parameters. Costs are relative units: the SAH estimates the cost of a ray through a node
/// as traversal_cost + intersection_cost * (expected number of primitives tested).
struct KdBuildConfig {
  KdHeuristic heuristic = KdHeuristic::Sah;  ///< how split planes are chosen
  /// Cost of one inner-node step. 1 by convention; only the ratio to intersection_cost matters.
  float traversal_cost = 1.0f;
  /// Cost of one primitive test relative to a node step: 0.05, a node cost of 20 triangle tests.
  /// By instruction count a watertight triangle test costs about 4 node steps (1 in a 4-wide leaf
  /// packet), but the SAH model ignores what a node step really costs on incoherent rays (a
  /// dependent load and an unpredictable branch per node), so smaller, shallower trees with larger
  /// leaves win, up to a point: higher costs build slower and trace no faster, lower ones build
  /// faster but trace primary rays slower on large flat regions (docs/design/kdtree.md, "Costs"; the sweep
  /// is bench/SweepBench.cpp). The top level and the sensors' level set their own intersection
  /// costs (TopLevel.h) and keep traversal_cost 1, so change this one, not that.
  float intersection_cost = 0.05f;
  /// Relative cost reduction for a split that cuts off empty space (Wald & Havran 2006: 0.2),
  /// which isolates geometry from empty space and pays off for rays that miss.
  float empty_bonus = 0.2f;
  /// Depth bound; 0 means automatic: 8 + 1.3 * log2(N) (Havran).
  int max_depth = 0;
  /// Leaf size at which the Median / SpatialMiddle heuristics stop splitting.
  std::uint32_t max_leaf_size = 4;
  /// Build subtrees on TBB's threads when they hold at least this many references (0: serial, and
  /// no pass runs in parallel chunks either). The tree does not depend on it. Low enough that the
  /// nodes of a few thousand references above the serial subtrees do not keep a second thread idle
  /// on the critical path (KdTreeBuilder.cpp's chunked passes cover the larger nodes).
  std::uint32_t parallel_threshold = 1024;
  /// Clip primitives to node boxes ("perfect splits"). Off: keep unclipped bounds (faster build,
  /// worse tree), so the benchmark can chart the difference.
  bool clip_primitives = true;
  /// SAH: nodes of at most this many references sweep every event (clipped bound) of every axis;
  /// larger nodes are binned (8 to 32 bins per axis) with exact empty-space cuts. In a mesh tree
  /// (leaves of ~12 references) it hardly matters; in a top level (leaves of 1-3 instances) a
  /// smaller value gives a costlier tree and a larger one a slower build: 8 balances the two.
  std::uint32_t exact_sweep_max = 8;
  /// SAH: binned nodes of at most this many references move the binned plane to the best exact
  /// event in the two bins around it (one more pass over the node). 0: never (a slightly faster
  /// build, a costlier tree with more references); the default refines everywhere.
  std::uint32_t refine_max = 0xFFFFFFFFu;
};

/// Writes every parameter on one line, for logs and benchmark output.
std::ostream& operator<<(std::ostream& os, const KdBuildConfig& c);

}  // namespace duplex
