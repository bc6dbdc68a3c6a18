/// \file TopLevelSensorsTest.cpp
/// The top level keeps sensors in a level of their own. Randomised edits (add, remove, move, mask,
/// and objects that change role from mesh to sensor and back) against a brute force over every
/// instance: closest hits see no sensor, intersectAll sees everything, and the crossing query
/// reports exactly the sensor crossings before the blocking hit. Thousands of small sensors (the
/// sensors' shallow tree and its four-wide leaf box test) against the same brute force on rays of
/// every kind that test treats apart; the sensors' own build configuration.

#include "duplex/accel/Crossing.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/sensors/SensorObject.h"
#include "duplex/accel/KdTree.h"

#include "MeshChecks.h"
#include "TestSupport.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <string>
#include <random>
#include <vector>

namespace duplex {
namespace {

std::shared_ptr<const Object> squareSensor(const std::string& name, std::uint32_t bins) {
  return std::make_shared<const SensorObject>(name, SensorSpec{.width = 2.5, .height = 2.0, .nx = bins, .ny = bins});
}

/// Brute force over the model: every instance asked directly in object space.
struct Model {
  std::map<std::uint32_t, InstanceDesc> instances;

  [[nodiscard]] Hit closest(const Ray& ray, std::uint32_t mask) const {
    Hit best;
    best.t = ray.tfar;
    QueryContext ctx;
    bool found = false;
    for (const auto& [id, d] : instances) {
      if (!d.object->blocks() || (d.mask & mask) == 0) continue;
      Ray r = d.world_from_object.inverse().apply(ray);
      r.tfar = best.t;
      Hit h = best;
      if (d.object->intersect(r, h, ctx)) {
        best = h;
        best.instance_id = id;
        found = true;
      }
    }
    return found ? best : Hit{};
  }
  /// (instance id, bin, t) of every sensor crossing with t <= t_max, sorted by t then id.
  [[nodiscard]] std::vector<Hit> crossings(const Ray& ray, float t_max, std::uint32_t mask) const {
    std::vector<Hit> out;
    QueryContext ctx;
    for (const auto& [id, d] : instances) {
      if (d.object->role() != ObjectRole::Crossing || (d.mask & mask) == 0) continue;
      Ray r = d.world_from_object.inverse().apply(ray);
      r.tfar = t_max;
      std::vector<Hit> hits;
      d.object->intersectAll(r, hits, ctx);
      for (Hit& h : hits) {
        h.instance_id = id;
        out.push_back(h);
      }
    }
    std::sort(out.begin(), out.end(),
              [](const Hit& a, const Hit& b) { return a.t != b.t ? a.t < b.t : a.instance_id < b.instance_id; });
    return out;
  }
};

Affine randomPlacement(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const glm::dvec3 axis = test::draw3<glm::dvec3>(u, rng) + glm::dvec3(0.0, 0.0, 1e-3);
  const double angle = 3.0 * u(rng), scale = 0.8 + 0.3 * u(rng);
  return Affine::fromRowMajor3x4(
      test::rotationScaleTranslation(axis, angle, glm::dvec3(scale), 4.0 * test::draw3<glm::dvec3>(u, rng)));
}

/// `count` 2 x 2-bin sensors at random placements (ids 0, 1, ...) and a sphere (id `sphere_id`).
std::vector<InstanceDesc> sensorsAndSphere(std::uint32_t count, std::uint64_t seed, std::uint32_t sphere_id) {
  std::vector<InstanceDesc> instances;
  const auto sensor = squareSensor("s", 2);
  std::mt19937_64 rng(seed);
  for (std::uint32_t i = 0; i < count; ++i) instances.push_back({sensor, randomPlacement(rng), i, 0xFFFFFFFFu});
  instances.push_back({test::buildChecked(test::icosphere(2)), Affine::identity(), sphere_id, 0xFFFFFFFFu});
  return instances;
}

TEST(TopLevelSensors, RandomEditsWithRoleChangesAgreeWithBruteForce) {
  const std::vector<std::shared_ptr<const Object>> objects{
      test::buildChecked(test::icosphere(1)), test::buildChecked(test::boxMesh({-1, -0.5f, -0.3f}, {1, 0.5f, 0.3f})),
      squareSensor("s1", 1), squareSensor("s4", 4)};
  std::mt19937_64 rng(2024);
  std::uniform_int_distribution<int> pick_object(0, 3);
  Model model;
  TopLevelConfig config;
  config.min_incremental_instances = 4;  // exercise the incremental path of both levels
  TopLevel top(config);
  std::uint32_t next_id = 0;
  auto describe = [&](std::uint32_t id) {
    InstanceDesc d;
    d.id = id;
    d.object = objects[static_cast<std::size_t>(pick_object(rng))];
    d.world_from_object = randomPlacement(rng);
    d.mask = (rng() % 4 == 0) ? 2u : 1u | 2u;
    return d;
  };
  std::vector<InstanceDesc> initial;
  for (; next_id < 40; ++next_id) {
    initial.push_back(describe(next_id));
    model.instances[next_id] = initial.back();
  }
  top.build(initial);
  std::size_t role_changes = 0, crossings_seen = 0, blocked_crossings = 0;
  for (int round = 0; round < 60; ++round) {
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits; ++e) {
      const int kind = static_cast<int>(rng() % 4);
      if (kind == 0 || model.instances.empty()) {  // add
        const InstanceDesc d = describe(next_id++);
        top.set(d);
        model.instances[d.id] = d;
      } else {
        auto it = model.instances.begin();
        std::advance(it, static_cast<long>(rng() % model.instances.size()));
        if (kind == 1) {  // remove
          top.remove(it->first);
          model.instances.erase(it);
        } else {  // move, or replace the object (possibly changing its role), and the mask
          InstanceDesc d = describe(it->first);
          if (kind == 2) d.object = it->second.object;
          role_changes += d.object->role() != it->second.object->role();
          top.set(d);
          it->second = d;
        }
      }
    }
    top.commit();
    ASSERT_EQ(top.size(), model.instances.size());
    const std::size_t sensors =
        static_cast<std::size_t>(std::count_if(model.instances.begin(), model.instances.end(), [](const auto& kv) {
          return kv.second.object->role() == ObjectRole::Crossing;
        }));
    ASSERT_EQ(top.stats().crossing_instances, sensors);
    ASSERT_EQ(top.stats().instances + sensors, model.instances.size());
    for (const auto& [id, d] : model.instances) ASSERT_TRUE(top.contains(id)) << id;

    const auto rays = randomRays(top.bounds(), 250, 900 + static_cast<std::uint64_t>(round));
    QueryContext ctx;
    std::vector<Crossing> crossings;
    std::vector<Hit> all;
    for (const Ray& ray : rays) {
      for (const std::uint32_t mask : {0xFFFFFFFFu, 1u}) {
        const Hit expect = model.closest(ray, mask);
        const Hit got = top.intersect(ray, ctx, mask);
        ASSERT_EQ(got.valid(), expect.valid()) << "round " << round;
        if (expect.valid()) {
          ASSERT_EQ(got.instance_id, expect.instance_id);
          ASSERT_NEAR(got.t, expect.t, 1e-4f * (1.0f + expect.t));
        }
        CrossingQuery q;
        q.surface_mask = mask;
        q.crossing_mask = mask;
        const SegmentEnd end = top.intersectWithCrossings(ray, crossings, ctx, q);
        ASSERT_EQ(end.hit.valid(), expect.valid());
        if (expect.valid()) {
          ASSERT_EQ(end.hit.instance_id, expect.instance_id);
        }
        const float t_end = expect.valid() ? expect.t : ray.tfar;
        const auto want = model.crossings(ray, t_end * (1.0f + kCrossingSlack), mask);
        ASSERT_EQ(crossings.size(), want.size()) << "round " << round;
        for (std::size_t k = 0; k < want.size(); ++k) {
          ASSERT_EQ(crossings[k].hit.instance_id, want[k].instance_id);
          ASSERT_EQ(crossings[k].hit.prim_id, want[k].prim_id);
          ASSERT_NEAR(crossings[k].hit.t, want[k].t, 1e-4f * (1.0f + want[k].t));
        }
        crossings_seen += want.size();
        blocked_crossings += model.crossings(ray, ray.tfar, mask).size() - want.size();
      }
      // intersectAll sees both levels.
      top.intersectAll(ray, all, ctx);
      std::size_t sensor_hits = 0;
      for (const Hit& h : all) sensor_hits += model.instances.at(h.instance_id).object->role() == ObjectRole::Crossing;
      ASSERT_EQ(sensor_hits, model.crossings(ray, ray.tfar, 0xFFFFFFFFu).size());
    }
  }
  // The randomised run exercised what it is meant to.
  EXPECT_GT(role_changes, 20u);
  EXPECT_GT(crossings_seen, 500u);
  EXPECT_GT(blocked_crossings, 100u) << "no sensor was ever behind a surface";
}

TEST(TopLevelSensors, ClosestHitNeverTraversesTheSensors) {
  // 2,000 sensors and one sphere: a closest-hit query visits the sphere's level only.
  std::vector<InstanceDesc> instances = sensorsAndSphere(2000, 5, 5000);
  const auto sensor = instances.front().object;
  TopLevel top;
  top.build(instances);
  EXPECT_EQ(top.stats().instances, 1u);
  EXPECT_EQ(top.stats().crossing_instances, 2000u);
  EXPECT_EQ(top.tree().prim_indices.size(), 1u);
  ASSERT_NE(top.crossingLevel(), nullptr);
  QueryContext ctx;
  for (const Ray& ray : randomRays(top.bounds(), 500, 6)) (void)top.intersect(ray, ctx);
  EXPECT_LE(ctx.stats.instance_visits, 500u) << "closest-hit queries reached sensor instances";
  // The sensors' level is still complete: every sensor's box holds its own instance.
  EXPECT_EQ(top.crossingLevel()->size(), 2000u);
  EXPECT_FALSE(top.bounds().empty());
  for (std::uint32_t i = 0; i < 2000; i += 97) EXPECT_TRUE(top.contains(i));
  EXPECT_THROW(top.remove(99999), InvalidArgument);
  // A duplicate id across the two levels is refused by build, which changes nothing.
  instances.push_back({sensor, Affine::identity(), 5000, 0xFFFFFFFFu});
  EXPECT_THROW(top.build(instances), InvalidArgument);
  EXPECT_EQ(top.size(), 2001u);
}

/// A room of many small sensors at random places and orientations (the benchmark's kind of scene)
/// and a few blocking slabs, offset by `offset`: the crossing query against brute force on rays of
/// every kind the sensors' leaf test treats apart: random rays, rays with one or two zero direction
/// components (the scalar box test), rays aimed exactly at a sensor's border, corner or inner bin
/// edge, rays starting inside the room (tnear > 0 on some), before and after incremental edits.
void checkManySmallSensors(const glm::dvec3& offset, const TopLevelConfig& config) {
  SensorSpec spec;
  spec.width = 0.1;
  spec.height = 0.1;
  spec.nx = 4;
  spec.ny = 4;
  spec.two_sided = true;
  const auto small = std::make_shared<const SensorObject>("small", spec);
  spec.two_sided = false;
  const auto one_sided = std::make_shared<const SensorObject>("one_sided", spec);
  const auto slab = test::buildChecked(test::boxMesh({-1.0f, -1.0f, -0.05f}, {1.0f, 1.0f, 0.05f}));
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Model model;
  auto place = [&](std::uint32_t id) {
    InstanceDesc d;
    d.id = id;
    d.object = id % 5 == 0 ? one_sided : small;
    // A quarter of the sensors axis-aligned (flat world boxes, border in a box face), the rest
    // rotated at random.
    Affine a;
    if (id % 4 != 0) {
      const glm::dvec3 axis = test::draw3<glm::dvec3>(u, rng) - glm::dvec3(0.5, 0.5, 0.5 - 1e-3);
      const double angle = 6.3 * u(rng);
      a = Affine::fromRowMajor3x4(test::rotationScaleTranslation(axis, angle, glm::dvec3(1.0), glm::dvec3(0.0)));
    }
    a.translation = offset + glm::dvec3(-4.8, -4.8, 0.2) + glm::dvec3(9.6, 9.6, 3.6) * test::draw3<glm::dvec3>(u, rng);
    d.world_from_object = a;
    d.mask = id % 7 == 0 ? 2u : 1u | 2u;
    return d;
  };
  std::vector<InstanceDesc> instances;
  for (std::uint32_t id = 0; id < 3000; ++id) instances.push_back(place(id));
  for (std::uint32_t k = 0; k < 6; ++k) {
    Affine a;
    a.translation = offset + glm::dvec3(-3.0 + 1.2 * k, 2.0 - 0.8 * k, 0.5 + 0.5 * k);
    instances.push_back({slab, a, 10000 + k, 0xFFFFFFFFu});
  }
  for (const InstanceDesc& d : instances) model.instances[d.id] = d;
  TopLevel top(config);
  top.build(instances);

  std::size_t checked = 0, crossed = 0, axis_rays = 0, aimed = 0;
  auto check = [&](const Ray& ray, std::uint32_t mask) {
    CrossingQuery q;
    q.crossing_mask = mask;
    QueryContext ctx;
    std::vector<Crossing> crossings;
    const SegmentEnd end = top.intersectWithCrossings(ray, crossings, ctx, q);
    const Hit expect = model.closest(ray, 0xFFFFFFFFu);
    ASSERT_EQ(end.hit.valid(), expect.valid());
    const float t_end = expect.valid() ? expect.t : ray.tfar;
    const auto want = model.crossings(ray, t_end * (1.0f + kCrossingSlack), mask);
    ASSERT_EQ(crossings.size(), want.size()) << ray;
    for (std::size_t k = 0; k < want.size(); ++k) {
      ASSERT_EQ(crossings[k].hit.instance_id, want[k].instance_id) << ray;
      ASSERT_EQ(crossings[k].hit.prim_id, want[k].prim_id) << ray;
      ASSERT_EQ(crossings[k].hit.t, want[k].t) << ray;
    }
    ++checked;
    crossed += want.size();
  };
  auto run = [&](std::uint64_t seed) {
    std::mt19937_64 r(seed);
    std::uniform_real_distribution<double> v(0.0, 1.0);
    auto origin = [&] { return offset + glm::dvec3(-5.0 + 10.0 * v(r), -5.0 + 10.0 * v(r), 4.0 * v(r)); };
    for (int i = 0; i < 1500; ++i) {
      Ray ray;
      ray.origin = glm::vec3(origin());
      glm::dvec3 dir(v(r) - 0.5, v(r) - 0.5, v(r) - 0.5);
      if (i % 4 == 1) {  // one or two zero components
        dir[static_cast<int>(r() % 3)] = 0.0;
        if (i % 8 == 1) dir[static_cast<int>(r() % 3)] = 0.0;
        if (dir == glm::dvec3(0.0)) dir.x = 1.0;
        ++axis_rays;
      }
      ray.dir = glm::vec3(dir);
      ray.tnear = i % 3 == 0 ? static_cast<float>(2.0 * v(r)) : 0.0f;
      ray.tfar = 20.0f;
      ASSERT_NO_FATAL_FAILURE(check(ray, i % 2 ? 0xFFFFFFFFu : 1u));
    }
    // Aimed at a sensor's border, corner or inner bin edge (local x or y in {-w/2, 0, w/2}).
    for (int i = 0; i < 1500; ++i) {
      const InstanceDesc& d = model.instances.at(static_cast<std::uint32_t>(r() % 3000));
      const double edges[3] = {-0.05, 0.0, 0.05};
      glm::dvec3 local(edges[r() % 3], -0.05 + 0.1 * v(r), 0.0);
      if (i % 2) std::swap(local.x, local.y);
      if (i % 5 == 0) local.y = edges[r() % 3];
      const glm::dvec3 target = d.world_from_object.point(local);
      const glm::dvec3 from = origin();
      Ray ray;
      ray.origin = glm::vec3(from);
      ray.dir = glm::vec3(target - from);
      ray.tfar = 2.0f;
      ASSERT_NO_FATAL_FAILURE(check(ray, 0xFFFFFFFFu));
      ++aimed;
    }
  };
  ASSERT_NO_FATAL_FAILURE(run(1));
  // Incremental edits: 1% of the sensors move or change mask, some leave and come back.
  for (int round = 0; round < 3; ++round) {
    for (int e = 0; e < 30; ++e) {
      const auto id = static_cast<std::uint32_t>(rng() % 3000);
      if (e % 10 == 0) {
        top.remove(id);
        top.commit();
      }
      const InstanceDesc d = place(id);
      top.set(d);
      model.instances[id] = d;
    }
    top.commit();
    ASSERT_NO_FATAL_FAILURE(run(10 + static_cast<std::uint64_t>(round)));
  }
  EXPECT_GT(crossed, 500u);
  EXPECT_GT(axis_rays, 1000u);
  EXPECT_EQ(checked, 4u * 3000u);
  EXPECT_EQ(aimed, 4u * 1500u);
}

TEST(TopLevelSensors, ManySmallSensorsAgreeWithBruteForce) {
  ASSERT_NO_FATAL_FAILURE(checkManySmallSensors(glm::dvec3(0.0), TopLevelConfig{}));
}

TEST(TopLevelSensors, ManySmallSensorsFarFromTheOriginAgreeWithBruteForce) {
  ASSERT_NO_FATAL_FAILURE(checkManySmallSensors(glm::dvec3(3000.0, -2000.0, 500.0), TopLevelConfig{}));
}

TEST(TopLevelSensors, ManySmallSensorsAgreeUnderTheMainLevelsBuildDefaults) {
  // The sensors' tree shape changes nothing but speed: deep tree with small leaves, as the main
  // level builds it.
  TopLevelConfig config;
  config.crossing_build = topLevelBuildDefaults();
  ASSERT_NO_FATAL_FAILURE(checkManySmallSensors(glm::dvec3(0.0), config));
}

TEST(TopLevelSensors, SensorLevelBuildsWithItsOwnConfiguration) {
  const std::vector<InstanceDesc> instances = sensorsAndSphere(500, 9, 900);
  TopLevel shallow;
  shallow.build(instances);
  TopLevelConfig deep_config;
  deep_config.crossing_build = topLevelBuildDefaults();
  TopLevel deep(deep_config);
  deep.build(instances);
  // A lower intersection cost and no empty bonus: fewer nodes, more references per leaf.
  const KdTreeStats a = shallow.stats().crossing_tree, b = deep.stats().crossing_tree;
  EXPECT_LT(a.nodes, b.nodes);
  EXPECT_GT(static_cast<double>(a.references) / static_cast<double>(a.leaves - a.empty_leaves),
            static_cast<double>(b.references) / static_cast<double>(b.leaves - b.empty_leaves));
  // setConfig reaches the nested level: after a rebuild the trees are the same.
  shallow.setConfig(deep_config);
  shallow.rebuild();
  EXPECT_EQ(shallow.stats().crossing_tree.nodes, b.nodes);
  EXPECT_EQ(shallow.stats().tree.nodes, deep.stats().tree.nodes);
  // The sensors' configuration is validated like the main one, naming it.
  TopLevelConfig bad;
  bad.crossing_build.intersection_cost = 0.0f;
  try {
    TopLevel t(bad);
    ADD_FAILURE() << "no exception";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("crossing_build"), std::string::npos) << e.what();
  }
  bad = TopLevelConfig{};
  bad.crossing_build.empty_bonus = 1.0f;
  EXPECT_THROW(shallow.setConfig(bad), InvalidArgument);
}

}  // namespace
}  // namespace duplex
