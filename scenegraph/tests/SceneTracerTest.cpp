// SceneTracer over a SceneGraph: 10,000 random graph edits (add, remove, move, re-parent, replace,
// hide, mask, deform or replace a library object under all its instances) in random batches, each commit checked
// against a brute force over the visible instances and the top-level invariants; picking (nearest, all, per instance)
// with node paths, sensors in picks, precision 10^6 units from the origin, rectangle selection, batch queries
// (intersectAll too) on 1 and 2 threads, lazy builds, and what queries see before a commit.

#include "MeshChecks.h"
#include "SceneChecks.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"
#include "duplex/sensors/SensorObject.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>
#include <chrono>
#include <thread>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

/// A graph whose library holds a few small meshes (objects 0..3).
struct Fixture {
  std::shared_ptr<ObjectLibrary> library = std::make_shared<ObjectLibrary>();
  SceneGraph graph{library};
  std::vector<ObjectId> objects;
  Fixture() {
    objects.push_back(library->add("sphere", buildChecked(icosphere(2))));
    objects.push_back(library->add("box", buildChecked(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f), "box"))));
    objects.push_back(library->add("grid", buildChecked(flatGrid(6, 2, 0.0f, 0.25f))));
    objects.push_back(library->add("soup", buildChecked(triangleSoup(120, 7))));
  }
};

/// `count` instances of the fixture's objects in turn under the root, placed at random within
/// `spread` (randomPlacement), committed.
void scatterInstances(Fixture& f, int count, double spread, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  for (int i = 0; i < count; ++i) f.graph.addInstance(kRootNode, f.objects[i % 4], randomPlacement(rng, spread));
  f.graph.commit();
}

