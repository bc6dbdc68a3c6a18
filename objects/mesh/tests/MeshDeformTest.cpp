/// \file MeshDeformTest.cpp
/// MeshObject::deformedMesh: refitted BVHs pass the invariant checker and agree with the brute
/// force on the moved triangles; the quality guard rebuilds when the SAH cost grows past its
/// limit; changes of triangle validity and kd-trees rebuild; bad positions are refused and change
/// nothing. Through the scene: deformObject / replaceObject reach every instance in one commit,
/// rollback drops them, and removed objects release their memory.

#include "BvhChecks.h"
#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"
#include "duplex/accel/WideBvh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

/// `p` moved by a smooth field: each axis by amplitude * sin(frequency * (p . w) + phase), with
/// random unit directions w and phases from `seed`.
std::vector<glm::vec3> smoothlyMoved(const std::vector<glm::vec3>& p, float amplitude, float frequency,
                                     std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::uniform_real_distribution<float> phase(0.0f, 6.2831853f);
  glm::vec3 w[3];
  float ph[3];
  for (int k = 0; k < 3; ++k) {
    w[k] = glm::normalize(draw3(n, rng));
    ph[k] = phase(rng);
  }
  std::vector<glm::vec3> out(p.size());
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int k = 0; k < 3; ++k) out[i][k] = p[i][k] + amplitude * std::sin(frequency * glm::dot(p[i], w[k]) + ph[k]);
  return out;
}

/// The structure's invariant checker (BVH or kd-tree, as built).
::testing::AssertionResult structureValid(const MeshObject& o) {
  if (o.structure() == MeshStructure::Bvh) return checkMeshBvh(o, BvhCheckOptions::of(o.buildConfig().bvh));
  return checkMeshTree(o);
}

/// Random rays through the mesh's surroundings against the brute force over its triangles.
void expectAgrees(const MeshObject& o, const std::string& label, std::uint64_t seed) {
  const RefScene ref(refTriangles(o.mesh()));
  Box around = o.bounds();
  around = enlarged(around, 0.5f);
  const auto rays = randomRays(around, 1500, seed);
  const DiffStats s = expectAgreesWithReference(o, ref, rays, label);
  EXPECT_GT(s.hits, s.rays / 20) << label;
}

class MeshDeform : public ::testing::TestWithParam<StructureCase> {};

TEST_P(MeshDeform, StepsAgreeWithTheBruteForceAndRefitWhileTheGuardAllows) {
  MeshBuildConfig config = GetParam().config;
  config.bvh.refit_limit = 1e6f;  // never rebuild for quality: every BVH step is a refit
  auto object = buildChecked(std::make_shared<const TriangleMesh>(icosphere(4)), config);
  const std::vector<glm::vec3> rest = object->mesh().positions();
  const double built = object->builtSahCost();
  for (int step = 1; step <= 6; ++step) {
    const std::string label = GetParam().name + ", step " + std::to_string(step);
    object = object->deformedMesh(smoothlyMoved(rest, 0.08f * step, 3.0f, 100 + step));
    ASSERT_TRUE(structureValid(*object)) << label;
    EXPECT_EQ(object->wasRefitted(), config.structure == MeshStructure::Bvh) << label;
    EXPECT_EQ(object->mesh().triangles(), icosphere(4).triangles()) << label;
    if (config.structure == MeshStructure::Bvh) {
      EXPECT_EQ(object->builtSahCost(), built) << label;  // refits keep the cost of the build
      EXPECT_GT(object->sahCost(), 0.0) << label;
    }
    expectAgrees(*object, label, 7 + step);
  }
}

class MeshDeformBvh : public ::testing::TestWithParam<StructureCase> {};

