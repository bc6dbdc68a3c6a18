// Edge cases of MeshObject and TriangleMesh, for each structure (the kd-tree and the BVH presets)
// unless a case is the kd-tree's own: axis-parallel rays (with +0/-0 components), rays lying
// exactly in split planes of the built tree, rays starting inside, [tnear, tfar] limits, flat
// axis-aligned meshes, one-triangle meshes, empty and degenerate meshes, out-of-range indices,
// rays with zero or NaN directions, all hits (intersectAll). Hits are compared with the double-precision brute force.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

/// Meshes the edge-case tests run over: closed sphere, flat grid, closed box, soup, and spot.
std::vector<std::shared_ptr<const TriangleMesh>> edgeCaseMeshes() {
  std::vector<std::shared_ptr<const TriangleMesh>> meshes = {
      std::make_shared<const TriangleMesh>(icosphere(3)),
      std::make_shared<const TriangleMesh>(flatGrid(16, 2, 0.25f, 0.125f)),
      std::make_shared<const TriangleMesh>(boxMesh(glm::vec3(-1.0f, -0.5f, 0.0f), glm::vec3(1.0f, 0.5f, 2.0f))),
      std::make_shared<const TriangleMesh>(triangleSoup(800, 17)),
  };
  if (auto spot = sharedMeshCached("spot.obj")) meshes.push_back(spot);
  return meshes;
}

/// A box around the mesh with positive extent on every axis.
Box around(const TriangleMesh& m, float grow = 0.5f) {
  Box b = m.bounds();
  for (int k = 0; k < 3; ++k)
    if (b.extent()[k] == 0.0f) {
      b.lo[k] -= 1.0f;
      b.hi[k] += 1.0f;
    }
  return enlarged(b, grow);
}

bool sameBits(const Hit& a, const Hit& b) {
  return std::memcmp(&a.t, &b.t, sizeof(float)) == 0 && std::memcmp(&a.u, &b.u, sizeof(float)) == 0 &&
         std::memcmp(&a.v, &b.v, sizeof(float)) == 0 && a.prim_id == b.prim_id && a.instance_id == b.instance_id &&
         std::memcmp(&a.ng, &b.ng, sizeof(a.ng)) == 0;
}

/// The sorted distinct triangles the object's structure references.
std::vector<std::uint32_t> referencedTriangles(const MeshObject& object) {
  std::vector<std::uint32_t> ids =
      object.structure() == MeshStructure::Bvh ? object.bvh().prim_indices : object.tree().prim_indices;
  ids.erase(std::remove(ids.begin(), ids.end(), WideBvh::kPadding), ids.end());
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  return ids;
}

/// The edge cases run for every structure (the kd-tree and each BVH preset).
class MeshEdgeCases : public ::testing::TestWithParam<StructureCase> {};

// ---------------------------------------------------------------------------------------------

TEST_P(MeshEdgeCases, AxisParallelRaysWithSignedZeros) {
  std::mt19937_64 rng(21);
  for (const auto& mesh : edgeCaseMeshes()) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, GetParam().config);
    const RefScene ref(refTriangles(*mesh));
    const Box box = around(*mesh);
    std::uniform_real_distribution<float> ux(box.lo.x, box.hi.x), uy(box.lo.y, box.hi.y), uz(box.lo.z, box.hi.z);
    std::vector<Ray> rays;
    for (int i = 0; i < 1200; ++i) {
      Ray r;
      const float x = ux(rng), y = uy(rng), z = uz(rng);
      r.origin = glm::vec3(x, y, z);
      if (i % 4 == 0) {
        // Through vertices on the two other axes: lands exactly on edges and vertices.
        const glm::vec3 v = mesh->positions()[rng() % mesh->positions().size()];
        const int axis = (i / 4) % 3;
        for (int k = 0; k < 3; ++k)
          if (k != axis) r.origin[k] = v[k];
      }
      const int axis = i % 3;
      // All eight sign patterns of the zero components.
      r.dir = glm::vec3((i >> 2) & 1 ? -0.0f : 0.0f, (i >> 3) & 1 ? -0.0f : 0.0f, (i >> 4) & 1 ? -0.0f : 0.0f);
      r.dir[axis] = (i >> 5) & 1 ? -1.0f : 1.0f;
      if (i % 7 == 0) r.dir[axis] *= 3.5f;  // not unit length
      rays.push_back(r);
    }
    const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " axis-parallel");
    EXPECT_GT(s.hits, s.rays / 20);
  }
}

