#include "BenchMeshes.h"

#include "BenchCommon.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"

#include <filesystem>
#include <iostream>
#include <stdexcept>

namespace duplex::bench {

std::string MeshSpec::label() const { return loop_steps == 0 ? file : file + " Loop x" + std::to_string(loop_steps); }

MeshSpec MeshSpec::parse(const std::string& spec) {
  MeshSpec s;
  const auto colon = spec.rfind(':');
  if (colon == std::string::npos) {
    s.file = spec;
    return s;
  }
  s.file = spec.substr(0, colon);
  const std::string steps = spec.substr(colon + 1);
  std::size_t used = 0;
  const int n = std::stoi(steps, &used);
  if (used != steps.size() || n < 0 || n > 4)
    throw std::invalid_argument("mesh spec '" + spec + "': Loop steps must be an integer in [0, 4]");
  s.loop_steps = n;
  return s;
}

std::string MeshCache::resolve(const std::string& file) const {
  namespace fs = std::filesystem;
  for (const fs::path& candidate : {fs::path(file), fs::path(data_dir_) / "meshes" / file, fs::path(data_dir_) / file})
    if (fs::is_regular_file(candidate)) return candidate.string();
  throw FileError("mesh '" + file + "' not found as given, nor in " + data_dir_ + "/meshes (set --data)");
}

const LoadedMesh& MeshCache::get(const MeshSpec& spec) {
  const auto key = std::make_pair(spec.file, spec.loop_steps);
  if (auto it = meshes_.find(key); it != meshes_.end()) return it->second;
  LoadedMesh loaded;
  loaded.spec = spec;
  if (spec.loop_steps == 0) {
    loaded.path = resolve(spec.file);
    const Stopwatch clock;
    loaded.mesh = std::make_shared<const TriangleMesh>(loadMesh(loaded.path));
    loaded.load_ms = clock.ms();
  } else {
    // Refine the finest mesh of this file made so far, one step at a time.
    const LoadedMesh& coarser = get(MeshSpec{spec.file, spec.loop_steps - 1});
    loaded.path = coarser.path;
    loaded.load_ms = coarser.load_ms;
    std::cerr << "  Loop subdivision of " << coarser.spec.label() << " (" << coarser.mesh->triangleCount()
              << " triangles) ..." << std::flush;
    const Stopwatch clock;
    loaded.mesh = std::make_shared<const TriangleMesh>(loopSubdivide(*coarser.mesh, 1));
    loaded.subdivide_ms = coarser.subdivide_ms + clock.ms();
    std::cerr << " " << loaded.mesh->triangleCount() << " triangles, " << fmt(clock.ms() / 1e3, 1) << " s\n";
  }
  return meshes_.emplace(key, std::move(loaded)).first->second;
}

}  // namespace duplex::bench
