// The wide-node traversal (two binary kd-tree levels per node, objects/src/KdWideTraversal.h:
// MeshObject::intersectWide / occludedWide), against the binary traversal of the same tree
// (MeshObject::intersect / occluded): same hit or miss, the same t bit for bit, the same
// triangle unless two triangles tie at that t (then the other one must be hit at the same t by the
// scalar watertight test), same occlusion. Rays: random, axis-parallel with +0 / -0 components, lying
// in split planes of the tree, aimed exactly at vertices, and a leaf too large for a child word.

#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/WatertightTriangle.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

/// Does triangle `prim` of `mesh` give `ray` a hit at exactly t (the scalar watertight test)?
bool hitAt(const TriangleMesh& mesh, std::uint32_t prim, const Ray& ray, float t_expected) {
  const auto v = mesh.vertices(prim);
  const WatertightRay wray(ray);
  float t, u, w;
  return intersectWatertight(wray, v[0], v[1], v[2], ray.tfar, t, u, w) && t == t_expected;
}

struct Agreement {
  std::size_t rays = 0, hits = 0, ties = 0;
};

::testing::AssertionResult wideAgreesWithBinary(const MeshObject& object, const Ray& ray, Agreement& a) {
  ++a.rays;
  Hit wide, binary;
  const bool hw = object.intersectWide(ray, wide), hb = object.intersect(ray, binary);
  if (hw != hb)
    return ::testing::AssertionFailure() << ray << ": wide " << (hw ? "hits" : "misses") << ", binary "
                                         << (hb ? "hits" : "misses");
  if (object.occludedWide(ray) != object.occluded(ray))
    return ::testing::AssertionFailure() << ray << ": occluded differs";
  if (!hw) return ::testing::AssertionSuccess();
  ++a.hits;
  if (wide.t != binary.t) return ::testing::AssertionFailure() << ray << ": wide " << wide << ", binary " << binary;
  if (wide.prim_id != binary.prim_id) {
    ++a.ties;
    if (!hitAt(object.mesh(), wide.prim_id, ray, wide.t) || !hitAt(object.mesh(), binary.prim_id, ray, binary.t))
      return ::testing::AssertionFailure() << ray << ": different triangles that do not tie: wide " << wide
                                           << ", binary " << binary;
  }
  return ::testing::AssertionSuccess();
}

void expectAgreement(const MeshObject& object, const std::vector<Ray>& rays, const std::string& label,
                     Agreement& a) {
  int failures = 0;
  for (const Ray& ray : rays) {
    const auto ok = wideAgreesWithBinary(object, ray, a);
    if (!ok && ++failures <= 5) ADD_FAILURE() << label << ": " << ok.message();
  }
  EXPECT_EQ(failures, 0) << label;
}

std::vector<std::shared_ptr<const TriangleMesh>> meshes() {
  std::vector<std::shared_ptr<const TriangleMesh>> m = {
      std::make_shared<const TriangleMesh>(icosphere(4)),
      std::make_shared<const TriangleMesh>(uvSphere(48, 24, 2.0, glm::dvec3(1e5, 0.0, 0.0))),
      std::make_shared<const TriangleMesh>(flatGrid(24, 1, 0.25f, 0.125f)),
      std::make_shared<const TriangleMesh>(boxMesh(glm::vec3(-1.0f, -0.5f, 0.0f), glm::vec3(1.0f, 0.5f, 2.0f))),
      std::make_shared<const TriangleMesh>(triangleSoup(3000, 5)),
  };
  for (const char* name : {"spot.obj", "koala.obj"})
    if (auto mesh = sharedMeshCached(name)) m.push_back(mesh);
  return m;
}

TEST(MeshObjectWideTraversal, RandomRaysAgreeWithTheBinaryTraversal) {
  for (const auto& mesh : meshes()) {
    const auto object = buildChecked(mesh);
    Agreement a;
    expectAgreement(*object, randomRays(enlarged(mesh->bounds(), 1.5f), 20000, 11), mesh->name() + " random", a);
    expectAgreement(*object, primaryRays(mesh->bounds(), 96, 96), mesh->name() + " primary", a);
    EXPECT_GT(a.hits, a.rays / 20) << mesh->name() << ": too few hits to compare";
  }
}

