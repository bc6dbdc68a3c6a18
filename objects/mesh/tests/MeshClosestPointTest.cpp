/// \file MeshClosestPointTest.cpp
/// Closest-point queries against a double-precision brute force (plane projection or the nearest
/// edge, computed independently of the library's Voronoi walk): meshes through both structures
/// under identity, rotated and unevenly scaled transforms, points near, far, inside closed meshes,
/// on vertices and edges and 10^6 units from the origin; the maximum distance; and the scene
/// query (visible instances only, masks, the batch version, node paths); and every instruction
/// set's search kernel against the plain scalar search, bit for bit.

#include "MeshChecks.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "MeshClosestPoint.h"
#include "TriangleBlock4.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/PointQuery.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Nearest point of segment [a, b] to p.
glm::dvec3 onSegment(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b) {
  const glm::dvec3 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  const double t = len2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / len2, 0.0, 1.0) : 0.0;
  return a + t * ab;
}

/// Distance from p to triangle (a, b, c): the plane projection when it falls inside (barycentric
/// coordinates from Cramer's rule), else the nearest of the three edges.
double refDistance(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 n = glm::cross(b - a, c - a);
  const double n2 = glm::dot(n, n);
  if (n2 > 0.0) {
    const glm::dvec3 q = p - (glm::dot(p - a, n) / n2) * n;
    const double u = glm::dot(glm::cross(c - b, q - b), n) / n2;
    const double v = glm::dot(glm::cross(a - c, q - c), n) / n2;
    const double w = 1.0 - u - v;
    if (u >= 0.0 && v >= 0.0 && w >= 0.0) return glm::length(p - q);
  }
  return std::min(
      {glm::length(p - onSegment(p, a, b)), glm::length(p - onSegment(p, b, c)), glm::length(p - onSegment(p, c, a))});
}

struct RefInstance {
  const TriangleMesh* mesh;
  Affine world_from_object;
  std::uint32_t id;
};

/// The nearest distance over every valid triangle of the instances, and the (instance, triangle)
/// pairs within `slack` of it (ties: any of them is a right answer).
double refNearest(const std::vector<RefInstance>& instances, const glm::dvec3& p) {
  double best = kInf;
  for (const RefInstance& inst : instances)
    for (std::size_t t = 0; t < inst.mesh->triangleCount(); ++t) {
      if (!inst.mesh->isValid(t)) continue;
      const auto v = inst.mesh->vertices(t);
      best = std::min(best, refDistance(p, inst.world_from_object.point(glm::dvec3(v[0])),
                                        inst.world_from_object.point(glm::dvec3(v[1])),
                                        inst.world_from_object.point(glm::dvec3(v[2]))));
    }
  return best;
}

/// The answer is the reference's distance, its point lies on the triangle it names (of the
/// instance it names) at that distance from p, and the normal is that triangle's.
/// `want_known`: refNearest(instances, p), when the caller has it already.
::testing::AssertionResult answerIsRight(const ClosestPoint& got, const std::vector<RefInstance>& instances,
                                         const glm::dvec3& p, double scale, std::optional<double> want_known = {}) {
  const double want = want_known ? *want_known : refNearest(instances, p);
  const double tol = 1e-9 * (scale + glm::length(p));
  if (!got.valid()) return ::testing::AssertionFailure() << "nothing found, reference " << want;
  if (!(std::abs(got.distance - want) <= tol))
    return ::testing::AssertionFailure() << "distance " << got.distance << ", reference " << want;
  if (!(std::abs(glm::length(got.point_ws - p) - got.distance) <= tol))
    return ::testing::AssertionFailure() << "the point is not at the reported distance";
  const RefInstance* inst = nullptr;
  for (const RefInstance& i : instances)
    if (i.id == got.instance_id || instances.size() == 1) inst = &i;
  if (!inst) return ::testing::AssertionFailure() << "unknown instance " << got.instance_id;
  if (got.prim_id >= inst->mesh->triangleCount()) return ::testing::AssertionFailure() << "bad prim " << got.prim_id;
  const auto v = inst->mesh->vertices(got.prim_id);
  const glm::dvec3 a = inst->world_from_object.point(glm::dvec3(v[0]));
  const glm::dvec3 b = inst->world_from_object.point(glm::dvec3(v[1]));
  const glm::dvec3 c = inst->world_from_object.point(glm::dvec3(v[2]));
  if (!(refDistance(got.point_ws, a, b, c) <= tol))
    return ::testing::AssertionFailure() << "the point is not on triangle " << got.prim_id;
  const glm::dvec3 n = glm::normalize(glm::cross(b - a, c - a));
  if (!(glm::length(got.normal_ws - n) <= 1e-6)) return ::testing::AssertionFailure() << "wrong normal";
  return ::testing::AssertionSuccess();
}