TEST(MeshObjectEdgeCases, RaysInSplitPlanes) {
  std::mt19937_64 rng(22);
  for (const auto& mesh : edgeCaseMeshes()) {
    SCOPED_TRACE(mesh->name());
    for (const ConfigCase& c : allConfigCases()) {
      if (c.name != "sah_clip" && c.name != "median_clip" && c.name != "middle_noclip") continue;
      SCOPED_TRACE(c.name);
      const auto object = buildChecked(mesh, c.config);
      const RefScene ref(refTriangles(*mesh));
      const Box box = around(*mesh);
      std::uniform_real_distribution<float> u01(0.0f, 1.0f);
      std::vector<Ray> rays;
      const auto& nodes = object->tree().nodes;
      for (std::uint32_t i = 0; i < nodes.size() && rays.size() < 1500;
           i += 1 + static_cast<std::uint32_t>(nodes.size() / 300)) {
        if (nodes[i].isLeaf()) continue;
        const int axis = nodes[i].axis();
        for (int rep = 0; rep < 4; ++rep) {
          Ray r;
          for (int k = 0; k < 3; ++k) r.origin[k] = box.lo[k] + u01(rng) * (box.hi[k] - box.lo[k]);
          r.origin[axis] = nodes[i].split();
          r.dir = glm::normalize(draw3(u01, rng) - 0.5f);
          if (rep < 3) r.dir[axis] = rep == 1 ? -0.0f : 0.0f;  // inside the plane; rep 3 starts on it
          if (rep == 2) r.dir[(axis + 1) % 3] = 0.0f;          // along the plane and axis-parallel
          if (r.dir == glm::vec3(0.0f)) r.dir[(axis + 2) % 3] = 1.0f;
          rays.push_back(r);
        }
      }
      if (rays.empty()) continue;  // the tree is a single leaf (e.g. SAH over the 12-triangle box)
      const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " split planes");
      EXPECT_GT(s.hits, 0u);
    }
  }
}

TEST_P(MeshEdgeCases, RaysStartingInsideClosedMeshesAlwaysHit) {
  auto sphere = std::make_shared<const TriangleMesh>(icosphere(3, 2.0, glm::dvec3(1.0, -1.0, 0.5)));
  auto box = std::make_shared<const TriangleMesh>(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f, 2.0f, 3.0f)));
  for (const auto& mesh : {sphere, box}) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, GetParam().config);
    const RefScene ref(refTriangles(*mesh));
    // Origins well inside (the box of the inner half): every direction must leave through the surface.
    Box inner = mesh->bounds();
    const glm::vec3 c = inner.center(), e = inner.extent() * 0.2f;
    inner = Box(c - e, c + e);
    const auto rays = randomRays(inner, 3000, 23);
    const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " from inside");
    EXPECT_EQ(s.hits, s.rays) << "a ray from inside a closed mesh escaped";
  }
}

TEST_P(MeshEdgeCases, TnearTfarLimits) {
  std::mt19937_64 rng(24);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  for (const auto& mesh : edgeCaseMeshes()) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, GetParam().config);
    const RefScene ref(refTriangles(*mesh));
    const auto base = randomRays(around(*mesh, 0.3f), 1500, 25);
    std::vector<Ray> rays;
    std::size_t limited_hits = 0;
    for (const Ray& r : base) {
      const RefHit h = ref.closestHit(r);
      if (!h.valid() || !(h.t > 1e-3)) continue;
      ++limited_hits;
      Ray before = r;  // ends before the first hit: a hit there must not be reported
      before.tfar = static_cast<float>(h.t * (0.2 + 0.79 * u01(rng)));
      Ray after = r;  // starts after the first hit: the next one (or a miss)
      after.tnear = static_cast<float>(h.t * (1.0 + 1e-3 + u01(rng)));
      Ray around_hit = r;  // a short interval containing the first hit
      around_hit.tnear = static_cast<float>(h.t * 0.99);
      around_hit.tfar = static_cast<float>(h.t * 1.01);
      Ray empty = r;  // tnear > tfar: nothing
      empty.tnear = static_cast<float>(h.t * 1.1);
      empty.tfar = static_cast<float>(h.t * 0.9);
      Ray point = r;  // tnear == tfar away from any hit
      point.tnear = point.tfar = static_cast<float>(h.t * 0.5);
      rays.insert(rays.end(), {before, after, around_hit, empty, point});
    }
    ASSERT_GT(limited_hits, 100u);
    // The comparison checks hit.t in [tnear, tfar] for every reported hit as well.
    const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " limited");
    EXPECT_GE(s.hits, limited_hits);  // at least all around_hit rays
    for (const Ray& r : rays)
      if (r.tnear > r.tfar) {
        Hit hit;
        EXPECT_FALSE(object->intersect(r, hit)) << r;
        EXPECT_FALSE(object->occluded(r)) << r;
      }
  }
}