TEST(SceneTracer, TenThousandRandomGraphEditsAgreeWithBruteForce) {
  Fixture f;
  SceneGraph& g = f.graph;
  std::mt19937_64 rng(2024);
  // Every draw is a statement of its own, in the order GCC evaluated the call arguments (last
  // first): the order of arguments is unspecified, and the counts checked at the end hold for the
  // edits this sequence makes, whichever compiler builds the test.
  // Start: a few groups and transform nodes with instances below them.
  std::vector<NodeId> parents{kRootNode};
  for (int i = 0; i < 6; ++i) {
    const Affine placement = randomPlacement(rng, 6.0);
    const NodeId parent = parents[rng() % parents.size()];
    parents.push_back(g.addTransform(parent, placement));
  }
  for (int i = 0; i < 30; ++i) {
    const Affine placement = randomPlacement(rng, 8.0);
    const ObjectId object = f.objects[rng() % 4];
    g.addInstance(parents[rng() % parents.size()], object, placement);
  }
  g.commit();
  TopLevelConfig config;  // small scene, large batches: keep them incremental to test that path
  config.min_incremental_instances = 0;
  config.max_incremental_fraction = 1.0;
  config.rebuild_ratio = 1.5;  // few quality rebuilds, so that most commits stay incremental
  SceneTracer tracer(g, config);
  const Box world(glm::vec3(-9.0f), glm::vec3(9.0f));
  // The sphere's rest positions: deformations wobble around them, so that it keeps its size.
  const std::vector<glm::vec3> rest = dynamic_cast<const MeshObject&>(*f.library->get(f.objects[0])).mesh().positions();
  std::size_t object_edits = 0;

  std::size_t edits = 0, commits = 0, rejected = 0, rays_checked = 0, hits = 0;
  while (edits < 10000) {
    const int batch = 1 + static_cast<int>(rng() % 20);
    for (int e = 0; e < batch; ++e, ++edits) {
      // Live nodes of each kind (pending state).
      std::vector<NodeId> inst = g.instances();
      std::vector<NodeId> containers;
      for (NodeId p : parents)
        if (g.contains(p)) containers.push_back(p);
      parents = containers;
      const int kind = static_cast<int>(rng() % 13);
      try {
        if (kind < 2 || inst.size() < 10) {
          const std::uint32_t mask = rng() % 3 == 0 ? 2u : 0xFFFFFFFFu;
          const Affine placement = randomPlacement(rng, 8.0);
          const ObjectId object = f.objects[rng() % 4];
          g.addInstance(containers[rng() % containers.size()], object, placement, {}, mask);
        } else if (kind < 3 && containers.size() < 12) {
          const Affine placement = randomPlacement(rng, 4.0);
          parents.push_back(g.addTransform(containers[rng() % containers.size()], placement));
        } else if (kind < 4) {
          // Remove an instance, or now and then a whole transform node's subtree.
          if (rng() % 5 == 0 && containers.size() > 3) {
            const NodeId victim = containers[1 + rng() % (containers.size() - 1)];
            g.remove(victim);
          } else {
            g.remove(inst[rng() % inst.size()]);
          }
        } else if (kind < 7) {  // move an instance or a transform node (moves its subtree)
          const bool node = rng() % 3 == 0 && containers.size() > 1;
          const NodeId target = node ? containers[1 + rng() % (containers.size() - 1)] : inst[rng() % inst.size()];
          Affine a = g.node(target).local;
          std::uniform_real_distribution<double> u(-0.7, 0.7);
          const double dz = u(rng);
          const double dy = u(rng);
          const double dx = u(rng);
          a.translation += glm::dvec3(dx, dy, dz);
          if (rng() % 50 == 0) a.translation.x = std::numeric_limits<double>::quiet_NaN();  // must be rejected
          g.setTransform(target, a);
        } else if (kind < 8) {  // re-parent (cycles must be rejected)
          const bool node = rng() % 2 == 0 && containers.size() > 1;
          const NodeId what = node ? containers[1 + rng() % (containers.size() - 1)] : inst[rng() % inst.size()];
          g.reparent(what, containers[rng() % containers.size()]);
        } else if (kind < 9) {
          const ObjectId object = f.objects[rng() % 4];  // drawn first, as GCC evaluated the call
          g.setObject(inst[rng() % inst.size()], object);
        } else if (kind < 11) {
          const bool node = rng() % 3 == 0 && containers.size() > 1;
          const NodeId target = node ? containers[1 + rng() % (containers.size() - 1)] : inst[rng() % inst.size()];
          g.setVisible(target, !g.node(target).visible);
        } else if (kind < 12) {
          const NodeId target = inst[rng() % inst.size()];
          g.setMask(target, g.node(target).mask == 2u ? 0xFFFFFFFFu : 2u);
        } else if (rng() % 3 != 0) {  // deform the sphere under all its instances (refit or rebuild)
          std::vector<glm::vec3> p = rest;
          std::uniform_real_distribution<float> u(-0.15f, 0.15f);
          const float wz = u(rng);
          const float wy = u(rng);
          const float wx = u(rng);
          const glm::vec3 wobble(wx, wy, wz);
          for (glm::vec3& v : p)
            v += wobble * glm::vec3(std::sin(3.0f * v.y), std::sin(3.0f * v.z), std::sin(3.0f * v.x));
          if (rng() % 20 == 0) p.pop_back();  // must be rejected
          g.deformObject(f.objects[0], p);
          ++object_edits;
        } else {  // the soup gets another topology
          const std::uint64_t soup_seed = rng();
          const std::size_t soup_size = 60 + static_cast<std::size_t>(rng() % 120);
          g.replaceObject(f.objects[3], buildChecked(triangleSoup(soup_size, soup_seed)));
          ++object_edits;
        }
      } catch (const InvalidArgument&) {
        ++rejected;
      }
    }
    g.commit();
    ++commits;
    const Model model = visibleModel(g);
    ASSERT_EQ(tracer.topLevel().size(), model.size()) << "commit " << commits;
    const auto tree_ok = checkIncrementalTree(tracer.topLevel(), model);
    ASSERT_TRUE(tree_ok) << "commit " << commits;
    const std::vector<Ray> rays = randomRays(world, 300, 77 + commits);
    QueryContext ctx;
    for (std::size_t r = 0; r < rays.size(); ++r) {
      const std::uint32_t mask = r % 4 == 0 ? 2u : 0xFFFFFFFFu;
      const Hit got = tracer.intersect(rays[r], ctx, mask);
      const Hit want = bruteIntersect(model, rays[r], mask);
      ++rays_checked;
      hits += got.valid();
      ASSERT_TRUE(sameHit(got, want)) << "commit " << commits << ", ray " << r << " " << rays[r] << " mask " << mask;
      ASSERT_EQ(tracer.occluded(rays[r], ctx, mask), want.valid()) << "commit " << commits << ", ray " << r;
    }
  }
  EXPECT_GE(commits, 800u);
  EXPECT_GT(object_edits, 400u);
  EXPECT_GT(rejected, 20u);  // NaN transforms and cycles were tried, and refused
  EXPECT_GT(hits, 7500u);    // enough rays met geometry for the comparison to mean something
  const TopLevelStats st = tracer.stats();
  EXPECT_GT(st.commits, 800u);
  EXPECT_GT(st.subtree_rebuilds, 100u);             // the incremental path ran ...
  EXPECT_LT(st.full_rebuilds, st.commits * 3 / 4);  // ... for a good part of the commits
  EXPECT_LE(st.sah_cost, tracer.topLevel().config().rebuild_ratio * st.fresh_sah_cost * (1.0 + 1e-9));
}

TEST(SceneTracer, QueriesSeeEditsOnlyAfterCommit) {
  Fixture f;
  const NodeId a = f.graph.addInstance(kRootNode, f.objects[1], Affine::identity(), "a");
  f.graph.commit();
  SceneTracer tracer(f.graph);
  Ray r;
  r.origin = glm::vec3(0.0f, 0.0f, -10.0f);
  r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  QueryContext ctx;
  ASSERT_TRUE(tracer.intersect(r, ctx).valid());
  EXPECT_NEAR(tracer.intersect(r, ctx).t, 9.0f, 1e-5f);
  f.graph.setTransform(a, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 5}));
  EXPECT_NEAR(tracer.intersect(r, ctx).t, 9.0f, 1e-5f) << "pending edit visible before commit";
  f.graph.commit();
  EXPECT_NEAR(tracer.intersect(r, ctx).t, 14.0f, 1e-5f);
  f.graph.setVisible(a, false);
  f.graph.commit();
  EXPECT_FALSE(tracer.intersect(r, ctx).valid());
  f.graph.setVisible(a, true);
  f.graph.rollback();  // undone: stays hidden
  f.graph.commit();
  EXPECT_FALSE(tracer.intersect(r, ctx).valid());
}

