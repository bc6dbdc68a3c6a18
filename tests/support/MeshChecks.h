#pragma once
/// \file MeshChecks.h
/// Differential checks of MeshObject queries against the double-precision brute force.

#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/BvhBuildConfig.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace duplex::test {

/// Builds a MeshObject and checks its tree with the invariant checker (every tree built in the
/// tests goes through here or calls a check* function directly).
std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh,
                                               const KdBuildConfig& config = {});

std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const KdBuildConfig& config = {});

/// Builds a MeshObject with a BVH and checks it with the BVH invariant checker.
std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh, const BvhBuildConfig& config);

std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const BvhBuildConfig& config);

/// Builds config.structure with its parameters, checked by that structure's checker.
std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh, const MeshBuildConfig& config);

/// A mesh structure with its build parameters, for tests parameterised over both structures.
struct StructureCase {
  std::string name;  ///< gtest name: "kdtree", "bvh_fast", ...
  MeshBuildConfig config;
};

/// Test names print the case's name.
inline void PrintTo(const StructureCase& c, std::ostream* os) { *os << c.name; }

/// The kd-tree (default parameters) and the BVH with each preset.
std::vector<StructureCase> structureCases();

/// The BVH with each preset (the cases about the BVH's own parameters and geometry).
std::vector<StructureCase> bvhStructureCases();

/// The kd-tree and the default BVH (the suites too slow to run for every preset).
std::vector<StructureCase> defaultStructureCases();

/// A one-triangle mesh object named `name` (cheap to build), its tree checked.
std::shared_ptr<const MeshObject> tinyMeshObject(const std::string& name);

/// The reported hit is self-consistent: t within [tnear, tfar], barycentrics inside the triangle,
/// the barycentric point equals origin + t * dir, and ng is the triangle's cross(v1 - v0, v2 - v0).
::testing::AssertionResult hitGeometryConsistent(const Hit& hit, const Ray& ray, const std::array<glm::vec3, 3>& v,
                                                 double scale);

/// Counts of a differential run, so that callers can assert the rays were not all misses.
struct DiffStats {
  std::size_t rays = 0, hits = 0, failures = 0;
};

/// Every ray: MeshObject::intersect against the brute force (same primitive, or same t within
/// 1e-5 relative; misses agree), the hit's geometry, and MeshObject::occluded (both overloads)
/// against "the reference has a hit in [tnear, tfar]". Reports the first failures in full.
DiffStats expectAgreesWithReference(const MeshObject& object, const RefScene& ref, std::span<const Ray> rays,
                                    const std::string& label);

}  // namespace duplex::test
