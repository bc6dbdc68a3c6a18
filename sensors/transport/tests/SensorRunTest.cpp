// Sensor runs against analytic answers: a point source's irradiance on a small
// sensor (I cos(theta) / d^2) and the exact per-bin flux over a large plane, directional light,
// a mirror's image source, energy conservation in a closed box of sensors (with and without an
// absorber), bit-identical results for any thread count, extension, resume, cancel and the stop
// rule; scene-file errors.

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"
#include "SlabRuns.h"
#include "SlabMedium.h"
#include "SensorRunChunk.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <numbers>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

TEST(SensorRun, PointSourceOnALargePlaneMatchesTheExactPerBinIntegral) {
  Fixture f;
  const double h = 1.0, w = 4.0;
  const std::uint32_t n = 8;
  f.add(sensor(w, w, n, n, /*two_sided=*/false, "floor"), Affine::identity(), "floor");
  const double power = 4.0 * kPi;  // I = 1 W/sr
  SensorScene scene = f.scene({pointLight({0.3, -0.2, h}, power)});
  SensorRunConfig cfg;
  cfg.seed = 11;
  SensorRun run(scene, cfg);
  ASSERT_EQ(run.runUntil(400000), SensorRunStatus::Completed);
  const SensorRunResults r = run.results();
  ASSERT_EQ(r.sensors.size(), 1u);
  const SensorResult& s = r.sensors[0];
  double z2 = 0.0, total = 0.0;
  for (std::uint32_t iy = 0; iy < n; ++iy) {
    for (std::uint32_t ix = 0; ix < n; ++ix) {
      const double x0 = -w / 2 + ix * w / n - 0.3, y0 = -w / 2 + iy * w / n + 0.2;
      const double expected = rectangleSolidAngle(x0, x0 + w / n, y0, y0 + w / n, h);  // I * Omega, I = 1
      total += expected;
      const std::size_t b = iy * n + ix;
      ASSERT_GT(s.flux_stderr_w[b], 0.0);
      const double z = (s.flux_w[b] - expected) / s.flux_stderr_w[b];
      EXPECT_LT(std::abs(z), 4.5) << "bin " << ix << ", " << iy << ": " << s.flux_w[b] << " vs " << expected;
      z2 += z * z;
      EXPECT_NEAR(s.irradiance_w_m2[b], s.flux_w[b] / (w * w / (n * n)), 1e-12);
    }
  }
  // The z-scores behave like standard normals: the standard errors are honest, not inflated.
  EXPECT_GT(z2 / (n * n), 0.5);
  EXPECT_LT(z2 / (n * n), 2.0);
  EXPECT_LT(std::abs(s.total_flux_w - total), 4.5 * s.total_flux_stderr_w);
  EXPECT_NEAR(s.efficiency, s.total_flux_w / power, 1e-15);
}

TEST(SensorRun, SmallSensorSeesICosThetaOverDSquared) {
  // A spot light (I = P / (2 pi (1 - cos a))) aimed at a small sensor 2 m away, tilted 40 degrees.
  Fixture f;
  const double d = 2.0, theta = 40.0 * kPi / 180.0, side = 0.1;
  const glm::dvec3 at(0.0, 0.0, d);
  f.add(sensor(side, side, 1, 1, true, "small"), facing({std::sin(theta), 0.0, -std::cos(theta)}, at), "small");
  Light spot;
  spot.type = LightType::Spot;
  spot.name = "spot";
  spot.direction = {0, 0, 1};
  spot.cone_angle = 5.0 * kPi / 180.0;
  spot.power_w = 10.0;
  const double intensity = spot.intensity({0, 0, 1});
  SensorScene scene = f.scene({spot});
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const SensorResult s = run.results().sensors[0];
  const double expected = intensity * std::cos(theta) / (d * d);
  EXPECT_LT(std::abs(s.irradiance_w_m2[0] - expected), 4.0 * s.stderr_w_m2[0])
      << s.irradiance_w_m2[0] << " vs " << expected;
  EXPECT_LT(s.relative_stderr, 0.02);  // the check above is a sharp one
}

TEST(SensorRun, DirectionalLightFluxIsItsPowerTimesProjectedArea) {
  Fixture f;
  const double side = 0.5, tilt = 60.0 * kPi / 180.0;
  f.add(sensor(side, side, 2, 2, true, "tilted"), facing({0.0, std::sin(tilt), std::cos(tilt)}, {0.1, 0.0, 0.0}),
        "tilted");
  const Light sun = beamLight({0, 0, 5}, {0, 0, -1}, 1.0, 3.0);
  SensorScene scene = f.scene({sun});
  SensorRun run(scene);
  (void)run.runUntil(100000);
  const SensorResult s = run.results().sensors[0];
  const double expected = sun.power_w * side * side * std::cos(tilt) / (kPi * sun.radius * sun.radius);
  EXPECT_LT(std::abs(s.total_flux_w - expected), 4.0 * s.total_flux_stderr_w);
  // Irradiance on a surface tilted by 60 degrees: E = (P / pi r^2) cos(tilt), the same in every bin.
  for (double e : s.irradiance_w_m2)
    EXPECT_NEAR(e, sun.power_w / kPi * std::cos(tilt), 0.1 * sun.power_w / kPi * std::cos(tilt));
}

TEST(SensorRun, MirrorMakesAnImageSource) {
  // Point source at height 1 over a mirror (z = 0, reflectance 0.8); a one-sided sensor facing
  // down at height 2 sees the source (distance 1) and its image at z = -1 (distance 3).
  Fixture f;
  Material mirror = Mirror{0.8};
  f.add(quad(50.0, "mirror"), Affine::identity(), "mirror", mirror);
  f.add(sensor(0.4, 0.4, 1, 1, /*two_sided=*/false, "up"), facing({0, 0, -1}, {0, 0, 2}), "up");
  SensorScene scene = f.scene({pointLight({0, 0, 1}, 4.0 * kPi)});
  SensorRun run(scene);
  (void)run.runUntil(300000);
  const SensorResult s = run.results().sensors[0];
  const double expected =
      rectangleSolidAngle(-0.2, 0.2, -0.2, 0.2, 1.0) + 0.8 * rectangleSolidAngle(-0.2, 0.2, -0.2, 0.2, 3.0);
  EXPECT_LT(std::abs(s.total_flux_w - expected), 4.0 * s.total_flux_stderr_w) << s.total_flux_w << " vs " << expected;
}