TEST(SceneTracer, ACommitWhoseWorldTransformDegeneratesChangesNeitherGraphNorTracer) {
  // Valid local transforms whose product is singular (1e-60 * 1e-60 underflows the determinant):
  // the graph's commit refuses the batch before observers run, so the tracer never sees it, and
  // after a rollback both go on in step.
  Fixture f;
  SceneGraph& g = f.graph;
  const NodeId y = g.addInstance(kRootNode, f.objects[1], Affine::identity(), "y");
  g.commit();
  SceneTracer tracer(g);
  const Affine tiny = Affine::fromRowMajor3x4({1e-60, 0, 0, 0, 0, 1e-60, 0, 0, 0, 0, 1e-60, 0});
  const NodeId t = g.addTransform(kRootNode, tiny, "tiny");
  (void)g.addInstance(t, f.objects[1], tiny, "x");
  expectErrorNaming<InvalidArgument>([&] { g.commit(); }, "/tiny/x");
  EXPECT_EQ(tracer.topLevel().size(), 1u);
  EXPECT_TRUE(g.hasPendingEdits());
  g.rollback();
  // Move the other instance: the tracer follows.
  g.setTransform(y, Affine::fromRowMajor3x4({1, 0, 0, 5, 0, 1, 0, 0, 0, 0, 1, 0}));
  EXPECT_NO_THROW(g.commit());
  EXPECT_EQ(tracer.topLevel().size(), 1u);
  Ray r;
  r.origin = glm::vec3(5.0f, 0.0f, -10.0f);
  r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  QueryContext ctx;
  const Hit h = tracer.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, y);
  r.origin.x = 0.0f;
  EXPECT_FALSE(tracer.intersect(r, ctx).valid()) << "the old place of y";
}

TEST(SceneTracer, RefusesAGraphWithUncommittedEdits) {
  Fixture f;
  f.graph.addInstance(kRootNode, f.objects[0]);
  expectErrorNaming<InvalidArgument>([&] { SceneTracer tracer(f.graph); }, "uncommitted");
  f.graph.commit();
  SceneTracer tracer(f.graph);
  EXPECT_EQ(tracer.topLevel().size(), 1u);
}

TEST(SceneTracer, PickingModesAndPaths) {
  Fixture f;
  SceneGraph& g = f.graph;
  // A row of boxes along -z from the camera, under nested nodes.
  const NodeId car = g.addGroup(kRootNode, "car");
  const NodeId body = g.addTransform(car, Affine::identity(), "body");
  std::vector<NodeId> boxes;
  for (int i = 0; i < 3; ++i)
    boxes.push_back(g.addInstance(body, f.objects[1],
                                  Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -4.0 * i}),
                                  "box" + std::to_string(i), i == 1 ? 4u : 1u));
  g.commit();
  SceneTracer tracer(g);
  PinholeCamera cam;  // at the origin... moved back so it looks down -z at the boxes
  cam.eye = glm::dvec3(0.0, 0.0, 10.0);
  const auto nearest = tracer.pick(cam, 50.0, 50.0, 100, 100);
  ASSERT_EQ(nearest.size(), 1u);
  EXPECT_EQ(nearest[0].instance, boxes[0]);
  EXPECT_EQ(nearest[0].path, (std::vector<NodeId>{car, body, boxes[0]}));
  EXPECT_NEAR(nearest[0].position_ws.z, 1.0, 1e-6);
  EXPECT_NEAR(nearest[0].normal_ws.z, 1.0, 1e-6);
  EXPECT_EQ(g.path(nearest[0].instance), "/car/body/box0");

  // Through the box faces' diagonals (shared edges): each face is still crossed once.
  const auto all = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::AllSorted);
  ASSERT_EQ(all.size(), 6u);
  for (std::size_t k = 0; k < all.size(); ++k) {
    EXPECT_EQ(all[k].instance, boxes[k / 2]);
    EXPECT_NEAR(all[k].position_ws.z, 1.0 - 4.0 * double(k / 2) - 2.0 * double(k % 2), 1e-6);
  }
  const auto per = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::PerInstance);
  ASSERT_EQ(per.size(), 3u);
  EXPECT_EQ(per[2].instance, boxes[2]);
  const auto masked = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::PerInstance, 4u);
  ASSERT_EQ(masked.size(), 1u);
  EXPECT_EQ(masked[0].instance, boxes[1]);
  // Off to the side: nothing.
  EXPECT_TRUE(tracer.pick(cam, 0.5, 0.5, 100, 100).empty());
  expectErrorNaming<InvalidArgument>([&] { (void)tracer.pick(cam, 1.0, 1.0, 0, 100); }, "image size");
}

