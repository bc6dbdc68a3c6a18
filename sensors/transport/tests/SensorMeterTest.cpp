// Illuminance meters at points (next-event connections): the inverse-square cosine law of point
// lights exactly, a directional light's beam, an area light against the configuration factor of a
// point to a parallel rectangle, the light a Lambertian floor reflects against its radial integral,
// occlusion, per-light values, and the refusals (materials a connection cannot pass, bad meters).

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "OpticsReference.h"
#include "SensorFixture.h"
#include "SlabRuns.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

namespace duplex {
namespace {

using namespace test;

TEST(SensorMeter, PointAndDirectionalLightsGiveTheirExactIrradiance) {
  Fixture f;
  Light point = pointLight({0.0, 0.0, 2.0}, 10.0);
  const Light beam = beamLight({0.0, 0.0, 5.0}, {0.0, 0.0, -1.0}, 1.0, kPi);  // 1 W/m^2 across the beam
  SensorScene scene = f.scene({point, beam});
  scene.setMeters({{"grid",
                    {{0, 0, 0}, {1, 0, 0}, {0, 0, 0}, {1, 0, 0}, {0.5, 0, 0}, {2, 0, 0}},
                    {{0, 0, 1}, {0, 0, 1}, {0, 0, -1}, {-1, 0, 0}, {0, 0, 1}, {0, 0, 1}}}});
  SensorRunConfig cfg;
  cfg.per_light = true;
  SensorRun run(scene, cfg);
  (void)run.runUntil(20000);
  const MeterResult m = run.results().meters.at(0);
  const double i = 10.0 / (4 * kPi);
  const double expected_point[6] = {i / 4,
                                    i * (2 / std::sqrt(5.0)) / 5,
                                    0,
                                    i * (1 / std::sqrt(5.0)) / 5,
                                    i * (2 / std::sqrt(4.25)) / 4.25,
                                    i * (2 / std::sqrt(8.0)) / 8};
  const double expected_beam[6] = {1, 1, 0, 0, 1, 0};  // inside the beam's cylinder, facing it
  for (int k = 0; k < 6; ++k) {
    // Each light's connection is the same for every ray of it: the per-light means are exact up to
    // the share of rays each light got, which the estimator corrects (P / P_light per ray).
    const double lp = m.light_irradiance_w_m2[0][k], lb = m.light_irradiance_w_m2[1][k];
    EXPECT_NEAR(lp, expected_point[k], 4.5 * m.light_stderr_w_m2[0][k] + 1e-12) << "point " << k;
    EXPECT_NEAR(lb, expected_beam[k], 4.5 * m.light_stderr_w_m2[1][k] + 1e-12) << "point " << k;
    EXPECT_NEAR(m.irradiance_w_m2[k], expected_point[k] + expected_beam[k], 4.5 * m.stderr_w_m2[k] + 1e-12);
  }
  // One light alone: every ray connects the same way, the estimate is exact.
  SensorScene alone = f.scene({point});
  alone.setMeters({{"p", {{1, 0, 0}}, {{0, 0, 1}}}});
  SensorRun single(alone);
  (void)single.runUntil(1000);
  EXPECT_NEAR(single.results().meters[0].irradiance_w_m2[0], expected_point[1], 1e-12 * expected_point[1]);
}

TEST(SensorMeter, AreaLightMatchesTheConfigurationFactor) {
  // A 1 x 0.6 panel of 3 W facing down at height 0.8: below its centre E = (P / A) 4 F_corner(a/2, b/2, h);
  // below a corner, F_corner(a, b, h).
  Fixture f;
  SensorScene scene = f.scene({areaLight(1.0, 0.6, facing({0, 0, -1}, {0, 0, 0.8}), 3.0)});
  scene.setMeters({{"floor", {{0, 0, 0}, {0.5, 0.3, 0}}, {{0, 0, 1}, {0, 0, 1}}}});
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const MeterResult m = run.results().meters[0];
  const double exitance = 3.0 / 0.6;
  const double centre = exitance * 4 * pointToParallelRectangleCorner(0.5, 0.3, 0.8),
               corner = exitance * pointToParallelRectangleCorner(1.0, 0.6, 0.8);
  EXPECT_LT(std::abs(m.irradiance_w_m2[0] - centre), 4.5 * m.stderr_w_m2[0])
      << m.irradiance_w_m2[0] << " vs " << centre;
  EXPECT_LT(std::abs(m.irradiance_w_m2[1] - corner), 4.5 * m.stderr_w_m2[1])
      << m.irradiance_w_m2[1] << " vs " << corner;
  EXPECT_LT(m.stderr_w_m2[0], 0.01 * centre);
}

TEST(SensorMeter, LambertianFloorReflectionMatchesItsRadialIntegral) {
  // A point source I at height H over a floor of reflectance rho (a square of half size 200); a
  // meter at height h facing down sees only the floor: E = int rho I H / (pi (H^2 + r^2)^1.5)
  // h^2 / (h^2 + r^2)^2 2 pi r dr (the floor's radiance times cos^2 / d^2), by quadrature in
  // u = r^2 (the square's corners beyond r = 200 add less than 1e-9 of it).
  Fixture f;
  const double rho = 0.5, H = 2.0, h = 1.0, power = 100.0;
  f.add(quad(200.0, "floor"), Affine::identity(), "floor", Material{Lambertian{rho}});
  SensorScene scene = f.scene({pointLight({0, 0, H}, power)});
  scene.setMeters({{"up", {{0, 0, h}, {0.7, 0, h}}, {{0, 0, -1}, {0, 0, 1}}}});
  SensorRun run(scene);
  (void)run.runUntil(400000);
  const MeterResult m = run.results().meters[0];
  const double i = power / (4 * kPi);
  double e = 0.0;
  const int n = 2000000;
  const double umax = 200.0 * 200.0;
  for (int k = 0; k < n; ++k) {  // midpoint rule in log-spaced u would be finer; u itself suffices here
    const double u0 = umax * std::pow(static_cast<double>(k) / n, 4), u1 = umax * std::pow((k + 1.0) / n, 4);
    const double u = 0.5 * (u0 + u1);
    e += rho * i * H / std::pow(H * H + u, 1.5) * h * h / std::pow(h * h + u, 2) * (u1 - u0);  // pi cancels
  }
  EXPECT_LT(std::abs(m.irradiance_w_m2[0] - e), 4.5 * m.stderr_w_m2[0] + 1e-3 * e)
      << m.irradiance_w_m2[0] << " vs " << e;
  // The second point faces up, towards the light: direct light only (I cos / d^2), as nothing
  // above reflects.
  const double d2 = 0.49 + 1.0, direct = i * (1.0 / std::sqrt(d2)) / d2;
  EXPECT_LT(std::abs(m.irradiance_w_m2[1] - direct), 4.5 * m.stderr_w_m2[1] + 1e-12);
}

TEST(SensorMeter, AnOccluderHidesTheLight) {
  Fixture f;
  f.add(quad(0.2, "blocker"), translate(0, 0, 1.0), "blocker");  // an absorber between light and meter
  SensorScene scene = f.scene({pointLight({0, 0, 2}, 1.0)});
  scene.setMeters({{"m", {{0, 0, 0}, {1, 0, 0}}, {{0, 0, 1}, {0, 0, 1}}}});
  SensorRun run(scene);
  (void)run.runUntil(1000);
  const MeterResult m = run.results().meters[0];
  EXPECT_EQ(m.irradiance_w_m2[0], 0.0);  // behind the blocker
  EXPECT_GT(m.irradiance_w_m2[1], 0.0);  // beside it
}

TEST(SensorMeter, RefusesWhatItCannotConnectThrough) {
  Fixture f;
  f.add(quad(1.0, "mirror"), Affine::identity(), "mirror", Material{Mirror{0.9}});
  SensorScene scene = f.scene({pointLight({0, 0, 2}, 1.0)});
  scene.setMeters({{"m", {{0, 0, 1}}, {{0, 0, -1}}}});
  try {
    SensorRun run(scene);
    ADD_FAILURE() << "a meter in a scene with a mirror was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("mirror"), std::string::npos) << e.what();
  }
  EXPECT_THROW(scene.setMeters({{"", {{0, 0, 0}}, {{0, 0, 1}}}}), InvalidArgument);
  EXPECT_THROW(scene.setMeters({{"a", {{0, 0, 0}}, {{0, 0, 0}}}}), InvalidArgument);
  EXPECT_THROW(scene.setMeters({{"a", {{0, 0, 0}}, {}}}), InvalidArgument);
  EXPECT_THROW(scene.setMeters({{"a", {{0, 0, 0}}, {{0, 0, 1}}}, {"a", {{1, 0, 0}}, {{0, 0, 1}}}}), InvalidArgument);
}

TEST(SensorMeter, SceneFileMeters) {
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 2], "power": 12.566370614359172}], "meters": [)";
  const SensorScene scene = SensorScene::load(writeTestFile(
      "meters.json", head + R"({"name": "grid", "points": [[0, 0, 0], [1, 0, 0]], "normal": [0, 0, 2]}]})"));
  ASSERT_EQ(scene.meters().size(), 1u);
  EXPECT_EQ(scene.meters()[0].normals[1], glm::dvec3(0, 0, 1));
  SensorRun run(scene);
  (void)run.runUntil(100);
  EXPECT_NEAR(run.results().meters[0].irradiance_w_m2[0], 0.25, 1e-12);  // I = 1 W/sr at 2 m
  expectLoadError(
      writeTestFile("meters_both.json",
                    head + R"({"name": "g", "points": [[0,0,0]], "normal": [0,0,1], "normals": [[0,0,1]]}]})"),
      {"/meters/0", "normal"});
  expectLoadError(writeTestFile("meters_count.json", head + R"({"name": "g", "points": [[0,0,0]], "normals": []}]})"),
                  {"/meters/0/normals"});
  expectLoadError(
      writeTestFile("meters_zero.json", head + R"({"name": "g", "points": [[0,0,0]], "normal": [0,0,0]}]})"),
      {"/meters/0/normal"});
}