TEST(SensorRun, SensorCoplanarWithAMirrorCountsEachArrivingRayOnce) {
  // A two-sided 1 x 1 sensor lying on a floor (z = 0) under a point source at height 1: it records
  // each ray that arrives at the floor there, once, whether the floor absorbs or mirrors it (the
  // reflected ray leaves from a point offset above the floor, so it does not cross the sensor
  // again). Both runs trace the same first segments: the sensor's sums are equal bit for bit, and
  // agree with the exact solid angle.
  auto run = [](const Material& floor) {
    Fixture f;
    f.add(quad(50.0, "floor"), Affine::identity(), "floor", floor);
    f.add(sensor(1.0, 1.0, 2, 2, /*two_sided=*/true, "on_floor"), Affine::identity(), "on_floor");
    SensorScene scene = f.scene({pointLight({0.1, -0.05, 1}, 4.0 * kPi)});
    SensorRunConfig cfg;
    cfg.seed = 5;
    SensorRun r(scene, cfg);
    (void)r.runUntil(200000);
    return r.results();
  };
  const SensorRunResults absorbed = run(Material{}), mirrored = run(Material{Mirror{1.0}});
  const SensorResult &a = absorbed.sensors[0], &m = mirrored.sensors[0];
  EXPECT_EQ(m.flux_w, a.flux_w);
  EXPECT_EQ(m.ray_count, a.ray_count);
  EXPECT_EQ(m.total_flux_w, a.total_flux_w);
  EXPECT_GT(mirrored.energy.escaped_w, 0.5 * 4.0 * kPi);  // the mirror sent the light back up
  const double expected = rectangleSolidAngle(-0.6, 0.4, -0.45, 0.55, 1.0);
  EXPECT_LT(std::abs(a.total_flux_w - expected), 4.0 * a.total_flux_stderr_w) << a.total_flux_w << " vs " << expected;
}

// Flux through a small square sensor (side a, centre c, unit normal n facing the light at the
// origin) by midpoint quadrature of I(d) cos / r^2 with the light's own intensity().
double quadratureFlux(const Light& light, const glm::dvec3& c, const glm::dvec3& n, double a) {
  glm::dvec3 t = glm::normalize(glm::cross(n, std::abs(n.z) < 0.9 ? glm::dvec3(0, 0, 1) : glm::dvec3(1, 0, 0)));
  const glm::dvec3 b = glm::cross(n, t);
  const int m = 100;
  double sum = 0.0;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j) {
      const glm::dvec3 p = c + ((i + 0.5) / m - 0.5) * a * t + ((j + 0.5) / m - 0.5) * a * b - light.position;
      const double r = glm::length(p);
      sum += light.intensity(p) * std::abs(glm::dot(n, p)) / (r * r * r) * (a / m) * (a / m);
    }
  return sum;
}

TEST(SensorRun, GoniometricLightFollowsItsTableAndOrientation) {
  // A rotationally symmetric table (100 cd at the nadir, 50 at the horizon, 0 at the zenith),
  // its nadir turned from -z to -x by a rotation of 90 degrees about y.
  Light lamp;
  lamp.type = LightType::Goniometric;
  lamp.name = "lamp";
  lamp.power_w = 20.0;
  lamp.profile = std::make_shared<const IesProfile>(IesProfile::fromTable({0, 90, 180}, {0}, {100, 50, 0}, "table"));
  lamp.world_from_light.linear = glm::transpose(glm::dmat3(0, 0, 1, 0, 1, 0, -1, 0, 0));  // rows of R_y(90)
  EXPECT_NEAR(lamp.intensity({-1, 0, 0}), 20.0 * 100.0 / lamp.profile->integral(), 1e-12);
  EXPECT_NEAR(lamp.intensity({0, 0, -1}), 20.0 * 50.0 / lamp.profile->integral(), 1e-12);
  Fixture f;
  const double a = 0.3;
  f.add(sensor(a, a, 1, 1, true, "nadir"), facing({1, 0, 0}, {-2, 0, 0}), "nadir");
  f.add(sensor(a, a, 1, 1, true, "side"), facing({0, 0, 1}, {0, 0, -2}), "side");
  f.add(sensor(a, a, 1, 1, true, "oblique"), facing({1, 0, 1}, {-1.2, 0, -1.2}), "oblique");
  SensorScene scene = f.scene({lamp});
  SensorRun run(scene);
  (void)run.runUntil(400000);
  const SensorRunResults r = run.results();
  const glm::dvec3 centres[3] = {{-2, 0, 0}, {0, 0, -2}, {-1.2, 0, -1.2}};
  const glm::dvec3 normals[3] = {{1, 0, 0}, {0, 0, 1}, glm::normalize(glm::dvec3(1, 0, 1))};
  for (int k = 0; k < 3; ++k) {
    const double expected = quadratureFlux(lamp, centres[k], normals[k], a);
    EXPECT_LT(std::abs(r.sensors[k].total_flux_w - expected), 4.0 * r.sensors[k].total_flux_stderr_w)
        << r.sensors[k].name << ": " << r.sensors[k].total_flux_w << " vs " << expected;
  }
  Light skewed = lamp;
  skewed.world_from_light.linear[0][0] = 1.1;
  EXPECT_THROW(skewed.validate(), InvalidArgument);
}

std::shared_ptr<const Object> disk(double diameter, std::uint32_t bins, const std::string& name) {
  return std::make_shared<const SensorObject>(
      name, SensorSpec{.shape = SensorShape::Disk, .width = diameter, .height = diameter, .nx = bins, .ny = bins});
}

