// Scattering fog in sensor runs (fog volumes attenuate and scatter): the
// Henyey-Greenstein sampler against its density and mean cosine; a closed box of sensors around a
// scattering fog registers all emitted power at albedo 1, and what a fog of albedo < 1 absorbs
// matches an independent random walk; single scattering in a thin slab against the quadrature of
// the single-scattering integrals; analog absorption against the attenuation-only run; threads;
// scenes that cannot scatter are refused.

#include "duplex/accel/Error.h"
#include "duplex/objects/VolumeObjectVdb.h"
#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/HenyeyGreenstein.h"
#include "duplex/accel/KdTree.h"
#include "SensorFixture.h"
#include "SlabMedium.h"

#include <gtest/gtest.h>
#include <openvdb/io/File.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

// CDF of the scattering-angle cosine: 2 pi times the integral of pdf from -1 to c.
double hgCdf(double g, double c) {
  if (g == 0.0) return 0.5 * (c + 1.0);
  return (1.0 - g * g) / (2.0 * g) * (1.0 / std::sqrt(1.0 + g * g - 2.0 * g * c) - 1.0 / (1.0 + g));
}

// The sampler is the exact inverse of the CDF for every g in (-1, 1), small |g| included (a
// sampler that switches to the isotropic 2u - 1 below |g| = 1e-3 is off by up to 1.5 |g|, a mean
// cosine of 0 instead of g, too little for the statistical test below to see). Reference: the
// closed-form inversion in long double (its cancellation costs ~1e-19 / |g|).
TEST(HenyeyGreenstein, SampleCosIsTheExactInverseOfTheCdf) {
  for (const double g : {-0.999, -0.7, -0.3, -5e-4, -1e-6, 1e-9, 1e-6, 5e-4, 2e-3, 0.29, 0.31, 0.9, 0.999}) {
    const HenyeyGreenstein hg{g};
    for (int i = 0; i <= 1000; ++i) {
      const double u = std::min(i / 1000.0, std::nextafter(1.0, 0.0));
      const long double gl = g, s = (1.0L - gl * gl) / (1.0L - gl + 2.0L * gl * u);
      const long double ref = std::clamp((1.0L + gl * gl - s * s) / (2.0L * gl), -1.0L, 1.0L);
      ASSERT_NEAR(hg.sampleCos(u), static_cast<double>(ref), 1e-9) << "g = " << g << ", u = " << u;
    }
  }
  EXPECT_EQ(HenyeyGreenstein{0.0}.sampleCos(0.25), -0.5);  // g = 0: isotropic, exactly
}

TEST(HenyeyGreenstein, MeanCosineIsGAndSamplesFollowThePdf) {
  for (const double g : {-0.7, 0.0, 0.0005, 0.4, 0.9}) {
    const HenyeyGreenstein hg{g};
    // The density integrates to 1 over the sphere (midpoint rule in cos).
    double integral = 0.0;
    const int q = 200000;
    for (int i = 0; i < q; ++i) integral += 2.0 * kPi * hg.pdf(-1.0 + (i + 0.5) * 2.0 / q) * 2.0 / q;
    EXPECT_NEAR(integral, 1.0, 1e-4) << "g = " << g;
    // Mean cosine, and a 20-bin histogram against the CDF.
    const int n = 400000, bins = 20;
    std::vector<int> count(bins, 0);
    double sum = 0.0, sum2 = 0.0;
    CounterRng rng(7, 0);
    for (int i = 0; i < n; ++i) {
      const double c = hg.sampleCos(rng.uniform());
      ASSERT_TRUE(c >= -1.0 && c <= 1.0);
      sum += c;
      sum2 += c * c;
      ++count[std::min(bins - 1, static_cast<int>((c + 1.0) * 0.5 * bins))];
    }
    const double mean = sum / n, se = std::sqrt((sum2 / n - mean * mean) / n);
    EXPECT_LT(std::abs(mean - g), 4.5 * se) << "g = " << g << ": mean cosine " << mean << " +- " << se;
    for (int b = 0; b < bins; ++b) {
      const double p = hgCdf(g, -1.0 + (b + 1) * 2.0 / bins) - hgCdf(g, -1.0 + b * 2.0 / bins);
      const double expected = n * p, sd = std::sqrt(n * p * (1.0 - p));
      EXPECT_LT(std::abs(count[b] - expected), 5.0 * sd + 1.0) << "g = " << g << ", bin " << b;
    }
  }
}