/// Points around a box: inside it, on a box three times as large, far away (ten diagonals), and the
/// mesh's own vertices and edge midpoints (mapped to world space).
std::vector<glm::dvec3> queryPoints(const TriangleMesh& mesh, const Affine& world_from_object, std::uint64_t seed) {
  Box b;
  for (const glm::vec3& v : mesh.positions()) b.extend(glm::vec3(world_from_object.point(glm::dvec3(v))));
  const glm::dvec3 lo(b.lo), hi(b.hi), centre = (lo + hi) * 0.5, half = (hi - lo) * 0.5;
  const double diag = glm::length(hi - lo);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<glm::dvec3> pts;
  for (int i = 0; i < 60; ++i) pts.push_back(centre + draw3<glm::dvec3>(u, rng) * half);
  for (int i = 0; i < 30; ++i) pts.push_back(centre + 3.0 * draw3<glm::dvec3>(u, rng) * half);
  for (int i = 0; i < 10; ++i) pts.push_back(centre + 10.0 * diag * glm::normalize(draw3<glm::dvec3>(u, rng)));
  for (std::size_t t = 0; t < mesh.triangleCount(); t += std::max<std::size_t>(1, mesh.triangleCount() / 20)) {
    const auto v = mesh.vertices(t);
    pts.push_back(world_from_object.point(glm::dvec3(v[0])));
    pts.push_back(world_from_object.point((glm::dvec3(v[1]) + glm::dvec3(v[2])) * 0.5));
  }
  return pts;
}

Affine placement(int which) {
  Affine a = Affine::identity();
  if (which >= 1) {  // rotated about a tilted axis, moved
    const double c = std::cos(0.7), s = std::sin(0.7);
    a.linear = glm::dmat3(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0) * glm::dmat3(1.0, 0.0, 0.0, 0.0, c, s, 0.0, -s, c);
    a.translation = glm::dvec3(2.0, -1.0, 0.5);
  }
  if (which >= 2) a.linear = a.linear * glm::dmat3(3.0, 0.0, 0.0, 0.0, 0.25, 0.0, 0.0, 0.0, 1.5);  // uneven scale
  if (which >= 3) a.translation = glm::dvec3(1e6, -1e6, 1e6);  // far from the origin
  if (which == 4) {  // a similarity with a reflection: rotated, mirrored and scaled by 2.5 alike on every axis
    a = placement(1);
    a.linear = a.linear * glm::dmat3(-2.5, 0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0, 2.5);
  }
  return a;
}

