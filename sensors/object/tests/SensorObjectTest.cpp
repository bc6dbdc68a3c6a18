// Sensor objects and the top level's crossing query: bins and border rules,
// one- and two-sided sensors, parallel rays, disk bin areas, and the crossing semantics (each
// crossing once, in t order, only before the first blocking hit) against a brute force.

#include "TestSupport.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"
#include "duplex/sensors/SensorObject.h"
#include "duplex/sensors/SensorTypes.h"
#include "SensorFixture.h"
#include "SlabMedium.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <vector>

namespace duplex {
namespace {

Ray downRay(double x, double y, double z = 1.0) {
  Ray r;
  r.origin = glm::vec3(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
  r.dir = glm::vec3(0.0f, 0.0f, -1.0f);
  return r;
}

using test::quad;
using test::sensor;
using test::translate;

SensorObject rectangle(double w, double h, std::uint32_t nx, std::uint32_t ny, bool two_sided = true) {
  return *sensor(w, h, nx, ny, two_sided);
}

TEST(SensorObject, BinsAreRowMajorFromTheLowerLeftCorner) {
  const SensorObject s = rectangle(2.0, 1.0, 4, 2);
  // Bin (0, 0) at (-w/2, -h/2), x fastest.
  EXPECT_EQ(s.binAt(-0.9, -0.4), 0u);
  EXPECT_EQ(s.binAt(0.9, -0.4), 3u);
  EXPECT_EQ(s.binAt(-0.9, 0.4), 4u);
  EXPECT_EQ(s.binAt(0.9, 0.4), 7u);
  EXPECT_DOUBLE_EQ(s.binArea(5), 0.25);
  EXPECT_DOUBLE_EQ(s.area(), 2.0);
}

TEST(SensorObject, EdgeAndBorderRules) {
  const SensorObject s = rectangle(2.0, 1.0, 4, 2);
  // Inner edges (x = -0.5, 0, 0.5; y = 0) go to the bin above; exactly representable here.
  EXPECT_EQ(s.binAt(-0.5, -0.25), 1u);
  EXPECT_EQ(s.binAt(0.0, -0.25), 2u);
  EXPECT_EQ(s.binAt(0.5, -0.25), 3u);
  EXPECT_EQ(s.binAt(-0.75, 0.0), 4u);
  // The border is closed: lower border to the first bin, upper border to the last.
  EXPECT_EQ(s.binAt(-1.0, -0.5), 0u);
  EXPECT_EQ(s.binAt(1.0, 0.5), 7u);
  EXPECT_EQ(s.binAt(1.0, -0.5), 3u);
  // Outside by one ulp.
  EXPECT_EQ(s.binAt(std::nextafter(1.0, 2.0), 0.0), kInvalidId);
  EXPECT_EQ(s.binAt(0.0, std::nextafter(-0.5, -1.0)), kInvalidId);
  // The same through crossings of rays.
  float t;
  SensorCell cell;
  ASSERT_TRUE(s.cross(downRay(1.0, 0.5), t, cell));
  EXPECT_EQ(cell.bin, 7u);
  EXPECT_FLOAT_EQ(t, 1.0f);
  ASSERT_TRUE(s.cross(downRay(0.0, 0.0), t, cell));
  EXPECT_EQ(cell.bin, 6u);
  EXPECT_FALSE(s.cross(downRay(1.0001, 0.0), t, cell));
}

TEST(SensorObject, OneSidedSensorsSeeOnlyRaysArrivingAtTheirFront) {
  const SensorObject one = rectangle(1.0, 1.0, 1, 1, /*two_sided=*/false);
  const SensorObject two = rectangle(1.0, 1.0, 1, 1, /*two_sided=*/true);
  float t;
  SensorCell cell;
  Ray down = downRay(0.1, 0.1, 1.0);  // from +z (front), travelling against the normal
  Ray up = down;
  up.origin.z = -1.0f;
  up.dir.z = 1.0f;  // from behind
  EXPECT_TRUE(one.cross(down, t, cell));
  EXPECT_FALSE(one.cross(up, t, cell));
  EXPECT_TRUE(two.cross(down, t, cell));
  EXPECT_TRUE(two.cross(up, t, cell));
}

TEST(SensorObject, ParallelRaysNeverCross) {
  const SensorObject s = rectangle(1.0, 1.0, 2, 2);
  float t;
  SensorCell cell;
  Ray in_plane;
  in_plane.origin = glm::vec3(-2.0f, 0.1f, 0.0f);
  in_plane.dir = glm::vec3(1.0f, 0.0f, 0.0f);
  EXPECT_FALSE(s.cross(in_plane, t, cell));
  Ray above = in_plane;
  above.origin.z = 0.5f;
  EXPECT_FALSE(s.cross(above, t, cell));
  // Outside [tnear, tfar]: no crossing.
  Ray short_ray = downRay(0.0, 0.0, 1.0);
  short_ray.tfar = 0.5f;
  EXPECT_FALSE(s.cross(short_ray, t, cell));
}

TEST(SensorObject, DiskBinAreasAreExact) {
  // Quadrant and full disk, and a brute-force grid count for an off-centre rectangle.
  const double r = 1.3;
  EXPECT_NEAR(diskRectangleArea(r, 0.0, 5.0, 0.0, 5.0), std::numbers::pi * r * r / 4.0, 1e-12);
  EXPECT_NEAR(diskRectangleArea(r, -5.0, 5.0, -5.0, 5.0), std::numbers::pi * r * r, 1e-12);
  EXPECT_EQ(diskRectangleArea(r, 1.0, 2.0, 1.0, 2.0), 0.0);
  const double x0 = 0.2, x1 = 1.1, y0 = -0.7, y1 = 0.9;
  const int n = 4000;
  std::size_t inside = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = x0 + (i + 0.5) * (x1 - x0) / n, y = y0 + (j + 0.5) * (y1 - y0) / n;
      inside += x * x + y * y <= r * r;
    }
  const double grid = static_cast<double>(inside) / (static_cast<double>(n) * n) * (x1 - x0) * (y1 - y0);
  EXPECT_NEAR(diskRectangleArea(r, x0, x1, y0, y1), grid, 2e-4);

  SensorSpec spec;
  spec.shape = SensorShape::Disk;
  spec.width = spec.height = 2.0 * r;
  spec.nx = 7;
  spec.ny = 5;
  const SensorObject disk("d", spec);
  double sum = 0.0;
  for (std::uint32_t b = 0; b < disk.binCount(); ++b) sum += disk.binArea(b);
  EXPECT_NEAR(sum, disk.area(), 1e-12);
  // Corners of the bounding square are outside the disk.
  EXPECT_EQ(disk.binAt(0.99 * r, 0.99 * r), kInvalidId);
  EXPECT_EQ(disk.binAt(r, 0.0), 2u * 7u + 6u);  // the right border: ix 6, iy 2
}

TEST(SensorObject, RejectsBadSpecs) {
  SensorSpec s;
  s.width = 0.0;
  EXPECT_THROW(SensorObject("a", s), InvalidArgument);
  s.width = 1.0;
  s.nx = 0;
  EXPECT_THROW(SensorObject("b", s), InvalidArgument);
  s.nx = 1;
  s.shape = SensorShape::Disk;
  s.height = 2.0;
  EXPECT_THROW(SensorObject("c", s), InvalidArgument);
  s.height = std::nan("");
  EXPECT_THROW(SensorObject("d", s), InvalidArgument);
}

// ---- the crossing query ----

TEST(CrossingQuery, CrossingsBeforeTheHitInOrderEachOnce) {
  // Sensors at z = 1, 2, 3 (the one at 2 is large: it spans many leaves), a wall at z = 2.5, and a
  // sensor lying on the wall.
  std::vector<InstanceDesc> inst = {{sensor(4, 4, 4, 4), translate(0, 0, 1), 10},
                                    {sensor(40, 40, 8, 8), translate(0, 0, 2), 11},
                                    {sensor(4, 4, 1, 1), translate(0, 0, 3), 12},
                                    {quad(5, "wall", 2.5), Affine::identity(), 20},
                                    {sensor(2, 2, 2, 2), translate(0, 0, 2.5), 13}};
  // Many small sensors elsewhere so that the tree has several leaves.
  for (std::uint32_t k = 0; k < 40; ++k)
    inst.push_back({sensor(0.5, 0.5, 1, 1), translate(10.0 + k, 7.0, -3.0 + 0.1 * k), 100 + k});
  TopLevel top;
  top.build(inst);
  QueryContext ctx;
  std::vector<Crossing> crossings;
  Ray r;
  r.origin = glm::vec3(0.3f, 0.2f, 0.0f);
  r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  const SegmentEnd end = top.intersectWithCrossings(r, crossings, ctx);
  ASSERT_TRUE(end.hit.valid());
  EXPECT_EQ(end.hit.instance_id, 20u);
  EXPECT_FLOAT_EQ(end.hit.t, 2.5f);
  EXPECT_EQ(end.transmittance, 1.0f);
  ASSERT_EQ(crossings.size(), 3u);
  EXPECT_EQ(crossings[0].hit.instance_id, 10u);
  EXPECT_EQ(crossings[1].hit.instance_id, 11u);
  EXPECT_EQ(crossings[2].hit.instance_id, 13u);  // coplanar with the wall: counted
  EXPECT_FLOAT_EQ(crossings[1].hit.t, 2.0f);
  // Bin of the crossing at z = 1: local (0.3, 0.2) in a 4 x 4 m sensor with 1 m bins -> (2, 2).
  EXPECT_EQ(crossings[0].hit.prim_id, 2u * 4u + 2u);
  // Closest-hit and any-hit queries never stop at a sensor.
  EXPECT_EQ(top.intersect(r, ctx).instance_id, 20u);
  Ray past = r;
  past.origin.x = 6.0f;  // beside the wall: crosses only the big sensor at z = 2
  EXPECT_FALSE(top.occluded(past, ctx));
  EXPECT_FALSE(top.intersect(past, ctx).valid());
  const SegmentEnd miss = top.intersectWithCrossings(past, crossings, ctx);
  EXPECT_FALSE(miss.hit.valid());
  ASSERT_EQ(crossings.size(), 1u);
  EXPECT_EQ(crossings[0].hit.instance_id, 11u);
  // Masks: no sensor role, no crossings; the hit stays.
  CrossingQuery q;
  q.crossing_mask = 0;
  EXPECT_EQ(top.intersectWithCrossings(r, crossings, ctx, q).hit.instance_id, 20u);
  EXPECT_TRUE(crossings.empty());
}

// Brute force: every sensor crossed within [tnear, t_hit (1 + slack)], sorted.
TEST(CrossingQuery, MatchesBruteForceOnRandomScenes) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int scene = 0; scene < 4; ++scene) {
    std::vector<InstanceDesc> inst;
    std::vector<std::shared_ptr<const SensorObject>> sensors;
    std::vector<Affine> sensor_world;
    for (std::uint32_t k = 0; k < 60; ++k) {
      const double width = 0.5 + std::abs(u(rng)), height = 0.5 + std::abs(u(rng));
      auto s = sensor(width, height, 3, 2, k % 2 == 0);
      // Random rotation (axis-angle) and position.
      glm::dvec3 axis = test::draw3<glm::dvec3>(u, rng);
      axis = glm::normalize(axis + glm::dvec3(0, 0, 1e-3));
      const double a = 3.0 * u(rng), c = std::cos(a), sn = std::sin(a), kk = 1 - c;
      const glm::dvec3 at = 5.0 * test::draw3<glm::dvec3>(u, rng);
      const Affine w =
          translate(at.x, at.y, at.z) *
          Affine::fromRowMajor3x4(
              {c + axis.x * axis.x * kk, axis.x * axis.y * kk - axis.z * sn, axis.x * axis.z * kk + axis.y * sn, 0,
               axis.y * axis.x * kk + axis.z * sn, c + axis.y * axis.y * kk, axis.y * axis.z * kk - axis.x * sn, 0,
               axis.z * axis.x * kk - axis.y * sn, axis.z * axis.y * kk + axis.x * sn, c + axis.z * axis.z * kk, 0});
      inst.push_back({s, w, k});
      sensors.push_back(s);
      sensor_world.push_back(w);
    }
    for (std::uint32_t k = 0; k < 10; ++k) {
      const double side = 0.5 + std::abs(u(rng));
      const glm::dvec3 at = 5.0 * test::draw3<glm::dvec3>(u, rng);
      inst.push_back({quad(side, "q"), translate(at.x, at.y, at.z), 1000 + k});
    }
    TopLevel top;
    top.build(inst);
    QueryContext ctx;
    std::vector<Crossing> crossings;
    std::size_t total = 0;
    for (int i = 0; i < 2000; ++i) {
      Ray r;
      r.origin = glm::vec3(6.0 * test::draw3<glm::dvec3>(u, rng));
      r.dir = glm::vec3(test::draw3<glm::dvec3>(u, rng));
      const SegmentEnd end = top.intersectWithCrossings(r, crossings, ctx);
      const Hit ref_hit = top.intersect(r, ctx);
      ASSERT_EQ(end.hit.valid(), ref_hit.valid());
      if (ref_hit.valid()) {
        EXPECT_EQ(end.hit.instance_id, ref_hit.instance_id);
        EXPECT_EQ(end.hit.t, ref_hit.t);
      }
      const float t_keep = (ref_hit.valid() ? ref_hit.t : r.tfar) * (1.0f + kCrossingSlack);
      std::vector<std::pair<float, std::uint32_t>> expected;
      for (std::size_t k = 0; k < sensors.size(); ++k) {
        const Affine of = sensor_world[k].inverse();
        Ray ro;
        ro.origin = glm::vec3(of.point(glm::dvec3(r.origin)));
        ro.dir = glm::vec3(of.vector(glm::dvec3(r.dir)));
        ro.tfar = t_keep;
        float t;
        SensorCell cell;
        if (sensors[k]->cross(ro, t, cell)) expected.push_back({t, static_cast<std::uint32_t>(k)});
      }
      std::sort(expected.begin(), expected.end());
      ASSERT_EQ(crossings.size(), expected.size()) << r;
      for (std::size_t k = 0; k < expected.size(); ++k) {
        EXPECT_EQ(crossings[k].hit.instance_id, expected[k].second);
        EXPECT_EQ(crossings[k].hit.t, expected[k].first);
      }
      total += expected.size();
    }
    EXPECT_GT(total, 100u);  // the scenes do produce crossings
  }
}