// A homogeneous fog of density sigma filling voxels [lo, hi)^3 of size `voxel`, moved by half a
// voxel so that it covers [lo voxel, hi voxel] in x and y, and [zlo voxel, zhi voxel] in z.
std::shared_ptr<const VolumeObject> fogBlock(float sigma, double voxel, int lo, int hi, int zlo, int zhi,
                                             const std::string& name) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(lo, lo, zlo), openvdb::Coord(hi - 1, hi - 1, zhi - 1)), sigma,
                    true);
  openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
  m.preScale(openvdb::Vec3d(voxel));
  m.postTranslate(openvdb::Vec3d(0.5 * voxel));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setName(name);
  return makeVolumeObject(grid, VolumeKind::Fog, name);
}

Material medium(double albedo, double g) { return Medium{albedo, g}; }

// Escape probability from the cube [-h, h]^3 of density sigma for a source at p, by an independent
// random walk: exponential distances, the phase function by rejection from its density.
struct WalkResult {
  double escaped, stderr_escaped;
};
WalkResult referenceWalk(double h, double sigma, double albedo, double g, glm::dvec3 p0, int walks) {
  std::mt19937_64 gen(12345);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const HenyeyGreenstein hg{g};
  const double pdf_max = std::max(hg.pdf(1.0), hg.pdf(-1.0));
  auto isotropic = [&] {
    const double z = 2.0 * uni(gen) - 1.0, phi = 2.0 * kPi * uni(gen), r = std::sqrt(1.0 - z * z);
    return glm::dvec3(r * std::cos(phi), r * std::sin(phi), z);
  };
  int escaped = 0;
  for (int i = 0; i < walks; ++i) {
    glm::dvec3 p = p0, d = isotropic();
    for (;;) {
      const double s = -std::log(1.0 - uni(gen)) / sigma;
      double exit = 1e300;
      for (int a = 0; a < 3; ++a)
        if (d[a] != 0.0) exit = std::min(exit, ((d[a] > 0 ? h : -h) - p[a]) / d[a]);
      if (s >= exit) {
        ++escaped;
        break;
      }
      p += s * d;
      if (uni(gen) >= albedo) break;
      // New direction: cos theta by rejection against the density, azimuth uniform.
      double c;
      do c = 2.0 * uni(gen) - 1.0;
      while (uni(gen) * pdf_max > hg.pdf(c));
      const glm::dvec3 t =
          glm::normalize(std::abs(d.x) < 0.9 ? glm::cross(d, glm::dvec3(1, 0, 0)) : glm::cross(d, glm::dvec3(0, 1, 0)));
      const glm::dvec3 b = glm::cross(d, t);
      const double phi = 2.0 * kPi * uni(gen), sn = std::sqrt(1.0 - c * c);
      d = glm::normalize(c * d + sn * std::cos(phi) * t + sn * std::sin(phi) * b);
    }
  }
  const double f = static_cast<double>(escaped) / walks;
  return {f, std::sqrt(f * (1.0 - f) / walks)};
}

// A fog cube [-0.5, 0.5]^3 (sigma 3: optical depth 1.5 from the centre to a face) inside the closed
// box of sensors [-1, 1]^3, a point source inside the fog.
struct FogBoxScene {
  Fixture f;
  SensorScene scene;
  explicit FogBoxScene(double albedo, double g)
      : scene([&] {
          closeBox(f);
          auto fog = fogBlock(3.0f, 0.05, -10, 10, -10, 10, "fog");
          const Box b = fog->bounds();
          EXPECT_NEAR(b.lo.x, -0.5, 1e-6);
          EXPECT_NEAR(b.hi.z, 0.5, 1e-6);
          f.add(fog, Affine::identity(), "fog", medium(albedo, g));
          return f.scene({pointLight({0.1, -0.05, 0.2}, 3.0)});
        }()) {}
};

