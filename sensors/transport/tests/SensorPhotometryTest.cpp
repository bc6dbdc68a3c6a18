// Photometry and colour: the CIE 1931 observer table, lights in lumens (directly, through the bands'
// V(lambda) weights, and an IES file's own candela), illuminance and luminous intensity against
// inverse-square references with k-sigma bounds, chromaticities of single bands, and the scene
// file's errors for lumens and band wavelengths.

#include "duplex/accel/Error.h"
#include "duplex/sensors/Photometry.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

TEST(Cie1931, TableIsTheTwoDegreeObserverEvery5nm) {
  const auto table = cie1931Observer();
  ASSERT_EQ(table.size(), 81u);
  double sx = 0.0, sy = 0.0, sz = 0.0;
  for (std::size_t i = 0; i < table.size(); ++i) {
    EXPECT_EQ(table[i].nm, 380.0 + 5.0 * static_cast<double>(i));
    EXPECT_LE(table[i].ybar, 1.0);
    sx += table[i].xbar;
    sy += table[i].ybar;
    sz += table[i].zbar;
  }
  EXPECT_EQ(table[35].nm, 555.0);
  EXPECT_EQ(table[35].ybar, 1.0);  // V(lambda) peaks at 555 nm
  // The equal-energy spectrum is white at (1/3, 1/3): the three functions have equal sums.
  EXPECT_NEAR(sx / sy, 1.0, 2e-4);
  EXPECT_NEAR(sz / sy, 1.0, 2e-4);
  EXPECT_NEAR(sy, 21.371327, 1e-6);
}

TEST(Cie1931, BandMeansIntegrateTheInterpolatedTable) {
  // [550, 560]: two trapezoids of the rows 550, 555, 560.
  const glm::dvec3 m = cieBandMean(550.0, 560.0);
  EXPECT_NEAR(m.y, (2.5 * (0.994950 + 1.0) + 2.5 * (1.0 + 0.995000)) / 10.0, 1e-12);
  EXPECT_NEAR(m.x, (2.5 * (0.433450 + 0.512050) + 2.5 * (0.512050 + 0.594500)) / 10.0, 1e-12);
  // Half a step: the value at 557.5 nm is interpolated.
  EXPECT_NEAR(cieBandMean(555.0, 557.5).y, (1.0 + 0.9975) / 2.0, 1e-12);
  // Outside the table the observer sees nothing; a band half outside keeps only its inner half.
  EXPECT_EQ(cieBandMean(200.0, 300.0), glm::dvec3(0.0));
  EXPECT_NEAR(cieBandMean(770.0, 790.0).y, cieBandMean(770.0, 780.0).y / 2.0, 1e-15);
  // The chromaticity of a narrow band at 550 nm lies on the spectral locus (0.3016, 0.6923).
  const glm::dvec3 n = cieBandMean(549.0, 551.0);
  EXPECT_NEAR(n.x / (n.x + n.y + n.z), 0.3016, 5e-4);
  EXPECT_NEAR(n.y / (n.x + n.y + n.z), 0.6923, 5e-4);
}

TEST(Photometry, ALumensOnlySceneTracesLuminousFluxDirectly) {
  // 1000 lm isotropic, 2 m above a one-sided square: the flux is I Omega with I = 1000 / (4 pi) cd.
  Fixture f;
  const double h = 2.0, side = 0.6;
  f.add(sensor(side, side, 2, 2, /*two_sided=*/false, "desk"), Affine::identity(), "desk");
  Light l = pointLight({0.0, 0.0, h}, 1.0);
  l.lumens = 1000.0;
  const SensorScene scene = f.scene({l});
  EXPECT_TRUE(scene.photometric());
  EXPECT_FALSE(scene.colorimetric());
  EXPECT_EQ(scene.lights()[0].power_w, 1000.0);  // the transported unit is the lumen
  SensorRunConfig cfg;
  cfg.seed = 5;
  SensorRun run(scene, cfg);
  (void)run.runUntil(400000);
  const SensorRunResults r = run.results();
  ASSERT_TRUE(r.photometric);
  EXPECT_EQ(r.emitted_lm, 1000.0);
  const SensorResult& s = r.sensors[0];
  ASSERT_EQ(s.illuminance_lx.size(), 4u);
  const double intensity = 1000.0 / (4.0 * std::numbers::pi);
  for (std::uint32_t b = 0; b < 4; ++b) {
    const double x0 = (b % 2) ? 0.0 : -side / 2, y0 = (b / 2) ? 0.0 : -side / 2;
    const double expected =
        intensity * rectangleSolidAngle(x0, x0 + side / 2, y0, y0 + side / 2, h) / (side * side / 4);
    EXPECT_EQ(s.illuminance_lx[b], s.irradiance_w_m2[b]);
    EXPECT_EQ(s.illuminance_stderr_lx[b], s.stderr_w_m2[b]);
    EXPECT_LT(std::abs(s.illuminance_lx[b] - expected), 4.5 * s.illuminance_stderr_lx[b])
        << "bin " << b << ": " << s.illuminance_lx[b] << " lx vs " << expected;
    EXPECT_NEAR(expected, intensity / (h * h), 0.04 * expected);  // about I / h^2 = 19.9 lx
  }
  EXPECT_EQ(s.luminous_flux_lm, s.total_flux_w);
  EXPECT_TRUE(s.cie_xyz.empty());
}