// Sensors never block, but a pick whose mask selects them sees them: the nearest pick returns a
// sensor in front of a surface, AllSorted lists it with the surface's hits (as intersectAll does),
// and a mask without the sensor's bits, or a sensor behind the surface, gives the surface.
TEST(SceneTracer, PickingSeesSensorsWhenTheMaskSelectsThem) {
  Fixture f;
  SceneGraph& g = f.graph;
  const ObjectId sensor = f.library->add(
      "sensor",
      std::make_shared<const SensorObject>("sensor", SensorSpec{.width = 1.0, .height = 1.0, .nx = 2, .ny = 2}));
  const NodeId box = g.addInstance(kRootNode, f.objects[1], Affine::identity(), "box", 1u);
  const NodeId front =
      g.addInstance(kRootNode, sensor, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3}), "front", 8u);
  const NodeId behind =
      g.addInstance(kRootNode, sensor, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -5}), "behind", 16u);
  g.commit();
  SceneTracer tracer(g);
  PinholeCamera cam;
  cam.eye = glm::dvec3(0.1, -0.2, 10.0);
  const auto nearest = tracer.pick(cam, 50.0, 50.0, 100, 100);
  ASSERT_EQ(nearest.size(), 1u);
  EXPECT_EQ(nearest[0].instance, front);
  EXPECT_NEAR(nearest[0].position_ws.z, 3.0, 1e-9);
  const auto surface = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::Nearest, 1u | 16u);
  ASSERT_EQ(surface.size(), 1u);
  EXPECT_EQ(surface[0].instance, box);
  EXPECT_NEAR(surface[0].position_ws.z, 1.0, 1e-9);
  const auto only_behind = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::Nearest, 16u);
  ASSERT_EQ(only_behind.size(), 1u);
  EXPECT_EQ(only_behind[0].instance, behind);
  EXPECT_NEAR(only_behind[0].position_ws.z, -5.0, 1e-9);

  const auto all = tracer.pick(cam, 50.0, 50.0, 100, 100, PickMode::AllSorted);
  ASSERT_EQ(all.size(), 4u);  // front sensor, the box's two faces, the sensor behind
  EXPECT_EQ(all[0].instance, front);
  EXPECT_EQ(all[1].instance, box);
  EXPECT_EQ(all[2].instance, box);
  EXPECT_EQ(all[3].instance, behind);
  // SceneTracer::intersectAll on the same ray (float) lists the same instances in the same order.
  Ray ray;
  ray.origin = glm::vec3(cam.eye);
  ray.dir = glm::vec3(cam.directionAt(50.0, 50.0, 100, 100));
  QueryContext ctx;
  const std::vector<Hit> hits = tracer.intersectAll(ray, ctx);
  ASSERT_EQ(hits.size(), all.size());
  for (std::size_t k = 0; k < hits.size(); ++k) {
    EXPECT_EQ(hits[k].instance_id, all[k].instance) << k;
    EXPECT_NEAR(hits[k].t, all[k].hit.t, 1e-5) << k;
  }
  EXPECT_TRUE(tracer.intersectAll(ray, ctx, 2u).empty());
  // Closest-hit queries never stop at a sensor.
  EXPECT_EQ(tracer.intersect(ray, ctx).instance_id, box);
}

TEST(SceneTracer, PicksReportCommittedPathsWhileEditsArePending) {
  // The tracer answers from the last commit; the path of a hit must come from the same state, not
  // from the graph's pending edits (a removed node is not "unknown" yet, a re-parented one is
  // still at its old place).
  Fixture f;
  SceneGraph& g = f.graph;
  const NodeId left = g.addGroup(kRootNode, "left");
  const NodeId right = g.addGroup(kRootNode, "right");
  const NodeId box = g.addInstance(left, f.objects[1], Affine::identity(), "box");
  g.commit();
  SceneTracer tracer(g);
  PinholeCamera cam;
  cam.eye = glm::dvec3(0.0, 0.0, 10.0);
  RayD ray;
  ray.origin = cam.eye;
  ray.dir = glm::dvec3(0.0, 0.0, -1.0);
  QueryContext ctx;
  const std::vector<NodeId> committed{left, box};

  g.reparent(box, right);
  EXPECT_EQ(g.pathIds(box), (std::vector<NodeId>{right, box})) << "the graph shows the pending edit";
  EXPECT_EQ(g.committedPathIds(box), committed);
  ASSERT_EQ(tracer.pick(cam, 50.0, 50.0, 100, 100).size(), 1u);
  EXPECT_EQ(tracer.pick(cam, 50.0, 50.0, 100, 100)[0].path, committed);
  EXPECT_EQ(tracer.intersectDetailed(ray, ctx).path, committed);
  g.remove(right);  // the box goes with it, still uncommitted
  EXPECT_FALSE(g.contains(box));
  EXPECT_EQ(g.committedPathIds(box), committed);
  EXPECT_EQ(tracer.intersectDetailed(ray, ctx).path, committed);
  const NodeId added = g.addInstance(kRootNode, f.objects[0], Affine::identity(), "added");
  expectErrorNaming<InvalidArgument>([&] { (void)g.committedPathIds(added); }, "last commit");
  g.rollback();
  g.reparent(box, right);
  g.commit();
  EXPECT_EQ(tracer.intersectDetailed(ray, ctx).path, (std::vector<NodeId>{right, box}));
  g.remove(box);
  g.commit();
  EXPECT_FALSE(tracer.intersectDetailed(ray, ctx).valid());
  expectErrorNaming<InvalidArgument>([&] { (void)g.committedPathIds(box); }, "last commit");
}

