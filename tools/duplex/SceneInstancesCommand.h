#pragma once
/// \file SceneInstancesCommand.h
/// `duplex scene instances`: N randomly rotated copies of one mesh on a grid (the paper-style
/// "1,000 instances of the hammer" scene), deterministic for a seed.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>

namespace duplex::cli {

struct SceneInstancesOptions {
  std::filesystem::path mesh;  ///< any format duplex::loadMesh reads (loaded for its bounds)
  std::uint64_t count = 1;     ///< N >= 1 instances
  std::uint64_t seed = 0;
  std::filesystem::path out;  ///< scene-json-v1 file to write
};

/// Writes one object (the mesh by path: relative to the output's folder when possible) and N
/// instances. Instance i sits in cell (i mod s, (i div s) mod s, i div s^2) of an s x s x s grid,
/// s = ceil(cbrt(N)), cells of side d = the diagonal of the mesh's bounds (so no two copies
/// overlap), cell (0,0,0) centred at the origin:
///   world_from_object = translate(d * cell) * rotate(q_i) * translate(-centre of the mesh bounds)
/// with q_i a unit quaternion uniform on SO(3) (Shoemake's method) from three numbers
/// u = (x >> 11) * 2^-53 of consecutive std::mt19937_64(seed) outputs x. Returns {"instances",
/// "grid", "cell", "mesh", "out"}. Throws duplex::Error for bad input.
[[nodiscard]] nlohmann::ordered_json runSceneInstances(const SceneInstancesOptions& options);

/// Adds `duplex scene instances` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addSceneInstancesCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