TEST(SensorScattering, ClosedBoxAroundAScatteringFogRegistersAllPowerAtAlbedoOne) {
  FogBoxScene s(1.0, 0.6);
  ASSERT_TRUE(s.scene.scatters());
  SensorRun run(s.scene);
  (void)run.runUntil(40000);
  const SensorRunResults r = run.results();
  EXPECT_NEAR(sensorSum(r), 3.0, 1e-12);
  EXPECT_NEAR(r.energy.escaped_w, 3.0, 1e-12);
  EXPECT_EQ(r.energy.medium_absorbed_w, 0.0);
  EXPECT_EQ(r.energy.depth_limited_w, 0.0);
  // The fog did scatter: several collisions per ray on average (optical depth 1.5 to the faces).
  EXPECT_GT(run.counters().scatterings, 40000u);
}

TEST(SensorScattering, AbsorbedPowerMatchesAnIndependentRandomWalk) {
  const double albedo = 0.7, g = 0.3;
  FogBoxScene s(albedo, g);
  SensorRunConfig cfg;
  cfg.seed = 5;
  SensorRun run(s.scene, cfg);
  const int rays = 200000;
  (void)run.runUntil(rays);
  const SensorRunResults r = run.results();
  // Per path: what does not reach the sensors was absorbed by the fog.
  EXPECT_NEAR(sensorSum(r) + r.energy.medium_absorbed_w, 3.0, 1e-12);
  EXPECT_EQ(r.energy.absorbed_w, 0.0);
  const WalkResult ref = referenceWalk(0.5, 3.0, albedo, g, {0.1, -0.05, 0.2}, 200000);
  const double f = sensorSum(r) / 3.0, se = std::sqrt(f * (1.0 - f) / rays);
  EXPECT_LT(std::abs(f - ref.escaped), 4.5 * std::hypot(se, ref.stderr_escaped))
      << "escaped " << f << " +- " << se << ", reference walk " << ref.escaped << " +- " << ref.stderr_escaped;
  EXPECT_GT(r.energy.medium_absorbed_w, 0.3);
}

// Single scattering (max_scatterings = 1) of a collimated beam at normal incidence on a slab of
// optical depth tau, albedo a, phase function p: per unit incident power
//   R1 = a int_0^tau ds e^-s int_0^1 2 pi p(-mu) e^(-s/mu) dmu,
//   T  = e^-tau + a int_0^tau ds e^-s int_0^1 2 pi p(mu) e^(-(tau - s)/mu) dmu,
// with the s integrals done in closed form and mu by the midpoint rule.
void singleScattering(double tau, double a, double g, double& r1, double& t) {
  const HenyeyGreenstein hg{g};
  const int n = 200000;
  r1 = 0.0;
  t = std::exp(-tau);
  for (int i = 0; i < n; ++i) {
    const double mu = (i + 0.5) / n, dmu = 1.0 / n;
    const double k = 1.0 + 1.0 / mu;
    r1 += a * 2.0 * kPi * hg.pdf(-mu) * (1.0 - std::exp(-tau * k)) / k * dmu;
    const double kk = 1.0 - 1.0 / mu;  // int_0^tau e^-s e^(-(tau-s)/mu) ds = (e^(-tau/mu) - e^-tau) / kk
    const double inner = std::abs(kk) < 1e-9 ? tau * std::exp(-tau) : (std::exp(-tau / mu) - std::exp(-tau)) / kk;
    t += a * 2.0 * kPi * hg.pdf(mu) * inner * dmu;
  }
}

