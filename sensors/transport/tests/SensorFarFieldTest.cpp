// Far-field sensors: the C-gamma grid (bins, edges, exact solid angles), an isotropic source's
// intensity P / (4 pi) in every cell, rays stopped by a floor never reach it, a rotated sensor, the
// round trip of a goniometric IES source (its table back within the statistical error, chi-square
// per cell near 1, its flux within 0.5%, the written LM-63-2002 file read back to the same table),
// thread counts and resumed runs bit-identical, the stop rule, and the scene-file keys.

#include "duplex/accel/Error.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/sensors/IesProfile.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace duplex {
namespace {

using namespace test;

std::shared_ptr<const SensorObject> farField(std::uint32_t nc, std::uint32_t ng) {
  return std::make_shared<const SensorObject>("far", SensorSpec{.shape = SensorShape::FarField, .nx = nc, .ny = ng});
}

glm::dvec3 direction(double c_deg, double gamma_deg) {
  const double c = c_deg * kPi / 180.0, g = gamma_deg * kPi / 180.0;
  return {std::sin(g) * std::cos(c), std::sin(g) * std::sin(c), -std::cos(g)};
}

TEST(SensorFarField, GridBinsEdgesAndExactSolidAngles) {
  const auto s = farField(8, 5);  // C every 45 degrees, gamma 0, 45, ..., 180
  EXPECT_EQ(s->binCount(), 40u);
  EXPECT_EQ(s->farFieldBinAt({0, 0, -1}), 0u);              // the nadir: C-plane 0, gamma 0
  EXPECT_EQ(s->farFieldBinAt({0, 0, 1}), 4u);               // the zenith: gamma 180
  EXPECT_EQ(s->farFieldBinAt({0, 1, 0}), 2u * 5 + 2);       // C 90, gamma 90
  EXPECT_EQ(s->farFieldBinAt(direction(359.0, 90.0)), 2u);  // C wraps to the plane of 0
  EXPECT_EQ(s->farFieldBinAt(direction(22.0, 90.0)), 2u);
  EXPECT_EQ(s->farFieldBinAt(direction(23.0, 90.0)), 1u * 5 + 2);
  EXPECT_EQ(s->farFieldBinAt(direction(90.0, 22.0)), 2u * 5 + 0);
  EXPECT_EQ(s->farFieldBinAt(direction(90.0, 23.0)), 2u * 5 + 1);
  EXPECT_EQ(s->farFieldBinAt({0, 0, 0}), kInvalidId);
  // An edge goes to the cell above it: gamma = 22.5 exactly (cos = sin of 67.5).
  const double c = std::cos(kPi / 8), sn = std::sin(kPi / 8);
  EXPECT_EQ(s->farFieldBinAt({sn, 0, -c}) % 5, 1u);
  double total = 0.0;
  for (std::uint32_t b = 0; b < s->binCount(); ++b) total += s->binArea(b);
  EXPECT_NEAR(total, 4.0 * kPi, 1e-12);
  // Polar caps of half height: dC (1 - cos 22.5 deg); a middle row dC (cos 67.5 - cos 112.5).
  EXPECT_NEAR(s->binArea(0), kPi / 4 * (1 - std::cos(kPi / 8)), 1e-15);
  EXPECT_NEAR(s->binArea(2), kPi / 4 * (std::cos(3 * kPi / 8) - std::cos(5 * kPi / 8)), 1e-15);
  EXPECT_DOUBLE_EQ(s->farFieldC(3), 135.0);
  EXPECT_DOUBLE_EQ(s->farFieldGamma(4), 180.0);
  EXPECT_THROW(farField(4, 1), InvalidArgument);
  EXPECT_THROW(farField(0, 3), InvalidArgument);
}

SensorRunResults runFor(const SensorScene& scene, std::uint64_t rays, unsigned threads = 2, std::uint64_t seed = 3) {
  SensorRunConfig cfg;
  cfg.seed = seed;
  cfg.threads = threads;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  return run.results();
}

TEST(SensorFarField, AnIsotropicSourceHasItsIntensityInEveryCell) {
  SceneGraph graph;
  (void)graph.commit();
  const double power = 3.0;
  const SensorScene scene(graph, {pointLight({1, 2, 3}, power)}, {}, {},
                          {{"far", farField(12, 7), Affine::identity()}});
  const SensorRunResults r = runFor(scene, 200000);
  ASSERT_EQ(r.sensors.size(), 1u);
  const SensorResult& s = r.sensors[0];
  EXPECT_EQ(s.shape, SensorShape::FarField);
  EXPECT_NEAR(s.total_flux_w, power, 1e-12 * power);  // every ray escapes with the full power
  EXPECT_NEAR(r.energy.escaped_w, s.total_flux_w, 1e-12 * power);
  double z2 = 0.0;
  for (std::uint32_t b = 0; b < s.flux_w.size(); ++b) {
    EXPECT_NEAR(s.flux_w[b], s.irradiance_w_m2[b] * s.bin_area_m2[b], 1e-15);
    const double z = (s.irradiance_w_m2[b] - power / (4 * kPi)) / s.stderr_w_m2[b];
    EXPECT_LT(std::abs(z), 4.5) << "cell " << b;
    z2 += z * z;
  }
  z2 /= static_cast<double>(s.flux_w.size());
  EXPECT_GT(z2, 0.6);
  EXPECT_LT(z2, 1.6);
}

TEST(SensorFarField, BlockedRaysNeverArriveAndARotatedSensorTurnsTheGrid) {
  Fixture f;
  f.add(quad(50.0, "floor"), Affine::identity(), "floor");  // absorbs everything going down
  // Rotated 90 degrees about x: the sensor's -z (its nadir) is world +y.
  const Affine rot = Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0});
  const SensorScene scene = [&] {
    (void)f.graph.commit();
    return SensorScene(f.graph, {pointLight({0, 0, 1}, 2.0)}, f.materials, {},
                       {{"up", farField(4, 9), Affine::identity()}, {"side", farField(4, 9), rot}});
  }();
  ASSERT_EQ(scene.sensors().size(), 2u);
  const SensorRunResults r = runFor(scene, 40000);
  const SensorResult& up = r.sensors[0];
  const SensorResult& side = r.sensors[1];
  EXPECT_NEAR(up.total_flux_w, r.energy.escaped_w, 1e-12);
  EXPECT_NEAR(side.total_flux_w, r.energy.escaped_w, 1e-12);
  double below = 0.0, beside_nadir_half = 0.0;
  for (std::uint32_t ic = 0; ic < 4; ++ic) {
    for (std::uint32_t ig = 0; ig < 9; ++ig) {
      const std::size_t b = ic * 9 + ig;
      if (ig < 4) below += up.flux_w[b];  // gamma < 90: towards the floor
      // In the side sensor's frame world -z (the floor) is local -y: C = 270.
      if (ic == 3) beside_nadir_half += side.flux_w[b];
    }
  }
  EXPECT_EQ(below, 0.0);
  EXPECT_GT(r.energy.absorbed_w, 0.9);  // about half of 2 W (the floor is not infinite)
  // The C-plane of 270 (local -y = world -z) sees only the upper rim: the rays that escape go up.
  EXPECT_LT(beside_nadir_half, 0.01 * side.total_flux_w);
}

