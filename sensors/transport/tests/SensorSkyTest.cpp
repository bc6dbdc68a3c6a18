// CIE standard skies and the sun: the luminance formulas against the standard's definitions and
// properties, the sampler's distribution against the formula cell by cell, the unobstructed
// overcast sky's horizontal and vertical illuminance against their closed forms (7 pi / 9 L_z and
// (pi / 6 + 4 / 9) L_z), a horizontal roof opening and a vertical window against numerical
// integrals over the opening, and the sun's direct light by altitude and azimuth from a scene file.

#include "duplex/accel/Error.h"
#include "duplex/sensors/CieSky.h"
#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <vector>

namespace duplex {
namespace {

using namespace test;

glm::dvec3 fromAngles(double zenith, double az) {  // az from north (+y) towards east (+x)
  return {std::sin(zenith) * std::sin(az), std::sin(zenith) * std::cos(az), std::cos(zenith)};
}

// The integral of g(dir) over the upper hemisphere by the midpoint rule in (zenith angle, azimuth)
// with dOmega = sin Z dZ daz: another parametrisation and rule than the sky's own quadrature.
double hemisphere(const std::function<double(const glm::dvec3&)>& g, int nz = 1000, int na = 2000) {
  double sum = 0.0;
  for (int i = 0; i < nz; ++i) {
    const double z = (i + 0.5) * (kPi / 2) / nz;
    for (int j = 0; j < na; ++j) sum += g(fromAngles(z, (j + 0.5) * 2 * kPi / na)) * std::sin(z);
  }
  return sum * (kPi / 2) / nz * 2 * kPi / na;
}

Light skyLight(const CieSky& sky, double zenith_radiance, double radius, glm::dvec3 centre = glm::dvec3(0.0)) {
  Light l;
  l.type = LightType::Sky;
  l.name = "sky";
  l.sky = std::make_shared<const CieSky>(sky);
  l.position = centre;
  l.radius = radius;
  l.power_w = zenith_radiance * sky.radianceIntegral() * kPi * radius * radius;
  return l;
}

TEST(CieSky, LuminanceFollowsTheStandardsFormulas) {
  const CieSky overcast = CieSky::overcast();
  EXPECT_NEAR(overcast.relativeLuminance({0, 0, 1}), 1.0, 1e-15);
  EXPECT_NEAR(overcast.relativeLuminance(fromAngles(kPi / 2 - 1e-12, 0.3)), 1.0 / 3.0, 1e-9);  // 1 : 3 at the horizon
  EXPECT_EQ(overcast.relativeLuminance({0, 1, -0.1}), 0.0);
  EXPECT_NEAR(overcast.horizontalIntegral(), 7 * kPi / 9, 1e-15);
  EXPECT_NEAR(hemisphere([&](const glm::dvec3& d) { return overcast.relativeLuminance(d) * d.z; }), 7 * kPi / 9, 1e-6);
  // Type 1 (the general sky's overcast) is 1 / (1 + 4 e^-0.7) at the horizon: close to the 1/3
  // of the overcast formula, as the standard says.
  const CieSky t1 = CieSky::general(1, {0, 0, 1});
  EXPECT_NEAR(t1.relativeLuminance(fromAngles(kPi / 2 - 1e-9, 1.0)), 1.0 / (1.0 + 4.0 * std::exp(-0.7)), 1e-9);
  // Type 5 is uniform: the integrals are 2 pi and pi.
  const CieSky uniform = CieSky::general(5, {0, 0, 1});
  EXPECT_NEAR(uniform.relativeLuminance(fromAngles(1.2, 2.0)), 1.0, 1e-12);
  EXPECT_NEAR(uniform.radianceIntegral(), 2 * kPi, 1e-9);
  EXPECT_NEAR(uniform.horizontalIntegral(), kPi, 1e-9);
  // The clear sky (type 12) by its definition, written out here: at a point 30 degrees from the
  // zenith and 90 degrees in azimuth from a sun at altitude 40.
  const double zs = kPi / 2 - 40 * kPi / 180;
  const glm::dvec3 sun = fromAngles(zs, kPi);
  const CieSky clear = CieSky::general(12, sun);
  const glm::dvec3 dir = fromAngles(kPi / 6, kPi / 2);
  const double chi = std::acos(glm::dot(dir, sun));
  auto f = [](double x) {
    return 1 + 10 * (std::exp(-3 * x) - std::exp(-3 * kPi / 2)) + 0.45 * std::cos(x) * std::cos(x);
  };
  auto phi = [](double z) { return 1 - std::exp(-0.32 / std::cos(z)); };
  EXPECT_NEAR(clear.relativeLuminance(dir), f(chi) * phi(kPi / 6) / (f(zs) * phi(0)), 1e-12);
  EXPECT_NEAR(clear.relativeLuminance({0, 0, 1}), 1.0, 1e-12);  // relative to the zenith
  // Its integrals against the independent quadrature.
  EXPECT_NEAR(clear.radianceIntegral(), hemisphere([&](const glm::dvec3& d) { return clear.relativeLuminance(d); }),
              2e-6 * clear.radianceIntegral());
  EXPECT_NEAR(clear.horizontalIntegral(),
              hemisphere([&](const glm::dvec3& d) { return clear.relativeLuminance(d) * d.z; }),
              2e-6 * clear.horizontalIntegral());
  EXPECT_THROW((void)CieSky::general(16, sun), InvalidArgument);
  EXPECT_THROW((void)CieSky::general(12, {0, 1, -0.5}), InvalidArgument);
}

TEST(CieSky, SampledDirectionsReproduceTheLuminanceCellByCell) {
  // Weighted samples estimate each cell's share of the integral of L: against the cells'
  // integrals by quadrature, within 4.5 standard errors, on a coarse grid that does not match the
  // sampler's own.
  const CieSky sky = CieSky::general(12, fromAngles(0.6, 2.0));
  constexpr int nu = 6, na = 10;
  const int n = 400000;
  std::vector<double> sum(nu * na, 0.0), sum2(nu * na, 0.0);
  double max_weight = 0.0;
  for (int k = 0; k < n; ++k) {
    CounterRng rng(7, static_cast<std::uint64_t>(k));
    const double u0 = rng.uniform(), u1 = rng.uniform();
    const CieSky::Sample s = sky.sample(u0, u1);
    ASSERT_GT(s.dir_ws.z, 0.0);
    ASSERT_NEAR(glm::length(s.dir_ws), 1.0, 1e-12);
    max_weight = std::max(max_weight, s.weight);
    // The density the sampler reports is the one it draws from: weight = L / (pdf integral).
    ASSERT_NEAR(s.weight, sky.relativeLuminance(s.dir_ws) / (sky.pdf(s.dir_ws) * sky.radianceIntegral()),
                1e-9 * s.weight);
    double az = std::atan2(s.dir_ws.x, s.dir_ws.y);
    if (az < 0) az += 2 * kPi;
    const int c = std::min(nu - 1, static_cast<int>(s.dir_ws.z * nu)) * na +
                  std::min(na - 1, static_cast<int>(az / (2 * kPi) * na));
    sum[c] += s.weight;
    sum2[c] += s.weight * s.weight;
  }
  EXPECT_LT(max_weight, 1.5);  // importance sampled: the weights stay close to 1
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < na; ++j) {
      double ref = 0.0;  // midpoint rule in (cos Z, azimuth) inside the cell, 200 x 200
      for (int a = 0; a < 200; ++a)
        for (int b = 0; b < 200; ++b) {
          const double u = (i + (a + 0.5) / 200) / nu, az = 2 * kPi * (j + (b + 0.5) / 200) / na;
          const double s = std::sqrt(1 - u * u);
          ref += sky.relativeLuminance({s * std::sin(az), s * std::cos(az), u});
        }
      ref *= (1.0 / nu / 200) * (2 * kPi / na / 200) / sky.radianceIntegral();
      const int c = i * na + j;
      const double mean = sum[c] / n, se = std::sqrt((sum2[c] / n - mean * mean) / (n - 1));
      EXPECT_LT(std::abs(mean - ref), 4.5 * se + 1e-6 * ref)
          << "cell " << i << ", " << j << ": " << mean << " vs " << ref;
    }
}

TEST(SensorSky, UnobstructedOvercastSkyGivesItsClosedForms) {
  // E_h = 7 pi / 9 L_z on a horizontal plane; E_v = (pi / 6 + 4 / 9) L_z on a vertical one (no
  // ground); a horizontal sensor reads E_h too. L_z = 2 W/(m^2 sr).
  Fixture f;
  const double lz = 2.0;
  f.add(sensor(1.0, 1.0, 1, 1, false), translate(0.3, -0.2, 0.1), "sensor");
  SensorScene scene = f.scene({skyLight(CieSky::overcast(), lz, 3.0)});
  scene.setMeters({{"m", {{0, 0, 0}, {0.5, 0.5, 0.5}, {0, 0, 0}}, {{0, 0, 1}, {1, 0, 0}, {0, -1, 0}}}});
  SensorRun run(scene);
  (void)run.runUntil(400000);
  const SensorRunResults r = run.results();
  const MeterResult& m = r.meters[0];
  const double eh = 7 * kPi / 9 * lz, ev = (kPi / 6 + 4.0 / 9) * lz;
  EXPECT_LT(std::abs(m.irradiance_w_m2[0] - eh), 4.5 * m.stderr_w_m2[0]) << m.irradiance_w_m2[0] << " vs " << eh;
  EXPECT_LT(m.stderr_w_m2[0], 0.003 * eh);
  for (int k : {1, 2})
    EXPECT_LT(std::abs(m.irradiance_w_m2[k] - ev), 4.5 * m.stderr_w_m2[k])
        << k << ": " << m.irradiance_w_m2[k] << " vs " << ev;
  const SensorResult& s = r.sensors[0];
  EXPECT_LT(std::abs(s.irradiance_w_m2[0] - eh), 4.5 * s.stderr_w_m2[0]) << s.irradiance_w_m2[0] << " vs " << eh;
  EXPECT_LT(s.stderr_w_m2[0], 0.02 * eh);
  EXPECT_NEAR(r.energy.emitted_w, lz * 4 * kPi / 3 * kPi * 9.0, 1e-9 * r.energy.emitted_w);
}

// An absorbing plane of half size 100 with a 1 x 1 hole at its centre (local z = 0, the hole
// [-0.5, 0.5]^2), placed by `world`: four squares in a pinwheel around the hole.
void planeWithHole(Fixture& f, const Affine& world, const std::string& name) {
  const double h = 50.0;
  const glm::dvec2 at[4] = {{h + 0.5, h - 0.5}, {0.5 - h, h + 0.5}, {-h - 0.5, 0.5 - h}, {h - 0.5, -h - 0.5}};
  for (int k = 0; k < 4; ++k)
    f.add(quad(h, name + std::to_string(k)), world * translate(at[k].x, at[k].y, 0.0), name + std::to_string(k));
}

// The irradiance at `x` on the plane of unit normal `n` from the sky (L_z = 1) seen through the
// opening {o + s ex + t ey : s, t in [-0.5, 0.5]} of unit normal `nw`: the integral of L cos_m
// cos_w / d^2 over the opening (midpoint rule, 500 x 500).
double throughOpening(const CieSky& sky, const glm::dvec3& x, const glm::dvec3& n, const glm::dvec3& o,
                      const glm::dvec3& ex, const glm::dvec3& ey) {
  const glm::dvec3 nw = glm::normalize(glm::cross(ex, ey));
  const int k = 500;
  double sum = 0.0;
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) {
      const glm::dvec3 p = o + ((i + 0.5) / k - 0.5) * ex + ((j + 0.5) / k - 0.5) * ey;
      const glm::dvec3 v = p - x;
      const double d2 = glm::dot(v, v), d = std::sqrt(d2);
      const glm::dvec3 u = v / d;
      sum += sky.relativeLuminance(u) * std::max(0.0, glm::dot(u, n)) * std::abs(glm::dot(u, nw)) / d2;
    }
  return sum / (k * k);
}

