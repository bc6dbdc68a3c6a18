// The non-template functions of MeshChecks.h, compiled once into the test support library rather than
// into every test file that includes the header.
#include "MeshChecks.h"

#include "BvhChecks.h"
#include "KdTreeChecks.h"

namespace duplex::test {

std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh, const KdBuildConfig& config) {
  auto object = std::make_shared<const MeshObject>(mesh, config);
  EXPECT_TRUE(checkMeshTree(*object, config.max_depth)) << "mesh '" << mesh->name() << "', " << config;
  return object;
}

std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const KdBuildConfig& config) {
  return buildChecked(std::make_shared<const TriangleMesh>(std::move(mesh)), config);
}

std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh, const BvhBuildConfig& config) {
  auto object = std::make_shared<const MeshObject>(mesh, config);
  EXPECT_TRUE(checkMeshBvh(*object, BvhCheckOptions::of(config))) << "mesh '" << mesh->name() << "', " << config;
  return object;
}

std::shared_ptr<const MeshObject> buildChecked(TriangleMesh mesh, const BvhBuildConfig& config) {
  return buildChecked(std::make_shared<const TriangleMesh>(std::move(mesh)), config);
}

std::shared_ptr<const MeshObject> buildChecked(std::shared_ptr<const TriangleMesh> mesh,
                                               const MeshBuildConfig& config) {
  if (config.structure == MeshStructure::Bvh) return buildChecked(std::move(mesh), config.bvh);
  return buildChecked(std::move(mesh), config.kd);
}

std::vector<StructureCase> structureCases() {
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

std::vector<StructureCase> bvhStructureCases() {
  std::vector<StructureCase> cases;
  for (const StructureCase& c : structureCases())
    if (c.config.structure == MeshStructure::Bvh) cases.push_back(c);
  return cases;
}

std::vector<StructureCase> defaultStructureCases() {
  std::vector<StructureCase> cases;
  for (const StructureCase& c : structureCases())
    if (c.name == "kdtree" || c.name == "bvh_medium") cases.push_back(c);
  return cases;
}

std::shared_ptr<const MeshObject> tinyMeshObject(const std::string& name) {
  return buildChecked(TriangleMesh::fromArrays(std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0},
                                               std::vector<std::uint32_t>{0, 1, 2}, name));
}

::testing::AssertionResult hitGeometryConsistent(const Hit& hit, const Ray& ray, const std::array<glm::vec3, 3>& v,
                                                 double scale) {
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

DiffStats expectAgreesWithReference(const MeshObject& object, const RefScene& ref, std::span<const Ray> rays,
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