TEST(SensorRun, DisksAndSpheresTakeTheirRadius) {
  // The file's "radius" (the convention of lights and shapes): a disk of radius R gets the flux
  // I 2 pi (1 - h / sqrt(h^2 + R^2)) and equals, bit for bit, the same disk given by its diameter.
  const auto file = [](const std::string& disk_size) {
    return R"({"format": "scene-json-v1", "objects": [], "instances": [],
      "lights": [{"type": "point", "position": [0, 0, 0], "power": 12.566370614359172}],
      "sensors": [{"name": "disk", "shape": "disk", )" +
           disk_size + R"(, "bins": 4, "transform": [1,0,0,0, 0,1,0,0, 0,0,1,1.5]},
                  {"name": "ball", "shape": "sphere", "radius": 3, "bins": [4, 2]}]})";
  };
  const SensorScene by_radius = SensorScene::load(writeTestFile("radius.json", file(R"("radius": 0.75)")));
  const SensorScene by_size = SensorScene::load(writeTestFile("diameter.json", file(R"("size": 1.5)")));
  EXPECT_EQ(by_radius.sensors()[0].object->spec().width, 1.5);
  EXPECT_EQ(by_radius.sensors()[1].object->spec().width, 6.0);
  SensorRun a(by_radius), b(by_size);
  (void)a.runUntil(200000);
  (void)b.runUntil(200000);
  const SensorRunResults ra = a.results(), rb = b.results();
  const double h = 1.5, radius = 0.75, expected = 2.0 * kPi * (1.0 - h / std::sqrt(h * h + radius * radius));
  EXPECT_LT(std::abs(ra.sensors[0].total_flux_w - expected), 4.0 * ra.sensors[0].total_flux_stderr_w);
  EXPECT_EQ(ra.sensors[0].flux_w, rb.sensors[0].flux_w);
  EXPECT_NEAR(ra.sensors[1].total_flux_w, 4.0 * kPi, 1e-9);  // the sphere around the source records it all
  // A rectangle has no radius; radius and size together are ambiguous.
  const std::string rect = R"({"format": "scene-json-v1", "objects": [], "instances": [],
      "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}], "sensors": [{"name": "s", )";
  expectLoadError(writeTestFile("rect_radius.json", rect + R"("radius": 1}]})"), {"/sensors/0/radius", "rectangle"});
  expectLoadError(writeTestFile("both.json", rect + R"("shape": "disk", "radius": 1, "size": 2}]})"),
                  {"/sensors/0/radius", "not both"});
  expectLoadError(writeTestFile("bad_radius.json", rect + R"("shape": "sphere", "radius": -1}]})"),
                  {"/sensors/0/radius"});
}

TEST(SensorRun, PointSourceThroughACoaxialDisk) {
  // Flux through a disk of radius R at distance h from an isotropic source: I 2 pi (1 - h / sqrt(h^2 + R^2)).
  Fixture f;
  const double h = 1.5, radius = 1.0;
  f.add(disk(2.0 * radius, 16, "disk"), translate(0, 0, h), "disk");
  SensorScene scene = f.scene({pointLight({0, 0, 0}, 4.0 * kPi)});
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const SensorResult s = run.results().sensors[0];
  const double expected = 2.0 * kPi * (1.0 - h / std::sqrt(h * h + radius * radius));
  EXPECT_LT(std::abs(s.total_flux_w - expected), 4.0 * s.total_flux_stderr_w) << s.total_flux_w << " vs " << expected;
  // Corner bins of the bounding square lie outside the disk: no area, no flux.
  EXPECT_EQ(s.bin_area_m2[0], 0.0);
  EXPECT_EQ(s.flux_w[0], 0.0);
  // Bin (8, 8) is the square [0, 1/8] x [0, 1/8], wholly inside the disk: its exact solid angle.
  const std::size_t centre = 8 * 16 + 8;
  const double bin_flux = rectangleSolidAngle(0.0, 0.125, 0.0, 0.125, h);
  EXPECT_LT(std::abs(s.flux_w[centre] - bin_flux), 4.5 * s.flux_stderr_w[centre])
      << s.flux_w[centre] << " vs " << bin_flux;
  EXPECT_DOUBLE_EQ(s.bin_area_m2[centre], 0.125 * 0.125);
}

TEST(SensorRun, LambertianAreaLightToAParallelCoaxialDisk) {
  // A square Lambertian source (side a, at z = 0, facing +z) and a disk of radius R at height h.
  // Reference: the power-weighted mean over the source of the view factor from a point at radial
  // offset r to the disk, F = (1 - (h^2 + r^2 - R^2) / sqrt((h^2 + r^2 + R^2)^2 - 4 r^2 R^2)) / 2
  // (the configuration factor of a differential area to a parallel disk), by midpoint quadrature.
  Fixture f;
  const double a = 0.6, h = 0.8, radius = 0.5, power = 3.0;
  f.add(disk(2.0 * radius, 4, "disk"), translate(0, 0, h), "disk");
  Light area;
  area.type = LightType::Area;
  area.name = "panel";
  area.width = area.height = a;
  area.power_w = power;
  SensorScene scene = f.scene({area});
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const SensorResult s = run.results().sensors[0];
  const int n = 400;
  double sum = 0.0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = -a / 2 + (i + 0.5) * a / n, y = -a / 2 + (j + 0.5) * a / n, r2 = x * x + y * y;
      const double q = h * h + r2 + radius * radius;
      sum += 0.5 * (1.0 - (h * h + r2 - radius * radius) / std::sqrt(q * q - 4.0 * r2 * radius * radius));
    }
  const double expected = power * sum / (n * n);
  EXPECT_LT(std::abs(s.total_flux_w - expected), 4.0 * s.total_flux_stderr_w) << s.total_flux_w << " vs " << expected;
  EXPECT_LT(s.relative_stderr, 0.01);
}

TEST(SensorRun, DielectricReflectsTheFresnelFraction) {
  // A collimated beam onto a large glass interface (ior 1.5) at z = 0; a one-sided sensor facing
  // down at z = 1 records only upward rays: the reflected fraction, Fresnel's R for unpolarised
  // light: 0.04 at normal incidence, 0.0892 at 60 degrees, 0.253 at 75.
  for (const double deg : {0.0, 30.0, 45.0, 60.0, 75.0}) {
    Fixture f;
    f.add(quad(500.0, "glass"), Affine::identity(), "glass", Material{Dielectric{1.5}});
    f.add(sensor(1000.0, 1000.0, 1, 1, /*two_sided=*/false, "sky"), facing({0, 0, -1}, {0, 0, 1}), "sky");
    const double th = deg * kPi / 180.0;
    Light beam;
    beam.type = LightType::Directional;
    beam.name = "beam";
    beam.position = {-std::sin(th), 0.0, std::cos(th)};  // the whole disk above the glass
    beam.direction = {std::sin(th), 0.0, -std::cos(th)};
    beam.radius = 0.2;
    beam.power_w = 1.0;
    SensorScene scene = f.scene({beam});
    SensorRun run(scene);
    (void)run.runUntil(200000);
    const SensorResult s = run.results().sensors[0];
    const double n = 1.5, ci = std::cos(th), ct = std::sqrt(1.0 - std::sin(th) * std::sin(th) / (n * n));
    const double rs = (ci - n * ct) / (ci + n * ct), rp = (n * ci - ct) / (n * ci + ct);
    const double fresnel = 0.5 * (rs * rs + rp * rp);
    EXPECT_LT(std::abs(s.total_flux_w - fresnel), 4.0 * s.total_flux_stderr_w)
        << deg << " deg: " << s.total_flux_w << " vs " << fresnel;
    EXPECT_GT(s.total_flux_w, 0.0);
  }
}

