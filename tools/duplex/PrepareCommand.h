#pragma once
/// \file PrepareCommand.h
/// `duplex prepare`: build the bottom-level structure of every mesh object of a scene once, save
/// them (saveStructures), and write a copy of the scene in duplex-scene-v1 whose mesh objects name
/// their "structure" files, so that loading the copy reads the structures instead of building them
/// (the paper's point: objects from a prepared library need no build).

#include "Command.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace duplex::cli {

struct PrepareOptions {
  std::filesystem::path scene;  ///< scene-json-v1 or duplex-scene-v1 file
  /// Output folder (created if needed): "<scene stem>.json" (duplex-scene-v1) and one
  /// "<object id>_<name>.dbvh" (or ".dkdt" for a kd-tree) per mesh object.
  std::filesystem::path out;
  int threads = 0;  ///< threads for the load and the builds; 0 means all hardware threads
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure);
  /// empty: each type's default.
  std::string structure;
};

/// Runs the command and returns {"scene": the written scene file, "format_in", "objects",
/// "mesh_objects", "structures" (files written), "load_ms", "build_ms", "save_ms", "threads",
/// "mesh_structures" (mesh objects per structure: {"bvh": n, "kdtree": m})}.
///
/// The copy keeps everything the source says, so that it loads into the same graph with the same
/// instance order (hence the same hit-file instance ids):
/// - scene-json-v1: objects become duplex-scene-v1 entries {"name", "mesh", "structure"} ("file"
///   or the inline arrays; other keys, ignored by v1, are dropped), instances become root
///   instance nodes named "instance<k>" (the names the v1 loader gives) with the same 12 numbers.
/// - duplex-scene-v1: the document is copied as is ("nodes", "edits"); mesh entries get
///   "structure" (replacing any).
/// Relative mesh file paths are rewritten relative to the output folder (absolute when no
/// relative path exists). Throws duplex::Error for bad input, an unwritable folder, or an output
/// file that would overwrite the source scene.
[[nodiscard]] nlohmann::ordered_json runPrepare(const PrepareOptions& options);

/// Adds `duplex prepare` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addPrepareCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