// A smooth type C table over the full circle (25 C-planes, 0 ... 360), nadir and zenith single-valued.
IesProfile sourceTable() {
  std::vector<double> vertical, horizontal, values;
  for (int g = 0; g <= 180; g += 10) vertical.push_back(g);
  for (int c = 0; c <= 360; c += 15) horizontal.push_back(c);
  for (const double c : horizontal)
    for (const double g : vertical) {
      const double gr = g * kPi / 180.0, cr = c * kPi / 180.0;
      // Asymmetric in gamma (nadir against zenith) and in C (+y against -y), so that a turned or
      // mirrored grid fails.
      values.push_back(40.0 + 120.0 * std::pow(std::cos(0.5 * gr), 2) +
                       std::pow(std::sin(gr), 2) * (30.0 * std::cos(cr) + 15.0 * std::sin(cr)));
    }
  return IesProfile::fromTable(vertical, horizontal, values, "source");
}

Light iesLight(std::shared_ptr<const IesProfile> profile, const glm::dvec3& position) {
  Light l;
  l.type = LightType::Goniometric;
  l.name = "ies";
  l.profile = std::move(profile);
  l.position = position;
  return l;
}

TEST(SensorFarField, AGoniometricSourceReproducesItsTableAndItsFlux) {
  const auto profile = std::make_shared<const IesProfile>(sourceTable());
  Light l = iesLight(profile, {0.5, -1, 2});
  l.power_w = profile->integral();  // W = the table's lumens: the measured W/sr are its candela
  SceneGraph graph;
  (void)graph.commit();
  // The far-field grid on the table's own angles: C every 15 degrees, gamma every 10.
  const SensorScene scene(graph, {l}, {}, {}, {{"far", farField(24, 19), Affine::identity()}});
  const std::uint64_t rays = 1'000'000;
  const SensorRunResults r = runFor(scene, rays);
  const SensorResult& s = r.sensors[0];
  EXPECT_LT(std::abs(s.total_flux_w - l.power_w), 0.005 * l.power_w) << s.total_flux_w << " vs " << l.power_w;
  EXPECT_LT(std::abs(s.total_flux_w - l.power_w), 4.5 * s.total_flux_stderr_w);

  const SensorObject& grid = *scene.sensors()[0].object;
  double chi2_table = 0.0, chi2_cells = 0.0;
  const std::size_t n = s.flux_w.size();
  for (std::uint32_t ic = 0; ic < 24; ++ic) {
    for (std::uint32_t ig = 0; ig < 19; ++ig) {
      const std::size_t b = ic * 19 + ig;
      const double c = grid.farFieldC(ic) * kPi / 180.0, g = grid.farFieldGamma(ig) * kPi / 180.0;
      // The table's value at the cell's angles, and the source's mean intensity over the cell
      // (midpoint rule in cos gamma and C, 40 x 40).
      const double table = profile->intensityAt(g, c);
      const double dg = kPi / 18, dc = kPi / 12;
      const double g0 = std::max(0.0, g - dg / 2), g1 = std::min(kPi, g + dg / 2);
      double mean = 0.0;
      for (int i = 0; i < 40; ++i)
        for (int j = 0; j < 40; ++j) {
          const double cg = std::cos(g0) + (i + 0.5) / 40 * (std::cos(g1) - std::cos(g0));
          mean += profile->intensityAt(std::acos(cg), c - dc / 2 + (j + 0.5) / 40 * dc) / 1600.0;
        }
      ASSERT_GT(s.stderr_w_m2[b], 0.0);
      const double zt = (s.irradiance_w_m2[b] - table) / s.stderr_w_m2[b];
      const double zc = (s.irradiance_w_m2[b] - mean) / s.stderr_w_m2[b];
      chi2_table += zt * zt;
      chi2_cells += zc * zc;
      EXPECT_LT(std::abs(zc), 4.5) << "C " << grid.farFieldC(ic) << ", gamma " << grid.farFieldGamma(ig);
    }
  }
  chi2_table /= static_cast<double>(n);
  chi2_cells /= static_cast<double>(n);
  // 456 cells: chi-square per cell 1 +- 0.066 (one standard deviation).
  EXPECT_GT(chi2_cells, 0.7);
  EXPECT_LT(chi2_cells, 1.35);
  EXPECT_GT(chi2_table, 0.7);
  EXPECT_LT(chi2_table, 1.35);
  RecordProperty("chi2_per_cell_vs_table", std::to_string(chi2_table));
  RecordProperty("chi2_per_cell_vs_cell_means", std::to_string(chi2_cells));
  RecordProperty("flux_relative_error", std::to_string(s.total_flux_w / l.power_w - 1.0));

  // The measured table written as LM-63-2002 reads back through the IES reader to the same numbers.
  const IesTable written = farFieldIesTable(s, r.rays, r.seed);
  const std::string text = formatIes(written);
  EXPECT_EQ(text.rfind("IESNA:LM-63-2002\n", 0), 0u);
  const IesProfile back = IesProfile::parse(text, "measured.ies");
  EXPECT_EQ(back.verticalAngles(), written.vertical_deg);
  EXPECT_EQ(back.horizontalAngles(), written.horizontal_deg);
  ASSERT_EQ(back.table().size(), 25u * 19u);
  EXPECT_EQ(back.table(), written.values);
  for (std::size_t b = 0; b < n; ++b) EXPECT_EQ(back.table()[b], s.irradiance_w_m2[b]);
  EXPECT_EQ(back.keywords().at("_UNITS"), "W/sr");
  EXPECT_NE(back.keywords().at("OTHER").find("not candela"), std::string::npos);
  EXPECT_EQ(back.lumensPerLamp(), -1.0);
  // Its integral is the measured flux up to the bilinear model's quadrature of the table.
  EXPECT_LT(std::abs(back.integral() - s.total_flux_w), 0.01 * s.total_flux_w);
}

