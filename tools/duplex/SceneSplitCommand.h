#pragma once
/// \file SceneSplitCommand.h
/// `duplex scene split`: cut one mesh into K objects by a deterministic rule (the paper's
/// scenes: koala in 19, 6,804 and 20,968 objects; docs/cli.md), written as scene-json-v1
/// with inline arrays and one identity instance per object.

#include "Command.h"

#include <duplex/objects/TriangleMesh.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <vector>

namespace duplex::cli {

struct SceneSplitOptions {
  std::filesystem::path mesh;  ///< any format duplex::loadMesh reads
  std::uint32_t objects = 1;   ///< K >= 1, at most the triangle count (after subdivision)
  int loop = 0;                ///< Loop subdivision steps applied before splitting
  std::filesystem::path out;   ///< scene-json-v1 file to write
};

/// The split rule, on triangle ids 0..n-1 of `mesh`; returns K lists of triangle ids, depth-first
/// left to right, each in increasing id order:
///   split(tris, k): if k == 1, emit tris; else kl = k / 2; axis = longest axis of the box of the
///   triangles' centroids (ties: x before y before z); order tris by (centroid on axis, id); the
///   first (2 n kl + k) div 2k go left with kl, the rest right with k - kl.
/// Centroids are (a + b + c) / 3 in double, summed in vertex order. Every triangle counts,
/// degenerate ones included. Throws InvalidArgument when K is 0 or exceeds the triangle count, or
/// a centroid is not finite.
[[nodiscard]] std::vector<std::vector<std::uint32_t>> splitTriangles(const TriangleMesh& mesh, std::uint32_t objects);

/// Runs the command. Objects are named part0 .. part<K-1>; inside an object vertices are
/// re-indexed in order of first use. Returns {"objects", "triangles", "degenerate_triangles",
/// "min_triangles", "max_triangles", "objects_without_valid_triangle", "out"}. An object made only
/// of degenerate triangles is written anyway (the rule counts them) but a scene-json-v1 reader
/// refuses it; it is counted and warned about on stderr. Throws duplex::Error for bad input.
[[nodiscard]] nlohmann::ordered_json runSceneSplit(const SceneSplitOptions& options);

/// Adds `duplex scene split` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addSceneSplitCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