TEST(SensorRun, FogAttenuatesAndTheBalanceCloses) {
  // A slab of fog (sigma = 0.8, 0.5 thick) between a point source and a sensor plane: the sensor
  // receives exp(-sigma L) of the direct flux along each ray, L = 0.5 / cos(theta) for a ray at
  // angle theta; at the bin right above the source, about exp(-0.4).
  Fixture f;
  Box slab;
  slab.lo = glm::vec3(-0.9f, -0.9f, 0.25f);  // inside the box of sensors
  slab.hi = glm::vec3(0.9f, 0.9f, 0.75f);
  f.add(std::make_shared<const test::SlabMedium>(0.8, slab), Affine::identity(), "fog");
  f.add(sensor(0.2, 0.2, 1, 1, true, "above"), translate(0, 0, 1), "above");
  closeBox(f);  // everything that leaves is counted
  SensorScene scene = f.scene({pointLight({0, 0, 0}, 4.0 * kPi)});
  SensorRunConfig cfg;
  cfg.roulette_threshold = 0.0;  // deterministic attenuation only: the balance closes per ray
  SensorRun run(scene, cfg);
  (void)run.runUntil(300000);
  const SensorRunResults r = run.results();
  const SensorResult& above = r.sensors[0];
  ASSERT_EQ(above.name, "above");
  // Reference: the solid-angle integral of exp(-0.8 * 0.5 / cos(theta)) over the 0.2 x 0.2 square at
  // height 1 (midpoint quadrature; d Omega = cos(theta) dA / d^2 = dA / d^3 at height 1).
  const int n = 200;
  double expected = 0.0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const double x = -0.1 + (i + 0.5) * 0.2 / n, y = -0.1 + (j + 0.5) * 0.2 / n, d = std::sqrt(x * x + y * y + 1.0);
      expected += std::exp(-0.8 * 0.5 * d) / (d * d * d) * (0.2 / n) * (0.2 / n);
    }
  EXPECT_LT(std::abs(above.total_flux_w - expected), 4.0 * above.total_flux_stderr_w)
      << above.total_flux_w << " vs " << expected;
  // What reaches the box faces plus what the fog took is what was emitted.
  double faces = 0.0;
  for (std::size_t k = 1; k < r.sensors.size(); ++k) faces += r.sensors[k].total_flux_w;
  EXPECT_GT(r.energy.medium_absorbed_w, 0.5);
  EXPECT_NEAR(faces + r.energy.medium_absorbed_w, 4.0 * kPi, 1e-9);
  EXPECT_EQ(r.energy.roulette_w, 0.0);
}