// The refit writes the leaf blocks, boxes and orders in its own pass: the result answers exactly
// as an object made by fromParts from the same mesh and tree (whose blocks come from the build's
// code), hit for hit, and the mesh's bounds and validity are those of a full validation.
TEST_P(MeshDeformBvh, RefitAnswersAsTheSameTreeThroughFromParts) {
  MeshBuildConfig config = GetParam().config;
  config.bvh.refit_limit = 1e6f;
  auto object = buildChecked(std::make_shared<const TriangleMesh>(icosphere(4)), config);
  const std::vector<glm::vec3> rest = object->mesh().positions();
  for (int step = 1; step <= 3; ++step) {
    const std::string label = GetParam().name + ", step " + std::to_string(step);
    object = object->deformedMesh(smoothlyMoved(rest, 0.1f * step, 3.0f, 200 + step));
    ASSERT_TRUE(object->wasRefitted()) << label;
    const TriangleMesh validated = object->mesh().withPositions(object->mesh().positions());
    EXPECT_EQ(object->mesh().bounds().lo, validated.bounds().lo) << label;
    EXPECT_EQ(object->mesh().bounds().hi, validated.bounds().hi) << label;
    EXPECT_TRUE(object->mesh().sameValidity(validated)) << label;
    const auto same = MeshObject::fromParts(std::make_shared<const TriangleMesh>(validated), object->bvh());
    Box around = enlarged(object->bounds(), 0.5f);
    for (const Ray& ray : randomRays(around, 2000, 300 + step)) {
      Hit a, b;
      const bool ha = object->intersect(ray, a), hb = same->intersect(ray, b);
      ASSERT_EQ(ha, hb) << label;
      if (!ha) continue;
      EXPECT_EQ(a.t, b.t) << label;
      EXPECT_EQ(a.prim_id, b.prim_id) << label;
      EXPECT_EQ(a.u, b.u) << label;
      EXPECT_EQ(a.v, b.v) << label;
    }
  }
}

TEST_P(MeshDeformBvh, TheGuardRebuildsWhenTheRefitLosesQuality) {
  const auto mesh = std::make_shared<const TriangleMesh>(icosphere(4));
  // The same vertices in another order: every triangle now spans the sphere, the refitted boxes
  // overlap everywhere.
  std::vector<glm::vec3> shuffled = mesh->positions();
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(5));
  MeshBuildConfig loose = GetParam().config, strict = GetParam().config;
  loose.bvh.refit_limit = 1e6f;
  strict.bvh.refit_limit = 1.5f;
  const auto refitted = buildChecked(mesh, loose)->deformedMesh(shuffled);
  ASSERT_TRUE(refitted->wasRefitted());
  EXPECT_GT(refitted->sahCost(), 1.5 * refitted->builtSahCost());  // the scramble is past the limit
  const auto rebuilt = buildChecked(mesh, strict)->deformedMesh(shuffled);
  EXPECT_FALSE(rebuilt->wasRefitted());
  EXPECT_DOUBLE_EQ(rebuilt->builtSahCost(), rebuilt->sahCost());  // a fresh build's own cost
  EXPECT_LT(rebuilt->sahCost(), refitted->sahCost());
  for (const auto* o : {refitted.get(), rebuilt.get()}) {
    EXPECT_TRUE(structureValid(*o));
    expectAgrees(*o, GetParam().name + (o->wasRefitted() ? " refitted" : " rebuilt"), 11);
  }
}