TEST_P(MeshEdgeCases, IntersectOnlyAcceptsCloserHits) {
  // Object::intersect searches [tnear, hit.t]: an existing closer hit is kept and false returned.
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const auto object = buildChecked(mesh, GetParam().config);
  const RefScene ref(refTriangles(*mesh));
  std::size_t checked = 0;
  for (const Ray& r : randomRays(around(*mesh, 0.5f), 1000, 26)) {
    const RefHit h = ref.closestHit(r);
    if (!h.valid() || h.t < 1e-3) continue;
    ++checked;
    Hit closer;
    closer.t = static_cast<float>(h.t * 0.5);
    closer.prim_id = 123456;
    closer.u = 0.25f;
    const Hit before = closer;
    EXPECT_FALSE(object->intersect(r, closer)) << r;
    EXPECT_TRUE(sameBits(closer, before)) << r << ": hit modified to " << closer;
    Hit farther;
    farther.t = static_cast<float>(h.t * 2.0 + 1.0);
    farther.prim_id = 123456;
    EXPECT_TRUE(object->intersect(r, farther)) << r;
    EXPECT_TRUE(hitMatches(farther, h, r, HitTolerance{}, false)) << r;
  }
  EXPECT_GT(checked, 100u);
}

TEST_P(MeshEdgeCases, FlatAxisAlignedMeshesIncludingInPlaneRays) {
  std::mt19937_64 rng(27);
  std::uniform_real_distribution<float> u(-0.5f, 2.5f);
  for (int axis = 0; axis < 3; ++axis) {
    SCOPED_TRACE(::testing::Message() << "normal axis " << axis);
    auto mesh = std::make_shared<const TriangleMesh>(flatGrid(16, axis, -0.75f, 0.125f));
    const auto object = buildChecked(mesh, GetParam().config);
    const RefScene ref(refTriangles(*mesh));
    std::vector<Ray> rays;
    for (int i = 0; i < 1500; ++i) {
      Ray r;
      r.origin = draw3(u, rng);
      r.dir = glm::normalize(draw3(u, rng) - 1.0f);
      if (i % 3 == 0) {  // in the mesh's plane
        r.origin[axis] = -0.75f;
        r.dir[axis] = i % 2 ? -0.0f : 0.0f;
      } else if (i % 3 == 1) {  // perpendicular to it, through grid vertices and edges
        r.dir = glm::vec3(0.0f);
        r.dir[axis] = i % 2 ? 1.0f : -1.0f;
        const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
        r.origin[a1] = 0.125f * static_cast<float>(rng() % 17);
        if (i % 5 == 0) r.origin[a2] = 0.125f * static_cast<float>(rng() % 17);
      }
      rays.push_back(r);
    }
    const auto s = expectAgreesWithReference(*object, ref, rays, "flat grid");
    EXPECT_GT(s.hits, 150u);  // the rays reach the grid (about 200 of the 1,500 hit it)
  }
}