TEST(SensorMeter, LightsGivenByLuminanceExitanceAndIlluminance) {
  // CIE 171's 1 m^2 panel of 1000 cd/m^2, 1 m above the meter and facing it: E = pi L 4 F_corner
  // (0.5, 0.5, 1); the same panel by its exitance pi 1000 lm/m^2; a beam of 500 lx.
  const auto scene = [](const std::string& panel) {
    return R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
      {"type": "area", "size": [2, 0.5], "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1], )" +
           panel + R"(},
      {"type": "directional", "position": [5, 0, 3], "direction": [0, 0, -1], "radius": 0.5, "illuminance": 500}],
      "meters": [{"name": "m", "points": [[0, 0, 0], [5, 0, 0]], "normal": [0, 0, 1]}]})";
  };
  const double l = 1000.0, expected = kPi * l * 4 * pointToParallelRectangleCorner(1.0, 0.25, 1.0);
  for (const std::string panel : {R"("luminance": 1000)", R"("exitance": 3141.592653589793)"}) {
    const SensorScene s = SensorScene::load(writeTestFile("luminance.json", scene(panel)));
    EXPECT_NEAR(s.lights()[0].power_w, kPi * l * 1.0, 1e-9);  // lumens over the 1 m^2 face
    EXPECT_NEAR(s.lights()[1].power_w, 500 * kPi * 0.25, 1e-9);
    SensorRun run(s);
    (void)run.runUntil(200000);
    const SensorRunResults r = run.results();
    ASSERT_TRUE(r.luminous_transport);
    const MeterResult& m = r.meters[0];
    EXPECT_LT(std::abs(m.illuminance_lx[0] - expected), 4.5 * m.illuminance_stderr_lx[0])
        << panel << ": " << m.illuminance_lx[0] << " vs " << expected;
    EXPECT_LT(std::abs(m.illuminance_lx[1] - 500.0), 4.5 * m.illuminance_stderr_lx[1]) << panel;
  }
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [)";
  expectLoadError(writeTestFile("lum_point.json", head + R"({"type": "point", "position": [0,0,0], "luminance": 1}]})"),
                  {"/lights/0/luminance", "area"});
  expectLoadError(
      writeTestFile("lum_both.json", head + R"({"type": "area", "size": [1, 1], "luminance": 1, "power": 2}]})"),
      {"/lights/0", "luminance"});
  expectLoadError(
      writeTestFile("lum_neg.json", head + R"({"type": "directional", "position": [0,0,0], "direction": [0,0,-1],
        "radius": 1, "illuminance": -3}]})"),
      {"/lights/0/illuminance"});
}