TEST(SensorFarField, ThreadsResumeAndTheStopRule) {
  const Light l = iesLight(std::make_shared<const IesProfile>(sourceTable()), {0, 0, 1});
  Fixture f;
  f.add(quad(1.0, "floor"), Affine::identity(), "floor", Material{Lambertian{0.7}});
  (void)f.graph.commit();
  const SensorScene scene(f.graph, {l}, f.materials, {}, {{"far", farField(6, 7), Affine::identity()}});
  SensorRunConfig cfg;
  cfg.batch_rays = 5000;
  const SensorRunResults one = [&] {
    cfg.threads = 1;
    SensorRun run(scene, cfg);
    (void)run.runUntil(30000);
    return run.results();
  }();
  const std::filesystem::path state =
      std::filesystem::temp_directory_path() / ("far_state_" + std::to_string(::getpid()) + ".bin");
  {
    cfg.threads = 2;
    cfg.chunk_rays = 333;
    SensorRun run(scene, cfg);
    (void)run.runUntil(12000);
    run.saveState(state);
  }
  SensorRun resumed(scene, cfg);
  resumed.loadState(state);
  (void)resumed.runUntil(30000);
  std::filesystem::remove(state);
  expectIdentical(one, resumed.results());
  EXPECT_EQ(one.sensors[0].irradiance_w_m2, resumed.results().sensors[0].irradiance_w_m2);

  SensorRun stopping(scene, cfg);
  SensorStopRule stop;
  stop.sensor = 0;
  stop.target = 0.01;
  stop.min_rays = 1000;
  EXPECT_EQ(stopping.runUntil(10'000'000, {}, stop), SensorRunStatus::TargetReached);
  EXPECT_LE(stopping.relativeStderr(0), 0.01);
  EXPECT_LT(stopping.raysDone(), 10'000'000u);
}

