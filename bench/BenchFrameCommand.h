#pragma once
/// \file BenchFrameCommand.h
/// `duplex bench frame`: interactive use replayed on a scene. Each frame moves k instances, commits,
/// and traces one camera frame: W x H primary rays (closest hit) and one shadow ray (any hit) from
/// each primary hit to a point light. The frame time runs from the first edit call to the last
/// shadow ray's answer; it is reported split into edit + commit and trace (primary rays, shadow-ray
/// set-up, shadow rays).
///
/// Sides, each replaying the same frames from the same initial transforms, one frame of each side
/// in turn (the order rotating every frame, so that no side always finds the caches as another
/// left them):
/// - ours: SceneGraph::setTransform per moved instance, SceneGraph::commit (the SceneTracer's
///   incremental top-level update), SceneTracer::intersect and SceneTracer::occluded on the whole
///   ray arrays (the batch queries, packets of consecutive rays: the way the library's users trace a
///   frame);
/// - with Embree 3 (the benchmark duplex_bench_frame; the installed tool has no Embree): its
///   two-level scene (one scene per object, one instance geometry per instance) with the top level
///   built with the default flags and with dynamic + low quality, each traced with rtcIntersect1 /
///   rtcOccluded1 and with rtcIntersect16 (coherent context flag) / rtcOccluded16: four sides,
///   the fastest of which (median frame time) is Embree's figure in the ratios.
///
/// The camera is that of `duplex rays --primary W H` (PinholeCamera::looking_at_box of the visible
/// instances' world bounds at load), fixed for all frames; the same W x H pixels, handed over in tiles
/// of 4 x 4 pixels (row-major tiles, row-major pixels inside a tile), the order a renderer uses.
/// The light: bounds centre + (0.3 x, 1.5 y, 0.9 z) of the bounds' extent. A shadow ray starts at
/// origin + t * dir of its primary ray's hit, direction light - start, t in [1e-4, 1 - 1e-4]; shadow
/// rays are in the order of their pixels.
///
/// The frames (so that other tracers can replay them), over the visible instances in
/// SceneDocument::instances order: rng = std::mt19937_64(seed), u(rng) = (rng() >> 11) * 2^-53,
/// side = 5% of the diagonal of the bounds above, delta() = ((u - 0.5) * side, (u - 0.5) * side,
/// (u - 0.5) * side) drawn x, y, z in that order. Frame f (each thread count and each k replays
/// frames 0..N-1 from the initial transforms): ids = 0..n-1; for j < k: swap(ids[j], ids[j + rng() %
/// (n - j)]); then for each of ids[0..k) in that order, world translation += delta(). An instance
/// below transform nodes gets the local transform that gives it the moved world transform.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace duplex::cli {

struct BenchFrameOptions {
  std::filesystem::path scene;
  /// --structure: the structure choice of the entries that choose none; empty: each type's default.
  std::string structure;
  /// Instances moved per frame, one run each: counts ("1"; "0": frames without edits) or
  /// percentages of the instances ("1%", at least 1).
  std::vector<std::string> moves{"1", "1%", "10%"};
  std::vector<int> threads{1, 2};  ///< one run per thread count (per k)
  int frames = 20;                 ///< frames per run (medians reported)
  std::uint32_t width = 1024;      ///< image width in pixels
  std::uint32_t height = 768;      ///< image height in pixels
  std::uint64_t seed = 1;          ///< seed of the moves
  /// Largest difference of a frame's hit counts (primary hits, blocked shadow rays) between ours and
  /// an Embree side, as a fraction of the primary rays, for hits_agree: transforms and hit distances
  /// are rounded differently.
  double hit_tolerance = 1e-4;
  /// Embree sides (duplex_bench_frame only): top-level builds ("default", "dynamic_low") and queries
  /// ("1": rtcIntersect1 / rtcOccluded1, "16": rtcIntersect16 / rtcOccluded16).
  std::vector<std::string> embree_top{"default", "dynamic_low"};
  std::vector<std::string> embree_queries{"1", "16"};
};

/// Runs the benchmark and returns one JSON object. Keys: scene, format, objects, instances,
/// triangles, width, height, primary_rays, frames, seed, move_cube_side, light, hit_tolerance,
/// sides (their names), runs (one per thread count and k: threads, moves_spec, moves; per side an
/// object named after it (ours, embree_default_1, embree_default_16, embree_dynamic_low_1,
/// embree_dynamic_low_16) with frame_ms_median, edit_commit_ms_median, trace_ms_median,
/// primary_ms_median, shadow_ms_median, frame_ms_min, frame_ms_max, and per frame frame_ms,
/// edit_commit_ms, trace_ms, primary_hits, shadow_rays, shadow_blocked; static_primary_hits and
/// static_shadow_blocked (the untimed frame before any move); with Embree: embree_best (the side
/// with the lowest frame_ms_median), embree_frame_ms_median, embree_edit_commit_ms_median,
/// embree_trace_ms_median (that side's), ratio_frame, ratio_edit_commit, ratio_trace (ours /
/// embree_best), ratio_frame_per_side, hits_max_diff and shadow_max_diff (largest per-frame
/// difference from ours over the Embree sides, in rays), hits_agree); machine. Times are wall-clock
/// milliseconds. Progress goes to stderr. Throws duplex::Error for bad input.
[[nodiscard]] nlohmann::ordered_json runBenchFrame(const BenchFrameOptions& options);

/// Adds the command line of the benchmark to `cmd` (the tool's `bench frame`, or the whole command
/// line of duplex_bench_frame), parsed into `options`.
void addBenchFrameOptions(CLI::App& cmd, BenchFrameOptions& options);

/// Adds `duplex bench frame` to the tool's `bench` group with its options; when it is the command
/// given, its callback sets `chosen` to run it (tools/support/Command.h).
void addBenchFrameCommand(CLI::App& bench, ChosenCommand& chosen);

}  // namespace duplex::cli