TEST(SceneTracer, PickingAndSelectionRefuseCamerasThatSelectEverything) {
  // A NaN or degenerate camera gave NaN or coincident frustum planes, which select every instance.
  Fixture f;
  (void)f.graph.addInstance(kRootNode, f.objects[1], Affine::identity(), "box");
  f.graph.commit();
  SceneTracer tracer(f.graph);
  PinholeCamera good;
  good.eye = glm::dvec3(0.0, 0.0, 10.0);
  ASSERT_EQ(tracer.selectRectangle(good, 40, 40, 60, 60, 100, 100).size(), 1u);
  ASSERT_TRUE(tracer.selectRectangle(good, 0, 0, 2, 2, 100, 100).empty());
  const auto bad = [&](auto&& change, const char* needle) {
    PinholeCamera c = good;
    change(c);
    expectErrorNaming<InvalidArgument>([&] { (void)tracer.selectRectangle(c, 0, 0, 2, 2, 100, 100); }, needle);
    expectErrorNaming<InvalidArgument>([&] { (void)tracer.pick(c, 50.0, 50.0, 100, 100); }, needle);
  };
  bad([](PinholeCamera& c) { c.eye.x = std::nan(""); }, "non-finite");
  bad([](PinholeCamera& c) { c.forward.z = INFINITY; }, "non-finite");
  bad([](PinholeCamera& c) { c.vertical_fov_deg = 0.0; }, "vertical_fov_deg");
  bad([](PinholeCamera& c) { c.vertical_fov_deg = std::nan(""); }, "vertical_fov_deg");
  bad([](PinholeCamera& c) { c.vertical_fov_deg = 180.0; }, "vertical_fov_deg");
  bad([](PinholeCamera& c) { c.up = c.right; }, "parallel");
  bad([](PinholeCamera& c) { c.forward = glm::dvec3(0.0); }, "zero");
}

TEST(SceneTracer, PickingFarFromTheOriginIsAsAccurateAsNearIt) {
  // The same unit sphere and the same relative camera, at the origin and 10^6 units away: the
  // picked points (relative to the sphere) agree to 1e-6 of the sphere's size. A float world ray
  // there would be off by up to 0.06 (the float spacing at 10^6).
  auto pickAt = [](double offset, double px, double py) {
    Fixture f;
    const Affine place = Affine::fromRowMajor3x4({1, 0, 0, offset, 0, 1, 0, offset, 0, 0, 1, offset});
    const NodeId t = f.graph.addTransform(kRootNode, place, "far");
    f.graph.addInstance(t, f.objects[0], Affine::identity(), "sphere");
    f.graph.commit();
    SceneTracer tracer(f.graph);
    PinholeCamera cam;
    cam.eye = glm::dvec3(offset, offset, offset + 4.0);
    const auto hits = tracer.pick(cam, px, py, 64, 64);
    return hits.empty() ? glm::dvec3(std::numeric_limits<double>::quiet_NaN())
                        : hits[0].position_ws - glm::dvec3(offset);
  };
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(20.0, 44.0);
  for (int k = 0; k < 50; ++k) {
    const double px = u(rng), py = u(rng);
    const glm::dvec3 near = pickAt(0.0, px, py), far = pickAt(1.0e6, px, py);
    ASSERT_TRUE(std::isfinite(near.x)) << px << ", " << py;
    EXPECT_LT(glm::length(near - far), 1e-6) << "pixel " << px << ", " << py << ": " << near.x << " vs " << far.x;
    EXPECT_NEAR(glm::length(near), 1.0, 0.05);  // on the (tessellated) unit sphere
  }
}

