#pragma once
/// \file ClosestCommand.h
/// `duplex closest`: load a scene, build both levels, answer a point file with the nearest surface
/// point of each record (SceneTracer::closestPoints), write a closest file, report the figures as
/// one JSON object.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace duplex::cli {

struct ClosestOptions {
  std::filesystem::path scene;   ///< scene-json-v1 or duplex-scene-v1 (timed edits are not applied)
  std::filesystem::path points;  ///< point file (16-byte records, RayFile.h)
  std::filesystem::path out;     ///< closest file to write (24-byte records, one per point, same order)
  std::string structure;         ///< --structure for the entries that choose none
  int threads = 0;               ///< loading, building and queries; 0 means all hardware threads
};

/// Runs the command and returns the report. Contract keys: points, found (records with a point
/// within their max_distance), threads, load_ms, build_ms (bottom levels plus the top level),
/// query_ms. Extra keys: objects, instances, format. A record's instance_id is the instance's
/// position in SceneDocument::instances, as in `duplex trace`'s hit files; a point with a
/// non-finite coordinate, or a NaN or negative max_distance, finds nothing. Volumes and sensors
/// are ignored (they have no closest-point query). Times are wall-clock milliseconds. Throws
/// duplex::Error naming the file for bad input.
[[nodiscard]] nlohmann::ordered_json runClosest(const ClosestOptions& options);

/// Adds `duplex closest` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addClosestCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