TEST(Photometry, BandsWithWavelengthsWeighByVLambdaAndGiveChromaticities) {
  // A light of 500 lm with equal power in a green and a red band, in a closed box of sensors: its
  // watts are its lumens over its efficacy, and every ray leaves through the box.
  Fixture f;
  closeBox(f);
  Light l = pointLight({0.1, -0.2, 0.3}, 1.0);
  l.lumens = 500.0;
  l.spectrum = {1.0, 1.0};
  f.graph.commit();
  const SensorScene scene(f.graph, {l}, f.materials, {"green", "red"}, {}, {{{550.0, 560.0}}, {{640.0, 650.0}}});
  ASSERT_TRUE(scene.colorimetric());
  const double kg = 683.0 * cieBandMean(550.0, 560.0).y, kr = 683.0 * cieBandMean(640.0, 650.0).y;
  EXPECT_NEAR(scene.luminousWeight(0), kg, 1e-12 * kg);
  EXPECT_NEAR(scene.lights()[0].power_w, 500.0 / (0.5 * kg + 0.5 * kr), 1e-12);
  SensorRunConfig cfg;
  cfg.seed = 17;
  SensorRun run(scene, cfg);
  (void)run.runUntil(200000);
  const SensorRunResults r = run.results();
  EXPECT_NEAR(r.emitted_lm, 500.0, 1e-9);
  double lm = 0.0, se2 = 0.0, w = 0.0;
  for (const SensorResult& s : r.sensors) {
    lm += s.luminous_flux_lm;
    se2 += s.luminous_flux_stderr_lm * s.luminous_flux_stderr_lm;
    w += s.total_flux_w;
    // Y is the luminous flux; the sensor's colour is a mix of the two bands' colours.
    ASSERT_EQ(s.total_cie_xyz.size(), 3u);
    EXPECT_NEAR(s.total_cie_xyz[1], s.luminous_flux_lm, 1e-9 * s.luminous_flux_lm);
    const glm::dvec3 g = cieBandMean(550.0, 560.0), red = cieBandMean(640.0, 650.0);
    EXPECT_GT(s.total_chromaticity_xy[0], g.x / (g.x + g.y + g.z));
    EXPECT_LT(s.total_chromaticity_xy[0], red.x / (red.x + red.y + red.z));
    ASSERT_EQ(s.cie_xyz.size(), 3 * s.irradiance_w_m2.size());
    ASSERT_EQ(s.chromaticity_xy.size(), 2 * s.irradiance_w_m2.size());
  }
  EXPECT_NEAR(w, scene.lights()[0].power_w, 1e-12 * w);  // the radiometric sums are exact
  EXPECT_LT(std::abs(lm - 500.0), 4.5 * std::sqrt(se2)) << lm << " lm of 500, SE " << std::sqrt(se2);
  EXPECT_GT(std::sqrt(se2), 0.0);
}

