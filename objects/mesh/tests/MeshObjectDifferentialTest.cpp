// Differential tests of MeshObject (kd-tree + watertight triangle test) against a double-precision
// brute force over all triangles: random rays (origins inside and around the mesh) and the primary
// camera rays of `duplex rays --primary`, over generated meshes (sphere, flat grid, triangle soup)
// and the shared real meshes when present; every kd-tree heuristic with and without clipping.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace duplex::test {
namespace {

/// Random rays from inside the bounds, random rays from a box three times as large (many start
/// outside and miss), and primary rays.
std::vector<Ray> mixedRays(const Box& bounds, std::size_t random_count, std::uint32_t primary_side,
                           std::uint64_t seed) {
  std::vector<Ray> rays = randomRays(bounds, random_count, seed);
  const std::vector<Ray> outer = randomRays(enlarged(bounds, 1.0f), random_count / 2, seed + 1);
  rays.insert(rays.end(), outer.begin(), outer.end());
  const std::vector<Ray> primary = primaryRays(bounds, primary_side, primary_side);
  rays.insert(rays.end(), primary.begin(), primary.end());
  return rays;
}

void runDifferential(std::shared_ptr<const TriangleMesh> mesh, std::size_t random_count, std::uint32_t primary_side,
                     const KdBuildConfig& config = {}) {
  const auto object = buildChecked(mesh, config);
  const RefScene ref(refTriangles(*mesh));
  const auto rays = mixedRays(mesh->bounds(), random_count, primary_side, 1234);
  const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name());
  // Not vacuous: a fair share of the rays hits, and some miss.
  EXPECT_GT(s.hits, s.rays / 10) << mesh->name();
  EXPECT_LT(s.hits, s.rays) << mesh->name();
}

TEST(MeshObjectDifferential, Icosphere) {
  runDifferential(std::make_shared<const TriangleMesh>(icosphere(4)), 3000, 48);
}

TEST(MeshObjectDifferential, UvSphere) {
  runDifferential(std::make_shared<const TriangleMesh>(uvSphere(48, 24)), 2000, 40);
}

TEST(MeshObjectDifferential, FlatAxisAlignedGrid) {
  for (int axis = 0; axis < 3; ++axis) {
    SCOPED_TRACE(::testing::Message() << "grid normal axis " << axis);
    // The grid's bounds are flat: random origins would all lie in its plane, so use a cube around it.
    auto mesh = std::make_shared<const TriangleMesh>(flatGrid(48, axis, 0.25f, 0.125f));
    const auto object = buildChecked(mesh);
    const RefScene ref(refTriangles(*mesh));
    Box around = mesh->bounds();
    around.lo[axis] = -3.0f;
    around.hi[axis] = 3.5f;
    auto rays = mixedRays(around, 2000, 40, 77 + axis);
    const auto s = expectAgreesWithReference(*object, ref, rays, "flat grid");
    EXPECT_GT(s.hits, s.rays / 10);
  }
}

TEST(MeshObjectDifferential, TriangleSoup) {
  runDifferential(std::make_shared<const TriangleMesh>(triangleSoup(3000, 99)), 3000, 40);
}

TEST(MeshObjectDifferential, BoxFarFromOrigin) {
  // A closed box 10^5 units away: float spacing there is 1/128.
  auto mesh = std::make_shared<const TriangleMesh>(
      boxMesh(glm::vec3(100000.0f, 100010.0f, -100020.0f), glm::vec3(100003.5f, 100012.25f, -100017.0f)));
  runDifferential(mesh, 2000, 32);
}

// The real meshes of the shared data folder (skipped, each with its own message, when it is absent).
struct SharedMeshCase {
  const char* name;  ///< gtest name
  const char* file;  ///< relative to the shared meshes folder
  int rays;
  int grid;
};

class MeshObjectDifferentialShared : public ::testing::TestWithParam<SharedMeshCase> {};

TEST_P(MeshObjectDifferentialShared, AgreesWithTheReference) {
  const SharedMeshCase& c = GetParam();
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, c.file);
  runDifferential(mesh, c.rays, c.grid);
}

INSTANTIATE_TEST_SUITE_P(SharedMeshes, MeshObjectDifferentialShared,
                         ::testing::Values(SharedMeshCase{"Spot", "spot.obj", 3000, 48},
                                           SharedMeshCase{"Koala", "koala.obj", 1000, 32},
                                           SharedMeshCase{"Hammer", "hammer.obj", 1000, 32},
                                           SharedMeshCase{"Plane", "plane.obj", 1500, 32},
                                           SharedMeshCase{"CornellBoxQuads", "cornell_box.obj", 2000, 40},
                                           // non-manifold CAD part
                                           SharedMeshCase{"RobotPartNonManifold", "abb_irb6640/link_4.stl", 1500, 32}),
                         [](const auto& info) { return std::string(info.param.name); });