TEST(SceneTracer, RectangleSelectionFindsExactlyTheBoxesInTheFrustum) {
  Fixture f;
  std::mt19937_64 rng(8);
  std::vector<NodeId> all;
  for (int i = 0; i < 300; ++i)
    all.push_back(f.graph.addInstance(kRootNode, f.objects[i % 4], randomPlacement(rng, 40.0)));
  f.graph.commit();
  SceneTracer tracer(f.graph);
  const PinholeCamera cam = PinholeCamera::looking_at_box(tracer.bounds());
  const std::uint32_t w = 200, h = 150;
  // Independent check: a box is selected iff some point of it projects into the rectangle in front
  // of the camera. Sampled: the 8 corners, centre and face centres of each box (inside: must be
  // selected); all 8 corners on one outer side of the rectangle or behind (must not be).
  auto project = [&](const glm::dvec3& p, double& x, double& y) {
    const glm::dvec3 d = p - cam.eye;
    const double z = glm::dot(d, cam.forward);
    if (z <= 0.0) return false;
    const double half_h = std::tan(0.5 * cam.vertical_fov_deg * 3.14159265358979 / 180.0);
    const double half_w = half_h * w / h;
    x = (glm::dot(d, cam.right) / z / half_w + 1.0) * 0.5 * w;
    y = (1.0 - glm::dot(d, cam.up) / z / half_h) * 0.5 * h;
    return true;
  };
  std::uniform_real_distribution<double> ux(0.0, w), uy(0.0, h);
  for (int q = 0; q < 40; ++q) {
    double x0 = ux(rng), x1 = ux(rng), y0 = uy(rng), y1 = uy(rng);
    if (x0 > x1) std::swap(x0, x1);
    if (y0 > y1) std::swap(y0, y1);
    const std::vector<NodeId> got = tracer.selectRectangle(cam, x0, y0, x1, y1, w, h, 0xFFFFFFFFu, RegionMode::Boxes);
    for (const NodeId id : all) {
      const Box b = tracer.topLevel().instanceBounds(id);
      int left = 0, right = 0, top = 0, bottom = 0, behind = 0, inside = 0;
      for (int c = 0; c < 8; ++c) {
        const glm::dvec3 p(c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z);
        double x, y;
        if (!project(p, x, y)) {
          ++behind;
          continue;
        }
        left += x < x0;
        right += x > x1;
        top += y < y0;
        bottom += y > y1;
        inside += x >= x0 && x <= x1 && y >= y0 && y <= y1;
      }
      const bool selected = std::binary_search(got.begin(), got.end(), id);
      if (inside > 0) {
        EXPECT_TRUE(selected) << "query " << q << ": instance " << id << " has a corner inside";
      }
      if (behind == 0 && (left == 8 || right == 8 || top == 8 || bottom == 8)) {
        EXPECT_FALSE(selected) << "query " << q << ": instance " << id << " is entirely outside";
      }
    }
  }
}

TEST(SceneTracer, BatchQueriesReportProgressAndStopWhenCancelled) {
  Fixture f;
  scatterInstances(f, 100, 20.0, 5);
  SceneTracer tracer(f.graph);
  const std::vector<Ray> rays = randomRays(tracer.bounds(), 50000, 6);
  std::vector<Hit> hits(rays.size()), reference(rays.size());
  tracer.intersect(rays, reference);
  std::vector<std::size_t> done;
  CancelToken token;
  WorkControl control;
  control.cancel = &token;
  control.progress = [&](std::size_t d, std::size_t total) {
    EXPECT_EQ(total, rays.size());
    done.push_back(d);
  };
  tracer.intersect(rays, hits, 0xFFFFFFFFu, control);
  ASSERT_FALSE(done.empty());
  EXPECT_EQ(done.back(), rays.size());
  EXPECT_TRUE(std::is_sorted(done.begin(), done.end()));
  for (std::size_t i = 0; i < rays.size(); ++i) ASSERT_TRUE(sameHit(hits[i], reference[i])) << i;
  // Cancelled after the first chunk: no further chunk starts, Cancelled is thrown.
  done.clear();
  control.progress = [&](std::size_t d, std::size_t) {
    done.push_back(d);
    token.cancel();
  };
  std::vector<std::uint8_t> blocked(rays.size());
  EXPECT_THROW(tracer.occluded(rays, blocked, 0xFFFFFFFFu, control), Cancelled);
  ASSERT_FALSE(done.empty());
  EXPECT_LT(done.back(), rays.size());
  std::vector<ClosestPoint> near(8);
  EXPECT_THROW(tracer.closestPoints(std::vector<ClosestPointRequest>(8), near, 0xFFFFFFFFu, control), Cancelled);
  token.reset();
  tracer.closestPoints(std::vector<ClosestPointRequest>(8), near, 0xFFFFFFFFu, control);
  EXPECT_TRUE(near[0].valid());
}

TEST(SceneTracer, BatchQueriesGiveTheSameResultsOnOneAndTwoThreads) {
  Fixture f;
  scatterInstances(f, 200, 20.0, 12);
  SceneTracer tracer(f.graph);
  const std::vector<Ray> rays = randomRays(tracer.bounds(), 20000, 4);
  std::vector<Hit> one(rays.size()), two(rays.size());
  std::vector<std::uint8_t> occ1(rays.size()), occ2(rays.size());
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    tracer.intersect(rays, one);
    tracer.occluded(rays, occ1);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    tracer.intersect(rays, two);
    tracer.occluded(rays, occ2);
  }
  QueryContext ctx;
  std::size_t hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    ASSERT_TRUE(sameHit(one[i], two[i])) << i;
    ASSERT_EQ(one[i].instance_id, two[i].instance_id) << i;
    ASSERT_TRUE(sameHit(one[i], tracer.intersect(rays[i], ctx))) << i;
    ASSERT_EQ(occ1[i], occ2[i]) << i;
    ASSERT_EQ(occ1[i] != 0, one[i].valid()) << i;
    hits += one[i].valid();
  }
  EXPECT_GT(hits, rays.size() / 10);
  std::vector<Hit> wrong(3);
  expectErrorNaming<InvalidArgument>([&] { tracer.intersect(rays, wrong); }, "20000 rays");
}

