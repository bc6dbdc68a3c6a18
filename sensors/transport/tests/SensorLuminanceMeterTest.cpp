// Luminance meters (a point meter with a half-angle: the mean radiance arriving within a cone):
// a Lambertian panel filling the cone reads M / pi, a cone beside it nothing; the overcast sky
// about the zenith its closed form L_z (2 + cos a) / 3 and the uniform sky L_z in any direction;
// a Lambertian floor under the overcast sky rho 7 / 9 L_z; the file keys and the refusals. Pinhole
// cameras: each pixel the mean radiance over its pyramid (a panel, the overcast sky by quadrature,
// a half-covered view).

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

TEST(SensorCamera, PixelsReadTheMeanRadianceOverTheirPyramids) {
  // A 4 x 3 pinhole camera (60 degrees vertical) looking at the zenith: under a Lambertian panel 1
  // above that fills the view every pixel reads M / pi; under the overcast sky each pixel
  // the mean of L_z (1 + 2 cos Z) / 3 over its pyramid (quadrature over the pixel in the image
  // plane: the integral of L cos^3 / f^2 dA over the pixel's solid angle); a panel covering the
  // right half of the view lights the right two columns only.
  const PointMeter cam = pinholeMeter("cam", {0, 0, 0}, {0, 0, 1}, {0, 1, 0}, kPi / 3, 4, 3);
  ASSERT_EQ(cam.points.size(), 12u);
  double omega = 0.0;
  for (const double w : cam.pixel_solid_angle) omega += w;
  const double tx = cam.image_tan_x, ty = cam.image_tan_y;
  EXPECT_NEAR(omega, 4 * std::atan(tx * ty / std::sqrt(1 + tx * tx + ty * ty)), 1e-12);  // the whole view
  {
    Fixture f;
    // M = 2, just larger than the view at distance 1 (2 tan_x = 1.54 by 2 tan_y = 1.15).
    SensorScene scene = f.scene({areaLight(1.6, 1.2, facing({0, 0, -1}, {0, 0, 1}), 2.0 * 1.6 * 1.2)});
    scene.setMeters({cam});
    SensorRun run(scene);
    (void)run.runUntil(600000);
    const MeterResult r = run.results().meters[0];
    EXPECT_EQ(r.image_width, 4u);
    for (std::size_t k = 0; k < 12; ++k) {
      EXPECT_LT(std::abs(r.radiance_w_m2_sr[k] - 2 / kPi), 4.5 * r.radiance_stderr_w_m2_sr[k]) << k;
      EXPECT_LT(r.radiance_stderr_w_m2_sr[k], 0.006 * 2 / kPi) << k;
    }
  }
  {
    Fixture f;
    SensorScene scene = f.scene({skyLight(CieSky::overcast(), 1.0, 2.0)});
    scene.setMeters({cam});
    SensorRun run(scene);
    (void)run.runUntil(400000);
    const MeterResult r = run.results().meters[0];
    for (std::uint32_t py = 0; py < 3; ++py)
      for (std::uint32_t px = 0; px < 4; ++px) {
        double sum = 0.0;
        const int n = 200;
        for (int i = 0; i < n; ++i)
          for (int j = 0; j < n; ++j) {
            const double x = tx * (2.0 * (px + (i + 0.5) / n) / 4 - 1), y = ty * (1.0 - 2.0 * (py + (j + 0.5) / n) / 3);
            const double c = 1.0 / std::sqrt(1 + x * x + y * y);  // cos of the angle to the axis (= cos Z)
            sum += (1 + 2 * c) / 3 * c * c * c;
          }
        const std::size_t k = py * 4 + px;
        const double ref = sum * (2 * tx / 4) * (2 * ty / 3) / (n * n) / cam.pixel_solid_angle[k];
        EXPECT_LT(std::abs(r.radiance_w_m2_sr[k] - ref), 4.5 * r.radiance_stderr_w_m2_sr[k])
            << px << ", " << py << ": " << r.radiance_w_m2_sr[k] << " vs " << ref;
        EXPECT_LT(r.radiance_stderr_w_m2_sr[k], 0.03 * ref);
      }
  }
  {
    Fixture f;
    // x from -4 to 0: the image's right (forward x up = z x y = -x, looking up with +y at the top).
    SensorScene scene = f.scene({areaLight(4.0, 4.0, facing({0, 0, -1}, {-2, 0, 1}), 32.0)});
    scene.setMeters({cam});
    SensorRun run(scene);
    (void)run.runUntil(200000);
    const MeterResult r = run.results().meters[0];
    for (std::size_t k = 0; k < 12; ++k) {
      if (k % 4 < 2) EXPECT_EQ(r.radiance_w_m2_sr[k], 0.0) << k;
      else EXPECT_LT(std::abs(r.radiance_w_m2_sr[k] - 2 / kPi), 4.5 * r.radiance_stderr_w_m2_sr[k]) << k;
    }
  }
}

TEST(SensorCamera, FileKeysAndRefusals) {
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
    {"type": "area", "size": [4, 4], "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,1], "luminance": 1000}],
    "meters": [)";
  const SensorScene scene = SensorScene::load(writeTestFile(
      "cam.json", head + R"({"name": "c", "camera": {"eye": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0],
                              "fov": 40, "pixels": [3, 2]}}]})"));
  const PointMeter& m = scene.meters()[0];
  EXPECT_EQ(m.image_width, 3u);
  EXPECT_EQ(m.image_height, 2u);
  EXPECT_NEAR(m.image_tan_y, std::tan(20 * kDeg), 1e-15);
  SensorRun run(scene);
  (void)run.runUntil(100000);
  const MeterResult r = run.results().meters[0];
  for (std::size_t k = 0; k < 6; ++k)
    EXPECT_LT(std::abs(r.luminance_cd_m2[k] - 1000.0), 4.5 * r.luminance_stderr_cd_m2[k]) << r.luminance_cd_m2[k];
  for (
      const char* bad :
      {R"({"name": "c", "points": [[0,0,0]], "camera": {"eye": [0,0,0], "target": [0,0,1], "fov": 40, "pixels": [3, 2]}})",
       R"({"name": "c", "camera": {"eye": [0,0,0], "target": [0,0,1], "fov": 40, "pixels": [0, 2]}})",
       R"({"name": "c", "camera": {"eye": [0,0,0], "target": [0,0,1], "fov": 180, "pixels": [3, 2]}})",
       R"({"name": "c", "camera": {"eye": [0,0,0], "target": [0,0,1], "up": [0,0,2], "fov": 40, "pixels": [3, 2]}})"})
    expectLoadError(writeTestFile("cam_bad.json", head + bad + "]}"), {"/meters/0"});
}

}  // namespace
}  // namespace duplex
