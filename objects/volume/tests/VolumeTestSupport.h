#pragma once
// What the volume folder's test files share. They are compiled as one unit
// (objects/volume/CMakeLists.txt), so a helper both need lives here, once.

#include "TestSupport.h"

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <openvdb/io/File.h>

#include <filesystem>
#include <random>

namespace duplex::test {

/// A direction drawn uniformly on the unit sphere (normalised Gaussian), unitless.
inline glm::dvec3 randomUnit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return glm::normalize(draw3<glm::dvec3>(n, rng));
}

/// Writes `grids` to the .vdb file `file` (replacing it).
inline void writeGrids(const std::filesystem::path& file, const openvdb::GridPtrVec& grids) {
  openvdb::io::File out(file.string());
  out.write(grids);
  out.close();
}

}  // namespace duplex::test