TEST(SensorFarField, IesWriterRefusesWhatTheReaderWouldAndKeepsKeywords) {
  IesTable t;
  t.vertical_deg = {0, 90, 180};
  t.horizontal_deg = {0};
  t.values = {1, 2.5, 1e-300};
  t.keywords = {{"TEST", "a\nb"}, {"_UNITS", "W/sr"}};
  const IesProfile p = IesProfile::parse(formatIes(t), "t.ies");
  EXPECT_EQ(p.keywords().at("TEST"), "a\nb");
  EXPECT_EQ(p.keywords().at("MANUFAC"), "");
  EXPECT_EQ(p.verticalAngles(), t.vertical_deg);
  EXPECT_EQ(p.table()[1], 2.5);
  EXPECT_EQ(p.table()[2], 1e-300);
  IesTable bad = t;
  bad.vertical_deg = {10, 90, 180};
  EXPECT_THROW((void)formatIes(bad), InvalidArgument);
  bad = t;
  bad.values[1] = -1;
  EXPECT_THROW((void)formatIes(bad), InvalidArgument);
  bad = t;
  bad.keywords = {{"A]B", "x"}};
  EXPECT_THROW((void)formatIes(bad), InvalidArgument);
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("written_" + std::to_string(::getpid()) + ".ies");
  writeIes(file, t);
  EXPECT_EQ(IesProfile::load(file).table(), p.table());
  std::filesystem::remove(file);
  EXPECT_THROW(writeIes("/nonexistent_dir/x.ies", t), FileError);
}