TEST_P(MeshDeform, TrianglesTurningDegenerateOrValidRebuild) {
  auto object = buildChecked(std::make_shared<const TriangleMesh>(icosphere(3)), GetParam().config);
  const TriangleMesh::Triangle t0 = object->mesh().triangles()[0];
  std::vector<glm::vec3> p = object->mesh().positions();
  const glm::vec3 kept = p[t0[1]];
  p[t0[1]] = p[t0[0]];  // triangle 0 (and its neighbours through that vertex) collapse
  const auto collapsed = object->deformedMesh(p);
  EXPECT_FALSE(collapsed->wasRefitted());
  EXPECT_GT(collapsed->mesh().degenerateCount(), 0u);
  EXPECT_TRUE(structureValid(*collapsed));
  expectAgrees(*collapsed, GetParam().name + " collapsed", 3);
  // And back: the triangles are valid again and must be found.
  p[t0[1]] = kept;
  const auto restored = collapsed->deformedMesh(p);
  EXPECT_FALSE(restored->wasRefitted());
  EXPECT_EQ(restored->mesh().degenerateCount(), 0u);
  EXPECT_TRUE(structureValid(*restored));
  const auto v = restored->mesh().vertices(0);
  const glm::vec3 centroid = (v[0] + v[1] + v[2]) / 3.0f;
  Ray ray;
  ray.origin = centroid * 3.0f;
  ray.dir = centroid - ray.origin;
  Hit hit;
  ASSERT_TRUE(restored->intersect(ray, hit));
  EXPECT_EQ(hit.prim_id, 0u);
  expectAgrees(*restored, GetParam().name + " restored", 4);
}

TEST_P(MeshDeform, BadPositionsAreRefusedNamingTheMesh) {
  const auto object =
      buildChecked(std::make_shared<const TriangleMesh>(icosphere(2, 1.0, glm::dvec3(0.0))), GetParam().config);
  std::vector<glm::vec3> p = object->mesh().positions();
  p.pop_back();
  expectErrorNaming<InvalidArgument>([&] { (void)object->deformedMesh(p); }, "vertices");
  p = object->mesh().positions();
  p[3].y = std::numeric_limits<float>::quiet_NaN();
  expectErrorNaming<InvalidArgument>([&] { (void)object->deformedMesh(p); }, "vertex 3");
  p[3].y = std::numeric_limits<float>::infinity();
  expectErrorNaming<InvalidArgument>([&] { (void)object->deformedMesh(p); }, "not finite");
  // All triangles collapsed onto one point: no valid triangle is left.
  std::fill(p.begin(), p.end(), glm::vec3(1.0f));
  EXPECT_THROW((void)object->deformedMesh(p), InvalidArgument);
  // Through the Object interface too, and the object still answers as before.
  EXPECT_EQ(object->deformableVertexCount(), object->mesh().positions().size());
  EXPECT_THROW((void)static_cast<const Object&>(*object).deformed(std::vector<glm::vec3>(2)), InvalidArgument);
  EXPECT_TRUE(structureValid(*object));
  expectAgrees(*object, GetParam().name + " after refusals", 5);
}

INSTANTIATE_TEST_SUITE_P(Structures, MeshDeform, ::testing::ValuesIn(structureCases()),
                         [](const auto& info) { return info.param.name; });
INSTANTIATE_TEST_SUITE_P(Structures, MeshDeformBvh, ::testing::ValuesIn(bvhStructureCases()),
                         [](const auto& info) { return info.param.name; });

Affine translation(double x) {
  Affine a = Affine::identity();
  a.translation = glm::dvec3(x, 0.0, 0.0);
  return a;
}

/// A library with one deformable sphere and a graph with two instances of it, and a tracer.
struct DeformScene {
  std::shared_ptr<ObjectLibrary> library = std::make_shared<ObjectLibrary>();
  SceneGraph graph{library};
  ObjectId sphere =
      library->add("sphere", buildChecked(std::make_shared<const TriangleMesh>(icosphere(3)), BvhBuildConfig{}));
  NodeId left = graph.addInstance(kRootNode, sphere, translation(-3.0), "left");
  NodeId right = graph.addInstance(kRootNode, sphere, translation(3.0), "right");
  DeformScene() { (void)graph.commit(); }

  /// Brute force over the visible instances as committed.
  [[nodiscard]] RefScene reference() const {
    std::vector<RefTriangle> tris;
    for (const NodeId id : graph.visibleInstances()) {
      const auto& mesh = dynamic_cast<const MeshObject&>(*library->get(graph.node(id).object)).mesh();
      const auto t = refTriangles(mesh, graph.worldTransform(id), id);
      tris.insert(tris.end(), t.begin(), t.end());
    }
    return RefScene(std::move(tris));
  }
};