// The bytes of a run's saved state: equal states are equal accumulators, bit for bit.
std::string stateBytes(const SensorRun& run, const std::string& tag) {
  const auto file = std::filesystem::temp_directory_path() /
                    ("duplex_sensor_state_" + tag + "_" + std::to_string(::getpid()) + ".bin");
  run.saveState(file);
  std::ifstream in(file, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::remove(file);
  return bytes;
}

// A fog slab between a point source of 2 W and a Lambertian ceiling, in a closed box of sensors.
SensorScene fogUnderCeiling(Fixture& f) {
  Box slab;
  slab.lo = glm::vec3(-0.9f, -0.9f, 0.25f);
  slab.hi = glm::vec3(0.9f, 0.9f, 0.75f);
  f.add(std::make_shared<const test::SlabMedium>(0.8, slab), Affine::identity(), "fog");
  f.add(quad(0.8, "ceiling"), translate(0, 0, 0.9), "ceiling", Material{Lambertian{0.9}});
  closeBox(f);
  return f.scene({pointLight({0, 0, 0}, 2.0)});
}

TEST(SensorRun, RouletteKeepsTheBalanceExactAndTheFluxUnbiased) {
  // The fog slab between a point source and a Lambertian ceiling: paths reach the ceiling with
  // e^-(0.4 / cos) of their power, below a roulette threshold of 0.9 of it. Per path the roulette
  // term is what it killed minus what it added, so the five terms still sum to the emitted power
  // exactly, and the box's flux agrees with the run without roulette.
  Fixture f;
  const SensorScene scene = fogUnderCeiling(f);
  auto run = [&](double threshold) {
    SensorRunConfig cfg;
    cfg.roulette_threshold = threshold;
    cfg.seed = 3;
    SensorRun r(scene, cfg);
    (void)r.runUntil(200000);
    return r.results();
  };
  const SensorRunResults with = run(0.9), without = run(0.0);
  const EnergyBalance& e = with.energy;
  EXPECT_GT(std::abs(e.roulette_w), 1e-4);  // the roulette acted
  EXPECT_NEAR(e.escaped_w + e.absorbed_w + e.medium_absorbed_w + e.depth_limited_w + e.roulette_w, e.emitted_w,
              1e-12 * e.emitted_w);
  EXPECT_NEAR(sensorSum(with), e.escaped_w, 1e-12);  // the closed box of sensors sees every escaping path
  for (const std::size_t k : {std::size_t{0}, std::size_t{1}, std::size_t{4}, std::size_t{5}}) {
    const SensorResult &a = with.sensors[k], &b = without.sensors[k];
    const double se = std::hypot(a.total_flux_stderr_w, b.total_flux_stderr_w);
    EXPECT_LT(std::abs(a.total_flux_w - b.total_flux_w), 4.5 * se)
        << a.name << ": " << a.total_flux_w << " vs " << b.total_flux_w;
  }
}

TEST(SensorRun, BatchesWhoseRouletteTermIsNegativeAddAndResume) {
  // The roulette's net term of a batch (what it killed minus what it added) has either sign: such
  // batches travel between runs and states like any other.
  Fixture f;
  const SensorScene scene = fogUnderCeiling(f);
  SensorRunConfig cfg;
  cfg.roulette_threshold = 0.9;
  cfg.seed = 3;
  cfg.batch_rays = 2000;
  SensorRun whole(scene, cfg);
  int negative = 0;
  double before = 0.0;
  (void)whole.runUntil(30000, [&](const SensorProgress& p) {
    const double sum = whole.results().energy.roulette_w * static_cast<double>(p.rays_done);
    negative += sum < before ? 1 : 0;
    before = sum;
  });
  EXPECT_GT(negative, 0);
  SensorRun worker(scene, cfg), sum(scene, cfg);
  for (std::uint64_t b = 0; b < 15; ++b) sum.addBatch(worker.traceBatch(b, 30000).bytes);
  EXPECT_EQ(stateBytes(whole, "roulette_whole"), stateBytes(sum, "roulette_sum"));
  const auto file =
      std::filesystem::temp_directory_path() / ("duplex_sensor_roulette_" + std::to_string(::getpid()) + ".bin");
  sum.saveState(file);
  SensorRun resumed(scene, cfg);
  resumed.loadState(file);
  std::filesystem::remove(file);
  EXPECT_EQ(stateBytes(resumed, "roulette_resumed"), stateBytes(whole, "roulette_whole2"));
}

TEST(SensorRun, ClosedBoxOfSensorsRecordsAllEmittedPower) {
  Fixture f;
  closeBox(f);
  SensorScene scene = f.scene({pointLight({0.1, 0.2, -0.3}, 5.0)});
  SensorRun run(scene);
  (void)run.runUntil(50000);
  const SensorRunResults r = run.results();
  EXPECT_NEAR(sensorSum(r), 5.0, 1e-12);
  EXPECT_NEAR(r.energy.escaped_w, 5.0, 1e-12);
  EXPECT_EQ(r.energy.absorbed_w, 0.0);
}

TEST(SensorRun, WithAnAbsorberInsideMissingPowerEqualsAbsorbedPower) {
  Fixture f;
  closeBox(f);
  f.add(quad(0.5, "absorber"), translate(0, 0, 0.5), "absorber");  // absorber (default material)
  Material white = Lambertian{0.7};
  f.add(quad(0.4, "white"), facing({1, 0, 0}, {-0.6, 0, 0}), "white", white);
  Material glass = Dielectric{1.5};
  f.add(quad(0.3, "glass"), facing({0, 1, 0}, {0, -0.5, 0}), "glass", glass);
  SensorScene scene = f.scene({pointLight({0, 0, 0}, 2.0)});
  SensorRun run(scene);
  (void)run.runUntil(50000);
  const SensorRunResults r = run.results();
  EXPECT_GT(r.energy.absorbed_w, 0.1);
  EXPECT_NEAR(sensorSum(r) + r.energy.absorbed_w, 2.0, 1e-12);
  EXPECT_NEAR(sensorSum(r), r.energy.escaped_w, 1e-12);
  EXPECT_EQ(r.energy.depth_limited_w, 0.0);
  // Materials keep a surviving path's power and nothing attenuates: every path ends with the power
  // it was emitted with, so each term is its ray count times that power, and the counts are the rays.
  const EnergyBalance& e = r.energy;
  EXPECT_GT(e.absorbed_rays, 1000u);
  EXPECT_EQ(e.escaped_rays + e.absorbed_rays, r.rays);
  EXPECT_EQ(e.medium_absorbed_rays + e.depth_limited_rays + e.roulette_rays + e.failed_rays, 0u);
  EXPECT_NEAR(e.absorbed_w, 2.0 * static_cast<double>(e.absorbed_rays) / static_cast<double>(r.rays), 1e-12);
  EXPECT_NEAR(e.escaped_w, 2.0 * static_cast<double>(e.escaped_rays) / static_cast<double>(r.rays), 1e-12);
  EXPECT_EQ(e.failed_w, 0.0);
}

TEST(SensorRun, EveryPathEndsOneWayAndTheCountsSumToTheRays) {
  // Fog, a Lambertian ceiling and a roulette threshold of 0.9 (it kills paths), a depth limit of 2
  // (it cuts some): every ending is counted once.
  Fixture f;
  const SensorScene scene = fogUnderCeiling(f);
  SensorRunConfig cfg;
  cfg.roulette_threshold = 0.9;
  cfg.max_depth = 2;
  SensorRun run(scene, cfg);
  (void)run.runUntil(40000);
  const EnergyBalance e = run.results().energy;
  EXPECT_EQ(e.escaped_rays + e.absorbed_rays + e.medium_absorbed_rays + e.depth_limited_rays + e.roulette_rays +
                e.failed_rays,
            40000u);
  EXPECT_GT(e.roulette_rays, 0u);
  EXPECT_GT(e.escaped_rays, 0u);
  EXPECT_EQ(e.failed_rays, 0u);
  EXPECT_NEAR(e.escaped_w + e.absorbed_w + e.medium_absorbed_w + e.depth_limited_w + e.roulette_w + e.failed_w,
              e.emitted_w, 1e-12 * e.emitted_w);
  // Counts travel with batches and states like the sums.
  SensorRun worker(scene, cfg), sum(scene, cfg);
  sum.addBatch(worker.traceBatch(0, 40000).bytes);
  EXPECT_EQ(sum.results().energy.roulette_rays, e.roulette_rays);
  EXPECT_EQ(sum.results().energy.depth_limited_rays, e.depth_limited_rays);
}

TEST(SensorRun, ADirectionThatDoesNotLeaveTheSurfaceIsAFailure) {
  const glm::dvec3 n(0.0, 0.0, 1.0);  // faces the incoming ray
  EXPECT_TRUE(detail::leavesSurface({0.3, 0.0, 0.9}, n, false));
  EXPECT_FALSE(detail::leavesSurface({0.3, 0.0, 0.9}, n, true));  // a refraction must cross
  EXPECT_TRUE(detail::leavesSurface({0.3, 0.0, -0.9}, n, true));
  EXPECT_FALSE(detail::leavesSurface({1.0, 0.0, 0.0}, n, false));  // tangent: neither side
  EXPECT_FALSE(detail::leavesSurface({1.0, 0.0, 0.0}, n, true));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(detail::leavesSurface({nan, 0.0, 1.0}, n, false));
  EXPECT_FALSE(detail::leavesSurface({0.0, 0.0, std::numeric_limits<double>::infinity()}, n, false));
}

SensorRunResults runWith(const SensorScene& scene, unsigned threads, std::uint32_t chunk, std::uint64_t rays,
                         std::uint64_t batch = SensorRunConfig{}.batch_rays) {
  SensorRunConfig cfg;
  cfg.seed = 99;
  cfg.threads = threads;
  cfg.chunk_rays = chunk;
  cfg.batch_rays = batch;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  return run.results();
}

SensorScene reflectingBox(Fixture& f) {
  closeBox(f);
  Material white = Lambertian{0.9};
  f.add(quad(0.5, "white"), translate(0, 0, -0.5), "white", white);
  return f.scene({pointLight({0, 0, 0.2}, 1.0)});
}

TEST(SensorRun, BitIdenticalForAnyThreadCountAndChunkSize) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  const SensorRunResults one = runWith(scene, 1, 1024, 70000);
  expectIdentical(one, runWith(scene, 2, 1024, 70000));
  expectIdentical(one, runWith(scene, 2, 97, 70000));
  EXPECT_GT(one.sensors[0].total_flux_w, 0.0);
}