std::filesystem::path writeScene(const std::string& name, const std::string& text) {
  const std::filesystem::path p =
      std::filesystem::temp_directory_path() / (name + "_" + std::to_string(::getpid()) + ".json");
  std::ofstream(p) << text;
  return p;
}

void expectFileError(const std::string& text, const std::string& needle) {
  const auto p = writeScene("farfield_bad", text);
  try {
    (void)SensorScene::load(p);
    ADD_FAILURE() << "accepted: " << text;
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
  std::filesystem::remove(p);
}

TEST(SensorFarField, SceneFileKeys) {
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}], "sensors": [)";
  const auto good = writeScene("farfield_good", head + R"({"name": "far", "shape": "farfield", "bins": [8, 5],
      "transform": [0,-1,0,0, 1,0,0,0, 0,0,1,0]}, {"name": "plate", "size": 1}]})");
  const SensorScene scene = SensorScene::load(good);
  std::filesystem::remove(good);
  ASSERT_EQ(scene.sensors().size(), 2u);
  EXPECT_EQ(scene.sensors()[0].name, "plate");  // the graph's sensors first
  const SensorInstance& far = scene.sensors()[1];
  EXPECT_EQ(far.node, kInvalidNode);
  EXPECT_EQ(far.object->spec().shape, SensorShape::FarField);
  EXPECT_EQ(far.object->binCount(), 40u);
  EXPECT_NEAR(far.frame_x.y, 1.0, 1e-15);  // local x is world y
  expectFileError(head + R"({"name": "f", "shape": "farfield", "bins": [8, 5], "size": 1}]})", "/sensors/0/size");
  expectFileError(head + R"({"name": "f", "shape": "farfield"}]})", "/sensors/0");
  expectFileError(head + R"({"name": "f", "shape": "farfield", "bins": [8, 1]}]})", "/sensors/0/bins/1");
  expectFileError(head + R"({"name": "f", "shape": "farfield", "bins": 8}]})", "/sensors/0/bins");
  expectFileError(
      head + R"({"name": "f", "shape": "farfield", "bins": [8, 5], "transform": [1,0,0,1, 0,1,0,0, 0,0,1,0]}]})",
      "/sensors/0/transform");
  expectFileError(
      head + R"({"name": "f", "shape": "farfield", "bins": [8, 5], "transform": [2,0,0,0, 0,2,0,0, 0,0,2,0]}]})",
      "/sensors/0/transform");
  expectFileError(head + R"({"name": "f", "shape": "farfield", "bins": [8, 5]}, {"name": "f", "size": 1}]})", "'f'");
  expectFileError(
      R"({"format": "duplex-scene-v1", "objects": [{"name": "s", "sensor": {"shape": "farfield", "bins": [4, 3]}}],
      "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}]})",
      "/objects/0/sensor/shape");
}

}  // namespace
}  // namespace duplex