TEST_P(MeshEdgeCases, OneTriangleMeshes) {
  std::mt19937_64 rng(28);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int m = 0; m < 20; ++m) {
    std::vector<glm::vec3> p = {draw3(u, rng), draw3(u, rng), draw3(u, rng)};
    if (m % 4 == 0)
      for (auto& q : p) q.y = 0.5f;  // axis-aligned
    auto mesh = std::make_shared<const TriangleMesh>(TriangleMesh::fromTriangles(p, {{0, 1, 2}}, "one"));
    ASSERT_EQ(mesh->triangleCount(), 1u);
    const auto object = buildChecked(mesh, GetParam().config);
    EXPECT_EQ(referencedTriangles(*object), std::vector<std::uint32_t>{0});
    const RefScene ref(refTriangles(*mesh));
    std::vector<Ray> rays = randomRays(around(*mesh, 1.0f), 300, 29 + m);
    // Rays aimed at the centroid from random points must hit it at t = 1 (up to rounding).
    const glm::dvec3 a(p[0]), b(p[1]), c(p[2]);
    for (int k = 0; k < 10; ++k) {
      Ray r;
      r.origin = (draw3(u, rng) * 3.0f);
      r.dir = glm::vec3((a + b + c) / 3.0 - glm::dvec3(r.origin));
      rays.push_back(r);
    }
    // Rays aimed at the corners and edge midpoints lie on the triangle's boundary: in float either
    // answer is right, but a hit must be at the target (t = 1).
    for (const glm::dvec3& target : {a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)}) {
      for (int k = 0; k < 10; ++k) {
        Ray r;
        r.origin = (draw3(u, rng) * 3.0f);
        r.dir = glm::vec3(target - glm::dvec3(r.origin));
        Hit hit;
        if (object->intersect(r, hit)) {
          EXPECT_NEAR(hit.t, 1.0, 1e-4) << r << " aimed at the boundary hits " << hit;
          EXPECT_TRUE(hitGeometryConsistent(hit, r, mesh->vertices(0), 1.0));
        }
        EXPECT_EQ(object->occluded(r), hit.valid()) << r;
      }
    }
    const auto s = expectAgreesWithReference(*object, ref, rays, "one triangle");
    EXPECT_GE(s.hits, 10u);  // at least the centroid rays
  }
}

// ---------------------------------------------------------------------------------------------
// Construction errors and degenerate input.

TEST(TriangleMeshErrors, EmptyMeshThrowsNamingTheMesh) {
  expectErrorNaming<InvalidArgument>([] { (void)TriangleMesh::fromArrays({}, {}, "empty-mesh-7"); }, "empty-mesh-7");
  const std::vector<float> positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  expectErrorNaming<InvalidArgument>([&] { (void)TriangleMesh::fromArrays(positions, {}, "no-triangles-8"); },
                                     "no-triangles-8");
  expectErrorNaming<InvalidArgument>([] { (void)TriangleMesh::fromTriangles({}, {}, "empty-vectors-9"); },
                                     "empty-vectors-9");
}

TEST(MeshObjectErrors, RefusedBuildConfigurationNamesTheMeshAndTheField) {
  auto mesh = std::make_shared<const TriangleMesh>(
      TriangleMesh::fromTriangles({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}, "config-mesh-3"));
  KdBuildConfig bad;
  bad.intersection_cost = -1.0f;
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject(mesh, bad); }, "config-mesh-3");
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject(mesh, bad); }, "intersection_cost");
  // The same mesh with the default configuration builds: the refusal was the configuration's.
  EXPECT_FALSE(buildChecked(mesh)->tree().empty());
}

TEST(TriangleMeshErrors, OutOfRangeIndexAndBadSizesThrow) {
  const std::vector<float> positions = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const std::vector<std::uint32_t> bad_index = {0, 1, 2, 0, 2, 3};
  expectErrorNaming<InvalidArgument>([&] { (void)TriangleMesh::fromArrays(positions, bad_index, "oob-mesh"); },
                                     "oob-mesh");
  const std::vector<std::uint32_t> huge_index = {0, 1, 0xFFFFFFFFu};
  expectErrorNaming<InvalidArgument>([&] { (void)TriangleMesh::fromArrays(positions, huge_index, "huge-index"); },
                                     "huge-index");
  const std::vector<float> ragged = {0, 0, 0, 1, 0, 0, 0, 1};
  expectErrorNaming<InvalidArgument>(
      [&] {
        (void)TriangleMesh::fromArrays(ragged, std::vector<std::uint32_t>{0, 1, 2}, "ragged");
      },
      "ragged");
  expectErrorNaming<InvalidArgument>(
      [&] {
        (void)TriangleMesh::fromArrays(positions, std::vector<std::uint32_t>{0, 1, 2, 0}, "four-indices");
      },
      "four-indices");
}