TEST(SensorRun, ExtendedCancelledAndResumedRunsEqualOneLongRun) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  // The same batches (the unit of the ordered sums) as the runs below.
  const SensorRunResults whole = runWith(scene, 2, 1024, 150000, 20000);
  SensorRunConfig cfg;
  cfg.seed = 99;
  cfg.batch_rays = 20000;
  {
    // Extended in calls that do not fall on batch or chunk boundaries.
    SensorRun run(scene, cfg);
    (void)run.runUntil(33333);
    (void)run.runUntil(100001);
    (void)run.runUntil(150000);
    expectIdentical(whole, run.results());
  }
  {
    // Cancelled from the progress callback after the first batch, then continued.
    SensorRun run(scene, cfg);
    std::uint64_t calls = 0;
    EXPECT_EQ(run.runUntil(150000,
                           [&](const SensorProgress& p) {
                             ++calls;
                             EXPECT_LE(p.rays_done, p.rays_target);
                             run.cancel();
                           }),
              SensorRunStatus::Cancelled);
    EXPECT_EQ(calls, 1u);
    EXPECT_EQ(run.raysDone(), 20000u);
    EXPECT_EQ(run.runUntil(150000), SensorRunStatus::Completed);
    expectIdentical(whole, run.results());
  }
  {
    // Saved and loaded into a fresh run (another process would do the same).
    const auto file =
        std::filesystem::temp_directory_path() / ("duplex_sensor_state_" + std::to_string(::getpid()) + ".bin");
    // Saved inside a batch: the state holds the open batch's sums beside the finished batches'.
    SensorRun first(scene, cfg);
    (void)first.runUntil(70000);
    first.saveState(file);
    SensorRun second(scene, cfg);
    second.loadState(file);
    EXPECT_EQ(second.raysDone(), 70000u);
    (void)second.runUntil(150000);
    expectIdentical(whole, second.results());
    // Another seed refuses the state.
    SensorRunConfig other = cfg;
    other.seed = 5;
    SensorRun third(scene, other);
    EXPECT_THROW(third.loadState(file), FileError);
    EXPECT_EQ(third.raysDone(), 0u);
    std::filesystem::remove(file);
    // A directory where the state should be is refused at once (not read as a file of absurd size).
    std::filesystem::create_directories(file);
    expectErrorNaming<FileError>([&] { third.loadState(file); }, "cannot open the run state: a directory, not a file");
    EXPECT_EQ(third.raysDone(), 0u);
    std::filesystem::remove(file);
  }
}

TEST(SensorRun, BatchesTracedElsewhereAndAddedInOrderEqualOneRun) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  SensorRunConfig cfg;
  cfg.seed = 99;
  cfg.batch_rays = 20000;
  cfg.threads = 2;
  constexpr std::uint64_t kRays = 110000;  // the last batch is shorter
  SensorRun whole(scene, cfg);
  (void)whole.runUntil(kRays);
  // Three "ranks" with 1, 2 and 1 threads trace the batches in turn; one run adds them in order.
  std::vector<std::unique_ptr<SensorRun>> workers;
  for (const unsigned threads : {1u, 2u, 1u}) {
    SensorRunConfig c = cfg;
    c.threads = threads;
    c.chunk_rays = 300 * threads;
    workers.push_back(std::make_unique<SensorRun>(scene, c));
  }
  SensorRun sum(scene, cfg);
  std::vector<std::uint64_t> sizes;
  for (std::uint64_t b = 0; b * cfg.batch_rays < kRays; ++b) {
    const SensorBatchTally t = workers[b % 3]->traceBatch(b, kRays);
    EXPECT_TRUE(t.complete);
    EXPECT_EQ(t.first_ray, b * cfg.batch_rays);
    EXPECT_EQ(t.rays, std::min<std::uint64_t>(cfg.batch_rays, kRays - t.first_ray));
    sum.addBatch(t.bytes);
    sizes.push_back(t.bytes.size());
  }
  EXPECT_EQ(sum.raysDone(), kRays);
  for (const auto& w : workers) EXPECT_EQ(w->raysDone(), 0u);  // tracing leaves a worker's sums alone
  expectIdentical(whole.results(), sum.results());
  EXPECT_EQ(stateBytes(whole, "whole"), stateBytes(sum, "sum"));
  EXPECT_EQ(whole.counters().segments, sum.counters().segments);
  // A tally holds the bins the batch reached: this scene's 6 x 4 x 4 bins at most, not more.
  const std::size_t bins = scene.binCount() + scene.angleBinCount();
  for (const std::uint64_t size : sizes) EXPECT_LE(size, 200 + bins * 28 + scene.sensors().size() * 16);
  // Continuing the summed run by itself gives the longer one-process run.
  SensorRun longer(scene, cfg);
  (void)longer.runUntil(150000);
  (void)sum.runUntil(150000);
  EXPECT_EQ(stateBytes(longer, "longer"), stateBytes(sum, "sum2"));
}

TEST(SensorRun, BatchTalliesOutOfOrderOfAnotherRunOrDamagedAreRefused) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  SensorRunConfig cfg;
  cfg.seed = 99;
  cfg.batch_rays = 5000;
  SensorRun worker(scene, cfg);
  const SensorBatchTally b0 = worker.traceBatch(0, 20000), b1 = worker.traceBatch(1, 20000);
  SensorRun run(scene, cfg);
  const std::string empty = stateBytes(run, "empty");
  expectErrorNaming<InvalidArgument>([&] { run.addBatch(b1.bytes); }, "added in order");
  SensorRunConfig other = cfg;
  other.seed = 7;
  SensorRun stranger(scene, other);
  expectErrorNaming<InvalidArgument>([&] { run.addBatch(stranger.traceBatch(0, 20000).bytes); },
                                     "another scene, seed or configuration");
  other = cfg;
  other.batch_rays = 4000;
  SensorRun regrouped(scene, other);
  EXPECT_THROW(run.addBatch(regrouped.traceBatch(0, 20000).bytes), InvalidArgument);
  std::vector<std::byte> cut(b0.bytes.begin(), b0.bytes.end() - 1);
  expectErrorNaming<InvalidArgument>([&] { run.addBatch(cut); }, "bytes, expected");
  // A bin index past the scene's bins, and a negative sum: refused, the run unchanged.
  std::vector<std::byte> bad = b0.bytes;
  const std::uint32_t far = 1u << 30;
  std::memcpy(bad.data() + 8 + 10 * 8, &far, sizeof far);
  expectErrorNaming<InvalidArgument>([&] { run.addBatch(bad); }, "out-of-range bins");
  bad = b0.bytes;
  std::uint64_t reached;
  std::memcpy(&reached, bad.data() + 8 + 6 * 8, sizeof reached);
  ASSERT_GT(reached, 0u);
  const double negative = -1.0;
  std::memcpy(bad.data() + 8 + 10 * 8 + reached * 4, &negative, sizeof negative);
  EXPECT_THROW(run.addBatch(bad), InvalidArgument);
  EXPECT_EQ(run.raysDone(), 0u);
  EXPECT_EQ(stateBytes(run, "refused"), empty);
  // The good tallies still add (in order) to what one run of 10,000 rays holds.
  run.addBatch(b0.bytes);
  run.addBatch(b1.bytes);
  SensorRun straight(scene, cfg);
  (void)straight.runUntil(10000);
  EXPECT_EQ(stateBytes(run, "good"), stateBytes(straight, "straight"));
  // A batch past the run's rays is no batch.
  EXPECT_THROW((void)worker.traceBatch(4, 20000), InvalidArgument);
}

