#pragma once
/// \file RaysCommand.h
/// `duplex rays`: write the contract's ray sets (primary camera rays or random rays) for a scene.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <optional>

namespace duplex::cli {

struct RaysOptions {
  /// scene-json-v1 or duplex-scene-v1 file; only its world bounds (the union of its visible
  /// instances' world boxes) are used
  std::filesystem::path scene;
  std::filesystem::path out;  ///< ray file to write
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure);
  /// empty: each type's default.
  std::string structure;
  /// Exactly one of the two sets: primary rays of a width x height image (duplex::primaryRays) or
  /// `random_count` random rays from `seed` (duplex::randomRays).
  std::optional<std::uint32_t> width, height;
  std::optional<std::uint64_t> random_count, seed;
};

/// Writes the ray file and returns {"rays": N, "out": PATH}. Throws duplex::Error for bad input
/// (including a scene without visible instances, which has no bounds to aim at).
[[nodiscard]] nlohmann::ordered_json runRays(const RaysOptions& options);

/// Adds `duplex rays` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addRaysCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