TEST(Photometry, OneBandHasItsOwnChromaticityInEveryLitBin) {
  Fixture f;
  f.add(sensor(4.0, 4.0, 8, 8, false, "floor"), Affine::identity(), "floor");
  Light l = pointLight({0.0, 0.0, 1.0}, 2.0);  // watts: the bands' wavelengths make it photometric
  f.graph.commit();
  const SensorScene scene(f.graph, {l}, f.materials, {"blue"}, {}, {{{450.0, 470.0}}});
  SensorRun run(scene);
  (void)run.runUntil(20000);
  const SensorResult s = run.results().sensors[0];
  const glm::dvec3 b = cieBandMean(450.0, 470.0);
  int lit = 0;
  for (std::size_t k = 0; k < s.flux_w.size(); ++k) {
    if (s.flux_w[k] == 0.0) {
      EXPECT_TRUE(std::isnan(s.chromaticity_xy[2 * k]));
      continue;
    }
    ++lit;
    EXPECT_NEAR(s.chromaticity_xy[2 * k], b.x / (b.x + b.y + b.z), 1e-12);
    EXPECT_NEAR(s.chromaticity_xy[2 * k + 1], b.y / (b.x + b.y + b.z), 1e-12);
    EXPECT_NEAR(s.illuminance_lx[k], 683.0 * b.y * s.irradiance_w_m2[k], 1e-9 * s.illuminance_lx[k]);
  }
  EXPECT_GT(lit, 60);
}

// An absolute-photometry file: 100 cd at the nadir, 50 at the horizon, 0 at the zenith.
const char* kLampIes =
    "IESNA:LM-63-2002\n[TEST] photometry test\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 100\n0 90 180\n0\n100 50 0\n";

TEST(Photometry, AnIesLightWithoutPowerEmitsItsCandelaTable) {
  writeTestFile("lamp.ies", kLampIes);
  const auto path = writeTestFile("ies.json", R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "ies", "file": "lamp.ies", "position": [0, 0, 3]}],
    "sensors": [{"name": "work", "size": [1, 1], "bins": [1, 1], "two_sided": false}]})");
  const SensorScene scene = SensorScene::load(path);
  ASSERT_TRUE(scene.photometric());
  const Light& l = scene.lights()[0];
  EXPECT_EQ(l.lumens, l.profile->integral());
  EXPECT_NEAR(l.intensity({0, 0, -1}), 100.0, 1e-9);  // the candela values are the intensity
  EXPECT_NEAR(l.intensity({1, 0, 0}), 50.0, 1e-9);
  SensorRunConfig cfg;
  cfg.seed = 23;
  SensorRun run(scene, cfg);
  (void)run.runUntil(300000);
  const SensorRunResults r = run.results();
  EXPECT_NEAR(r.emitted_lm, l.profile->integral(), 1e-9);
  // Reference: the midpoint quadrature of I(d) cos / r^2 over the square.
  double expected = 0.0;
  const int n = 200;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const glm::dvec3 p(-0.5 + (i + 0.5) / n, -0.5 + (j + 0.5) / n, 0.0), d = p - glm::dvec3(0, 0, 3);
      const double r2 = glm::dot(d, d);
      expected += l.intensity(d) * 3.0 / std::sqrt(r2) / r2 / (n * n);  // mean over the unit square
    }
  const SensorResult& s = r.sensors[0];
  EXPECT_LT(std::abs(s.illuminance_lx[0] - expected), 4.5 * s.illuminance_stderr_lx[0])
      << s.illuminance_lx[0] << " lx vs " << expected;
}

TEST(Photometry, FarFieldSensorsMeasureCandela) {
  Fixture f;
  const double cd = 80.0;
  Light l = pointLight({0.0, 0.0, 0.0}, 1.0);
  l.lumens = 4.0 * std::numbers::pi * cd;
  f.graph.commit();
  FarFieldSensor far{
      "far", std::make_shared<const SensorObject>("far", SensorSpec{.shape = SensorShape::FarField, .nx = 4, .ny = 5}),
      Affine::identity()};
  const SensorScene scene(f.graph, {l}, f.materials, {}, {far});
  SensorRun run(scene);
  (void)run.runUntil(100000);
  const SensorResult s = run.results().sensors[0];
  double z2 = 0.0;
  for (std::size_t b = 0; b < s.illuminance_lx.size(); ++b) {
    const double z = (s.illuminance_lx[b] - cd) / s.illuminance_stderr_lx[b];
    z2 += z * z;
    EXPECT_LT(std::abs(z), 4.5) << "cell " << b << ": " << s.illuminance_lx[b] << " cd";
  }
  EXPECT_GT(z2 / 20.0, 0.3);
  EXPECT_LT(z2 / 20.0, 2.5);
  EXPECT_NEAR(s.luminous_flux_lm, l.lumens, 1e-9 * l.lumens);  // every ray escapes
  const IesTable table = farFieldIesTable(s, 100000, 1);
  EXPECT_EQ(table.values[0], s.illuminance_lx[0]);
  bool candela = false;
  for (const auto& [key, value] : table.keywords) candela = candela || (key == "_UNITS" && value == "cd");
  EXPECT_TRUE(candela);
}

