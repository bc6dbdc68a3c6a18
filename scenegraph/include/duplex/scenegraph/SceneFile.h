#pragma once
/// \file SceneFile.h
/// Reading scene files. scene-json-v1 (the interchange format shared with tools outside the
/// project) is implemented to the letter:
///
///   {"format": "scene-json-v1",
///    "objects": [{"name": N, "mesh": {"file": PATH}} |
///                {"name": N, "mesh": {"positions": [x0,y0,z0,...], "indices": [i0,i1,i2,...]}}],
///    "instances": [{"object": N, "transform": [r00,r01,r02,t0, r10,r11,r12,t1, r20,r21,r22,t2]}]}
///
/// The transform is row-major 3x4, object space to world; a relative PATH is relative to the JSON
/// file; the instance id is the position in "instances"; numbers are read as double; unknown keys
/// are ignored.

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/scenegraph/Scene.h"

#include <cstddef>
#include <filesystem>

namespace duplex {

struct SceneLoadOptions {
  KdBuildConfig build;  ///< bottom-level build parameters for meshes
};

/// Figures of a load, for tools that report them.
struct SceneLoadReport {
  double load_ms = 0.0;   ///< parsing and reading mesh files
  double build_ms = 0.0;  ///< bottom-level structures
  std::size_t triangles = 0;
  std::size_t degenerate_triangles = 0;
  std::size_t complex_edge_warnings = 0;
};

/// Reads a scene file. Errors throw FileError with the file name and the JSON path of the bad
/// value (e.g. "scene.json: /instances/3/transform/5: expected a number"). Mesh files named by
/// several objects are read and built once and shared.
[[nodiscard]] Scene loadScene(const std::filesystem::path& path, const SceneLoadOptions& options = {},
                              SceneLoadReport* report = nullptr);

}  // namespace duplex