TEST(SensorSky, SkyThroughARoofOpeningAndAWindowMatchesTheIntegralOverTheOpening) {
  // The CIE clear sky with the sun at altitude 35, azimuth 200 (behind the roof and the wall for
  // the meters, so only the sky's light arrives): a 1 x 1 roof opening 1.5 above the floor meters,
  // and a 1 x 1 window in a vertical wall, its centre 0.6 above a meter 0.8 behind it facing it.
  const glm::dvec3 sun = fromAngles(kPi / 2 - 35 * kPi / 180, 200 * kPi / 180);
  const CieSky sky = CieSky::general(12, sun);
  for (const bool window : {false, true}) {
    Fixture f;
    // The wall: the plane y = 5 (facing -y), the window's centre at (0, 5, 0.6).
    const Affine place = window ? facing({0, -1, 0}, {0, 5, 0.6}) : translate(0, 0, 1.5);
    planeWithHole(f, place, "wall");
    const double lz = 1000.0;
    SensorScene scene = f.scene({skyLight(sky, lz, 150.0)});
    const std::vector<glm::dvec3> pts = window ? std::vector<glm::dvec3>{{0, 4.2, 0}, {0.3, 4.5, 0.2}}
                                               : std::vector<glm::dvec3>{{0, 0, 0}, {0.8, 0.2, 0}};
    const std::vector<glm::dvec3> ns =
        window ? std::vector<glm::dvec3>{{0, 1, 0}, {0, 1, 0}} : std::vector<glm::dvec3>{{0, 0, 1}, {0, 0, 1}};
    scene.setMeters({{"m", pts, ns}});
    SensorRun run(scene);
    (void)run.runUntil(300000);
    const MeterResult m = run.results().meters[0];
    const glm::dvec3 o = place.point({0, 0, 0}), ex = place.vector({1, 0, 0}), ey = place.vector({0, 1, 0});
    for (std::size_t k = 0; k < pts.size(); ++k) {
      const double ref = lz * throughOpening(sky, pts[k], ns[k], o, ex, ey);
      EXPECT_LT(std::abs(m.irradiance_w_m2[k] - ref), 4.5 * m.stderr_w_m2[k] + 2e-4 * ref)
          << (window ? "window " : "roof ") << k << ": " << m.irradiance_w_m2[k] << " +- " << m.stderr_w_m2[k] << " vs "
          << ref;
      EXPECT_LT(m.stderr_w_m2[k], 0.02 * ref);
    }
  }
}

