#pragma once
/// \file MeshChecks.h
/// Differential checks of MeshObject queries against the double-precision brute force.

#include "BvhChecks.h"
#include "KdTreeChecks.h"
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
inline std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh,
                                                      const KdBuildConfig& config = {}) {
  auto object = std::make_shared<const MeshObject>(mesh, config);
  EXPECT_TRUE(checkMeshTree(*object, config.max_depth)) << "mesh '" << mesh->name() << "', " << config;
  return object;
}

inline std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const KdBuildConfig& config = {}) {
  return buildChecked(std::make_shared<const TriangleMesh>(std::move(mesh)), config);
}

/// Builds a MeshObject with a BVH and checks it with the BVH invariant checker.
inline std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh,
                                                      const BvhBuildConfig& config) {
  auto object = std::make_shared<const MeshObject>(mesh, config);
  EXPECT_TRUE(checkMeshBvh(*object, BvhCheckOptions::of(config))) << "mesh '" << mesh->name() << "', " << config;
  return object;
}

inline std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const BvhBuildConfig& config) {
  return buildChecked(std::make_shared<const TriangleMesh>(std::move(mesh)), config);
}

/// Builds config.structure with its parameters, checked by that structure's checker.
inline std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh,
                                                      const MeshBuildConfig& config) {
  if (config.structure == MeshStructure::Bvh) return buildChecked(std::move(mesh), config.bvh);
  return buildChecked(std::move(mesh), config.kd);
}

/// A mesh structure with its build parameters, for tests parameterised over both structures.
struct StructureCase {
  std::string name;  ///< gtest name: "kdtree", "bvh_fast", ...
  MeshBuildConfig config;
};

/// Test names print the case's name.
inline void PrintTo(const StructureCase& c, std::ostream* os) { *os << c.name; }

/// The kd-tree (default parameters) and the BVH with each preset.
inline std::vector<StructureCase> structureCases() {
  std::vector<StructureCase> cases;
  MeshBuildConfig kd;
  kd.structure = MeshStructure::KdTree;
  cases.push_back({"kdtree", kd});
  for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium, BvhPreset::High}) {
    MeshBuildConfig c;
    c.structure = MeshStructure::Bvh;
    c.bvh = BvhBuildConfig::preset(p);
    cases.push_back({"bvh_" + std::string(toString(p)), c});
  }
  return cases;
}

/// The BVH with each preset (the cases about the BVH's own parameters and geometry).
inline std::vector<StructureCase> bvhStructureCases() {
  std::vector<StructureCase> cases;
  for (const StructureCase& c : structureCases())
    if (c.config.structure == MeshStructure::Bvh) cases.push_back(c);
  return cases;
}

/// The kd-tree and the default BVH (the suites too slow to run for every preset).
inline std::vector<StructureCase> defaultStructureCases() {
  std::vector<StructureCase> cases;
  for (const StructureCase& c : structureCases())
    if (c.name == "kdtree" || c.name == "bvh_medium") cases.push_back(c);
  return cases;
}

/// A one-triangle mesh object named `name` (cheap to build), its tree checked.
inline std::shared_ptr<const MeshObject> tinyMeshObject(const std::string& name) {
  return buildChecked(TriangleMesh::fromArrays(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0},
                                               std::vector<std::uint32_t>{0, 1, 2}, name));
}