TEST(SensorMeter, DiskLightMatchesThePointToDiskFactor) {
  // A disk of radius R = 0.6 and 1000 cd/m^2 facing down 1 m above the meter: at offset r from its
  // axis E = pi L F, F = (1 - (h^2 + r^2 - R^2) / sqrt((h^2 + r^2 + R^2)^2 - 4 r^2 R^2)) / 2.
  const SensorScene scene = SensorScene::load(writeTestFile("disk_light.json", R"({"format": "scene-json-v1",
    "objects": [], "instances": [], "lights": [{"type": "disk", "radius": 0.6, "luminance": 1000,
      "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1]}],
    "meters": [{"name": "m", "points": [[0, 0, 0], [0.5, 0, 0], [0, 1.5, 0]], "normal": [0, 0, 1]}]})"));
  const double big_r = 0.6, h = 1.0, l = 1000.0;
  EXPECT_NEAR(scene.lights()[0].power_w, kPi * l * kPi * big_r * big_r, 1e-9);  // lumens: pi L x pi R^2
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const MeterResult m = run.results().meters[0];
  for (int k = 0; k < 3; ++k) {
    const double r = glm::length(m.points[k]);
    const double f = 0.5 * (1 - (h * h + r * r - big_r * big_r) /
                                    std::sqrt(std::pow(h * h + r * r + big_r * big_r, 2) - 4 * r * r * big_r * big_r));
    EXPECT_LT(std::abs(m.illuminance_lx[k] - kPi * l * f), 4.5 * m.illuminance_stderr_lx[k])
        << "r = " << r << ": " << m.illuminance_lx[k] << " vs " << kPi * l * f;
  }
  expectLoadError(writeTestFile("disk_size.json", R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "disk", "size": [1, 1], "power": 1}]})"),
                  {"/lights/0", "size"});
}