TEST(SensorSky, SceneFileSkyWithSunByAltitudeAndAzimuth) {
  // A clear sky of 8000 lx horizontal illuminance and a sun of 60000 lx direct normal
  // illuminance at altitude 30, azimuth 180 (south, -y): a meter facing up reads 8000 + 60000 sin
  // 30; one facing south the sky's vertical share plus 60000 cos 30; one facing north the sky only.
  const std::string text = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
    {"type": "sky", "name": "day", "model": "clear", "horizontal_illuminance": 8000,
     "sun": {"altitude": 30, "azimuth": 180, "normal_illuminance": 60000}, "centre": [0, 0, 0], "radius": 4}],
    "meters": [{"name": "m", "points": [[0, 0, 0], [0, 0, 0], [0, 0, 0]], "normals": [[0, 0, 1], [0, -1, 0], [0, 1, 0]]}]})";
  const SensorScene scene = SensorScene::load(writeTestFile("sky.json", text));
  ASSERT_EQ(scene.lights().size(), 2u);
  EXPECT_EQ(scene.lights()[1].name, "day/sun");
  const glm::dvec3 sun = fromAngles(kPi / 3, kPi);
  EXPECT_NEAR(glm::length(scene.lights()[1].direction + sun), 0.0, 1e-12);
  const CieSky& sky = *scene.lights()[0].sky;
  const double lz = 8000 / sky.horizontalIntegral();
  SensorRunConfig cfg;
  cfg.per_light = true;
  SensorRun run(scene, cfg);
  (void)run.runUntil(200000);
  const SensorRunResults r = run.results();
  ASSERT_TRUE(r.luminous_transport);
  const MeterResult& m = r.meters[0];
  const double sky_south =
      lz * hemisphere([&](const glm::dvec3& d) { return sky.relativeLuminance(d) * std::max(0.0, -d.y); });
  const double sky_north =
      lz * hemisphere([&](const glm::dvec3& d) { return sky.relativeLuminance(d) * std::max(0.0, d.y); });
  const double sky_ref[3] = {8000, sky_south, sky_north}, sun_ref[3] = {30000, 60000 * std::cos(kPi / 6), 0};
  for (int k = 0; k < 3; ++k) {
    EXPECT_LT(std::abs(m.light_illuminance_lx[0][k] - sky_ref[k]), 4.5 * m.light_stderr_w_m2[0][k] + 1e-4 * sky_ref[k])
        << k << ": sky " << m.light_illuminance_lx[0][k] << " vs " << sky_ref[k];
    EXPECT_LT(std::abs(m.light_illuminance_lx[1][k] - sun_ref[k]),
              4.5 * m.light_stderr_w_m2[1][k] + 1e-9 * sun_ref[k] + 1e-12)
        << k << ": sun " << m.light_illuminance_lx[1][k] << " vs " << sun_ref[k];
    EXPECT_LT(std::abs(m.illuminance_lx[k] - sky_ref[k] - sun_ref[k]),
              4.5 * m.illuminance_stderr_lx[k] + 1e-4 * sky_ref[k]);
  }
  // Bad skies name the key.
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [)";
  expectLoadError(
      writeTestFile(
          "sky_nosun.json",
          head + R"({"type": "sky", "model": "clear", "zenith_luminance": 1, "centre": [0,0,0], "radius": 1}]})"),
      {"/lights/0", "sun"});
  expectLoadError(writeTestFile("sky_level.json", head + R"({"type": "sky", "centre": [0,0,0], "radius": 1}]})"),
                  {"/lights/0", "zenith_luminance"});
  expectLoadError(
      writeTestFile(
          "sky_type.json",
          head +
              R"({"type": "sky", "model": "cie", "cie_type": 17, "zenith_luminance": 1, "centre": [0,0,0], "radius": 1}]})"),
      {"/lights/0/cie_type"});
  expectLoadError(
      writeTestFile(
          "sky_model.json",
          head + R"({"type": "sky", "model": "foggy", "zenith_luminance": 1, "centre": [0,0,0], "radius": 1}]})"),
      {"/lights/0/model", "foggy"});
  expectLoadError(
      writeTestFile(
          "sky_alt.json",
          head +
              R"({"type": "sky", "zenith_luminance": 1, "centre": [0,0,0], "radius": 1, "sun": {"altitude": -5, "azimuth": 0}}]})"),
      {"/lights/0/sun/altitude"});
  expectLoadError(writeTestFile("sky_radius.json",
                                head + R"({"type": "sky", "zenith_luminance": 1, "centre": [0,0,0], "radius": 0}]})"),
                  {"/lights/0/radius"});
}

}  // namespace
}  // namespace duplex
