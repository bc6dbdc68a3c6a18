// Paths restarting from surfaces far from the origin: the offset off a surface follows the hit's
// own rounding error (its triangle and transform), not the size of the scene or of the object, so
// that a thin glass pane, a thin layer, a diffuse or mirror reflector with a sensor just above it
// behave at 1 km and 100 km from the origin as at the origin, and in a mesh that reaches 1 km.
// Every surface event that restarts a path is covered: refraction and reflection (glass),
// scattering (Lambertian), specular reflection (mirror) and sensors close to the surface.

#include "duplex/objects/ProceduralMesh.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorRunChunk.h"
#include "SlabRuns.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <cstdio>
#include <numbers>

namespace duplex {
namespace {

using namespace test;
constexpr double kDeg = std::numbers::pi / 180.0;

TEST(SensorRestart, PaneTransmitsTheSameFarFromTheOrigin) {
  // A 6 mm pane of n = 1.52 (faces normal to z) at 60 degrees, moved along x: authored there and
  // placed by a translation.
  const double n = 1.52, d = 0.006, th = 60.0 * kDeg;
  const Material glass = Dielectric{n};
  const SlabResponse ref = slabUnpolarised(n, d, 0.0, th);
  for (const double x : {0.0, 1e3, 1e5}) {
    const SlabFrame fr{{x, 0.0, 0.0}, {0, 0, 1}, {1, 0, 0}};
    expectSlab(slabRun(fr, d, glass, th, false), ref, "pane authored at x = " + std::to_string(x));
    expectSlab(slabRun(fr, d, glass, th, true), ref, "pane placed at x = " + std::to_string(x));
  }
  // At the origin, in a mesh that also holds a triangle 1 km away.
  const SlabFrame origin{{0.0, 0.0, 0.0}, {0, 0, 1}, {1, 0, 0}};
  expectSlab(slabRun(origin, d, glass, th, false, {{1000, 0, 0}, {1000, 1, 0}, {1000, 0, 1}}), ref,
             "pane in a mesh reaching 1 km");
}

TEST(SensorRestart, ThinLayersAlongTheirDistanceToTheOrigin) {
  // Layers whose thickness is 1e-4 of their distance to the origin, the distance along their normal.
  const double n = 1.52, th = 60.0 * kDeg;
  const Material glass = Dielectric{n};
  for (const double dist : {1e3, 1e5}) {
    const double d = 1e-4 * dist;
    const SlabResponse ref = slabUnpolarised(n, d, 0.0, th);
    const SlabFrame fr{{dist, 0.0, 0.0}, {1, 0, 0}, {0, 0, 1}};
    expectSlab(slabRun(fr, d, glass, th, false), ref,
               "layer of " + std::to_string(d) + " authored at x = " + std::to_string(dist));
    expectSlab(slabRun(fr, d, glass, th, true), ref,
               "layer of " + std::to_string(d) + " placed at x = " + std::to_string(dist));
  }
}

// A reflector plate (2 x 2, 1 mm thick) with its top face normal to frame.n at frame.centre, a beam at
// theta, and a two-sided sensor (100 x 100) at height h above the face: it records the beam coming
// down (1) and the reflected light going up (exactly rho times the configuration factor from the
// lit spot to the sensor for a Lambertian plate, rho for a mirror).
void expectReflectorWithSensorAbove(const SlabFrame& fr, const Material& m, double h, double theta, bool placed) {
  SCOPED_TRACE(placed ? "placed" : "authored");
  Fixture f;
  const double thick = 1e-3;
  const glm::dvec3 size = glm::dvec3(2.0) - (2.0 - thick) * glm::abs(fr.n);
  const glm::dvec3 box_centre = fr.centre - (thick / 2) * fr.n;
  if (placed)
    f.add(boxAt(size, glm::dvec3(0.0), "plate"), translate(box_centre.x, box_centre.y, box_centre.z), "plate", m);
  else f.add(boxAt(size, box_centre, "plate"), Affine::identity(), "plate", m);
  const double a = 50.0;
  f.add(sensor(2 * a, 2 * a, 1, 1, true, "above"), facing(fr.n, fr.centre + h * fr.n), "above");
  const glm::dvec3 dir = std::sin(theta) * fr.t - std::cos(theta) * fr.n;
  const SensorScene scene = f.scene({beamLight(fr.centre - dir * (2.0 * h / std::cos(theta)), dir, 1e-4 * h)});
  SensorRunConfig cfg;
  cfg.seed = 5;
  SensorRun run(scene, cfg);
  (void)run.runUntil(40000);
  const SensorRunResults r = run.results();
  EXPECT_EQ(r.energy.failed_rays, 0u);
  const SensorResult& s = r.sensors[0];
  // The lit spot is the plate's centre, right below the sensor's.
  const double factor = m.is<Lambertian>() ? pointToParallelRectangle(-a, a, -a, a, h) : 1.0;
  const double reflectance =
      m.is<Lambertian>() ? m.as<Lambertian>()->reflectance.value : m.as<Mirror>()->reflectance.value;
  const double expected = 1.0 + reflectance * factor;
  const std::string what = std::string(m.name()) + " at " + std::to_string(glm::length(fr.centre)) +
                           (placed ? " placed" : " authored") + ", sensor " + std::to_string(h) + " above";
  std::printf("%s: %.5f +- %.5f (exact %.5f)\n", what.c_str(), s.total_flux_w, s.total_flux_stderr_w, expected);
  EXPECT_LT(std::abs(s.total_flux_w - expected), 4.0 * s.total_flux_stderr_w + 2e-3 * expected) << what;
}

TEST(SensorRestart, ReflectorsWithASensorJustAboveFarFromTheOrigin) {
  const Material lambert = Lambertian{0.6};
  const Material mirror = Mirror{0.8};
  for (const bool placed : {false, true}) {
    // Normal across the displacement: a sensor 1 mm above a plate 100 km away.
    const SlabFrame across{{1e5, 0.0, 0.0}, {0, 0, 1}, {1, 0, 0}};
    expectReflectorWithSensorAbove(across, lambert, 1e-3, 30.0 * kDeg, placed);
    expectReflectorWithSensorAbove(across, mirror, 1e-3, 30.0 * kDeg, placed);
    // Normal along the displacement: the sensor 1e-4 of the distance above the plate.
    const SlabFrame along{{1e3, 0.0, 0.0}, {1, 0, 0}, {0, 0, 1}};
    expectReflectorWithSensorAbove(along, lambert, 0.1, 30.0 * kDeg, placed);
    expectReflectorWithSensorAbove(along, mirror, 0.1, 30.0 * kDeg, placed);
  }
}

TEST(SensorRestart, OffsetBoundsFollowTheTriangleNotTheMesh) {
  // The bound is a few float ulps of the hit's own coordinates across the plane, whatever else the
  // mesh holds, and it grows with a transform's magnification of world errors.
  const std::array<glm::vec3, 3> small{glm::vec3(0, 0, 0), glm::vec3(1, 0, 0), glm::vec3(0, 1, 0)};
  SurfaceInstance si;
  const detail::RestartPoint at_origin = detail::restartFromTriangle(small, 0.25f, 0.25f, si, {0, 0, 1});
  EXPECT_NEAR(at_origin.p_ws.x, 0.25, 1e-15);
  EXPECT_EQ(at_origin.p_ws.z, 0.0);
  EXPECT_GT(at_origin.offset, 0.0);
  EXPECT_LT(at_origin.offset, 1e-5);  // gamma(12) of a unit triangle, twice
  // The same triangle moved to x = 1e5 in its plane: no larger across the plane than at the origin,
  // beyond the extent term.
  std::array<glm::vec3, 3> far = small;
  for (glm::vec3& v : far) v.x += 1e5f;
  const detail::RestartPoint moved = detail::restartFromTriangle(far, 0.25f, 0.25f, si, {0, 0, 1});
  EXPECT_LE(moved.offset, at_origin.offset * 1.0000001);
  // Moved along its normal to z = 1e5: bounded by a few ulps there (ulp(1e5) = 2^-7).
  std::array<glm::vec3, 3> high = small;
  for (glm::vec3& v : high) v.z += 1e5f;
  const detail::RestartPoint up = detail::restartFromTriangle(high, 0.25f, 0.25f, si, {0, 0, 1});
  EXPECT_GT(up.offset, 0x1p-24 * 1e5);
  EXPECT_LT(up.offset, 8.0 * 0x1p-24 * 1e5 + at_origin.offset);
  // Placed at z = 1e5 by a translation: the world error and the object error both count.
  SurfaceInstance placed;
  placed.world_from_object.translation = {0, 0, 1e5};
  placed.object_from_world = placed.world_from_object.inverse();
  placed.identity = false;
  const detail::RestartPoint tr = detail::restartFromTriangle(small, 0.25f, 0.25f, placed, {0, 0, 1});
  EXPECT_NEAR(tr.p_ws.z, 1e5, 1e-9);
  EXPECT_GT(tr.offset, 0x1p-24 * 1e5);
  EXPECT_LT(tr.offset, 8.0 * 0x1p-24 * 1e5 + at_origin.offset);
}

TEST(SensorRestart, RebuiltPointIsTheHitOnTheTriangle) {
  // The point rebuilt from the hit's triangle and barycentrics is where the ray met it (o + t d, to
  // float precision), on a rotated, scaled and moved instance, and lies on the far side of the
  // offset: a ray from origin + offset along the normal does not meet the same triangle again.
  Fixture f;
  Affine placed = facing(glm::normalize(glm::dvec3(0.3, -0.5, 0.8)), {120.0, -40.0, 7.0});
  placed.linear *= 2.5;
  f.add(boxAt({1.0, 2.0, 3.0}, {0.1, 0.2, -0.3}, "box"), placed, "box", Material{Mirror{1.0}});
  f.add(sensor(1.0, 1.0, 1, 1), translate(0, 0, -50), "s");
  const SensorScene scene = f.scene({pointLight({0, 0, 0}, 1.0)});
  const TopLevel& top = scene.tracer().topLevel();
  QueryContext ctx;
  int hits = 0;
  for (int k = 0; k < 200; ++k) {
    const glm::dvec3 target =
        placed.point({0.1 + 0.4 * std::sin(k * 1.3), 0.2 + 0.9 * std::cos(k * 0.7), -0.3 + 1.4 * std::sin(k * 0.31)});
    const glm::dvec3 o(120.0 + 30.0 * std::cos(k * 0.9), -40.0 + 30.0 * std::sin(k * 0.9), 40.0);
    Ray ray;
    ray.origin = glm::vec3(o);
    ray.dir = glm::vec3(glm::normalize(target - o));
    const Hit hit = top.intersect(ray, ctx);
    if (!hit.valid()) continue;
    ++hits;
    const SurfaceInstance* si = scene.surfaceOf(hit.instance_id);
    ASSERT_NE(si, nullptr);
    const glm::dvec3 n = glm::normalize(glm::dvec3(hit.ng));
    const detail::RestartPoint rp =
        detail::restartFromTriangle(si->mesh->mesh().vertices(hit.prim_id), hit.u, hit.v, *si, n);
    const glm::dvec3 traced = glm::dvec3(ray.origin) + double(hit.t) * glm::dvec3(ray.dir);
    EXPECT_LT(glm::length(rp.p_ws - traced), 1e-4) << k;
    // Leaving to the side the ray came from, the same triangle is not met again.
    const glm::dvec3 back = glm::dot(glm::dvec3(ray.dir), n) < 0.0 ? n : -n;
    Ray again;
    again.origin = glm::vec3(rp.p_ws + back * rp.offset);
    again.dir = glm::vec3(glm::normalize(glm::dvec3(ray.dir) - 2.0 * glm::dot(glm::dvec3(ray.dir), n) * n));
    const Hit second = top.intersect(again, ctx);
    EXPECT_FALSE(second.valid() && second.prim_id == hit.prim_id && second.instance_id == hit.instance_id) << k;
  }
  EXPECT_GT(hits, 150);
}

}  // namespace
}  // namespace duplex