TEST(SceneTracer, StreamedBatchesEqualTheSpanVersionsOnOneAndTwoThreads) {
  Fixture f;
  scatterInstances(f, 200, 20.0, 14);
  SceneTracer tracer(f.graph);
  // Not a multiple of the block size, so that the last block of a range is short.
  const std::vector<Ray> rays = randomRays(tracer.bounds(), 20011, 9);
  std::vector<Hit> reference(rays.size());
  std::vector<std::uint8_t> reference_occ(rays.size());
  tracer.intersect(rays, reference);
  tracer.occluded(rays, reference_occ);
  for (int threads = 1; threads <= 2; ++threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    std::vector<Hit> hits(rays.size());
    std::vector<std::uint8_t> occ(rays.size(), 7);
    std::vector<std::atomic<int>> loaded(rays.size()), stored(rays.size());
    const auto load = [&](std::size_t first, std::span<Ray> block) {
      ASSERT_LE(block.size(), SceneTracer::kStreamBlock);
      ASSERT_LE(first + block.size(), rays.size());
      for (std::size_t k = 0; k < block.size(); ++k) {
        block[k] = rays[first + k];
        loaded[first + k].fetch_add(1);
      }
    };
    tracer.intersectBlocks(rays.size(), load, [&](std::size_t first, std::span<const Hit> block) {
      for (std::size_t k = 0; k < block.size(); ++k) {
        hits[first + k] = block[k];
        stored[first + k].fetch_add(1);
      }
    });
    tracer.occludedBlocks(rays.size(), load, [&](std::size_t first, std::span<const std::uint8_t> block) {
      std::copy(block.begin(), block.end(), occ.begin() + static_cast<std::ptrdiff_t>(first));
    });
    for (std::size_t i = 0; i < rays.size(); ++i) {
      ASSERT_EQ(loaded[i].load(), 2) << i;  // each ray read once per batch, stored once
      ASSERT_EQ(stored[i].load(), 1) << i;
      ASSERT_TRUE(sameHit(hits[i], reference[i])) << i;
      ASSERT_EQ(hits[i].instance_id, reference[i].instance_id) << i;
      ASSERT_EQ(occ[i], reference_occ[i]) << i;
    }
  }
  // An exception from the loader or the store reaches the caller; empty functions are refused.
  const auto copy_rays = [&](std::size_t first, std::span<Ray> block) {
    std::copy_n(rays.begin() + static_cast<std::ptrdiff_t>(first), block.size(), block.begin());
  };
  EXPECT_THROW(tracer.intersectBlocks(rays.size(), copy_rays,
                                      [](std::size_t first, std::span<const Hit>) {
                                        if (first > 1000) throw std::runtime_error("disk full");
                                      }),
               std::runtime_error);
  expectErrorNaming<InvalidArgument>(
      [&] { tracer.occludedBlocks(rays.size(), copy_rays, SceneTracer::OccludedBlockStore{}); }, "occludedBlocks");
  // Cancelled once the first progress report arrives (a batch as large as the span test's).
  const std::vector<Ray> many = randomRays(tracer.bounds(), 50000, 6);
  const auto copy_many = [&](std::size_t first, std::span<Ray> block) {
    std::copy_n(many.begin() + static_cast<std::ptrdiff_t>(first), block.size(), block.begin());
  };
  CancelToken token;
  WorkControl control;
  control.cancel = &token;
  control.progress = [&](std::size_t, std::size_t) { token.cancel(); };
  std::atomic<std::size_t> stored_count{0};
  EXPECT_THROW(
      tracer.intersectBlocks(
          many.size(), copy_many, [&](std::size_t, std::span<const Hit> block) { stored_count += block.size(); },
          0xFFFFFFFFu, control),
      Cancelled);
  EXPECT_LT(stored_count.load(), many.size());
  // No rays: nothing is called.
  tracer.intersectBlocks(
      0, [](std::size_t, std::span<Ray>) { FAIL(); }, [](std::size_t, std::span<const Hit>) { FAIL(); });
}