/// The scalar search the SIMD kernels (MeshClosestPoint.h) must equal bit for bit: every box and
/// triangle box measured one at a time in double, children sorted by an insertion sort.
void scalarSearch(const WideBvh& bvh, const detail::TriangleBlock4* blocks, const glm::dvec3& p,
                  detail::ClosestPointSearch& s) {
  if (bvh.root == BvhRef::kEmpty) return;
  constexpr double kSlack = 1.0 + 1e-10;
  double prune2 = s.best2 * kSlack;
  std::vector<std::pair<std::uint32_t, double>> stack{{bvh.root, distanceSquared(bvh.bounds, p)}};
  while (!stack.empty()) {
    const auto [ref, box_d2] = stack.back();
    stack.pop_back();
    if (!(box_d2 < prune2)) continue;
    if (BvhRef::isLeaf(ref)) {
      for (std::uint32_t i = 0; i < BvhRef::leafCount(ref); ++i) {
        const detail::TriangleBlock4& b = blocks[BvhRef::leafBlock(ref) + i / 4];
        const int k = static_cast<int>(i % 4);
        double box2 = 0.0;
        for (int a = 0; a < 3; ++a) {
          const double x0 = b.v[a][k], x1 = b.v[3 + a][k], x2 = b.v[6 + a][k];
          const double lo = std::min(x0, std::min(x1, x2)), hi = std::max(x0, std::max(x1, x2));
          const double g = std::max(std::max(lo - p[a], p[a] - hi), 0.0);
          box2 += g * g;
        }
        if (!(box2 < prune2)) continue;
        const glm::dvec3 c = closestPointOnTriangle(p, glm::dvec3(b.vertex(k, 0)), glm::dvec3(b.vertex(k, 1)),
                                                    glm::dvec3(b.vertex(k, 2)));
        const double d2 = glm::dot(c - p, c - p);
        if (!(d2 < s.best2)) continue;
        s.best2 = d2;
        prune2 = d2 * kSlack;
        s.block = &b;
        s.lane = k;
        s.point = c;
      }
      continue;
    }
    const BvhNode8& node = bvh.nodes[ref];
    std::vector<std::pair<double, std::uint32_t>> order;
    for (int k = 0; k < BvhNode8::kWidth && node.child[k] != BvhRef::kEmpty; ++k) {
      double d2 = 0.0;
      for (int a = 0; a < 3; ++a) {
        const double g = std::max(std::max(double{node.lo[a][k]} - p[a], p[a] - double{node.hi[a][k]}), 0.0);
        d2 += g * g;
      }
      if (d2 < prune2) order.emplace_back(d2, node.child[k]);
    }
    for (std::size_t i = 1; i < order.size(); ++i)  // descending, equal keys in slot order
      for (std::size_t j = i; j > 0 && order[j - 1].first < order[j].first; --j) std::swap(order[j - 1], order[j]);
    for (const auto& [d2, child] : order) stack.emplace_back(child, d2);
  }
}

// Every instruction set's kernel that the CPU runs (capped by DUPLEX_ISA) returns what the scalar
// search returns, bit for bit: the same squared distance, triangle and point, so no path's result
// depends on the width it measured boxes with. Meshes with shared vertices and edges (ties), a
// soup with slivers and axis-aligned triangles; leaves of up to 16 triangles.
TEST(MeshClosestPointKernels, EveryPathEqualsTheScalarSearchBitForBit) {
  const TriangleMesh meshes[] = {icosphere(3), triangleSoup(3000, 11), flatGrid(24)};
  std::size_t compared = 0;
  for (const TriangleMesh& mesh : meshes) {
    std::vector<Box> boxes;
    for (std::size_t t = 0; t < mesh.triangleCount(); ++t) {
      const auto v = mesh.vertices(t);
      Box b;
      for (const glm::vec3& x : v) b.extend(x);
      boxes.push_back(b);
    }
    for (const std::uint32_t max_leaf : {4u, 8u, 16u}) {
      BvhBuildConfig config;
      config.max_leaf_size = max_leaf;
      const WideBvh bvh = buildWideBvh(boxes, config);
      ASSERT_EQ(bvh.leaf_block, 4u);
      std::vector<detail::TriangleBlock4> blocks(bvh.prim_indices.size() / 4);
      for (std::size_t b = 0; b < blocks.size(); ++b) {
        std::uint32_t prim = bvh.prim_indices[4 * b];
        for (int k = 0; k < 4; ++k) {  // padding lanes repeat the block's last triangle
          if (bvh.prim_indices[4 * b + k] != WideBvh::kPadding) prim = bvh.prim_indices[4 * b + k];
          const auto v = mesh.vertices(prim);
          blocks[b].set(k, v[0], v[1], v[2], prim);
        }
      }
      const Box box = mesh.bounds();
      const glm::dvec3 lo(box.lo), hi(box.hi), centre = (lo + hi) * 0.5, half = (hi - lo) * 0.5;
      std::mt19937_64 rng(max_leaf);
      std::uniform_real_distribution<double> u(-1.0, 1.0);
      std::vector<glm::dvec3> points;
      for (int i = 0; i < 300; ++i) points.push_back(centre + 1.5 * draw3<glm::dvec3>(u, rng) * half);
      for (int i = 0; i < 30; ++i)
        points.push_back(centre + 20.0 * glm::length(half) * glm::normalize(draw3<glm::dvec3>(u, rng)));
      for (std::size_t t = 0; t < mesh.triangleCount(); t += 7) points.emplace_back(mesh.vertices(t)[0]);
      for (const glm::dvec3& p : points) {
        for (const double radius2 : {kInf, 0.01 * glm::dot(half, half)}) {
          detail::ClosestPointSearch want;
          want.best2 = radius2;
          scalarSearch(bvh, blocks.data(), p, want);
          for (const SimdIsa isa : {SimdIsa::Sse2, SimdIsa::Avx2, SimdIsa::Avx512}) {
            if (isa > widestSimdIsa()) continue;
            detail::ClosestPointSearch got;
            got.best2 = radius2;
            detail::meshClosestPointKernel(isa)(bvh, blocks.data(), p, got);
            ASSERT_EQ(got.best2, want.best2) << toString(isa) << " at point " << &p - points.data();
            ASSERT_EQ(got.block, want.block) << toString(isa) << " at point " << &p - points.data();
            ASSERT_EQ(got.lane, want.lane) << toString(isa) << " at point " << &p - points.data();
            ASSERT_EQ(got.point, want.point) << toString(isa) << " at point " << &p - points.data();
            ++compared;
          }
        }
      }
    }
  }
  EXPECT_GT(compared, 3000u);
}

