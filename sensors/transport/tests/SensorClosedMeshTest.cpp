// A light source inside a closed mesh (docs/design/sensors.md, "Where methods fail"): no path may leave a closed
// watertight mesh, whatever its material, near the origin or far from it, and the energy balance
// closes exactly. Also the depth limit: in a closed mirror every path ends by it.

#include "MeshChecks.h"
#include "SensorFixture.h"
#include "TestSupport.h"

#include <gtest/gtest.h>

namespace duplex {
namespace {

using test::Fixture;

// A closed icosphere (radius 0.8, 1,280 triangles) around the light, the box of six sensors
// [-1, 1]^3 outside it, a two-sided 0.5 x 0.5 sensor inside it; everything moved by `offset`.
SensorScene sphereAroundTheLight(Fixture& f, const Material& m, const glm::dvec3& offset) {
  const auto mesh = std::make_shared<const TriangleMesh>(test::icosphere(3, 0.8));
  f.add(test::buildChecked(mesh), test::translate(offset.x, offset.y, offset.z), "shell", m);
  const glm::dvec3 normals[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (int k = 0; k < 6; ++k) {
    const std::string name = "outside" + std::to_string(k);
    f.add(test::sensor(2.0, 2.0, 2, 2, true, name), test::facing(normals[k], normals[k] + offset), name);
  }
  f.add(test::sensor(0.5, 0.5, 2, 2, true, "inside"), test::translate(offset.x, offset.y, offset.z + 0.3), "inside");
  return f.scene({test::pointLight(offset + glm::dvec3(0.05, -0.1, 0.02), 3.0)});
}

double outsideFlux(const SensorRunResults& r) {
  double sum = 0.0;
  for (const SensorResult& s : r.sensors)
    if (s.name != "inside") sum += s.total_flux_w;
  return sum;
}

const SensorResult& inside(const SensorRunResults& r) {
  for (const SensorResult& s : r.sensors)
    if (s.name == "inside") return s;
  throw std::runtime_error("no sensor named 'inside'");
}

SensorRunResults trace(const SensorScene& scene, std::uint64_t rays, SensorRunConfig cfg = {}) {
  cfg.seed = 17;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  return run.results();
}

class SensorClosedMesh : public ::testing::TestWithParam<double> {};

// An absorbing shell takes all the power at the first hit: nothing outside, the inside sensor sees
// the direct flux only (a 0.5 x 0.5 square 0.3 above the source: about a tenth of it).
TEST_P(SensorClosedMesh, AbsorbingShellTakesEverything) {
  const glm::dvec3 offset(GetParam(), -2.0 * GetParam(), 3.0 * GetParam());
  Fixture f;
  const SensorScene scene = sphereAroundTheLight(f, Material{}, offset);
  const SensorRunResults r = trace(scene, 20000);
  EXPECT_EQ(r.energy.escaped_w, 0.0);
  EXPECT_EQ(outsideFlux(r), 0.0);
  EXPECT_NEAR(r.energy.absorbed_w, 3.0, 1e-12);
  EXPECT_GT(inside(r).total_flux_w, 0.1);
  EXPECT_LT(inside(r).total_flux_w, 0.6);
}

// A white Lambertian shell (reflectance 0.9) bounces each path about ten times: no path leaks
// through an edge or is pushed outside by the offset of a reflected ray, and the power ends as
// absorbed, killed by the roulette or cut by the depth limit, summing to the emitted power.
TEST_P(SensorClosedMesh, NoPathLeavesAWhiteShell) {
  const glm::dvec3 offset(GetParam(), -2.0 * GetParam(), 3.0 * GetParam());
  Fixture f;
  const SensorScene scene = sphereAroundTheLight(f, Material{Lambertian{0.9}}, offset);
  const SensorRunResults r = trace(scene, 100000);
  const EnergyBalance& e = r.energy;
  EXPECT_EQ(e.escaped_w, 0.0);
  EXPECT_EQ(outsideFlux(r), 0.0);
  EXPECT_NEAR(e.absorbed_w + e.roulette_w + e.depth_limited_w, 3.0, 1e-12 * 3.0);
  EXPECT_GT(e.absorbed_w, 1.0);
  // The bounces come back through the inside sensor: far more than the direct tenth.
  EXPECT_GT(inside(r).total_flux_w, 0.6);
}

// A perfect mirror shell loses nothing, so the roulette never acts and every path is cut by the
// depth limit, at any limit (0: at the first hit).
TEST_P(SensorClosedMesh, MirrorShellEndsEveryPathAtTheDepthLimit) {
  const glm::dvec3 offset(GetParam(), -2.0 * GetParam(), 3.0 * GetParam());
  Fixture f;
  const SensorScene scene = sphereAroundTheLight(f, Material{Mirror{1.0}}, offset);
  double previous_inside = 0.0;
  for (const std::uint32_t depth : {0u, 3u, 12u}) {
    SensorRunConfig cfg;
    cfg.max_depth = depth;
    const SensorRunResults r = trace(scene, 5000, cfg);
    const EnergyBalance& e = r.energy;
    EXPECT_EQ(e.escaped_w, 0.0) << "max_depth " << depth;
    EXPECT_EQ(e.absorbed_w, 0.0) << "max_depth " << depth;
    EXPECT_EQ(e.roulette_w, 0.0) << "max_depth " << depth;
    EXPECT_NEAR(e.depth_limited_w, 3.0, 1e-12 * 3.0) << "max_depth " << depth;
    EXPECT_EQ(outsideFlux(r), 0.0) << "max_depth " << depth;
    // Longer paths cross the inside sensor more often: its flux grows with the limit.
    EXPECT_GT(inside(r).total_flux_w, previous_inside) << "max_depth " << depth;
    previous_inside = inside(r).total_flux_w;
  }
}

INSTANTIATE_TEST_SUITE_P(NearAndFar, SensorClosedMesh, ::testing::Values(0.0, 1.0e4), [](const auto& info) {
  return info.param == 0.0 ? std::string("AtTheOrigin") : std::string("TenThousandAway");
});

}  // namespace
}  // namespace duplex