TEST(SensorRun, StopsWhenTheChosenSensorIsPreciseEnough) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  SensorRunConfig cfg;
  cfg.batch_rays = 5000;
  SensorRun run(scene, cfg);
  SensorStopRule stop;
  stop.sensor = 4;  // the top face
  stop.target = 0.02;
  stop.min_rays = 5000;
  EXPECT_EQ(run.runUntil(10000000, {}, stop), SensorRunStatus::TargetReached);
  EXPECT_LE(run.relativeStderr(4), 0.02);
  EXPECT_LT(run.raysDone(), 10000000u);
  EXPECT_EQ(run.raysDone() % 5000, 0u);
}

TEST(SensorRun, ClosestHitBaselineTracesTheSamePaths) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  SensorRunConfig cfg;
  SensorRun with(scene, cfg);
  cfg.closest_hit_only = true;
  SensorRun without(scene, cfg);
  (void)with.runUntil(20000);
  (void)without.runUntil(20000);
  EXPECT_EQ(with.counters().segments, without.counters().segments);
  EXPECT_EQ(with.results().energy.absorbed_w, without.results().energy.absorbed_w);
  EXPECT_GT(with.counters().crossings, 0u);
  EXPECT_EQ(without.counters().crossings, 0u);
}

TEST(SensorRun, BadLightsAndConfigurationsAreRefused) {
  Fixture f;
  f.add(sensor(1, 1, 1, 1, true, "s"), Affine::identity(), "s");
  EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, 0.0)}), InvalidArgument);
  EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, -1.0)}), InvalidArgument);
  EXPECT_THROW((void)f.scene({pointLight({0, 0, NAN}, 1.0)}), InvalidArgument);
  const SensorScene dark = f.scene({});
  SensorRun run(dark);
  EXPECT_THROW((void)run.runUntil(10), InvalidArgument);
  SensorRunConfig bad;
  bad.chunk_rays = 0;
  EXPECT_THROW(SensorRun(dark, bad), InvalidArgument);
}

// ---- scene files ----

const char* kQuadObject =
    R"({"name": "floor", "mesh": {"positions": [-5,-5,0, 5,-5,0, 5,5,0, -5,5,0], "indices": [0,1,2, 0,2,3]}})";

TEST(SensorSceneFile, ReadsLightsSensorsAndMaterials) {
  const std::string text = std::string(R"({"format": "scene-json-v1", "objects": [)") + kQuadObject +
                           R"(], "instances": [{"object": "floor", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 12.5},
               {"type": "spot", "position": [0, 0, 3], "direction": [0, 0, -1], "half_angle": 30, "power": 1},
               {"type": "directional", "position": [0, 0, 3], "direction": [0, 0, -1], "radius": 2, "power": 1},
               {"type": "area", "size": [1, 2], "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,4], "power": 1}],
    "sensors": [{"name": "top", "shape": "rectangle", "size": [2, 1], "bins": [4, 2], "two_sided": true,
                 "transform": [1,0,0,0, 0,1,0,0, 0,0,1,2]},
                {"name": "round", "shape": "disk", "size": 1, "bins": [3, 3], "two_sided": false,
                 "transform": [2,0,0,0, 0,2,0,0, 0,0,2,1]}]})";
  const SensorScene scene = SensorScene::load(writeTestFile("ok.json", text));
  ASSERT_EQ(scene.lights().size(), 4u);
  EXPECT_EQ(scene.totalPower(), 15.5);
  ASSERT_EQ(scene.sensors().size(), 2u);
  EXPECT_EQ(scene.sensors()[0].name, "top");
  EXPECT_EQ(scene.sensors()[0].object->binCount(), 8u);
  EXPECT_EQ(scene.sensors()[1].area_scale, 4.0);
  EXPECT_EQ(scene.binCount(), 17u);
  EXPECT_TRUE(scene.materialOf(scene.document()->instances[0]).is<Absorber>());
}

// scene-json-v1 ignores unknown keys (tools outside the project may add their own), also inside
// lights and sensors; the project's own format refuses them, naming the key's JSON pointer.
TEST(SensorSceneFile, UnknownKeysAreIgnoredInSceneJsonV1AndRefusedInTheOwnFormat) {
  const std::string lights = R"("lights": [{"type": "point", "position": [0, 0, 1], "power": 2, "colour": "red"}])";
  const std::string sensors = R"("sensors": [{"name": "s", "size": 1, "bins": [2, 2], "vendor": "acme"}])";
  const SensorScene v1 = SensorScene::load(writeTestFile(
      "v1_unknown.json",
      R"({"format": "scene-json-v1", "objects": [], "instances": [], "note": "x", )" + lights + ", " + sensors + "}"));
  EXPECT_EQ(v1.totalPower(), 2.0);
  ASSERT_EQ(v1.sensors().size(), 1u);
  EXPECT_EQ(v1.sensors()[0].object->binCount(), 4u);

  const std::string light_only = R"("lights": [{"type": "point", "position": [0, 0, 1], "power": 2}])";
  const std::string sensor_only = R"("sensors": [{"name": "s", "size": 1, "bins": [2, 2]}])";
  const auto own = [](const std::string& name, const std::string& body) {
    return writeTestFile(name, R"({"format": "duplex-scene-v1", "objects": [], "nodes": [], )" + body + "}");
  };
  (void)SensorScene::load(own("own_known.json", light_only + ", " + sensor_only));  // the keys alone are fine
  expectErrorNaming<FileError>([&] { (void)SensorScene::load(own("own_light.json", lights + ", " + sensor_only)); },
                               "/lights/0/colour");
  expectErrorNaming<FileError>([&] { (void)SensorScene::load(own("own_sensor.json", light_only + ", " + sensors)); },
                               "/sensors/0/vendor");
}