/// The reported hit is self-consistent: t within [tnear, tfar], barycentrics inside the triangle,
/// the barycentric point equals origin + t * dir, and ng is the triangle's cross(v1 - v0, v2 - v0).
inline ::testing::AssertionResult hitGeometryConsistent(const Hit& hit, const Ray& ray,
                                                        const std::array<glm::vec3, 3>& v, double scale) {
  if (!(hit.t >= ray.tnear && hit.t <= ray.tfar))
    return ::testing::AssertionFailure() << ray << ": " << hit << " outside [tnear, tfar]";
  const double bary_eps = 1e-5;
  if (!(hit.u >= -bary_eps && hit.v >= -bary_eps && double(hit.u) + hit.v <= 1.0 + bary_eps))
    return ::testing::AssertionFailure() << ray << ": " << hit << " barycentrics outside the triangle";
  const glm::dvec3 pb = (1.0 - double(hit.u) - double(hit.v)) * glm::dvec3(v[0]) + double(hit.u) * glm::dvec3(v[1]) +
                        double(hit.v) * glm::dvec3(v[2]);
  const glm::dvec3 pr = glm::dvec3(ray.origin) + double(hit.t) * glm::dvec3(ray.dir);
  const double err = glm::length(pb - pr);
  const double allowed = 1e-5 * (scale + double(hit.t) * glm::length(glm::dvec3(ray.dir)));
  if (!(err <= allowed))
    return ::testing::AssertionFailure() << ray << ": " << hit << " barycentric point is " << err
                                         << " away from origin + t dir (allowed " << allowed << ")";
  const glm::dvec3 n = glm::cross(glm::dvec3(v[1]) - glm::dvec3(v[0]), glm::dvec3(v[2]) - glm::dvec3(v[0]));
  if (!(glm::length(glm::dvec3(hit.ng) - n) <= 1e-5 * glm::length(n)))
    return ::testing::AssertionFailure() << ray << ": ng (" << hit.ng.x << ", " << hit.ng.y << ", " << hit.ng.z
                                         << ") is not cross(v1 - v0, v2 - v0) = (" << n.x << ", " << n.y << ", " << n.z
                                         << ")";
  return ::testing::AssertionSuccess();
}

/// Counts of a differential run, so that callers can assert the rays were not all misses.
struct DiffStats {
  std::size_t rays = 0, hits = 0, failures = 0;
};

/// Every ray: MeshObject::intersect against the brute force (same primitive, or same t within
/// 1e-5 relative; misses agree), the hit's geometry, and MeshObject::occluded (both overloads)
/// against "the reference has a hit in [tnear, tfar]". Reports the first failures in full.
inline DiffStats expectAgreesWithReference(const MeshObject& object, const RefScene& ref, std::span<const Ray> rays,
                                           const std::string& label) {
  DiffStats s;
  const double scale = coordinateScale(object.bounds());
  HitTolerance tol;
  tol.abs_scale = 1e-6 * scale;
  QueryContext ctx;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    ++s.rays;
    Hit hit;
    const bool reported = object.intersect(ray, hit);
    Hit hit_ctx;
    const bool reported_ctx = static_cast<const Object&>(object).intersect(ray, hit_ctx, ctx);
    const bool occ = object.occluded(ray);
    const bool occ_ctx = static_cast<const Object&>(object).occluded(ray, ctx);
    auto fail = [&](const auto& what) {
      if (s.failures++ < 8) ADD_FAILURE() << label << ", ray " << i << ": " << what;
    };
    if (reported != hit.valid()) fail("intersect's return value disagrees with hit.valid()");
    if (reported_ctx != reported || hit_ctx.prim_id != hit.prim_id ||
        !(hit_ctx.t == hit.t || (!reported && !reported_ctx)))
      fail("the QueryContext overload of intersect gives another answer");
    const auto match = agreesWithReference(hit, ray, ref, tol, false);
    if (!match) fail(match.message());
    if (hit.valid()) {
      ++s.hits;
      if (hit.instance_id != kInvalidId) fail("a mesh hit must leave instance_id alone");
      if (hit.prim_id >= object.mesh().triangleCount() || !object.mesh().isValid(hit.prim_id)) {
        fail("hit on a degenerate or out-of-range primitive");
      } else {
        const auto geom = hitGeometryConsistent(hit, ray, object.mesh().vertices(hit.prim_id), scale);
        if (!geom) fail(geom.message());
      }
    }
    const auto occ_match = occlusionAgrees(occ, ray, ref, tol);
    if (!occ_match) fail(occ_match.message());
    if (occ_ctx != occ) fail("the QueryContext overload of occluded gives another answer");
  }
  EXPECT_EQ(s.failures, 0u) << label << ": " << s.failures << " of " << s.rays << " rays disagree with the reference";
  return s;
}

}  // namespace duplex::test