/// The tracer's hits on random rays against the brute force of the committed scene.
void expectTracerAgrees(const SceneTracer& tracer, const DeformScene& s, const std::string& label,
                        double min_hit_fraction = 0.05) {
  const RefScene ref = s.reference();
  const auto rays = randomRays(Box(glm::vec3(-6.0f, -3.0f, -3.0f), glm::vec3(6.0f, 3.0f, 3.0f)), 2000, 99);
  QueryContext ctx;
  HitTolerance tol;
  tol.abs_scale = 1e-5;
  std::size_t hits = 0, failures = 0;
  for (const Ray& r : rays) {
    const Hit hit = tracer.intersect(r, ctx);
    hits += hit.valid();
    const auto ok = agreesWithReference(hit, r, ref, tol, true);
    if (!ok && failures++ < 5) ADD_FAILURE() << label << ": " << ok.message();
  }
  EXPECT_GE(static_cast<double>(hits), min_hit_fraction * static_cast<double>(rays.size())) << label;
}

TEST(SceneDeform, EveryInstanceFollowsInOneCommit) {
  DeformScene s;
  SceneTracer tracer(s.graph);
  const auto before = s.library->get(s.sphere);
  const std::vector<glm::vec3> rest = dynamic_cast<const MeshObject&>(*before).mesh().positions();
  std::vector<glm::vec3> grown(rest.size());
  for (std::size_t i = 0; i < rest.size(); ++i) grown[i] = 1.6f * rest[i];
  s.graph.deformObject(s.sphere, grown);
  // Pending: the library and the tracer still hold the old sphere.
  EXPECT_TRUE(s.graph.hasPendingEdits());
  EXPECT_EQ(s.library->get(s.sphere), before);
  EXPECT_NE(s.graph.pendingObject(s.sphere), before);
  Ray ray;  // passes 1.3 above the right sphere's centre: misses radius 1, hits radius 1.6
  ray.origin = glm::vec3(3.0f, 1.3f, -10.0f);
  ray.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  QueryContext ctx;
  EXPECT_FALSE(tracer.intersect(ray, ctx).valid());
  const ChangeSet cs = s.graph.commit();
  EXPECT_EQ(cs.object_changed, (std::vector<NodeId>{s.left, s.right}));
  EXPECT_EQ(cs.objects_changed, (std::vector<ObjectId>{s.sphere}));
  EXPECT_TRUE(cs.moved.empty());
  const Hit hit = tracer.intersect(ray, ctx);
  ASSERT_TRUE(hit.valid());
  EXPECT_EQ(hit.instance_id, s.right);
  EXPECT_TRUE(dynamic_cast<const MeshObject&>(*s.library->get(s.sphere)).wasRefitted());
  expectTracerAgrees(tracer, s, "grown");
  // Steps chain their refits within a batch: two deformations before one commit, the last wins.
  s.graph.deformObject(s.sphere, smoothlyMoved(rest, 0.1f, 2.0f, 1));
  s.graph.deformObject(s.sphere, smoothlyMoved(rest, 0.2f, 2.0f, 2));
  (void)s.graph.commit();
  EXPECT_EQ(dynamic_cast<const MeshObject&>(*s.library->get(s.sphere)).mesh().positions(),
            smoothlyMoved(rest, 0.2f, 2.0f, 2));
  expectTracerAgrees(tracer, s, "wobbled");
}