class MeshClosestPoint : public ::testing::TestWithParam<StructureCase> {};

TEST_P(MeshClosestPoint, AgreesWithTheBruteForceUnderEveryTransform) {
  for (const auto& [name, mesh] : {std::pair<std::string, std::shared_ptr<const TriangleMesh>>{
                                       "icosphere", std::make_shared<const TriangleMesh>(icosphere(3))},
                                   {"soup", std::make_shared<const TriangleMesh>(triangleSoup(300, 5))},
                                   {"grid", std::make_shared<const TriangleMesh>(flatGrid(8, 2, 0.0f, 0.25f))}}) {
    const auto object = buildChecked(mesh, GetParam().config);
    for (int which = 0; which < 5; ++which) {
      const Affine world = placement(which);
      const Affine object_from_world = world.inverse();
      const std::vector<RefInstance> ref{{mesh.get(), world, 0}};
      const double scale = coordinateScale(object->bounds()) * 3.0;
      std::size_t checked = 0;
      for (const glm::dvec3& p : queryPoints(*mesh, world, 11 + which)) {
        ClosestPoint best;
        QueryContext ctx;
        const bool found = object->closestPoint(PointQuery::make(p, world, object_from_world), best, ctx);
        EXPECT_TRUE(found);
        ASSERT_TRUE(answerIsRight(best, ref, p, scale))
            << name << ", placement " << which << ", point (" << p.x << ", " << p.y << ", " << p.z << ")";
        ++checked;
      }
      EXPECT_GT(checked, 100u);
    }
  }
}

TEST_P(MeshClosestPoint, TheMaximumDistanceBoundsTheSearch) {
  const auto mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const auto object = buildChecked(mesh, GetParam().config);
  const glm::dvec3 p(0.0, 0.0, 3.0);  // the unit sphere is about 2 away
  const std::vector<RefInstance> ref{{mesh.get(), Affine::identity(), 0}};
  const double d = refNearest(ref, p);
  QueryContext ctx;
  ClosestPoint near;
  near.distance = d * (1.0 - 1e-6);  // just short of the surface: nothing
  EXPECT_FALSE(object->closestPoint(PointQuery::make(p, Affine::identity(), Affine::identity()), near, ctx));
  EXPECT_FALSE(near.valid());
  ClosestPoint reach;
  reach.distance = d * (1.0 + 1e-6);
  EXPECT_TRUE(object->closestPoint(PointQuery::make(p, Affine::identity(), Affine::identity()), reach, ctx));
  EXPECT_NEAR(reach.distance, d, 1e-12);
}

