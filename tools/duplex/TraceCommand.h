#pragma once
/// \file TraceCommand.h
/// `duplex trace`: load a scene (scene-json-v1 or duplex-scene-v1) into a SceneGraph, build both
/// levels (SceneTracer), trace a ray file with the tracer's batch queries, write a hit file, and
/// report the figures as one JSON object.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>

namespace duplex::cli {

struct TraceOptions {
  /// scene-json-v1 or duplex-scene-v1 file (read by loadSceneDocument; the latter's timed edits
  /// are not applied: the scene is traced as loaded).
  std::filesystem::path scene;
  std::filesystem::path rays;  ///< ray file (32-byte records)
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure);
  /// empty: each type's default.
  std::string structure;
  std::filesystem::path hits;  ///< hit file to write (20-byte records, one per ray, same order)
  /// Worker threads for loading, building and tracing; 0 means all hardware threads.
  int threads = 0;
  /// Occlusion instead of closest hit. A record is then {t=0, u=0, v=0, instance 0,
  /// prim 0xFFFFFFFF} when the ray is blocked and the miss record {t=+inf, 0, 0, 0xFFFFFFFF,
  /// 0xFFFFFFFF} when it is free.
  bool any_hit = false;
  /// Transmittance instead of hits (exact contract): when set, `hits` is not written (and may be
  /// empty) and this file gets one float32 per ray, the transmittance along [tnear, tfar] through
  /// all fog volumes, 0 where a surface blocks the ray (SceneTracer::transmittance).
  std::filesystem::path transmittance;
  /// Trace this many times (>= 1); the reported trace time is the median.
  int repeat = 1;
  /// Rays read, traced and written per block (>= 1): memory holds one block of rays and results
  /// (about 100 bytes per ray), whatever the file's size. Results do not depend on it.
  std::int64_t block_rays = std::int64_t{1} << 20;
  /// --single: trace one ray at a time instead of in packets (SceneTracer::setBatchPackets); the
  /// hits are the same bit for bit, only the speed differs (for comparisons).
  bool single = false;
};

/// Runs the command and returns the report. Contract keys: rays, hits (rays that hit, or are
/// blocked with any_hit), threads, load_ms (scene parse, mesh files, and adding the nodes to the
/// graph), build_ms (bottom levels, built or read from prepared structures, plus the top level),
/// trace_ms (median of the runs; a run's time is its tracing summed over the blocks, reading and
/// writing the files excluded), mrays_per_s. Extra keys: repeat, any_hit, objects, instances,
/// triangles (in the object library), instanced_triangles (summed over instances),
/// bottom_build_ms, top_build_ms, trace_ms_all, format, structures_loaded (prepared bottom levels
/// read instead of built), graph_ms (part of load_ms), block_rays (rays per block, at most the
/// ray count), packets (false with --single). Times are wall-clock milliseconds. The output file is written atomically:
/// it appears complete, or not at all when anything fails (a full disk included). With `transmittance`: hits counts the
/// blocked rays (transmittance 0), and the extra keys transmittance (true) and mean_transmittance are added.
///
/// A hit record's instance_id is the position of the instance in SceneDocument::instances: for
/// scene-json-v1 its position in "instances" (the contract); for duplex-scene-v1 its position in
/// depth-first file order of the node tree, hidden instances included (never hit, but counted).
/// Throws duplex::Error (naming the file) for bad input, and InvalidArgument when neither or both
/// of hits and transmittance are given, or transmittance with any_hit.
[[nodiscard]] nlohmann::ordered_json runTrace(const TraceOptions& options);

/// Adds `duplex trace` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addTraceCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
