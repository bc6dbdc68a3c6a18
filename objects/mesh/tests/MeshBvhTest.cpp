// The mesh BVH against a double-precision brute force: random and primary rays over generated
// meshes, for each build preset; run once per SIMD path (ctest's ISA variants).

#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace duplex::test {
namespace {

std::vector<Ray> mixedRays(const Box& bounds, std::size_t random_count, std::uint32_t primary_side,
                           std::uint64_t seed) {
  std::vector<Ray> rays = randomRays(bounds, random_count, seed);
  const std::vector<Ray> outer = randomRays(enlarged(bounds, 1.0f), random_count / 2, seed + 1);
  rays.insert(rays.end(), outer.begin(), outer.end());
  const std::vector<Ray> primary = primaryRays(bounds, primary_side, primary_side);
  rays.insert(rays.end(), primary.begin(), primary.end());
  return rays;
}

void runBvhDifferential(const TriangleMesh& source, std::size_t random_count, std::uint32_t primary_side) {
  auto mesh = std::make_shared<const TriangleMesh>(source);
  const RefScene ref(refTriangles(*mesh));
  const auto rays = mixedRays(mesh->bounds(), random_count, primary_side, 4321);
  for (const BvhPreset preset : {BvhPreset::Fast, BvhPreset::Medium, BvhPreset::High}) {
    SCOPED_TRACE(std::string("preset ") + std::string(toString(preset)));
    const MeshObject object(mesh, BvhBuildConfig::preset(preset));
    ASSERT_EQ(object.structure(), MeshStructure::Bvh);
    const auto s = expectAgreesWithReference(object, ref, rays, mesh->name());
    EXPECT_GT(s.hits, s.rays / 10) << mesh->name();
    EXPECT_LT(s.hits, s.rays) << mesh->name();
  }
}

TEST(MeshBvh, Icosphere) { runBvhDifferential(icosphere(4), 3000, 48); }
TEST(MeshBvh, TriangleSoup) { runBvhDifferential(triangleSoup(3000, 99), 3000, 40); }
TEST(MeshBvh, BoxFarFromOrigin) {
  runBvhDifferential(boxMesh(glm::vec3(100000.0f, 100010.0f, -100020.0f), glm::vec3(100003.5f, 100012.25f, -100017.0f)),
                     2000, 32);
}

}  // namespace
}  // namespace duplex::test