// The configuration factor from a point x of unit normal n to a planar polygon (world vertices v),
// by Lambert's contour integral: F = |sum_i angle(r_i, r_i+1) n . (r_i x r_i+1) / |r_i x r_i+1|| / 2 pi,
// r_i = v_i - x (the polygon wholly in front of the point).
double pointToPolygon(const glm::dvec3& x, const glm::dvec3& n, const std::vector<glm::dvec3>& v) {
  double sum = 0.0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const glm::dvec3 a = v[i] - x, b = v[(i + 1) % v.size()] - x, c = glm::cross(a, b);
    const double angle = std::acos(std::clamp(glm::dot(glm::normalize(a), glm::normalize(b)), -1.0, 1.0));
    sum += angle * glm::dot(n, c) / glm::length(c);
  }
  return std::abs(sum) / (2.0 * kPi);
}

// The L-shaped (non-convex) hexagon of the polygon and mesh lights, in the light's local plane.
const std::vector<glm::dvec2> kLShape = {{-0.5, -0.5}, {0.5, -0.5}, {0.5, -0.1},
                                         {-0.1, -0.1}, {-0.1, 0.5}, {-0.5, 0.5}};

// Runs `scene` (one light of luminance `l`, the L shape placed by (x, y) -> (x, -y, 1), and one
// meter) and checks every meter point against pi L F, F by the contour integral, within 4 SE + 0.5%.
void expectLShapeIlluminance(const SensorScene& scene, double l, const char* what) {
  std::vector<glm::dvec3> world;
  for (const glm::dvec2& p : kLShape) world.emplace_back(p.x, -p.y, 1.0);
  SensorRun run(scene);
  (void)run.runUntil(400000);
  const MeterResult m = run.results().meters[0];
  for (std::size_t k = 0; k < m.points.size(); ++k) {
    const double expected = kPi * l * pointToPolygon(m.points[k], {0, 0, 1}, world);
    std::printf("%s, point %zu: %.3f +- %.3f lx (exact %.3f)\n", what, k, m.illuminance_lx[k],
                m.illuminance_stderr_lx[k], expected);
    EXPECT_LT(std::abs(m.illuminance_lx[k] - expected), 4.0 * m.illuminance_stderr_lx[k] + 5e-3 * expected)
        << what << ", point " << k;
  }
}