INSTANTIATE_TEST_SUITE_P(Structures, MeshClosestPoint, ::testing::ValuesIn(structureCases()),
                         [](const auto& info) { return info.param.name; });

TEST(SceneClosestPoint, VisibleInstancesMasksBatchesAndPaths) {
  auto library = std::make_shared<ObjectLibrary>();
  SceneGraph graph(library);
  const auto sphere_mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const auto box_mesh = std::make_shared<const TriangleMesh>(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f), "box"));
  const ObjectId sphere = library->add("sphere", buildChecked(sphere_mesh, BvhBuildConfig{}));
  MeshBuildConfig kd;
  kd.structure = MeshStructure::KdTree;
  const ObjectId box = library->add("box", buildChecked(box_mesh, kd));
  std::mt19937_64 rng(3);
  std::vector<NodeId> nodes;
  const NodeId group = graph.addTransform(kRootNode, placement(1), "group");
  for (int i = 0; i < 40; ++i) {
    Affine a = randomPlacement(rng, 12.0);
    if (i % 3 == 0) a.linear = a.linear * glm::dmat3(1.0, 0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0, 0.5);
    nodes.push_back(graph.addInstance(i % 2 ? group : kRootNode, i % 4 ? sphere : box, a, {}, i % 5 == 0 ? 2u : 1u));
  }
  graph.setVisible(nodes[7], false);
  (void)graph.commit();
  SceneTracer tracer(graph);
  auto reference = [&](std::uint32_t mask) {
    std::vector<RefInstance> r;
    for (const NodeId id : graph.visibleInstances()) {
      const NodeInfo info = graph.node(id);
      if ((info.mask & mask) == 0) continue;
      r.push_back({info.object == sphere ? sphere_mesh.get() : box_mesh.get(), graph.worldTransform(id), id});
    }
    return r;
  };
  std::uniform_real_distribution<double> u(-20.0, 20.0);
  std::vector<ClosestPointRequest> requests;
  for (int i = 0; i < 150; ++i) requests.push_back({draw3<glm::dvec3>(u, rng), i % 10 == 0 ? 1.0 : kInf});
  for (const std::uint32_t mask : {0xFFFFFFFFu, 1u, 2u}) {
    const auto ref = reference(mask);
    std::vector<ClosestPoint> batch(requests.size());
    tracer.closestPoints(requests, batch, mask);
    std::size_t found = 0;
    for (std::size_t i = 0; i < requests.size(); ++i) {
      const SceneClosestPoint one = tracer.closestPoint(requests[i].point_ws, requests[i].max_distance, mask);
      EXPECT_EQ(one.point.distance, batch[i].distance) << i;
      EXPECT_EQ(one.point.instance_id, batch[i].instance_id) << i;
      const double want = refNearest(ref, requests[i].point_ws);
      if (want > requests[i].max_distance) {
        EXPECT_FALSE(one.valid()) << "request " << i << ": found " << one.point.distance << " beyond the maximum";
        EXPECT_EQ(one.point.distance, kInf);
        continue;
      }
      ++found;
      ASSERT_TRUE(answerIsRight(one.point, ref, requests[i].point_ws, 40.0, want))
          << "request " << i << ", mask " << mask;
      EXPECT_NE(one.instance, nodes[7]);  // hidden
      EXPECT_EQ(one.path, graph.committedPathIds(one.instance));
    }
    EXPECT_GT(found, requests.size() / 2) << "mask " << mask;
  }
  // Nothing to find: a NaN point, a negative reach, and a size mismatch in the batch.
  EXPECT_FALSE(tracer.closestPoint(glm::dvec3(std::nan(""), 0.0, 0.0)).valid());
  EXPECT_FALSE(tracer.closestPoint(glm::dvec3(0.0), -1.0).valid());
  std::vector<ClosestPoint> small(2);
  EXPECT_THROW(tracer.closestPoints(requests, small), InvalidArgument);
}

}  // namespace
}  // namespace duplex::test
