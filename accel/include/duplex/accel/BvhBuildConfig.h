#pragma once
/// \file BvhBuildConfig.h
/// Parameters of the wide BVH build (WideBvh.h), with the presets we ship and why.

#include <cstdint>
#include <ostream>
#include <string>
#include <string_view>

namespace duplex {

/// Named parameter sets of the BVH build.
enum class BvhPreset {
  /// Few bins, large leaves: the quickest build, for objects rebuilt often (deforming meshes).
  Fast,
  /// Binned SAH with 32 bins per axis and SAH-chosen leaves: the default, the balance of build
  /// and trace time for objects built once per load.
  Medium,
  /// Medium plus spatial splits (SBVH, Stich et al. 2009): references are split where that lowers
  /// the SAH, which pays for long, thin or overlapping triangles traced many times.
  High,
};

/// The name parseBvhPreset() reads: "fast", "medium" or "high".
std::string_view toString(BvhPreset p);
/// Parses "fast", "medium", "high"; throws InvalidArgument otherwise.
BvhPreset parseBvhPreset(std::string_view name);

/// Build parameters. Costs are relative units: the SAH estimates the cost of a ray through a node
/// as traversal_cost + intersection_cost * (expected number of leaf blocks tested), where a leaf of
/// n primitives costs ceil(n / leaf_block) block tests (the SIMD width of the leaf test).
struct BvhBuildConfig {
  /// Most bins per axis.
  static constexpr std::uint32_t kMaxBins = 256;
  /// Bins per axis of the binned SAH (2 to kMaxBins; nodes of fewer references use one per
  /// reference).
  std::uint32_t bins = 32;
  /// Cost of one wide-node step relative to one leaf-block test.
  float traversal_cost = 1.0f;
  /// Cost of one leaf-block test (a SIMD test of leaf_block primitives).
  float intersection_cost = 1.0f;
  /// Leaves hold at most this many primitives (1 to 16); a node of more is always split.
  std::uint32_t max_leaf_size = 8;
  /// Primitives per leaf block: the leaf test's SIMD width (4). Leaf ranges in prim_indices start
  /// at multiples of it and are padded to it, so that block k holds prim_indices[4k, 4k + 4).
  std::uint32_t leaf_block = 4;
  /// Spatial splits (the High preset, with a clip function): 0 disables them; otherwise a spatial
  /// split is tried in ranges of 64 or more references whose best object split leaves children
  /// overlapping by more than this fraction of the root's surface area (Stich et al.'s alpha), and
  /// taken where its SAH cost is lower.
  float spatial_split_alpha = 0.0f;
  /// Spatial splits may add at most this many references per input primitive (0.5: 50% more).
  float spatial_split_budget = 0.5f;
  /// Build subtrees as TBB tasks when they hold at least this many references (0: serial). The
  /// tree does not depend on it.
  std::uint32_t parallel_threshold = 4096;
  /// Refits (new positions, same triangles: MeshObject::deformed) keep the tree while its SAH cost
  /// stays at most this multiple of the cost it had when it was last built; beyond it the object
  /// is rebuilt. 1 rebuilds on any loss, a large value never rebuilds. The default keeps the trace
  /// time of smoothly deforming meshes within about ten percent of a fresh build (docs/design/bvh.md).
  float refit_limit = 1.15f;

  /// The parameters of a preset.
  static BvhBuildConfig preset(BvhPreset p);
  /// Parses a preset name optionally followed by overrides, comma separated:
  /// "medium", "fast,leaf=4", "high,alpha=1e-4,budget=0.3", "bins=16". Keys: bins, ct, ci, leaf,
  /// alpha, budget, parallel, refit. Throws InvalidArgument naming the bad part; the result is validated.
  static BvhBuildConfig parse(std::string_view text);
  /// Throws InvalidArgument naming the first parameter out of range.
  void validate() const;
  /// The text parse() reads back to an equal config (every parameter, preset-free).
  [[nodiscard]] std::string toString() const;
  /// Equal parameters, compared exactly.
  bool operator==(const BvhBuildConfig&) const = default;
};

/// Writes toString(), for logs and benchmark output.
std::ostream& operator<<(std::ostream& os, const BvhBuildConfig& c);

}  // namespace duplex