void expectError(const std::string& name, const std::string& body, const std::vector<std::string>& needles) {
  const auto path = writeTestFile(name, std::string(R"({"format": "duplex-scene-v1", "objects": [], )") + body + "}");
  expectLoadError(path, needles);
}

TEST(Photometry, ASpectrumMayNameItsBands) {
  const auto path = writeTestFile("named_spectrum.json", R"({"format": "duplex-scene-v1", "objects": [],
    "bands": [{"name": "g", "nm": [540, 560]}, {"name": "r", "nm": [620, 640]}],
    "sensors": [{"name": "s", "size": 1}],
    "lights": [{"type": "point", "position": [0, 0, 1], "lumens": 100, "spectrum": {"r": 3, "g": 1}}]})");
  const SensorScene scene = SensorScene::load(path);
  EXPECT_EQ(scene.lights()[0].spectrum, (std::vector<double>{1.0, 3.0}));
  const double kg = 683.0 * cieBandMean(540.0, 560.0).y, kr = 683.0 * cieBandMean(620.0, 640.0).y;
  EXPECT_NEAR(scene.lights()[0].power_w, 100.0 / (0.25 * kg + 0.75 * kr), 1e-12);
}

TEST(Photometry, MalformedLumensAndBandsNameTheFileAndTheLightOrBand) {
  writeTestFile("lamp.ies", kLampIes);
  const std::string sensor = R"("sensors": [{"name": "s", "size": 1}], )";
  expectError("both.json", sensor + R"("lights": [{"type": "point", "position": [0,0,1], "power": 1, "lumens": 5}])",
              {"/lights/0", "not both"});
  expectError("neither.json", sensor + R"("lights": [{"type": "point", "position": [0,0,1]}])",
              {"/lights/0", "missing key \"power\""});
  expectError("negative.json", sensor + R"("lights": [{"type": "point", "position": [0,0,1], "lumens": -5}])",
              {"/lights/0/lumens", "lumens must be > 0"});
  expectError("mixed.json",
              sensor + R"("lights": [{"type": "point", "name": "bulb", "position": [0,0,1], "lumens": 800},
                                     {"type": "ies", "name": "lamp", "file": "lamp.ies", "position": [0,0,2], "power": 3}])",
              {"'lamp' is given in watts", "'bulb' in lumens", "wavelengths"});
  expectError("mixed_ies.json",
              sensor + R"("lights": [{"type": "point", "name": "bulb", "position": [0,0,1], "power": 8},
                                     {"type": "ies", "name": "lamp", "file": "lamp.ies", "position": [0,0,2]}])",
              {"'bulb' is given in watts", "'lamp' in lumens"});
  expectError("nm_order.json", sensor + R"("bands": [{"name": "a", "nm": [400, 500]}, {"name": "b", "nm": [600, 600]}],
                          "lights": [{"type": "point", "position": [0,0,1], "power": 1}])",
              {"/bands/1/nm", "0 < lo < hi"});
  expectError("nm_some.json", sensor + R"("bands": [{"name": "a", "nm": [400, 500]}, "b"],
                          "lights": [{"type": "point", "position": [0,0,1], "power": 1}])",
              {"/bands/1", "every band has wavelengths"});
  expectError("nm_key.json", sensor + R"("bands": [{"name": "a", "nm": [400, 500], "colour": 1}],
                          "lights": [{"type": "point", "position": [0,0,1], "power": 1}])",
              {"/bands/0", "colour"});
  expectError("spectrum_band.json",
              sensor + R"("bands": [{"name": "g", "nm": [500, 600]}, {"name": "r", "nm": [600, 700]}],
                          "lights": [{"type": "point", "position": [0,0,1], "lumens": 10, "spectrum": {"g": 1, "b": 2}}])",
              {"/lights/0/spectrum", "unknown band \"b\""});
  expectError("invisible.json",
              sensor + R"("bands": [{"name": "ir", "nm": [900, 1000]}, {"name": "g", "nm": [500, 600]}],
                          "lights": [{"type": "point", "name": "heater", "position": [0,0,1], "lumens": 10,
                                      "spectrum": [1, 0]}])",
              {"'heater'", "luminous efficacy is 0"});
}

}  // namespace
}  // namespace duplex
