// Angular bins of the incoming direction (optional per sensor): a point
// source at a known direction fills exactly one bin; the light leaving a Lambertian area source
// follows the cosine law, P (sin^2 theta1 - sin^2 theta0) per polar bin, uniform in azimuth; bin
// geometry; bit-identical for any thread count; scene-file keys.

#include "duplex/accel/Error.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

std::shared_ptr<const SensorObject> angularSensor(double size, std::uint32_t nt, std::uint32_t np, bool two_sided,
                                                  const std::string& name) {
  return std::make_shared<const SensorObject>(
      name, SensorSpec{.width = size, .height = size, .two_sided = two_sided, .theta_bins = nt, .phi_bins = np});
}

TEST(SensorAngular, BinGeometry) {
  const auto s = angularSensor(1.0, 9, 12, true, "s");
  const double deg = kPi / 180.0;
  EXPECT_EQ(s->angleBinAt(std::cos(35 * deg), 100 * deg), 3u * 9u + 3u);
  EXPECT_EQ(s->angleBinAt(-std::cos(35 * deg), 100 * deg), 3u * 9u + 3u);  // either face
  EXPECT_EQ(s->angleBinAt(1.0, 0.0), 0u);
  EXPECT_EQ(s->angleBinAt(0.0, -1e-12), 11u * 9u + 8u);          // 90 degrees: last theta bin; phi just below 360
  EXPECT_EQ(s->angleBinAt(0.5, 2.0 * kPi + 0.1), 0u * 9u + 6u);  // phi wraps; theta = 60 degrees: bin 6
  double total = 0.0;
  for (std::uint32_t b = 0; b < 9 * 12; ++b) total += s->angleBinSolidAngle(b);
  EXPECT_NEAR(total, 2.0 * kPi, 1e-12);  // one hemisphere
  EXPECT_EQ(angularSensor(1.0, 0, 1, true, "none")->angleBinAt(1.0, 0.0), kInvalidId);
  SensorSpec bad;
  bad.theta_bins = 4;
  bad.phi_bins = 0;
  EXPECT_THROW(SensorObject("bad", bad), InvalidArgument);
  bad.theta_bins = 2048;
  bad.phi_bins = 1024;
  EXPECT_THROW(SensorObject("bad", bad), InvalidArgument);
}

TEST(SensorAngular, PointSourceAtAKnownDirectionFillsOneBin) {
  // A small sensor, rotated about its normal by 20 degrees; the source at polar angle 35 degrees and
  // azimuth 100 degrees in the sensor's frame (phi measured from its local +x).
  const double deg = kPi / 180.0, theta = 35 * deg, phi = 100 * deg, rot = 20 * deg;
  Affine world = translate(0.5, -0.2, 0.3);
  world.linear = glm::dmat3(std::cos(rot), std::sin(rot), 0, -std::sin(rot), std::cos(rot), 0, 0, 0, 1);  // columns
  const glm::dvec3 in_ws(std::sin(theta) * std::cos(phi + rot), std::sin(theta) * std::sin(phi + rot), std::cos(theta));
  Fixture f;
  f.add(angularSensor(0.01, 9, 12, false, "s"), world, "s");
  SensorScene scene = f.scene({pointLight(world.translation + 2.0 * in_ws, 1.0)});
  SensorRun run(scene);
  (void)run.runUntil(2000000);
  const SensorRunResults r = run.results();
  const SensorResult& s = r.sensors[0];
  ASSERT_EQ(s.angular_flux_w.size(), 108u);
  EXPECT_EQ(s.theta_bins, 9u);
  EXPECT_EQ(s.phi_bins, 12u);
  const std::size_t expected = 3 * 9 + 3;  // phi in [90, 120), theta in [30, 40)
  EXPECT_GT(s.total_flux_w, 0.0);
  for (std::size_t b = 0; b < s.angular_flux_w.size(); ++b) {
    if (b == expected) {
      EXPECT_EQ(s.angular_flux_w[b], s.total_flux_w);  // the same deposits, in the same order
      EXPECT_EQ(s.angular_ray_count[b], s.ray_count[0]);
    } else {
      EXPECT_EQ(s.angular_flux_w[b], 0.0) << "bin " << b;
    }
  }
  // And the flux is I cos(theta) A / d^2 (within its error).
  const double exact = 1.0 / (4.0 * kPi) * std::cos(theta) * 1e-4 / 4.0;
  EXPECT_LT(std::abs(s.total_flux_w - exact), 4.5 * s.total_flux_stderr_w);
}

