// Per-light results (SensorRunConfig::per_light): each light's irradiance against the
// inverse-square cosine law of that light alone, the per-light values summing to the totals, the
// per-light tallies kept through a saved and loaded run state, luminous per-light values in a
// lumens-only run, and batch tallies that carry them bit for bit.

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <numbers>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

// Bin b of a side x side one-sided sensor at the origin in 2 x 2 bins: its mean irradiance from an
// isotropic point of `power` at p (above the plane): I times the bin's solid angle over its area.
double binIrradiance(std::uint32_t b, double side, const glm::dvec3& p, double power) {
  const double x0 = (b % 2) ? 0.0 : -side / 2, y0 = (b / 2) ? 0.0 : -side / 2;
  const double omega = rectangleSolidAngle(x0 - p.x, x0 + side / 2 - p.x, y0 - p.y, y0 + side / 2 - p.y, p.z);
  return power / (4.0 * std::numbers::pi) * omega / (side * side / 4);
}

struct TwoLights {
  Fixture f;
  double side = 1.0;
  glm::dvec3 p0{-0.8, 0.3, 1.5}, p1{0.6, -0.2, 2.5};
  double w0 = 1.0, w1 = 3.0;
  SensorScene scene() {
    f.add(sensor(side, side, 2, 2, /*two_sided=*/false, "desk"), Affine::identity(), "desk");
    Light a = pointLight(p0, w0), b = pointLight(p1, w1);
    a.name = "left";
    b.name = "right";
    return f.scene({a, b});
  }
};

TEST(SensorPerLight, EachLightMatchesItsOwnInverseSquareLawAndTheySumToTheTotal) {
  TwoLights t;
  const SensorScene scene = t.scene();
  SensorRunConfig cfg;
  cfg.seed = 11;
  cfg.per_light = true;
  SensorRun run(scene, cfg);
  (void)run.runUntil(400000);
  const SensorRunResults r = run.results();
  ASSERT_EQ(r.light_names, (std::vector<std::string>{"left", "right"}));
  EXPECT_EQ(r.light_emitted_w, (std::vector<double>{1.0, 3.0}));
  const SensorResult& s = r.sensors[0];
  ASSERT_EQ(s.light_irradiance_w_m2.size(), 2u);
  const glm::dvec3 pos[2] = {t.p0, t.p1};
  const double power[2] = {t.w0, t.w1};
  for (std::uint32_t b = 0; b < 4; ++b) {
    double sum = 0.0, sum_total = 0.0;
    for (int l = 0; l < 2; ++l) {
      const double expected = binIrradiance(b, t.side, pos[l], power[l]);
      const double got = s.light_irradiance_w_m2[l][b], se = s.light_stderr_w_m2[l][b];
      EXPECT_GT(se, 0.0);
      EXPECT_LT(std::abs(got - expected), 4.5 * se)
          << "light " << l << " bin " << b << ": " << got << " vs " << expected;
      sum += s.light_flux_w[l][b];
      sum_total += expected;
    }
    // A ray comes from one light: the per-light sums partition the bin's sum.
    EXPECT_NEAR(sum, s.flux_w[b], 1e-12 * s.flux_w[b]);
    EXPECT_LT(std::abs(s.irradiance_w_m2[b] - sum_total), 4.5 * s.stderr_w_m2[b]);
  }
  EXPECT_NEAR(s.light_total_flux_w[0] + s.light_total_flux_w[1], s.total_flux_w, 1e-12 * s.total_flux_w);
  // Without per_light nothing of it is kept, and the totals are the same rays' (bit for bit).
  SensorRunConfig plain = cfg;
  plain.per_light = false;
  SensorRun other(scene, plain);
  (void)other.runUntil(400000);
  const SensorRunResults q = other.results();
  EXPECT_TRUE(q.light_names.empty());
  EXPECT_TRUE(q.sensors[0].light_flux_w.empty());
  EXPECT_EQ(q.sensors[0].flux_w, s.flux_w);
}

TEST(SensorPerLight, SavedStateKeepsThePerLightSums) {
  TwoLights t;
  const SensorScene scene = t.scene();
  SensorRunConfig cfg;
  cfg.per_light = true;
  cfg.batch_rays = 10000;
  SensorRun whole(scene, cfg), first(scene, cfg);
  (void)whole.runUntil(50000);
  (void)first.runUntil(25000);
  const auto file =
      std::filesystem::temp_directory_path() / ("duplex_sensor_per_light_" + std::to_string(::getpid()) + ".bin");
  first.saveState(file);
  SensorRun resumed(scene, cfg);
  resumed.loadState(file);
  (void)resumed.runUntil(50000);
  const SensorResult a = whole.results().sensors[0], b = resumed.results().sensors[0];
  EXPECT_EQ(a.light_flux_w, b.light_flux_w);
  EXPECT_EQ(a.light_flux_stderr_w, b.light_flux_stderr_w);
  EXPECT_EQ(a.light_total_flux_w, b.light_total_flux_w);
  // A state without per-light sums is another run's.
  SensorRunConfig plain = cfg;
  plain.per_light = false;
  SensorRun other(scene, plain);
  EXPECT_THROW(other.loadState(file), FileError);
  std::filesystem::remove(file);
}