TEST(SensorScattering, ThinSlabSingleScatteringMatchesTheQuadrature) {
  const double albedo = 0.8, g = 0.5, sigma = 2.0;
  Fixture f;
  // Slab [-10, 10]^2 x [0, 0.1]: optical depth 0.2, wide enough that a sideways ray leaving
  // through its rim is negligible.
  f.add(fogBlock(static_cast<float>(sigma), 0.1, -100, 100, 0, 1, "slab"), Affine::identity(), "slab",
        medium(albedo, g));
  f.add(sensor(80, 80, 1, 1, true, "top"), translate(0, 0, 0.2), "top");
  f.add(sensor(80, 80, 1, 1, true, "bottom"), translate(0, 0, -0.1), "bottom");
  Light beam;
  beam.type = LightType::Directional;
  beam.name = "beam";
  beam.position = {0.0, 0.0, 0.15};  // below the top sensor: the beam itself does not cross it
  beam.direction = {0.0, 0.0, -1.0};
  beam.radius = 0.3;
  beam.power_w = 1.0;
  SensorScene scene = f.scene({beam});
  SensorRunConfig cfg;
  cfg.max_scatterings = 1;
  cfg.seed = 3;
  SensorRun run(scene, cfg);
  const int rays = 300000;
  (void)run.runUntil(rays);
  const SensorRunResults r = run.results();
  double r1, t;
  singleScattering(sigma * 0.1, albedo, g, r1, t);
  const SensorResult& top = r.sensors[scene.findSensor("top")];
  const SensorResult& bottom = r.sensors[scene.findSensor("bottom")];
  EXPECT_LT(std::abs(top.total_flux_w - r1), 4.5 * top.total_flux_stderr_w) << top.total_flux_w << " vs " << r1;
  EXPECT_LT(std::abs(bottom.total_flux_w - t), 4.5 * bottom.total_flux_stderr_w) << bottom.total_flux_w << " vs " << t;
  EXPECT_GT(top.total_flux_w, 0.01);
  // Every path escapes (through a sensor or sideways past both), is absorbed at its first collision
  // or is cut at its second.
  EXPECT_NEAR(r.energy.escaped_w + r.energy.medium_absorbed_w + r.energy.depth_limited_w, 1.0, 1e-12);
  const double sideways = r.energy.escaped_w - (top.total_flux_w + bottom.total_flux_w);
  EXPECT_GE(sideways, -1e-12);
  EXPECT_LT(sideways, 1e-4);
}

TEST(SensorScattering, AnalogAbsorptionAgreesWithAttenuation) {
  // The same fog once attenuating (no material: exact transmittance per ray) and once as a medium
  // of albedo 0 (every sampled collision absorbs): the sensor above receives the same flux.
  auto run = [](bool as_medium, double& flux, double& se, bool& scatters) {
    Fixture f;
    auto fog = fogBlock(1.5f, 0.05, -10, 10, -10, 10, "fog");
    f.add(fog, Affine::identity(), "fog", as_medium ? medium(0.0, 0.0) : Material{});
    f.add(sensor(1.0, 1.0, 4, 4, true, "above"), translate(0, 0, 1.0), "above");
    SensorScene scene = f.scene({pointLight({0, 0, 0}, 1.0)});
    scatters = scene.scatters();
    SensorRunConfig cfg;
    cfg.roulette_threshold = 0.0;
    SensorRun r(scene, cfg);
    (void)r.runUntil(200000);
    EXPECT_EQ(r.counters().scatterings > 0, as_medium);
    const SensorRunResults res = r.results();
    flux = res.sensors[0].total_flux_w;
    se = res.sensors[0].total_flux_stderr_w;
    EXPECT_NEAR(res.energy.medium_absorbed_w + res.energy.escaped_w, 1.0, 1e-12);  // the sensor never absorbs
  };
  double f0, s0, f1, s1;
  bool sc0, sc1;
  run(false, f0, s0, sc0);
  run(true, f1, s1, sc1);
  EXPECT_FALSE(sc0);  // a fog without material only attenuates
  EXPECT_TRUE(sc1);
  EXPECT_LT(std::abs(f0 - f1), 4.5 * std::hypot(s0, s1)) << f0 << " +- " << s0 << " vs " << f1 << " +- " << s1;
  EXPECT_GT(s1, s0);  // analog absorption is the noisier estimator
}

