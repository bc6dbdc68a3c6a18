#pragma once
// What the volume folder's test files share. They are compiled as one unit
// (objects/volume/CMakeLists.txt), so a helper both need lives here, once.

#include "TestSupport.h"

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <filesystem>
#include <random>
#include <string>

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

/// An empty grid named `name` of the OpenVDB grid type `grid_type` ("Tree_vec3s_5_4_3", ...), made by
/// OpenVDB's own registry. The tests that need grids of other value types than float only to see
/// them refused make them this way: each grid class instantiated here would cost about as much
/// compile time as the rest of this unit.
inline openvdb::GridBase::Ptr registeredGrid(const std::string& grid_type, const std::string& name) {
  openvdb::initialize();
  openvdb::GridBase::Ptr grid = openvdb::GridBase::createGrid(grid_type);
  grid->setName(name);
  return grid;
}

}  // namespace duplex::test