TEST(SceneDeform, RollbackAndFailedEditsChangeNothing) {
  DeformScene s;
  SceneTracer tracer(s.graph);
  const auto before = s.library->get(s.sphere);
  const auto rest = dynamic_cast<const MeshObject&>(*before).mesh().positions();
  s.graph.deformObject(s.sphere, smoothlyMoved(rest, 0.3f, 2.0f, 3));
  s.graph.rollback();
  EXPECT_FALSE(s.graph.hasPendingEdits());
  EXPECT_EQ(s.graph.pendingObject(s.sphere), before);
  EXPECT_TRUE(s.graph.commit().empty());
  EXPECT_EQ(s.library->get(s.sphere), before);
  std::vector<glm::vec3> bad = rest;
  bad[0].x = std::numeric_limits<float>::infinity();
  expectErrorNaming<InvalidArgument>([&] { s.graph.deformObject(s.sphere, bad); }, "'sphere'");
  expectErrorNaming<InvalidArgument>([&] { s.graph.deformObject(s.sphere, std::vector<glm::vec3>(3)); }, "'sphere'");
  expectErrorNaming<InvalidArgument>([&] { s.graph.deformObject(77, rest); }, "77");
  expectErrorNaming<InvalidArgument>([&] { s.graph.replaceObject(s.sphere, nullptr); }, "'sphere'");
  EXPECT_FALSE(s.graph.hasPendingEdits());
  EXPECT_EQ(s.library->get(s.sphere), before);
  expectTracerAgrees(tracer, s, "unchanged");
}

TEST(SceneDeform, ReplacingWithAnotherTopologyAndRemovingObjects) {
  DeformScene s;
  SceneTracer tracer(s.graph);
  std::weak_ptr<const Object> old = s.library->get(s.sphere);
  std::shared_ptr<const Object> cube =
      buildChecked(boxMesh(glm::vec3(-1.2f), glm::vec3(1.2f), "cube"), BvhBuildConfig{});
  const std::weak_ptr<const Object> cube_ref = cube;
  s.graph.replaceObject(s.sphere, std::move(cube));
  const ChangeSet cs = s.graph.commit();
  EXPECT_EQ(cs.object_changed, (std::vector<NodeId>{s.left, s.right}));
  EXPECT_EQ(s.library->get(s.sphere), cube_ref.lock());
  EXPECT_EQ(s.library->name(s.sphere), "sphere");  // same handle, same name
  EXPECT_TRUE(old.expired());                      // nothing holds the replaced sphere any more
  expectTracerAgrees(tracer, s, "cube");

  // An object in use cannot be removed: the message names its instances.
  expectErrorNaming<InvalidArgument>([&] { s.graph.removeObject(s.sphere); }, "/left");
  // Not while a pending edit or the committed state still uses it either.
  const ObjectId spare = s.library->add("spare", tinyMeshObject("spare"));
  s.graph.setObject(s.right, spare);
  expectErrorNaming<InvalidArgument>([&] { s.graph.removeObject(spare); }, "/right");  // pending user
  s.graph.remove(s.left);
  expectErrorNaming<InvalidArgument>([&] { s.graph.removeObject(s.sphere); }, "committed or pending");
  (void)s.graph.commit();
  const std::size_t with_sphere = s.library->memoryBytes();
  EXPECT_EQ(with_sphere, s.library->memoryBytes(s.sphere) + s.library->memoryBytes(spare));
  s.graph.removeObject(s.sphere);
  EXPECT_TRUE(cube_ref.expired());  // neither the library nor the tracer holds it any more
  EXPECT_FALSE(s.library->contains(s.sphere));
  EXPECT_EQ(s.library->count(), 1u);
  EXPECT_EQ(s.library->size(), 2u);  // ids are not reused
  EXPECT_EQ(s.library->memoryBytes(), s.library->memoryBytes(spare));
  expectErrorNaming<InvalidArgument>([&] { (void)s.library->get(s.sphere); }, "removed");
  expectErrorNaming<InvalidArgument>([&] { s.graph.addInstance(kRootNode, s.sphere); }, "removed");
  expectErrorNaming<InvalidArgument>([&] { s.graph.removeObject(s.sphere); }, std::to_string(s.sphere));
  // Its name is free again.
  EXPECT_EQ(s.library->find("sphere"), std::nullopt);
  EXPECT_EQ(s.library->add("sphere", tinyMeshObject("sphere")), 2u);
  expectTracerAgrees(tracer, s, "after removal", 0.0);
}

}  // namespace
}  // namespace duplex::test
