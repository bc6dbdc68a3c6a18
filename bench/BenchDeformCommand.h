#pragma once
/// \file BenchDeformCommand.h
/// `duplex bench deform`: a mesh object of a scene deforms step by step (every vertex moved by a
/// smooth random field), committed through SceneGraph::deformObject as an application would; per
/// step the refit (or the quality guard's rebuild) is timed against a fresh build of the same
/// positions, and after the last step primary rays through the scene compare the refitted tree
/// with a fresh one.
///
/// The deformation (so that other tools can replay it): rng = std::mt19937_64(seed), u(rng) =
/// (rng() >> 11) * 2^-53, d = the length of the diagonal of the object's bounds at rest (object
/// space), c = their centre. Step k = 1..K draws, for each axis a = x, y, z in turn, a direction
/// w_a = normalize(g, g, g) (g = u - 0.5 each) and a phase phi_a = 2 pi u, then moves every vertex p
/// (its position after step k-1) by amplitude * d * sin(4 pi / d * dot(p - c, w_a) + phi_a) along
/// axis a: a random wave of wavelength d / 2 per axis, the steps adding up.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>

namespace duplex::cli {

struct BenchDeformOptions {
  std::filesystem::path scene;
  std::string structure;        ///< --structure for the scene's entries that choose none
  std::string object;           ///< the library object (scene-file object name) that deforms
  int steps = 100;              ///< deformation steps, one commit each
  std::uint64_t seed = 1;       ///< seed of the deformation
  double amplitude = 0.002;     ///< per-step displacement, as a fraction of the object's diagonal
  int threads = 0;              ///< 0 means all hardware threads
  std::uint32_t primary = 512;  ///< primary rays of a W x W image (the camera of `duplex rays`)
  int trace_rounds = 5;         ///< paired trace rounds (refitted, fresh) after the last step
};

/// Runs the benchmark and returns one JSON object. Keys: scene, object, triangles, vertices,
/// instances (visible instances of the object), structure (its bottom-level structure), config
/// (the build parameters refits and rebuilds use), refit_limit, steps, seed, amplitude, threads,
/// refit_ms_median (SceneGraph::deformObject of the steps that refitted: new mesh, refit, leaf
/// blocks), refit_ms_max, rebuild_ms_median (a fresh MeshObject of the same positions, each step),
/// refit_speedup (rebuild_ms_median / refit_ms_median), guard_rebuild_ms_median (deformObject of
/// the steps the quality guard rebuilt; null without any), commit_ms_median (the commit after each
/// step: the top level updating the instances), rebuilds (steps the guard rebuilt; every step for
/// a kd-tree), sah_cost_refitted, sah_cost_fresh (after the last step), primary_rays,
/// mrays_per_s_refitted, mrays_per_s_fresh, trace_slowdown_after_refits (median over the paired
/// rounds of time refitted / time fresh - 1: 0.05 means 5% slower), agreement_refit_vs_fresh
/// (fraction of primary rays with the same hit: instance, triangle and t), machine. Times are
/// wall-clock milliseconds. Progress goes to stderr. Throws duplex::Error for bad input (unknown
/// object, an object that is not a mesh or has no visible instance).
[[nodiscard]] nlohmann::ordered_json runBenchDeform(const BenchDeformOptions& options);

/// Adds the command line of the benchmark to `cmd` (the tool's `bench deform`).
void addBenchDeformOptions(CLI::App& cmd, BenchDeformOptions& options);

/// Adds `duplex bench deform` to the tool's `bench` group with its options; when it is the command
/// given, its callback sets `chosen` to run it (tools/support/Command.h).
void addBenchDeformCommand(CLI::App& bench, ChosenCommand& chosen);

}  // namespace duplex::cli
