#pragma once
/// \file InfoCommand.h
/// `duplex info`: load a scene (scene-json-v1 or duplex-scene-v1) and report what it holds (objects,
/// instances, triangles, mesh structures, timed edits, world bounds) and what loading it took,
/// without tracing anything.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace duplex::cli {

struct InfoOptions {
  /// scene-json-v1 or duplex-scene-v1 file (its timed edits are counted, not applied).
  std::filesystem::path scene;
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure);
  /// empty: each type's default.
  std::string structure;
  int threads = 0;  ///< loading and building; 0 means all hardware threads
};

/// Loads the scene and returns its report. Keys: format, objects (library objects), instances
/// (instance nodes, hidden ones included), visible_instances, triangles (in the object library),
/// instanced_triangles (summed over instances), mesh_structures (distinct mesh objects per
/// structure), edits (timed edits of a duplex-scene-v1 file), world_bounds ({"min": [x, y, z],
/// "max": [x, y, z]}, world space, scene units: the union of the visible instances' world boxes, rounded outward;
/// null without any), structures_loaded (prepared bottom levels read instead of built), threads,
/// load_ms, build_ms (bottom levels), graph_ms; times in wall-clock milliseconds. Throws
/// duplex::Error naming the file for bad input.
[[nodiscard]] nlohmann::ordered_json runInfo(const InfoOptions& options);

/// Adds `duplex info` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addInfoCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