// ---------------------------------------------------------------------------------------------
// Every heuristic, with and without clipping, plus the knobs that change the tree's shape.

class MeshObjectConfigs : public ::testing::TestWithParam<ConfigCase> {};

TEST_P(MeshObjectConfigs, AgreeWithReference) {
  const KdBuildConfig& config = GetParam().config;
  std::vector<std::shared_ptr<const TriangleMesh>> meshes = {
      std::make_shared<const TriangleMesh>(icosphere(3)),
      std::make_shared<const TriangleMesh>(flatGrid(24, 2, 0.5f, 0.25f)),
      std::make_shared<const TriangleMesh>(triangleSoup(1500, 7)),
  };
  if (auto spot = sharedMeshCached("spot.obj")) meshes.push_back(spot);
  for (const auto& mesh : meshes) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, config);
    const RefScene ref(refTriangles(*mesh));
    Box around = mesh->bounds();
    for (int k = 0; k < 3; ++k)
      if (around.extent()[k] == 0.0f) {
        around.lo[k] -= 1.0f;
        around.hi[k] += 1.0f;
      }
    const auto rays = mixedRays(around, 800, 24, 555);
    const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " / " + GetParam().name);
    EXPECT_GT(s.hits, s.rays / 10);
  }
}

INSTANTIATE_TEST_SUITE_P(AllHeuristics, MeshObjectConfigs, ::testing::ValuesIn(allConfigCases()),
                         [](const auto& info) { return info.param.name; });

// A serial and a TBB-parallel build give the identical tree (the parallel build appends subtrees
// in depth-first order).
TEST(MeshObjectBuild, ParallelBuildEqualsSerialBuild) {
  auto mesh = std::make_shared<const TriangleMesh>(triangleSoup(6000, 4242));
  KdBuildConfig serial, parallel;
  serial.parallel_threshold = 0;
  parallel.parallel_threshold = 32;
  const auto a = buildChecked(mesh, serial);
  const auto b = buildChecked(mesh, parallel);
  ASSERT_EQ(a->tree().nodes.size(), b->tree().nodes.size());
  for (std::size_t i = 0; i < a->tree().nodes.size(); ++i) {
    const KdNode& x = a->tree().nodes[i];
    const KdNode& y = b->tree().nodes[i];
    ASSERT_EQ(x.isLeaf(), y.isLeaf()) << "node " << i;
    if (x.isLeaf()) {
      ASSERT_EQ(x.primOffset(), y.primOffset()) << "node " << i;
      ASSERT_EQ(x.primCount(), y.primCount()) << "node " << i;
    } else {
      ASSERT_EQ(x.axis(), y.axis()) << "node " << i;
      ASSERT_EQ(x.split(), y.split()) << "node " << i;
      ASSERT_EQ(x.upperChild(), y.upperChild()) << "node " << i;
    }
  }
  EXPECT_EQ(a->tree().prim_indices, b->tree().prim_indices);
}

// The SAH tree is no worse than the simple heuristics by its own cost model (a regression guard
// on the split search that does not depend on timing).
TEST(MeshObjectBuild, SahCostNotAboveSimpleHeuristics) {
  auto mesh = std::make_shared<const TriangleMesh>(triangleSoup(4000, 11));
  KdBuildConfig sah, median, middle;
  median.heuristic = KdHeuristic::Median;
  middle.heuristic = KdHeuristic::SpatialMiddle;
  const double c_sah = buildChecked(mesh, sah)->tree().stats(sah.traversal_cost, sah.intersection_cost).sah_cost;
  const double c_median = buildChecked(mesh, median)->tree().stats(sah.traversal_cost, sah.intersection_cost).sah_cost;
  const double c_middle = buildChecked(mesh, middle)->tree().stats(sah.traversal_cost, sah.intersection_cost).sah_cost;
  EXPECT_LE(c_sah, c_median);
  EXPECT_LE(c_sah, c_middle);
  // Against a single leaf (cost = Ci * N) the SAH tree must be far cheaper.
  EXPECT_LT(c_sah, 0.25 * sah.intersection_cost * 4000);
}

}  // namespace
}  // namespace duplex::test
