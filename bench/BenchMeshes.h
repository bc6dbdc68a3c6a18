#pragma once
/// \file BenchMeshes.h
/// The benchmark's inputs: mesh specs ("koala.obj:2" = koala.obj refined by two steps of Loop
/// subdivision) resolved against the data folder, loaded once per process.

#include "duplex/objects/TriangleMesh.h"

#include <map>
#include <memory>
#include <string>
#include <utility>

namespace duplex::bench {

/// A parsed mesh spec.
struct MeshSpec {
  std::string file;    ///< as given (relative to the data folder's meshes/ unless it exists as is)
  int loop_steps = 0;  ///< uniform Loop subdivision steps applied after loading
  /// "koala.obj" or "koala.obj Loop x2".
  [[nodiscard]] std::string label() const;
  /// Parses "file" or "file:steps"; throws std::invalid_argument for a bad step count.
  static MeshSpec parse(const std::string& spec);
};

/// A loaded mesh and how long it took to make.
struct LoadedMesh {
  MeshSpec spec;
  std::string path;
  std::shared_ptr<const TriangleMesh> mesh;
  double load_ms = 0.0;       ///< reading the file
  double subdivide_ms = 0.0;  ///< Loop subdivision (cumulative over steps made in this process)
};

/// Loads meshes by spec and keeps them: "koala.obj:2" reuses "koala.obj:1" when that was loaded.
class MeshCache {
 public:
  explicit MeshCache(std::string data_dir) : data_dir_(std::move(data_dir)) {}
  /// Throws duplex::FileError when the file cannot be found or read.
  const LoadedMesh& get(const MeshSpec& spec);

 private:
  [[nodiscard]] std::string resolve(const std::string& file) const;
  std::string data_dir_;
  std::map<std::pair<std::string, int>, LoadedMesh> meshes_;
};

}  // namespace duplex::bench