TEST(SensorAngular, LambertianAreaSourceFollowsTheCosineLaw) {
  // A 0.1 x 0.1 Lambertian source in z = 0 emitting +z, under a two-sided 20 x 20 sensor at
  // z = 0.001: every ray crosses it except those within 0.003 degrees of grazing (a share of
  // cos^2 below 3e-9). Polar bin [t0, t1] receives P (sin^2 t1 - sin^2 t0); azimuth bins P / n_phi.
  Fixture f;
  const std::uint32_t nt = 9, np = 8;
  f.add(angularSensor(20.0, nt, np, true, "s"), translate(0, 0, 0.001), "s");
  Light area;
  area.type = LightType::Area;
  area.name = "panel";
  area.width = area.height = 0.1;
  area.power_w = 2.0;
  SensorScene scene = f.scene({area});
  SensorRun run(scene);
  (void)run.runUntil(300000);
  const SensorRunResults r = run.results();
  const SensorResult& s = r.sensors[0];
  EXPECT_NEAR(s.total_flux_w, 2.0, 1e-6);
  double z2 = 0.0;
  int terms = 0;
  for (std::uint32_t it = 0; it < nt; ++it) {
    const double t0 = it * 0.5 * kPi / nt, t1 = (it + 1) * 0.5 * kPi / nt;
    const double ring = 2.0 * (std::sin(t1) * std::sin(t1) - std::sin(t0) * std::sin(t0));
    double sum = 0.0;
    for (std::uint32_t ip = 0; ip < np; ++ip) {
      const std::size_t b = ip * nt + it;
      sum += s.angular_flux_w[b];
      const double z = (s.angular_flux_w[b] - ring / np) / s.angular_stderr_w[b];
      EXPECT_LT(std::abs(z), 4.5) << "theta bin " << it << ", phi bin " << ip;
      z2 += z * z;
      ++terms;
    }
    EXPECT_NEAR(sum, ring, 0.02 * ring + 1e-3) << "theta bin " << it;
  }
  // The errors are neither hidden nor inflated.
  EXPECT_GT(z2 / terms, 0.5);
  EXPECT_LT(z2 / terms, 2.0);
}

TEST(SensorAngular, BitIdenticalForAnyThreadCountWithBandsAndSpheres) {
  // Angular bins, a sphere sensor and bands in one scene with a diffuse floor; 1 and 2 threads and
  // two chunk sizes give the same bits.
  Fixture f;
  f.add(angularSensor(2.0, 6, 4, true, "angles"), translate(0, 0, 1.0), "angles");
  SensorSpec ball;
  ball.shape = SensorShape::Sphere;
  ball.width = ball.height = 6.0;
  ball.nx = 8;
  ball.ny = 4;
  f.add(std::make_shared<const SensorObject>("ball", ball), Affine::identity(), "ball");
  const Material floor = Lambertian{{0.5, {0.9, 0.3}}};
  f.add(quad(1.0, "floor"), translate(0, 0, -0.5), "floor", floor);
  Light l = pointLight({0.1, 0, 0}, 2.0);
  l.spectrum = {1, 1};
  SensorScene scene = f.scene({l}, {"a", "b"});
  auto results = [&](unsigned threads, std::uint32_t chunk) { return runWith(scene, threads, chunk, 40000); };
  const SensorRunResults one = results(1, 1024);
  expectIdentical(one, results(2, 1024));
  expectIdentical(one, results(2, 77));
  EXPECT_GT(one.sensors[scene.findSensor("angles")].angular_flux_w[0], 0.0);
  EXPECT_NEAR(one.sensors[scene.findSensor("ball")].total_flux_w, one.energy.escaped_w, 1e-12);  // encloses all
}

// Each sensor may have up to 2^20 angular bins; many such sensors in many bands would need more
// accumulator memory than the machine has: the run is refused at construction with a message
// giving the sizes (before, the allocation threw std::bad_alloc or the process was killed).
TEST(SensorAngular, RunsWhoseAccumulatorsDoNotFitAreRefused) {
  Fixture f;
  for (int k = 0; k < 64; ++k) {
    const std::string name = "wide" + std::to_string(k);
    f.add(angularSensor(0.1, 1024, 1024, true, name), translate(0.2 * k, 0, 1), name);
  }
  std::vector<std::string> bands;
  for (int b = 0; b < 256; ++b) bands.push_back("band" + std::to_string(b));
  const SensorScene scene = f.scene({pointLight({0, 0, 0}, 1.0)}, bands);
  try {
    SensorRun run(scene, SensorRunConfig{});
    FAIL() << "a run needing 256 GiB of accumulators was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("67108864 angular bins in 256 bands"), std::string::npos) << e.what();
  }
  // A smaller limit refuses a small run too; the default accepts it.
  Fixture g;
  g.add(angularSensor(0.1, 4, 4, true, "small"), translate(0, 0, 1), "small");
  const SensorScene small = g.scene({pointLight({0, 0, 0}, 1.0)});
  SensorRunConfig tight;
  tight.max_accumulator_bytes = 100;
  EXPECT_THROW(SensorRun(small, tight), InvalidArgument);
  EXPECT_NO_THROW(SensorRun(small, SensorRunConfig{}));
}

TEST(SensorAngular, SceneFilesDeclareAngularBins) {
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("duplex_angular_" + std::to_string(::getpid()) + ".json");
  auto write = [&](const std::string& bins) {
    std::ofstream(file) << R"({"format": "scene-json-v1", "objects": [], "instances": [],
      "lights": [{"type": "point", "position": [0, 0, 1], "power": 1}],
      "sensors": [{"name": "s", "size": [1, 1], "angular_bins": )"
                        << bins << R"(}]})";
    return file;
  };
  {
    const SensorScene scene = SensorScene::load(write("[6, 4]"));
    EXPECT_EQ(scene.sensors()[0].object->spec().theta_bins, 6u);
    EXPECT_EQ(scene.sensors()[0].object->spec().phi_bins, 4u);
    EXPECT_EQ(scene.angleBinCount(), 24u);
  }
  EXPECT_EQ(SensorScene::load(write("5")).sensors()[0].object->spec().phi_bins, 1u);
  for (const std::string bad : {"0", "[3]", "[3, 0]", "\"x\"", "[2048, 1024]"}) {
    try {
      (void)SensorScene::load(write(bad));
      ADD_FAILURE() << bad << ": no error";
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find("/sensors/0/angular_bins"), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace duplex
