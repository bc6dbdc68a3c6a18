#pragma once
/// \file BenchUpdateCommand.h
/// `duplex bench update`: the update benchmark of the paper's table. Loads a scene (scene-json-v1
/// or duplex-scene-v1) and measures, for every two-level structure on the same seeded edit plan:
/// full build; update after moving M instances (median over --repeat commits); add and remove of
/// one instance; primary-ray Mrays/s right after the updates (and, for ours, after a fresh
/// top-level build: the slowdown the incremental commits left behind).
///
/// Structures: ours incremental (SceneGraph + SceneTracer, TopLevelUpdate::Incremental), ours with
/// a full top-level rebuild per commit (TopLevelUpdate::FullRebuild, the paper's method), and, when
/// the tool was built with Embree 3, Embree two-level scenes with the default top-level flags and
/// with dynamic + low quality. Each timed interval runs from the first edit call until queries see
/// the new scene (graph bookkeeping, notifications and the top-level update included).
///
/// The edit plan (so that other tracers can replay it), over the visible instances in
/// SceneDocument::instances order (for scene-json-v1: the "instances" order):
///   rng = std::mt19937_64(seed), u(rng) = (rng() >> 11) * 2^-53, side = 5% of the diagonal of the
///   union of their world boxes, delta() = ((u - 0.5) * side, (u - 0.5) * side, (u - 0.5) * side)
///   drawn x, y, z in that order.
///   R move steps: ids = 0..N-1; for j < M: k = j + rng() % (N - j), swap(ids[j], ids[k]); then
///     for each of ids[0..M) in that order, world translation += delta(). One commit per step.
///   R add/remove steps (after the moves): object = rng() % objects (library order), base =
///     rng() % N, world transform = base's current one with translation + delta(); add it under
///     the root (commit), remove it (commit).
/// A moved instance below transform nodes gets the local transform that gives it the moved world
/// transform (parents do not move).

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>

namespace duplex::cli {

struct BenchUpdateOptions {
  std::filesystem::path scene;
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure),
  /// also the build of the warm full-build rounds; empty: each type's default.
  std::string structure;
  /// Instances moved per commit: a count ("1") or a percentage of the instances ("1%", at least 1).
  std::string moves = "1";
  int repeat = 50;              ///< commits per measurement (medians reported)
  std::uint64_t seed = 1;       ///< seed of the edit plan
  int threads = 0;              ///< builds, commits and tracing; 0 means all hardware threads
  std::uint32_t primary = 512;  ///< primary rays of a W x W image (the camera of `duplex rays`)
  /// Rounds of full builds: each round one of ours (warm), one from the prepared library and one
  /// of Embree's (default flags), in alternating order; the dynamic / low quality Embree top level
  /// is built this many times after them.
  int build_repeat = 7;
  /// Commits per measurement of the baselines (full top-level rebuild, Embree): the first ones of
  /// the same plan. 0 means `repeat`. Lets ours run 1,000 commits (the trace after 1,000 commits)
  /// without 1,000 full rebuilds of each baseline.
  int baseline_repeat = 0;
};

/// Runs the benchmark and returns one JSON object. Keys: scene, objects, instances, triangles,
/// threads, seed, moves, moves_spec, repeat, move_cube_side, primary_rays, build_ms,
/// bottom_build_ms, top_build_ms, update_ms_median, update_ms_max, add_ms_median,
/// remove_ms_median, mrays_per_s, hits, top_level_full_rebuilds, top_level_subtree_rebuilds,
/// top_rebuild_ms_median, mrays_per_s_fresh, trace_slowdown_pct, full_rebuild_ms_median,
/// full_rebuild_add_ms_median, full_rebuild_remove_ms_median, full_rebuild_mrays_per_s,
/// baseline_repeat, trace_slowdown_paired_pct (incremental tree against one built from scratch,
/// alternated single-threaded runs, median CPU-time ratio), mrays_per_s_paired and
/// mrays_per_s_fresh_paired (those runs, one thread),
/// instance_visits_per_ray(_fresh), top_level_sah_cost(_fresh) (the incremental tree's SAH cost and
/// a fresh build's over the same instances), agreement_incremental_vs_fresh (same instance, triangle
/// and t);
/// with Embree the same figures prefixed "embree_" and "embree_dynamic_low_" plus
/// embree_*build*_ms, agreement_with_embree (fraction of primary rays with the same instance and
/// triangle as ours with full rebuilds, which replayed the same baseline plan) and
/// embree_update_over_ours; full builds: build_ms_warm_median, bottom_build_ms_warm_median,
/// prepared_build_ms_median, prepared_bottom_load_ms_median, prepared_library_bytes,
/// full_build_rounds, and with Embree full_build_ratio_median / _min / _max and
/// prepared_build_ratio_median / _min / _max (over the rounds, each round's ours / Embree's full
/// two-level build, timed side by side), embree_high_build_ms and
/// full_build_ratio_vs_embree_high_median / _min / _max (the same against Embree's object scenes of
/// high quality, with spatial splits, built in each round after its default build); machine. Times are wall-clock
/// milliseconds. Progress goes to stderr. Throws duplex::Error for bad input.
[[nodiscard]] nlohmann::ordered_json runBenchUpdate(const BenchUpdateOptions& options);

/// Adds the command line of the benchmark to `cmd` (the tool's `bench update`, or the whole command
/// line of duplex_bench_update), parsed into `options`.
void addBenchUpdateOptions(CLI::App& cmd, BenchUpdateOptions& options);

/// Adds `duplex bench update` to the tool's `bench` group with its options; when it is the command
/// given, its callback sets `chosen` to run it (tools/support/Command.h).
void addBenchUpdateCommand(CLI::App& bench, ChosenCommand& chosen);

}  // namespace duplex::cli