TEST(SensorPerLight, LumensOnlyRunsGivePerLightIlluminance) {
  TwoLights t;
  t.w0 = 400.0;
  t.w1 = 1200.0;
  t.f.add(sensor(t.side, t.side, 2, 2, false, "desk"), Affine::identity(), "desk");
  Light a = pointLight(t.p0, 1.0), b = pointLight(t.p1, 1.0);
  a.lumens = t.w0;
  b.lumens = t.w1;
  const SensorScene scene = t.f.scene({a, b});
  SensorRunConfig cfg;
  cfg.per_light = true;
  SensorRun run(scene, cfg);
  (void)run.runUntil(200000);
  const SensorRunResults r = run.results();
  EXPECT_TRUE(r.luminous_transport);
  EXPECT_EQ(r.light_emitted_lm, (std::vector<double>{400.0, 1200.0}));
  const SensorResult& s = r.sensors[0];
  ASSERT_EQ(s.light_illuminance_lx.size(), 2u);
  EXPECT_EQ(s.light_illuminance_lx, s.light_irradiance_w_m2);  // the transported unit is the lumen
  for (std::uint32_t bin = 0; bin < 4; ++bin) {
    const double expected = binIrradiance(bin, t.side, t.p1, t.w1);
    EXPECT_LT(std::abs(s.light_illuminance_lx[1][bin] - expected), 4.5 * s.light_illuminance_stderr_lx[1][bin]);
    EXPECT_EQ(s.flux_lm[bin], s.flux_w[bin]);
  }
}

TEST(SensorPerLight, BatchTalliesCarryItBitForBit) {
  // Batches traced by another run and added in order give the per-light sensor and meter values of
  // one run, bit for bit; a per-light tally is refused by a run without (and the reverse), and a
  // truncated one.
  TwoLights t;
  SensorScene scene = t.scene();
  scene.setMeters({{"m", {{0, 0, 0}, {0.3, 0.1, 0}}, {{0, 0, 1}, {0, 0, 1}}}});
  SensorRunConfig cfg;
  cfg.per_light = true;
  cfg.batch_rays = 10000;
  SensorRun whole(scene, cfg), worker(scene, cfg), sum(scene, cfg);
  (void)whole.runUntil(40000);
  for (std::uint64_t b = 0; b < 4; ++b) sum.addBatch(worker.traceBatch(b, 40000).bytes);
  const SensorRunResults a = whole.results(), c = sum.results();
  ASSERT_EQ(a.sensors[0].light_flux_w.size(), 2u);
  EXPECT_EQ(a.sensors[0].light_flux_w, c.sensors[0].light_flux_w);
  EXPECT_EQ(a.sensors[0].light_flux_stderr_w, c.sensors[0].light_flux_stderr_w);
  EXPECT_EQ(a.sensors[0].light_total_flux_w, c.sensors[0].light_total_flux_w);
  EXPECT_EQ(a.sensors[0].light_total_flux_stderr_w, c.sensors[0].light_total_flux_stderr_w);
  EXPECT_EQ(a.meters[0].light_irradiance_w_m2, c.meters[0].light_irradiance_w_m2);
  EXPECT_EQ(a.meters[0].light_stderr_w_m2, c.meters[0].light_stderr_w_m2);
  EXPECT_EQ(a.meters[0].irradiance_w_m2, c.meters[0].irradiance_w_m2);
  EXPECT_EQ(a.sensors[0].flux_w, c.sensors[0].flux_w);
  SensorRunConfig plain = cfg;
  plain.per_light = false;
  SensorRun plain_worker(scene, plain), plain_sum(scene, plain);
  EXPECT_THROW(sum.addBatch(plain_worker.traceBatch(4, 50000).bytes), InvalidArgument);
  const SensorBatchTally next = worker.traceBatch(4, 50000);
  EXPECT_THROW(plain_sum.addBatch(next.bytes), InvalidArgument);
  std::vector<std::byte> cut = next.bytes;
  cut.resize(cut.size() - 8);
  EXPECT_THROW(sum.addBatch(cut), InvalidArgument);
  sum.addBatch(next.bytes);  // the refusals left the run as it was
  (void)whole.runUntil(50000);
  EXPECT_EQ(whole.results().sensors[0].light_flux_w, sum.results().sensors[0].light_flux_w);
}

}  // namespace
}  // namespace duplex