TEST(SensorScattering, BitIdenticalForAnyThreadCount) {
  FogBoxScene s(0.9, -0.2);
  auto results = [&](unsigned threads, std::uint32_t chunk) { return runWith(s.scene, threads, chunk, 30000); };
  const SensorRunResults one = results(1, 1024);
  expectIdentical(one, results(2, 1024));
  expectIdentical(one, results(2, 61));
  EXPECT_GT(one.energy.medium_absorbed_w, 0.0);
}

// A run state fingerprints the fog's grid (VolumeObject::contentHash): resuming it in a scene
// whose fog has another density, or one more voxel, under the same object name is refused; the
// same grid built again resumes.
TEST(SensorScattering, ResumeRefusesAStateWhoseFogGridChanged) {
  const std::filesystem::path state =
      std::filesystem::temp_directory_path() / ("duplex_fog_state_" + std::to_string(::getpid()) + ".bin");
  const auto scene = [](Fixture& f, float sigma, int hi) {
    closeBox(f);
    f.add(fogBlock(sigma, 0.05, -10, hi, -10, 10, "fog"), Affine::identity(), "fog", medium(0.9, 0.0));
    return f.scene({pointLight({0.1, -0.05, 0.2}, 3.0)});
  };
  SensorRunConfig cfg;
  cfg.seed = 5;
  {
    Fixture f;
    const SensorScene s = scene(f, 3.0f, 10);
    SensorRun run(s, cfg);
    (void)run.runUntil(2000);
    run.saveState(state);
  }
  const auto resumes = [&](float sigma, int hi) {
    Fixture f;
    const SensorScene s = scene(f, sigma, hi);
    SensorRun run(s, cfg);
    try {
      run.loadState(state);
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(state.filename().string()), std::string::npos) << e.what();
      EXPECT_EQ(run.raysDone(), 0u);
      return false;
    }
    return run.raysDone() == 2000u;
  };
  EXPECT_TRUE(resumes(3.0f, 10));   // the same grid, built again
  EXPECT_FALSE(resumes(3.5f, 10));  // another density
  EXPECT_FALSE(resumes(3.0f, 11));  // a larger block (same object name)
  std::filesystem::remove(state);
}

// Every feature at once: a scattering fog with a per-band albedo, bands, a per-band Lambertian
// floor, a sensor with angular bins, a sphere sensor around everything, roulette acting (threshold
// 0.5). 1 and 2 threads and two chunk sizes give the same bits; the sphere (two-sided, enclosing
// everything, every path leaves through it once) sees exactly the escaped power, and the balance
// closes.
TEST(SensorScattering, EveryFeatureOnIsBitIdenticalForAnyThreadCount) {
  Fixture f;
  f.add(fogBlock(3.0f, 0.05, -10, 10, -10, 10, "fog"), Affine::identity(), "fog", [] {
    return Material{Medium{{0.8, {0.95, 0.5}}, 0.4}};
  }());
  const Material floor = Lambertian{{0.5, {0.9, 0.3}}};
  f.add(quad(1.0, "floor"), translate(0, 0, -0.7), "floor", floor);
  SensorSpec angles;
  angles.width = angles.height = 1.5;
  angles.nx = angles.ny = 3;
  angles.theta_bins = 5;
  angles.phi_bins = 3;
  f.add(std::make_shared<const SensorObject>("angles", angles), translate(0, 0, 0.8), "angles");
  SensorSpec ball;
  ball.shape = SensorShape::Sphere;
  ball.width = ball.height = 6.0;
  ball.nx = 6;
  ball.ny = 4;
  f.add(std::make_shared<const SensorObject>("ball", ball), facing({0.3, 0.2, 1.0}, {0, 0, 0}), "ball");
  Light l = pointLight({0.1, -0.05, 0.2}, 3.0);
  l.spectrum = {1, 2};
  const SensorScene scene = f.scene({l}, {"a", "b"});
  SensorRunConfig cfg;
  cfg.roulette_threshold = 0.5;
  auto results = [&](unsigned threads, std::uint32_t chunk) { return runWith(scene, threads, chunk, 20000, cfg); };
  const SensorRunResults one = results(1, 1024);
  expectIdentical(one, results(2, 1024));
  expectIdentical(one, results(2, 61));
  const EnergyBalance& e = one.energy;
  EXPECT_GT(e.medium_absorbed_w, 0.1);
  EXPECT_GT(e.absorbed_w, 0.01);
  EXPECT_NEAR(e.escaped_w + e.absorbed_w + e.medium_absorbed_w + e.depth_limited_w + e.roulette_w, e.emitted_w,
              1e-12 * e.emitted_w);
  EXPECT_NEAR(one.sensors[scene.findSensor("ball")].total_flux_w, e.escaped_w, 1e-12);
  EXPECT_GT(one.sensors[scene.findSensor("angles")].angular_flux_w[0], 0.0);
}