TEST(TriangleMeshErrors, FromArraysKeepsLayout) {
  const std::vector<float> positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0.5f};
  const std::vector<std::uint32_t> indices = {0, 1, 2, 2, 1, 3};
  const TriangleMesh m = TriangleMesh::fromArrays(positions, indices, "layout");
  ASSERT_EQ(m.positions().size(), 4u);
  EXPECT_EQ(m.positions()[3], glm::vec3(1.0f, 1.0f, 0.5f));
  ASSERT_EQ(m.triangleCount(), 2u);
  EXPECT_EQ(m.triangles()[1], (TriangleMesh::Triangle{2, 1, 3}));
  EXPECT_EQ(m.degenerateCount(), 0u);
  EXPECT_EQ(m.bounds(), Box(glm::vec3(0.0f), glm::vec3(1.0f, 1.0f, 0.5f)));
  EXPECT_EQ(m.name(), "layout");
}

TEST_P(MeshEdgeCases, CountedNeverHitAndLeftOutOfTheTree) {
  // 0: valid; 1: zero area (collinear, distinct vertices); 2: repeated index; 3: NaN vertex;
  // 4: infinite vertex; 5: valid; 6: all three the same point.
  std::vector<glm::vec3> p = {
      {0, 0, 0},          {1, 0, 0},    {0, 1, 0},  // 0..2 triangle 0
      {2, 0, 0},          {3, 0, 0},    {4, 0, 0},  // 3..5 collinear
      {kNaN, 0.5f, 0.5f}, {kInf, 0, 0},             // 6, 7
      {0, 0, 1},          {1, 0, 1},    {0, 1, 1},  // 8..10 triangle 5
  };
  const std::vector<TriangleMesh::Triangle> t = {{0, 1, 2}, {3, 4, 5},  {0, 0, 1}, {0, 6, 1},
                                                 {7, 1, 2}, {8, 9, 10}, {3, 3, 3}};
  auto mesh = std::make_shared<const TriangleMesh>(TriangleMesh::fromTriangles(p, t, "degenerate"));
  EXPECT_EQ(mesh->degenerateCount(), 5u);
  for (std::size_t i = 0; i < t.size(); ++i) EXPECT_EQ(mesh->isValid(i), i == 0 || i == 5) << "triangle " << i;
  // Bounds cover only the valid triangles (no NaN, no inf, not the collinear points at x = 2..4).
  EXPECT_EQ(mesh->bounds(), Box(glm::vec3(0.0f), glm::vec3(1.0f, 1.0f, 1.0f)));
  const auto object =
      buildChecked(mesh, GetParam().config);  // the checker also rejects references to degenerate triangles
  EXPECT_EQ(referencedTriangles(*object), (std::vector<std::uint32_t>{0, 5}));
  // Rays along and across the degenerate ones: never reported.
  const RefScene ref(refTriangles(*mesh));
  std::vector<Ray> rays;
  for (float x : {2.0f, 2.5f, 3.0f, 4.0f}) {
    Ray down;
    down.origin = glm::vec3(x, 0.0f, 1.0f);
    down.dir = glm::vec3(0.0f, 0.0f, -1.0f);
    rays.push_back(down);
    Ray along;
    along.origin = glm::vec3(x - 5.0f, 0.0f, 0.0f);
    along.dir = glm::vec3(1.0f, 0.0f, 0.0f);
    rays.push_back(along);
  }
  for (const glm::vec3& o :
       {glm::vec3(0.25f, 0.25f, 3.0f), glm::vec3(0.1f, 0.0f, -2.0f), glm::vec3(0.5f, 0.0f, 0.5f)}) {
    Ray r;
    r.origin = o;
    r.dir = glm::vec3(0.0f, 0.0f, o.z > 0.5f ? -1.0f : 1.0f);
    rays.push_back(r);
  }
  const auto more = randomRays(Box(glm::vec3(-1.0f), glm::vec3(5.0f, 2.0f, 2.0f)), 2000, 30);
  rays.insert(rays.end(), more.begin(), more.end());
  const auto s = expectAgreesWithReference(*object, ref, rays, "degenerate");
  EXPECT_GT(s.hits, 10u);
  for (const Ray& r : rays) {
    Hit hit;
    if (object->intersect(r, hit)) {
      EXPECT_TRUE(hit.prim_id == 0 || hit.prim_id == 5) << r << " hit degenerate triangle " << hit.prim_id;
    }
  }
}

