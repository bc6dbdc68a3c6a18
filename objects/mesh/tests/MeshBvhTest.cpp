// Both mesh structures (the BVH with each preset, and the kd-tree) against the double-precision
// brute force: random and primary rays over generated meshes, the mesh fixtures and the shared
// meshes (skipped with a message when absent). Run once per SIMD path (ctest's ISA variants), so
// that each BVH kernel is compared with the reference; every structure goes through its checker.

#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <tuple>
#include <vector>

namespace duplex::test {
namespace {

/// Random rays from inside the box, from a box three times as large, and primary rays.
std::vector<Ray> mixedRays(const Box& bounds, std::size_t random_count, std::uint32_t primary_side,
                           std::uint64_t seed) {
  std::vector<Ray> rays = randomRays(bounds, random_count, seed);
  const std::vector<Ray> outer = randomRays(enlarged(bounds, 1.0f), random_count / 2, seed + 1);
  rays.insert(rays.end(), outer.begin(), outer.end());
  const std::vector<Ray> primary = primaryRays(bounds, primary_side, primary_side);
  rays.insert(rays.end(), primary.begin(), primary.end());
  return rays;
}

/// The mesh's bounds with positive extent on every axis (flat meshes get a unit margin).
Box aroundMesh(const TriangleMesh& m) {
  Box b = m.bounds();
  for (int k = 0; k < 3; ++k)
    if (b.extent()[k] == 0.0f) {
      b.lo[k] -= 1.0f;
      b.hi[k] += 1.0f;
    }
  return b;
}

DiffStats runDifferential(const std::shared_ptr<const TriangleMesh>& mesh, const StructureCase& c,
                          std::size_t random_count, std::uint32_t primary_side, bool expect_misses = true) {
  const auto object = buildChecked(mesh, c.config);
  EXPECT_EQ(object->structure(), c.config.structure);
  const RefScene ref(refTriangles(*mesh));
  const auto rays = mixedRays(aroundMesh(*mesh), random_count, primary_side, 4321);
  const std::string label = mesh->name() + " / " + c.name + " / " + std::string(toString(widestSimdIsa()));
  const auto s = expectAgreesWithReference(*object, ref, rays, label);
  // Not vacuous: a fair share of the rays hits, and some miss.
  EXPECT_GT(s.hits, s.rays / 20) << label;
  if (expect_misses) {
    EXPECT_LT(s.hits, s.rays) << label;
  }
  return s;
}

class MeshStructureDifferential : public ::testing::TestWithParam<StructureCase> {};

TEST_P(MeshStructureDifferential, Icosphere) {
  runDifferential(std::make_shared<const TriangleMesh>(icosphere(4)), GetParam(), 3000, 48);
}

TEST_P(MeshStructureDifferential, UvSphere) {
  runDifferential(std::make_shared<const TriangleMesh>(uvSphere(48, 24)), GetParam(), 2000, 40);
}

TEST_P(MeshStructureDifferential, TriangleSoup) {
  runDifferential(std::make_shared<const TriangleMesh>(triangleSoup(3000, 99)), GetParam(), 3000, 40);
}

TEST_P(MeshStructureDifferential, FlatAxisAlignedGrids) {
  for (int axis = 0; axis < 3; ++axis) {
    SCOPED_TRACE(::testing::Message() << "grid normal axis " << axis);
    runDifferential(std::make_shared<const TriangleMesh>(flatGrid(48, axis, 0.25f, 0.125f)), GetParam(), 1500, 32);
  }
}

TEST_P(MeshStructureDifferential, BoxFarFromOrigin) {
  // A closed box 10^5 units away: float spacing there is 1/128.
  runDifferential(std::make_shared<const TriangleMesh>(boxMesh(glm::vec3(100000.0f, 100010.0f, -100020.0f),
                                                               glm::vec3(100003.5f, 100012.25f, -100017.0f))),
                  GetParam(), 2000, 32);
}

/// The BVH's own parameters: run for each BVH preset only.
class MeshBvhDifferential : public MeshStructureDifferential {};

TEST_P(MeshBvhDifferential, ManySmallLeavesAndFewLargeOnes) {
  // Leaf sizes at both ends of the range and more bins than most nodes have references.
  auto mesh = std::make_shared<const TriangleMesh>(triangleSoup(2000, 5));
  for (const std::uint32_t leaf : {1u, 3u, 16u}) {
    StructureCase c = GetParam();
    c.config.bvh.max_leaf_size = leaf;
    c.config.bvh.bins = leaf == 16 ? 2 : BvhBuildConfig::kMaxBins;
    c.name += "_leaf" + std::to_string(leaf);
    runDifferential(mesh, c, 1000, 24);
  }
}

TEST_P(MeshStructureDifferential, Fixtures) {
  // Every fixture the loader accepts (the others test its errors).
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(fixtureDir())) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::size_t loaded = 0;
  for (const auto& path : files) {
    std::shared_ptr<const TriangleMesh> mesh;
    try {
      mesh = std::make_shared<const TriangleMesh>(loadMesh(path));
    } catch (const std::exception&) {
      continue;
    }
    ++loaded;
    SCOPED_TRACE(path.filename().string());
    runDifferential(mesh, GetParam(), 1500, 32);
  }
  EXPECT_GE(loaded, 4u) << "fixtures in " << fixtureDir();
}

INSTANTIATE_TEST_SUITE_P(Structures, MeshStructureDifferential, ::testing::ValuesIn(structureCases()),
                         [](const auto& info) { return info.param.name; });
INSTANTIATE_TEST_SUITE_P(Structures, MeshBvhDifferential, ::testing::ValuesIn(bvhStructureCases()),
                         [](const auto& info) { return info.param.name; });

// ---------------------------------------------------------------------------------------------
// The shared meshes, each structure on each (skipped, each with its own message, when absent).

struct SharedMeshCase {
  const char* name;  ///< gtest name
  const char* file;  ///< relative to the shared meshes folder
  int rays;
  int grid;
};

class MeshStructureShared : public ::testing::TestWithParam<std::tuple<StructureCase, SharedMeshCase>> {};

TEST_P(MeshStructureShared, AgreesWithTheReference) {
  const auto& [structure, c] = GetParam();
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, c.file);
  runDifferential(mesh, structure, c.rays, c.grid, false);
}