TEST(SensorSceneFile, OwnFormatInstancesSensorObjectsAndReadsMaterials) {
  const std::string text = R"({"format": "duplex-scene-v1",
    "objects": [{"name": "floor", "plane": {"size": 10}, "material": {"type": "lambertian", "reflectance": 0.5}},
                {"name": "cell", "sensor": {"size": [1, 1], "bins": 2}}],
    "nodes": [{"instance": "floor", "object": "floor"},
              {"group": "row", "translate": [0, 0, 1], "children": [
                {"instance": "a", "object": "cell"}, {"instance": "b", "object": "cell", "transform": {"translate": [2, 0, 0]}}]}],
    "lights": [{"type": "point", "position": [0, 0, 3], "power": 1}]})";
  const SensorScene scene = SensorScene::load(writeTestFile("own.json", text));
  ASSERT_EQ(scene.sensors().size(), 2u);
  EXPECT_EQ(scene.sensors()[0].name, "a");
  EXPECT_EQ(scene.sensors()[1].name, "b");
  const Material& m = scene.materialOf(scene.document()->instances[0]);
  ASSERT_TRUE(m.is<Lambertian>());
  EXPECT_EQ(m.as<Lambertian>()->reflectance.value, 0.5);
}

// An LM-63 file next to the scenes: rotationally symmetric, 100 cd at the nadir, 50 at the horizon.
void writeLampIes() {
  (void)writeTestFile("lamp.ies",
                      "IESNA:LM-63-2002\n[TEST] sensor test\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 100\n"
                      "0 90 180\n0\n100 50 0\n");
}

TEST(SensorSceneFile, ReadsAnIesLight) {
  writeLampIes();
  const std::string text = R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "ies", "file": "lamp.ies", "position": [0, 0, 3], "power": 5}],
    "sensors": [{"name": "floor", "size": 1}]})";
  const SensorScene scene = SensorScene::load(writeTestFile("ies.json", text));
  ASSERT_EQ(scene.lights().size(), 1u);
  const Light& l = scene.lights()[0];
  EXPECT_EQ(l.type, LightType::Goniometric);
  EXPECT_NEAR(l.intensity({0, 0, -1}), 5.0 * 100.0 / l.profile->integral(), 1e-12);
}

void expectFileError(const std::string& name, const std::string& body, const std::string& needle) {
  const auto path = writeTestFile(name, std::string(R"({"format": "scene-json-v1", "objects": [)") + kQuadObject +
                                            R"(], "instances": [], )" + body + "}");
  expectLoadError(path, {needle});
}

TEST(SensorSceneFile, MalformedEntriesNameTheFileAndPointer) {
  writeLampIes();
  expectFileError("zero_power.json", R"("lights": [{"type": "point", "position": [0,0,1], "power": 0}])",
                  "/lights/0/power");
  expectFileError("negative_power.json", R"("lights": [{"type": "point", "position": [0,0,1], "power": -2}])",
                  "power must be > 0");
  expectFileError("no_position.json", R"("lights": [{"type": "point", "power": 1}])",
                  "/lights/0: missing key \"position\"");
  expectFileError("bad_type.json", R"("lights": [{"type": "laser", "power": 1}])", "/lights/0/type");
  expectFileError(
      "spot_angle.json",
      R"("lights": [{"type": "spot", "position": [0,0,1], "direction": [0,0,-1], "half_angle": 0, "power": 1}])",
      "/lights/0/half_angle");
  expectFileError(
      "zero_dir.json",
      R"("lights": [{"type": "directional", "position": [0,0,1], "direction": [0,0,0], "radius": 1, "power": 1}])",
      "/lights/0/direction");
  expectFileError("no_size.json", R"("sensors": [{"name": "s", "bins": [2, 2]}])", "/sensors/0: missing key \"size\"");
  expectFileError("zero_bins.json", R"("sensors": [{"name": "s", "size": [1, 1], "bins": [0, 2]}])",
                  "/sensors/0/bins/0");
  expectFileError("bad_shape.json", R"("sensors": [{"name": "s", "shape": "hexagon", "size": 1}])", "/sensors/0/shape");
  expectFileError("disk_oval.json", R"("sensors": [{"name": "s", "shape": "disk", "size": [1, 2]}])",
                  "/sensors/0/size");
  expectFileError("short_transform.json", R"("sensors": [{"name": "s", "size": 1, "transform": [1, 0, 0]}])",
                  "/sensors/0/transform");
  expectFileError("singular.json", R"("sensors": [{"name": "s", "size": 1, "transform": [0,0,0,0, 0,0,0,0, 0,0,0,0]}])",
                  "singular");
  expectFileError("no_name.json", R"("sensors": [{"size": 1}])", "missing key \"name\"");
  expectFileError("twice.json", R"("sensors": [{"name": "s", "size": 1}, {"name": "s", "size": 1}])", "/sensors/1");
  expectFileError("missing_ies.json",
                  R"("lights": [{"type": "ies", "file": "no_such.ies", "position": [0,0,1], "power": 1}])",
                  "/lights/0/file");
  expectFileError(
      "ies_sheared.json",
      R"("lights": [{"type": "ies", "file": "lamp.ies", "transform": [2,0,0,0, 0,1,0,0, 0,0,1,0], "power": 1}])",
      "rotation");
  expectFileError("sensors_not_array.json", R"("sensors": {"name": "s"})", "/sensors");
}

TEST(SensorRun, FingerprintTellsADiskLightFromItsSquare) {
  // A disk light emits from the disk inscribed in its width x width square: a state traced with
  // one must not resume with the other.
  auto fingerprint = [](bool disk) {
    Fixture f;
    f.add(quad(1.0, "floor"), translate(0, 0, -1), "floor", Material{Lambertian{0.5}});
    f.add(sensor(1.0, 1.0, 2, 2), translate(0, 0, 0.5), "sensor");
    Light l = areaLight(0.4, 0.4, Affine::identity(), 1.0);
    l.disk = disk;
    const SensorScene scene = f.scene({l});
    return SensorRun(scene, SensorRunConfig{}).fingerprint();
  };
  EXPECT_NE(fingerprint(false), fingerprint(true));
  EXPECT_EQ(fingerprint(true), fingerprint(true));
}

}  // namespace
}  // namespace duplex