TEST(SensorMeter, PolygonLightMatchesLambertsContourIntegral) {
  // An L-shaped (non-convex) hexagon of 1000 cd/m^2 facing down 1 m above the floor (the transform
  // maps local (x, y) to world (x, -y, 1)): E = pi L F at points under it, under its notch and
  // beside it, F by the contour integral; its lumens are pi L A.
  const double l = 1000.0, area = 1.0 - 0.6 * 0.6;
  const SensorScene scene = SensorScene::load(writeTestFile("polygon_light.json", R"({"format": "scene-json-v1",
    "objects": [], "instances": [], "lights": [{"type": "polygon", "luminance": 1000,
      "vertices": [[-0.5, -0.5], [0.5, -0.5], [0.5, -0.1], [-0.1, -0.1], [-0.1, 0.5], [-0.5, 0.5]],
      "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1]}],
    "meters": [{"name": "m", "points": [[0, 0, 0], [-0.3, 0.3, 0], [0.3, -0.3, 0], [1.2, 0.4, 0]],
                "normal": [0, 0, 1]}]})"));
  EXPECT_NEAR(scene.lights()[0].power_w, kPi * l * area, 1e-9);
  expectLShapeIlluminance(scene, l, "polygon light");
  // The contour integral of the square agrees with the rectangle's closed form (the reference's check).
  EXPECT_NEAR(pointToPolygon({0, 0, 0}, {0, 0, 1}, {{-0.5, -0.5, 1}, {0.5, -0.5, 1}, {0.5, 0.5, 1}, {-0.5, 0.5, 1}}),
              4 * pointToParallelRectangleCorner(0.5, 0.5, 1.0), 1e-12);
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [)";
  expectLoadError(writeTestFile("bowtie.json", head + R"({"type": "polygon", "power": 1,
    "vertices": [[0, 0], [1, 1], [1, 0], [0, 1]]}]})"),
                  {"/lights/0/vertices", "not a simple polygon"});
  expectLoadError(
      writeTestFile("two.json", head + R"({"type": "polygon", "power": 1, "vertices": [[0, 0], [1, 1]]}]})"),
      {"/lights/0/vertices", "at least 3"});
}

TEST(SensorMeter, EmissiveMeshEqualsThePolygonItSplits) {
  // The L-shaped hexagon of the polygon test as a mesh object of four triangles (two per
  // rectangle of the L, counter-clockwise: their front faces towards local +z, placed facing
  // down), not instanced: the same illuminance, by the same contour integral, and lumens pi L A.
  const SensorScene scene = SensorScene::load(writeTestFile("mesh_light.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "lamp", "mesh": {
      "positions": [-0.5,-0.5,0, 0.5,-0.5,0, 0.5,-0.1,0, -0.5,-0.1,0, -0.1,-0.1,0, -0.1,0.5,0, -0.5,0.5,0],
      "indices": [0,1,2, 0,2,3, 3,4,5, 3,5,6]}}],
    "instances": [], "lights": [{"type": "mesh", "object": "lamp", "luminance": 1000,
      "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1]}],
    "meters": [{"name": "m", "points": [[0, 0, 0], [-0.3, 0.3, 0], [0.3, -0.3, 0], [1.2, 0.4, 0]],
                "normal": [0, 0, 1]}]})"));
  const double l = 1000.0, area = 1.0 - 0.6 * 0.6;
  EXPECT_NEAR(scene.lights()[0].power_w, kPi * l * area, 1e-6 * kPi * l * area);  // float vertices
  expectLShapeIlluminance(scene, l, "emissive mesh");
  const std::string head = R"({"format": "scene-json-v1", "objects": [{"name": "tri",
    "mesh": {"positions": [0,0,0, 1,0,0, 0,1,0], "indices": [0,1,2]}}],
    "instances": [], "lights": [)";
  expectLoadError(writeTestFile("mesh_missing.json", head + R"({"type": "mesh", "object": "lamp", "power": 1}]})"),
                  {"/lights/0/object", "no object \"lamp\""});
}

}  // namespace
}  // namespace duplex
