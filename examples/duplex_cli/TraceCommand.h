#pragma once
/// \file TraceCommand.h
/// `duplex trace`: load a scene-json-v1 file, build both levels, trace a ray file, write a hit
/// file, and report the figures as one JSON object.

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>

namespace duplex::cli {

struct TraceOptions {
  std::filesystem::path scene;  ///< scene-json-v1 file
  std::filesystem::path rays;   ///< ray file (32-byte records)
  std::filesystem::path hits;   ///< hit file to write (20-byte records, one per ray, same order)
  /// Worker threads for loading, building and tracing; 0 means all hardware threads.
  int threads = 0;
  /// Occlusion instead of closest hit. A record is then {t=0, u=0, v=0, instance 0,
  /// prim 0xFFFFFFFF} when the ray is blocked and the miss record {t=+inf, 0, 0, 0xFFFFFFFF,
  /// 0xFFFFFFFF} when it is free.
  bool any_hit = false;
  /// Trace this many times (>= 1); the reported trace time is the median.
  int repeat = 1;
};

/// Runs the command and returns the report. Contract keys: rays, hits (rays that hit, or are
/// blocked with any_hit), threads, load_ms (scene parse and mesh files), build_ms (bottom levels
/// plus top level), trace_ms (median of the runs), mrays_per_s. Extra keys: repeat, any_hit,
/// objects, instances, triangles (in the object library), instanced_triangles (summed over
/// instances), bottom_build_ms, top_build_ms, trace_ms_all. Times are wall-clock milliseconds.
/// Throws duplex::Error (naming the file) for bad input.
[[nodiscard]] nlohmann::ordered_json runTrace(const TraceOptions& options);

}  // namespace duplex::cli