TEST(CrossingQuery, MediaAttenuateEachSegment) {
  Box slab;
  slab.lo = glm::vec3(-5, -5, 0.5f);
  slab.hi = glm::vec3(5, 5, 1.5f);
  std::vector<InstanceDesc> inst = {{sensor(4, 4, 1, 1), translate(0, 0, 1), 1},
                                    {sensor(4, 4, 1, 1), translate(0, 0, 2), 2},
                                    {std::make_shared<const test::SlabMedium>(0.7, slab), Affine::identity(), 3},
                                    {quad(5, "wall", 3), Affine::identity(), 4}};
  TopLevel top;
  top.build(inst);
  QueryContext ctx;
  std::vector<Crossing> crossings;
  Ray r;
  r.dir = glm::vec3(0, 0, 1);
  const SegmentEnd end = top.intersectWithCrossings(r, crossings, ctx);
  ASSERT_EQ(crossings.size(), 2u);
  EXPECT_NEAR(crossings[0].transmittance, std::exp(-0.7 * 0.5), 1e-6);  // half the slab
  EXPECT_NEAR(crossings[1].transmittance, std::exp(-0.7), 1e-6);        // the whole slab
  EXPECT_NEAR(end.transmittance, std::exp(-0.7), 1e-6);
  CrossingQuery no_media;
  no_media.medium_mask = 0;
  EXPECT_EQ(top.intersectWithCrossings(r, crossings, ctx, no_media).transmittance, 1.0f);
  EXPECT_EQ(crossings[1].transmittance, 1.0f);
}

TEST(SensorTypes, RegistryHasTheSensorType) {
  const ObjectTypeRegistry& r = sensorTypeRegistry();
  ASSERT_NE(r.find("sensor"), nullptr);
  EXPECT_FALSE(r.find("sensor")->in_scene_json_v1);
  EXPECT_EQ(builtinObjectTypes().find("sensor"), nullptr);  // duplex::objects knows nothing of sensors
  ObjectTypeRegistry twice = sensorTypeRegistry();
  EXPECT_THROW(registerSensorTypes(twice), InvalidArgument);
}

}  // namespace
}  // namespace duplex