TEST(TriangleMeshDegenerate, OnlyDegenerateTrianglesThrows) {
  const std::vector<glm::vec3> p = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {kNaN, 0, 0}};
  expectErrorNaming<InvalidArgument>(
      [&] {
        (void)TriangleMesh::fromTriangles(p, {{0, 1, 2}, {0, 0, 1}, {3, 1, 0}}, "all-degenerate");
      },
      "all-degenerate");
}

TEST_P(MeshEdgeCases, ZeroAndNaNDirectionsAndBadRaysMiss) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(2));
  const auto object = buildChecked(mesh, GetParam().config);
  // Each ray would hit the sphere if its bad component were sane.
  Ray good;
  good.origin = glm::vec3(0.1f, 0.05f, -3.0f);
  good.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  {
    Hit hit;
    ASSERT_TRUE(object->intersect(good, hit));
    ASSERT_TRUE(object->occluded(good));
  }
  std::vector<std::pair<std::string, Ray>> bad;
  auto add = [&](const std::string& what, auto mutate) {
    Ray r = good;
    mutate(r);
    bad.emplace_back(what, r);
  };
  add("zero direction", [](Ray& r) { r.dir = glm::vec3(0.0f); });
  add("negative zero direction", [](Ray& r) { r.dir = glm::vec3(-0.0f, 0.0f, -0.0f); });
  add("NaN direction", [](Ray& r) { r.dir = glm::vec3(kNaN); });
  add("NaN z direction", [](Ray& r) { r.dir.z = kNaN; });
  add("NaN x direction", [](Ray& r) { r.dir.x = kNaN; });
  add("infinite direction", [](Ray& r) { r.dir.z = kInf; });
  add("NaN origin", [](Ray& r) { r.origin.y = kNaN; });
  add("infinite origin", [](Ray& r) { r.origin.z = -kInf; });
  add("NaN tnear", [](Ray& r) { r.tnear = kNaN; });
  add("NaN tfar", [](Ray& r) { r.tfar = kNaN; });
  add("tnear > tfar", [](Ray& r) {
    r.tnear = 5.0f;
    r.tfar = 1.0f;
  });
  QueryContext ctx;
  for (const auto& [what, r] : bad) {
    Hit hit;
    hit.t = 1e30f;
    const Hit before = hit;
    EXPECT_FALSE(object->intersect(r, hit)) << what;
    EXPECT_TRUE(sameBits(hit, before)) << what << ": hit modified";
    EXPECT_FALSE(object->occluded(r)) << what;
    Hit hit_ctx;
    EXPECT_FALSE(static_cast<const Object&>(*object).intersect(r, hit_ctx, ctx)) << what;
    EXPECT_FALSE(static_cast<const Object&>(*object).occluded(r, ctx)) << what;
  }
}

TEST_P(MeshEdgeCases, TinyDirectionComponents) {
  // Components so small that 1/d overflows (the traversal then treats them as zero) or is huge.
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const auto object = buildChecked(mesh, GetParam().config);
  const RefScene ref(refTriangles(*mesh));
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<float> u(-1.5f, 1.5f);
  std::vector<Ray> rays;
  for (int i = 0; i < 1500; ++i) {
    Ray r;
    r.origin = draw3(u, rng);
    r.dir = glm::normalize(draw3(u, rng));
    const float tiny[4] = {1e-20f, -1e-30f, 1e-39f, -1e-44f};  // the last two are subnormal
    r.dir[i % 3] = tiny[(i / 3) % 4];
    if (i % 5 == 0) r.dir[(i + 1) % 3] = tiny[(i / 12) % 4];
    rays.push_back(r);
  }
  const auto s = expectAgreesWithReference(*object, ref, rays, "tiny components");
  EXPECT_GT(s.hits, s.rays / 5);  // the rays reach the sphere (about a quarter hit it)
}

/// The cases about the BVH's own geometry: run for each BVH preset only.
class MeshBvhEdgeCases : public MeshEdgeCases {};