TEST(MeshObjectWideTraversal, AxisParallelAndInPlaneRaysAgree) {
  std::mt19937 rng(3);
  for (const auto& mesh : meshes()) {
    const auto object = buildChecked(mesh);
    const Box b = mesh->bounds();
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<Ray> rays;
    // Axis-parallel, with the other components +0 or -0.
    for (int i = 0; i < 3000; ++i) {
      const int axis = i % 3;
      glm::vec3 o;
      for (int k = 0; k < 3; ++k) o[k] = b.lo[k] + (b.hi[k] - b.lo[k]) * (1.2f * u(rng) - 0.1f);
      glm::vec3 d(i & 4 ? -0.0f : 0.0f, i & 8 ? -0.0f : 0.0f, i & 16 ? -0.0f : 0.0f);
      d[axis] = i & 32 ? -1.0f : 1.0f;
      o[axis] = d[axis] > 0 ? b.lo[axis] - 1.0f : b.hi[axis] + 1.0f;
      rays.push_back(Ray{o, 0.0f, d, kInf});
    }
    // Lying in split planes of the tree (origin on the plane, no component along its axis), and
    // starting on one with a component along it.
    for (const KdNode& node : object->tree().nodes) {
      if (node.isLeaf() || rays.size() > 12000) continue;
      const int axis = node.axis();
      glm::vec3 o;
      for (int k = 0; k < 3; ++k) o[k] = b.lo[k] + (b.hi[k] - b.lo[k]) * u(rng);
      o[axis] = node.split();
      glm::vec3 d(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f);
      d[axis] = rays.size() % 2 ? 0.0f : -0.0f;
      rays.push_back(Ray{o, 0.0f, d, kInf});
      d[axis] = u(rng) - 0.5f;
      rays.push_back(Ray{o, 0.0f, d, kInf});
    }
    Agreement a;
    expectAgreement(*object, rays, mesh->name() + " axis-parallel / in-plane", a);
  }
}

TEST(MeshObjectWideTraversal, VertexAimedRaysAgree) {
  std::mt19937 rng(9);
  for (const auto& mesh : meshes()) {
    const auto object = buildChecked(mesh);
    const auto& positions = mesh->positions();
    // Origins all around the mesh (also off the plane of a flat one).
    const Box b = mesh->bounds();
    const glm::vec3 margin(glm::length(b.hi - b.lo));
    const std::vector<Ray> origins = randomRays(Box{b.lo - margin, b.hi + margin}, 6000, 13);
    std::uniform_int_distribution<std::size_t> pick(0, positions.size() - 1);
    std::vector<Ray> rays;
    for (const Ray& r : origins) {
      const glm::vec3 target = positions[pick(rng)];
      rays.push_back(Ray{r.origin, 0.0f, target - r.origin, kInf});
    }
    Agreement a;
    expectAgreement(*object, rays, mesh->name() + " vertex-aimed", a);
    EXPECT_GT(a.hits, a.rays / 2) << mesh->name();
  }
}

// 300 copies of one triangle cannot be separated: one leaf of 75 blocks, more than a child word
// holds (63), so the leaf goes through KdWideTree::big_leaves.
TEST(MeshObjectWideTraversal, LeafLargerThanAChildWordAgrees) {
  std::vector<float> positions = {0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f,
                                  2.0f, 2.0f, 1.0f, 3.0f, 2.0f, 1.0f, 2.0f, 3.0f, 1.0f};
  std::vector<std::uint32_t> indices;
  for (int i = 0; i < 300; ++i) indices.insert(indices.end(), {0, 1, 2});
  indices.insert(indices.end(), {3, 4, 5});
  const auto object = buildChecked(TriangleMesh::fromArrays(positions, indices, "copies"));
  std::size_t largest = 0;
  for (const KdNode& node : object->tree().nodes)
    if (node.isLeaf()) largest = std::max<std::size_t>(largest, node.primCount());
  ASSERT_GT(largest, 4u * 63u) << "the test needs a leaf of more than 63 blocks";
  Agreement a;
  std::vector<Ray> rays = randomRays(Box{glm::vec3(-1.0f), glm::vec3(4.0f)}, 4000, 21);
  for (int i = 0; i < 200; ++i)
    rays.push_back(Ray{glm::vec3(0.2f, 0.2f, 5.0f), 0.0f, glm::vec3(0.001f * static_cast<float>(i), 0.0f, -1.0f), kInf});
  expectAgreement(*object, rays, "copies", a);
  EXPECT_GT(a.hits, 100u);
}

}  // namespace
}  // namespace duplex::test