TEST(SceneTracer, CommitsCompleteWhileQueriesKeepOverlapping) {
  Fixture f;
  scatterInstances(f, 300, 20.0, 15);
  const std::vector<NodeId> nodes = f.graph.visibleInstances();
  SceneTracer tracer(f.graph);
  const std::vector<Ray> rays = randomRays(tracer.bounds(), 3000, 10);
  // Query threads count the queries they start while a commit is under way. A commit waits only
  // for the queries already running, so the count stays small (what scheduling lets through
  // around the commit's own wait); with a lock that lets new queries pass a waiting commit it
  // grows without end, and the query threads stop at kBound so that the commit gets in and the
  // test fails instead of hanging.
  constexpr int kQueryThreads = 3;
  constexpr long kBound = 100;
  std::atomic<bool> stop{false}, in_commit{false}, starved{false};
  std::atomic<long> started{0}, commit_start{0}, total{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kQueryThreads; ++t) {
    threads.emplace_back([&] {
      std::vector<std::uint8_t> blocked(rays.size());
      tbb::task_arena one(1);  // each query thread traces alone, so that the queries overlap
      while (!stop.load() && !starved.load()) {
        const long n = started.fetch_add(1) + 1;
        if (in_commit.load() && n - commit_start.load() > kBound) {
          starved.store(true);
          break;
        }
        one.execute([&] { tracer.occluded(rays, blocked); });
        total.fetch_add(1);
      }
    });
  }
  while (total.load() < 3 * kQueryThreads) std::this_thread::yield();
  std::mt19937 rng(3);
  long most = 0;
  for (int c = 0; c < 30 && !starved.load(); ++c) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
    std::mt19937_64 placement(rng());
    f.graph.setTransform(nodes[rng() % nodes.size()], randomPlacement(placement, 20.0));
    commit_start.store(started.load());
    in_commit.store(true);
    f.graph.commit();
    in_commit.store(false);
    most = std::max(most, started.load() - commit_start.load());
  }
  stop.store(true);
  for (std::thread& t : threads) t.join();
  EXPECT_FALSE(starved.load()) << "more than " << kBound << " queries started while one commit waited";
  EXPECT_LE(most, kBound);
  EXPECT_GT(total.load(), 30);  // the queries did overlap the commits
}

TEST(SceneTracer, BatchIntersectAllEqualsOneRayAtATimeOnOneAndTwoThreads) {
  Fixture f;
  scatterInstances(f, 120, 6.0, 13);  // overlapping, so that many rays pass several layers
  SceneTracer tracer(f.graph);
  const std::vector<Ray> rays = randomRays(tracer.bounds(), 4000, 5);
  std::vector<Hit> flat[2];
  std::vector<std::size_t> offsets[2];
  for (int threads = 1; threads <= 2; ++threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    offsets[threads - 1] = {7, 7};  // replaced, not appended to
    tracer.intersectAll(rays, flat[threads - 1], offsets[threads - 1]);
  }
  QueryContext ctx;
  std::size_t layered = 0;
  for (int k = 0; k < 2; ++k) {
    ASSERT_EQ(offsets[k].size(), rays.size() + 1);
    ASSERT_EQ(offsets[k].front(), 0u);
    ASSERT_EQ(offsets[k].back(), flat[k].size());
  }
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const std::vector<Hit> single = tracer.intersectAll(rays[i], ctx);
    const Hit closest = tracer.intersect(rays[i], ctx);
    for (int k = 0; k < 2; ++k) {
      const std::size_t b = offsets[k][i], e = offsets[k][i + 1];
      ASSERT_EQ(e - b, single.size()) << "ray " << i << ", " << k + 1 << " threads";
      for (std::size_t j = 0; j < single.size(); ++j) {
        ASSERT_TRUE(sameHit(flat[k][b + j], single[j])) << i << " " << j;
        ASSERT_EQ(flat[k][b + j].instance_id, single[j].instance_id) << i << " " << j;
        if (j > 0) {
          ASSERT_LE(flat[k][b + j - 1].t, flat[k][b + j].t) << i << " " << j;
        }
      }
      // The first of the layers is the closest hit.
      ASSERT_EQ(e > b, closest.valid()) << i;
      if (e > b) {
        ASSERT_EQ(flat[k][b].t, closest.t) << i;
      }
    }
    layered += single.size() >= 2;
  }
  EXPECT_GT(layered, rays.size() / 20) << "too few rays pass several layers to test the batch";
  // Results replace what the vectors held; no rays give offsets {0} and no hits.
  std::vector<Hit> old_hits(5);
  std::vector<std::size_t> old_offsets{3, 4};
  tracer.intersectAll(std::span<const Ray>(rays.data(), 1), old_hits, old_offsets);
  ASSERT_EQ(old_offsets.size(), 2u);
  EXPECT_EQ(old_hits.size(), old_offsets[1]);
  EXPECT_EQ(old_hits.size(), offsets[0][1]);
  tracer.intersectAll(std::span<const Ray>(), old_hits, old_offsets);
  EXPECT_EQ(old_offsets, std::vector<std::size_t>{0});
  EXPECT_TRUE(old_hits.empty());
}

TEST(SceneTracer, ObjectsAreBuiltLazilyOnceAndShared) {
  auto library = std::make_shared<ObjectLibrary>();
  const ObjectId used = library->addDeferred("used", "mesh", [] { return buildChecked(icosphere(1)); });
  const ObjectId unused = library->addDeferred("unused", "mesh", [] { return buildChecked(icosphere(1)); });
  SceneGraph g(library);
  for (int i = 0; i < 50; ++i)
    g.addInstance(kRootNode, used, Affine::fromRowMajor3x4({1, 0, 0, 3.0 * i, 0, 1, 0, 0, 0, 0, 1, 0}));
  g.commit();
  SceneTracer tracer(g);
  EXPECT_EQ(library->buildCount(), 1u);
  EXPECT_TRUE(library->isBuilt(used));
  EXPECT_FALSE(library->isBuilt(unused));
  EXPECT_EQ(tracer.topLevel().size(), 50u);
}

}  // namespace
}  // namespace duplex::test