TEST(SensorScattering, ScenesThatCannotScatterAreRefused) {
  {  // a medium material on a mesh
    Fixture f;
    f.add(quad(1.0, "wall"), Affine::identity(), "wall", medium(0.5, 0.0));
    EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, 1.0)}), InvalidArgument);
  }
  {  // a surface material on a fog
    Fixture f;
    f.add(fogBlock(1.0f, 0.1, -2, 2, -2, 2, "fog"), Affine::identity(), "fog", Material{Lambertian{0.5}});
    EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, 1.0)}), InvalidArgument);
  }
  {  // a scattering fog beside a medium that cannot sample free flights
    Fixture f;
    f.add(fogBlock(1.0f, 0.1, -2, 2, -2, 2, "fog"), Affine::identity(), "fog", medium(0.5, 0.0));
    f.add(std::make_shared<const SlabMedium>(1.0, Box(glm::vec3(2), glm::vec3(3))), Affine::identity(), "slab");
    try {
      (void)f.scene({pointLight({0, 0, 1}, 1.0)});
      ADD_FAILURE() << "no error";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find("'slab'"), std::string::npos) << e.what();
    }
  }
  {  // g outside (-1, 1)
    Fixture f;
    f.add(fogBlock(1.0f, 0.1, -2, 2, -2, 2, "fog"), Affine::identity(), "fog", medium(0.5, 1.0));
    EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, 1.0)}), InvalidArgument);
  }
}

TEST(SensorScattering, SceneFilesDeclareScatteringFogs) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("duplex_scatter_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    openvdb::initialize();
    auto grid = openvdb::FloatGrid::create(0.0f);
    grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(-5), openvdb::Coord(4)), 2.0f, true);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(0.1));
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    grid->setName("density");
    openvdb::io::File file((dir / "fog.vdb").string());
    file.write({grid});
  }
  auto write = [&](const std::string& material) {
    std::ofstream(dir / "s.json") << R"({"format": "scene-json-v1",
      "objects": [{"name": "fog", "volume": {"file": "fog.vdb", "kind": "fog"}, "material": )"
                                  << material << R"(}],
      "instances": [{"object": "fog", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
      "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}],
      "sensors": [{"name": "s", "size": [1, 1], "transform": [1,0,0,0, 0,1,0,0, 0,0,1,1]}]})";
    return dir / "s.json";
  };
  {
    const SensorScene scene = SensorScene::load(write(R"({"type": "medium", "albedo": 0.9, "g": 0.25})"));
    ASSERT_TRUE(scene.scatters());
    ASSERT_EQ(scene.scatteringMedia().size(), 1u);
    const Medium* medium = scene.scatteringMedia()[0].material.as<Medium>();
    ASSERT_NE(medium, nullptr);
    EXPECT_EQ(medium->albedo.value, 0.9);
    EXPECT_EQ(medium->g, 0.25);
  }
  auto error = [&](const std::string& material) {
    try {
      (void)SensorScene::load(write(material));
    } catch (const FileError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error(R"({"type": "medium", "albedo": 1.5})").find("/objects/0/material/albedo"), std::string::npos);
  EXPECT_NE(error(R"({"type": "medium", "albedo": 0.5, "g": 1})").find("/objects/0/material/g"), std::string::npos);
  EXPECT_NE(error(R"({"type": "medium"})").find("albedo"), std::string::npos);
  EXPECT_NE(error(R"({"type": "lambertian", "reflectance": 0.5})").find("'fog'"), std::string::npos);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace duplex