TEST_P(MeshBvhEdgeCases, RaysInChildBoxPlanes) {
  // The BVH's counterpart of rays in split planes (RaysInSplitPlanes, the kd-tree's): rays lying
  // in (and starting on) the planes of child boxes, where the conservative box test decides alone
  // whether a child is entered.
  std::mt19937_64 rng(32);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  for (const auto& mesh : edgeCaseMeshes()) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, GetParam().config);
    const RefScene ref(refTriangles(*mesh));
    const Box box = around(*mesh);
    std::vector<Ray> rays;
    const auto& nodes = object->bvh().nodes;
    for (std::size_t n = 0; n < nodes.size() && rays.size() < 1500; n += 1 + nodes.size() / 200)
      for (int k = 0; k < nodes[n].childCount(); ++k) {
        const int axis = static_cast<int>(rng() % 3);
        Ray r;
        for (int a = 0; a < 3; ++a) r.origin[a] = box.lo[a] + u01(rng) * (box.hi[a] - box.lo[a]);
        r.origin[axis] = rng() % 2 ? nodes[n].lo[axis][k] : nodes[n].hi[axis][k];
        r.dir = glm::normalize(draw3(u01, rng) - 0.5f);
        if (k % 3 != 2) r.dir[axis] = k % 2 ? -0.0f : 0.0f;  // inside the plane; else starts on it
        if (r.dir == glm::vec3(0.0f)) r.dir[(axis + 1) % 3] = 1.0f;
        rays.push_back(r);
      }
    if (rays.empty()) continue;  // a single-leaf BVH
    const auto s = expectAgreesWithReference(*object, ref, rays, mesh->name() + " child box planes");
    EXPECT_GT(s.hits, 0u);
  }
}

/// Every hit of the line within [tnear, tfar] in the reference, sorted by t.
std::vector<RefHit> refAllHits(const RefScene& ref, const Ray& r) {
  std::vector<RefHit> out;
  if (!refQueryable(r)) return out;
  const glm::dvec3 o(r.origin), d(r.dir);
  for (const RefTriangle& tri : ref.triangles()) {
    const double t = refIntersect(o, d, tri);
    if (t >= r.tnear && t <= r.tfar) out.push_back({t, tri.prim, kInvalidId});
  }
  std::sort(out.begin(), out.end(), [](const RefHit& a, const RefHit& b) { return a.t < b.t; });
  return out;
}

/// intersectAll against the reference: every reported hit is a reference hit (up to the tie
/// tolerance), and every reference crossing (hits within the tolerance form one: the library merges
/// the triangles around a shared edge or vertex) is reported, except within rounding of tnear/tfar.
::testing::AssertionResult allHitsAgree(const std::vector<Hit>& hits, const std::vector<RefHit>& expected, const Ray& r,
                                        const HitTolerance& tol) {
  for (std::size_t i = 1; i < hits.size(); ++i)
    if (!(hits[i - 1].t <= hits[i].t)) return ::testing::AssertionFailure() << r << ": hits not sorted by t";
  for (const Hit& h : hits) {
    if (!(h.t >= r.tnear && h.t <= r.tfar))
      return ::testing::AssertionFailure() << r << ": " << h << " outside [tnear, tfar]";
    const bool known = std::any_of(expected.begin(), expected.end(), [&](const RefHit& e) {
      return std::abs(double(h.t) - e.t) <= tSlack(e.t, r, tol) + (e.prim == h.prim_id ? 1e-4 * e.t : 0.0);
    });
    if (!known) return ::testing::AssertionFailure() << r << ": " << h << " is no reference hit";
  }
  for (std::size_t i = 0; i < expected.size();) {
    std::size_t j = i + 1;
    while (j < expected.size() && expected[j].t - expected[j - 1].t <= tSlack(expected[j].t, r, tol)) ++j;
    const double lo = expected[i].t, hi = expected[j - 1].t, slack = tSlack(hi, r, tol);
    const bool reported = std::any_of(hits.begin(), hits.end(), [&](const Hit& h) {
      return double(h.t) >= lo - slack - 1e-4 * lo && double(h.t) <= hi + slack + 1e-4 * hi;
    });
    const bool at_end = lo - double(r.tnear) <= slack || double(r.tfar) - hi <= slack;
    if (!reported && !at_end)
      return ::testing::AssertionFailure() << r << ": reference crossing at t=" << lo << " (prim " << expected[i].prim
                                           << ") not reported; " << hits.size() << " hits";
    i = j;
  }
  return ::testing::AssertionSuccess();
}