INSTANTIATE_TEST_SUITE_P(
    SharedMeshes, MeshStructureShared,
    ::testing::Combine(::testing::ValuesIn(structureCases()),
                       ::testing::Values(SharedMeshCase{"Spot", "spot.obj", 2000, 40},
                                         SharedMeshCase{"Koala", "koala.obj", 400, 16},
                                         SharedMeshCase{"Hammer", "hammer.obj", 400, 16},
                                         SharedMeshCase{"Plane", "plane.obj", 800, 24},
                                         SharedMeshCase{"CornellBoxQuads", "cornell_box.obj", 1500, 32},
                                         SharedMeshCase{"RobotBase", "abb_irb6640/base_link.stl", 600, 24},
                                         // non-manifold CAD part
                                         SharedMeshCase{"RobotLink4", "abb_irb6640/link_4.stl", 800, 24})),
    [](const auto& info) { return std::get<0>(info.param).name + "_" + std::string(std::get<1>(info.param).name); });

// The structures agree with each other hit for hit where the reference leaves a choice (ties
// between triangles at the same distance are allowed to differ, not the distance).
TEST(MeshStructures, ClosestHitsAgreeBetweenStructures) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(4));
  const auto rays = mixedRays(mesh->bounds(), 4000, 32, 99);
  std::vector<std::shared_ptr<const MeshObject>> objects;
  std::vector<std::string> names;
  for (const StructureCase& c : structureCases()) {
    objects.push_back(buildChecked(mesh, c.config));
    names.push_back(c.name);
  }
  ASSERT_GE(objects.size(), 3u);
  std::size_t hits = 0;
  for (const Ray& r : rays) {
    Hit first;
    const bool hit0 = objects[0]->intersect(r, first);
    hits += hit0;
    for (std::size_t k = 1; k < objects.size(); ++k) {
      Hit h;
      const bool hk = objects[k]->intersect(r, h);
      ASSERT_EQ(hk, hit0) << names[k] << " vs " << names[0] << ": " << r;
      if (hk && h.prim_id == first.prim_id) {
        EXPECT_EQ(h.t, first.t) << names[k] << ": " << r;
      }
      if (hk) {
        EXPECT_NEAR(h.t, first.t, 1e-5 * first.t) << names[k] << ": " << r;
      }
      EXPECT_EQ(objects[k]->occluded(r), objects[0]->occluded(r)) << names[k] << ": " << r;
    }
  }
  EXPECT_GT(hits, rays.size() / 4);
}

}  // namespace
}  // namespace duplex::test
