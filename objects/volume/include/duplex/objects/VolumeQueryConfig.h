#pragma once
/// \file VolumeQueryConfig.h
/// How a VolumeObject answers its queries: the fog transmittance method and its parameters, the
/// majorant level of delta and ratio tracking, and the level-set root search. One struct with
/// documented defaults (docs/design/volumes.md charts the accuracy and speed of every choice).

#include <cstdint>
#include <ostream>
#include <string_view>

namespace duplex {

/// Transmittance estimators of a fog volume. All of them see the same density field: each active
/// voxel a constant over the unit cube around its centre (index space), inactive voxels 0,
/// negative values clamped to 0.
enum class FogMethod : std::uint8_t {
  /// Exact integration of the piecewise-constant field: a hierarchical DDA over active nodes, then
  /// a voxel DDA summing density x length. Deterministic, no noise; cost grows with the voxels
  /// crossed.
  Exact,
  /// Ratio tracking (Cramer 1978; Novak et al. 2014), unbiased: tentative collisions drawn with the
  /// majorant of each VDB node the ray crosses, each multiplying the estimate by 1 - density /
  /// majorant. With `residual`, the node's minimum density is taken out analytically first
  /// (residual ratio tracking, Novak et al. 2014), so homogeneous nodes cost no collisions.
  RatioTracking,
  /// Delta tracking (Woodcock et al. 1965), unbiased: the estimate is 1 when a free flight drawn
  /// with node majorants escapes the segment, else 0 (averaged over `samples` flights).
  DeltaTracking,
  /// Fixed-step ray marching at `march_step` voxels (midpoint rule), biased (a comparison method,
  /// the classic renderer's default).
  RayMarching,
};

/// "exact", "ratio", "delta" or "march".
[[nodiscard]] std::string_view toString(FogMethod method);
/// Writes toString(method).
std::ostream& operator<<(std::ostream& os, FogMethod method);

/// Query options of a VolumeObject (validated by VolumeObject::withConfig and load).
struct VolumeQueryConfig {
  /// Method of VolumeObject::transmittance() (and so of TopLevel / SceneTracer transmittance and
  /// `duplex trace --transmittance`). Default Exact: it is deterministic (the same answer for a ray
  /// on any thread count, as the CLI's byte-identical outputs need), has no noise, and in the
  /// benchmark (docs/design/volumes.md) it is as fast as or faster than ratio tracking at equal error
  /// on voxel-resolution data.
  FogMethod transmittance = FogMethod::Exact;
  /// Stochastic methods: estimates averaged per query (>= 1).
  std::uint32_t samples = 1;
  /// RayMarching: step length in voxels (index-space units along the ray), > 0.
  double march_step = 0.5;
  /// Majorant source for delta and ratio tracking: 0 = each leaf node (8^3 voxels), 1 = each lower
  /// internal node (128^3), 2 = each upper internal node (4096^3). Finer levels mean tighter
  /// majorants (fewer null collisions) and more node steps; empty nodes are skipped at every level.
  int majorant_level = 0;
  /// RatioTracking: subtract each node's minimum density analytically (residual ratio tracking).
  bool residual = true;
  /// Mixed into every stochastic query's random stream. transmittance() seeds from a hash of the
  /// ray and this seed, so the same ray gets the same estimate on any thread.
  std::uint64_t seed = 0x5eed;

  /// Level sets: sampling step of the zero-crossing search, in voxels (> 0, <= 1). A crossing pair
  /// closer than the step can be missed (thin features).
  double levelset_step = 0.5;
  /// Level sets: bisection steps after a sign change is bracketed, then one secant step (0 to 60).
  int refine_steps = 14;
};

}  // namespace duplex
