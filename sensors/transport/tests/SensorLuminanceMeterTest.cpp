// Luminance meters (a point meter with a half-angle: the mean radiance arriving within a cone):
// a Lambertian panel filling the cone reads M / pi, a cone beside it nothing; the overcast sky
// about the zenith its closed form L_z (2 + cos a) / 3 and the uniform sky L_z in any direction;
// a Lambertian floor under the overcast sky rho 7 / 9 L_z; the file keys and the refusals.

#include "duplex/accel/Error.h"
#include "duplex/sensors/CieSky.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace duplex {
namespace {

using namespace test;

constexpr double kDeg = kPi / 180.0;

Light skyLight(const CieSky& sky, double zenith_radiance, double radius) {
  Light l;
  l.type = LightType::Sky;
  l.name = "sky";
  l.sky = std::make_shared<const CieSky>(sky);
  l.radius = radius;
  l.power_w = zenith_radiance * sky.radianceIntegral() * kPi * radius * radius;
  return l;
}

TEST(SensorLuminanceMeter, LambertianPanelFillingTheConeReadsItsExitanceOverPi) {
  // A 2 x 2 panel of 8 W 1 above the meter, facing it: M = 2 W/m^2, L = M / pi. The panel's edges
  // are 45 degrees off the axis, so a 30 degree cone sees only the panel; a cone looking sideways
  // sees nothing.
  Fixture f;
  SensorScene scene = f.scene({areaLight(2.0, 2.0, facing({0, 0, -1}, {0, 0, 1}), 8.0)});
  PointMeter m{"lum", {{0, 0, 0}, {0.2, -0.1, 0}, {0, 0, 0}}, {{0, 0, 1}, {0, 0, 1}, {1, 0, 0}}};
  m.half_angle = 30 * kDeg;
  scene.setMeters({m});
  SensorRun run(scene);
  (void)run.runUntil(300000);
  const MeterResult r = run.results().meters[0];
  ASSERT_TRUE(r.irradiance_w_m2.empty());
  EXPECT_EQ(r.half_angle, m.half_angle);
  const double l = 2.0 / kPi;
  for (int k : {0, 1}) {
    EXPECT_LT(std::abs(r.radiance_w_m2_sr[k] - l), 4.5 * r.radiance_stderr_w_m2_sr[k])
        << k << ": " << r.radiance_w_m2_sr[k] << " vs " << l;
    EXPECT_LT(r.radiance_stderr_w_m2_sr[k], 0.01 * l);
  }
  EXPECT_EQ(r.radiance_w_m2_sr[2], 0.0);
}

TEST(SensorLuminanceMeter, SkiesReadTheirLuminance) {
  // Overcast: the mean of (1 + 2 cos Z) / 3 over the cone of half-angle a about the zenith is
  // (2 + cos a) / 3; a uniform sky reads L_z wherever the cone lies above the horizon.
  for (const bool uniform : {false, true}) {
    Fixture f;
    const double lz = 3000.0;
    SensorScene scene = f.scene({skyLight(uniform ? CieSky::general(5, {0, 0, 1}) : CieSky::overcast(), lz, 2.0)});
    PointMeter m{"sky", {{0, 0, 0}, {0.5, 0.5, 0.5}}, {{0, 0, 1}, {std::cos(kPi / 4), 0, std::sin(kPi / 4)}}};
    m.half_angle = 20 * kDeg;
    scene.setMeters({m});
    SensorRun run(scene);
    (void)run.runUntil(400000);
    const MeterResult r = run.results().meters[0];
    const double zenith = uniform ? lz : lz * (2 + std::cos(m.half_angle)) / 3;
    EXPECT_LT(std::abs(r.radiance_w_m2_sr[0] - zenith), 4.5 * r.radiance_stderr_w_m2_sr[0])
        << r.radiance_w_m2_sr[0] << " vs " << zenith;
    EXPECT_LT(r.radiance_stderr_w_m2_sr[0], 0.01 * zenith);
    if (uniform)
      EXPECT_LT(std::abs(r.radiance_w_m2_sr[1] - lz), 4.5 * r.radiance_stderr_w_m2_sr[1]) << r.radiance_w_m2_sr[1];
  }
}

TEST(SensorLuminanceMeter, LambertianFloorUnderTheOvercastSkyReadsRhoEOverPi) {
  // The unobstructed floor receives E_h = 7 pi / 9 L_z everywhere and reflects L = rho E_h / pi.
  Fixture f;
  const double rho = 0.4, lz = 1.0;
  f.add(quad(2.0, "floor"), Affine::identity(), "floor", Material{Lambertian{rho}});
  SensorScene scene = f.scene({skyLight(CieSky::overcast(), lz, 3.0)});
  PointMeter m{"down", {{0, 0, 1}}, {{0, 0, -1}}};
  m.half_angle = 25 * kDeg;
  scene.setMeters({m});
  SensorRun run(scene);
  (void)run.runUntil(400000);
  const MeterResult r = run.results().meters[0];
  const double expected = rho * 7.0 / 9.0 * lz;
  EXPECT_LT(std::abs(r.radiance_w_m2_sr[0] - expected), 4.5 * r.radiance_stderr_w_m2_sr[0])
      << r.radiance_w_m2_sr[0] << " +- " << r.radiance_stderr_w_m2_sr[0] << " vs " << expected;
  EXPECT_LT(r.radiance_stderr_w_m2_sr[0], 0.03 * expected);
}

TEST(SensorLuminanceMeter, FileKeysAndRefusals) {
  // CIE 171's panel of 1000 cd/m^2 seen head-on: the meter reads 1000 cd/m^2.
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
    {"type": "area", "size": [4, 4], "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1], "luminance": 1000}],
    "meters": [)";
  const SensorScene scene = SensorScene::load(writeTestFile(
      "lum.json", head + R"({"name": "l", "points": [[0, 0, 0]], "normal": [0, 0, 1], "half_angle": 10}]})"));
  EXPECT_NEAR(scene.meters()[0].half_angle, 10 * kDeg, 1e-15);
  SensorRun run(scene);
  (void)run.runUntil(100000);
  const SensorRunResults r = run.results();
  ASSERT_TRUE(r.photometric);
  const MeterResult& m = r.meters[0];
  EXPECT_LT(std::abs(m.luminance_cd_m2[0] - 1000.0), 4.5 * m.luminance_stderr_cd_m2[0]) << m.luminance_cd_m2[0];
  EXPECT_TRUE(m.illuminance_lx.empty());
  expectLoadError(writeTestFile("lum_wide.json",
                                head + R"({"name": "l", "points": [[0,0,0]], "normal": [0,0,1], "half_angle": 95}]})"),
                  {"/meters/0/half_angle"});
  expectLoadError(writeTestFile("lum_zero.json",
                                head + R"({"name": "l", "points": [[0,0,0]], "normal": [0,0,1], "half_angle": 0}]})"),
                  {"/meters/0/half_angle"});
  Fixture f;
  SensorScene s = f.scene({pointLight({0, 0, 1}, 1.0)});
  PointMeter bad{"bad", {{0, 0, 0}}, {{0, 0, 1}}};
  bad.half_angle = 2.0;
  EXPECT_THROW(s.setMeters({bad}), InvalidArgument);
}

}  // namespace
}  // namespace duplex