TEST_P(MeshEdgeCases, IntersectAllAgreesWithTheReferenceAndTheKdTree) {
  QueryContext ctx;
  for (const auto& mesh : edgeCaseMeshes()) {
    SCOPED_TRACE(mesh->name());
    const auto object = buildChecked(mesh, GetParam().config);
    const auto kd = buildChecked(mesh, KdBuildConfig{});
    const RefScene ref(refTriangles(*mesh));
    HitTolerance tol;
    tol.abs_scale = 1e-6 * coordinateScale(mesh->bounds());
    std::vector<Ray> rays = randomRays(around(*mesh), 600, 33);
    // Half of them aimed through the mesh's bounds, so that most cross several surfaces.
    const auto targets = randomRays(mesh->bounds().empty() ? around(*mesh) : around(*mesh, 0.0f), 300, 34);
    for (std::size_t i = 0; i < targets.size(); ++i) {
      rays[2 * i].dir = targets[i].origin - rays[2 * i].origin;
      if (rays[2 * i].dir == glm::vec3(0.0f)) rays[2 * i].dir = targets[i].dir;
    }
    // Limited intervals too: only the hits inside count.
    for (std::size_t i = 0; i < rays.size(); i += 3) rays[i].tfar = 0.5f;
    for (std::size_t i = 1; i < rays.size(); i += 5) rays[i].tnear = 0.3f;
    std::size_t failures = 0, total = 0;
    for (const Ray& r : rays) {
      std::vector<Hit> hits, kd_hits;
      hits.push_back(Hit{});  // intersectAll appends: earlier entries stay
      object->intersectAll(r, hits, ctx);
      ASSERT_FALSE(hits.front().valid()) << "an earlier entry was modified";
      hits.erase(hits.begin());
      total += hits.size();
      const auto match = allHitsAgree(hits, refAllHits(ref, r), r, tol);
      if (!match && failures++ < 5) ADD_FAILURE() << match.message();
      kd->intersectAll(r, kd_hits, ctx);
      // Same triangle test in the leaves: the structures report the same crossings.
      bool same = kd_hits.size() == hits.size();
      for (std::size_t k = 0; same && k < hits.size(); ++k) same = kd_hits[k].t == hits[k].t;
      if (!same && failures++ < 5)
        ADD_FAILURE() << r << ": " << hits.size() << " hits, the kd-tree's " << kd_hits.size();
      // The closest of them is intersect()'s hit.
      Hit closest;
      if (object->intersect(r, closest)) {
        if (hits.empty() || !(hits.front().t == closest.t))
          if (failures++ < 5) ADD_FAILURE() << r << ": intersect " << closest << " is not the first of intersectAll";
      }
    }
    EXPECT_EQ(failures, 0u);
    EXPECT_GT(total, rays.size() / 5) << "the aimed rays cross the surfaces";
  }
}

TEST_P(MeshEdgeCases, NullMeshAndRefusedConfigurationsThrow) {
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject(nullptr, GetParam().config); }, "mesh");
  auto mesh = std::make_shared<const TriangleMesh>(
      TriangleMesh::fromTriangles({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}, "config-mesh-4"));
  MeshBuildConfig bad = GetParam().config;
  bad.kd.intersection_cost = -1.0f;
  bad.bvh.bins = 1;
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject(mesh, bad); }, "config-mesh-4");
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject(mesh, bad); },
                                     GetParam().config.structure == MeshStructure::Bvh ? "bins" : "intersection_cost");
  // The other structure's parameters are not this one's concern.
  MeshBuildConfig other = GetParam().config;
  if (other.structure == MeshStructure::Bvh) other.kd.intersection_cost = -1.0f;
  else other.bvh.bins = 1;
  EXPECT_EQ(buildChecked(mesh, other)->structure(), other.structure);
}

INSTANTIATE_TEST_SUITE_P(Structures, MeshEdgeCases, ::testing::ValuesIn(structureCases()),
                         [](const auto& info) { return info.param.name; });
INSTANTIATE_TEST_SUITE_P(Structures, MeshBvhEdgeCases, ::testing::ValuesIn(bvhStructureCases()),
                         [](const auto& info) { return info.param.name; });

}  // namespace
}  // namespace duplex::test
