// Materials of optical engineering against closed forms: a glass slab's transmittance and
// reflectance with its multiple internal reflections and Beer-Lambert absorption; Lambertian,
// Gaussian and ABg reflectors conserving energy in a closed box of sensors; the Gaussian and ABg
// lobes sampled exactly (chi-square against their truncated densities); ideal coatings per band;
// a ball lens's focal distance against the paraxial formula; materials per instance; file errors.

#include "duplex/accel/Error.h"
#include "duplex/example/AnalyticSphere.h"
#include "duplex/objects/ProceduralMesh.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"
#include "SlabRuns.h"
#include "SurfaceScatter.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

TEST(SensorMaterials, GlassSlabTransmitsTheClosedFormWithInternalReflectionsAndAbsorption) {
  // A slab of thickness d, index n, absorption alpha, lit at normal incidence. With R the
  // interface's Fresnel reflectance and tau = exp(-alpha d): T = (1-R)^2 tau / (1 - R^2 tau^2),
  // R_slab = R + (1-R)^2 R tau^2 / (1 - R^2 tau^2), the rest absorbed.
  const double n = 1.5, d = 0.5, alpha = -std::log(0.8) / d, tau = 0.8;
  Fixture f;
  const Material glass = Dielectric{n, alpha};
  f.add(buildChecked(makeBox({6.0, 6.0, d}, "slab")), Affine::identity(), "slab", glass);
  f.add(sensor(2.0, 2.0, 1, 1, false, "below"), translate(0, 0, -1.0), "below");            // records rays going down
  f.add(sensor(2.0, 2.0, 1, 1, false, "above"), facing({0, 0, -1}, {0, 0, 1.0}), "above");  // rays going up
  const SensorScene scene = f.scene({beamLight({0, 0, 2.0}, {0, 0, -1}, 0.5, 1.0)});
  SensorRunConfig cfg;
  cfg.seed = 31;
  SensorRun run(scene, cfg);
  (void)run.runUntil(400000);
  const SensorRunResults r = run.results();
  const double rf = std::pow((n - 1) / (n + 1), 2);
  const double t_expected = (1 - rf) * (1 - rf) * tau / (1 - rf * rf * tau * tau);
  const double r_expected = rf + (1 - rf) * (1 - rf) * rf * tau * tau / (1 - rf * rf * tau * tau);
  const SensorResult& below = r.sensors[scene.findSensor("below")];
  const SensorResult& above = r.sensors[scene.findSensor("above")];
  EXPECT_LT(std::abs(below.total_flux_w - t_expected), 4.5 * below.total_flux_stderr_w)
      << "T " << below.total_flux_w << " +- " << below.total_flux_stderr_w << " vs " << t_expected;
  EXPECT_LT(std::abs(above.total_flux_w - r_expected), 4.5 * above.total_flux_stderr_w)
      << "R " << above.total_flux_w << " +- " << above.total_flux_stderr_w << " vs " << r_expected;
  // Every path leaves through one of the sensors or is absorbed (in the glass, or by the roulette's
  // net term): the balance closes exactly, and the glass took 1 - T - R in expectation.
  std::printf("slab: T %.5f +- %.5f (closed form %.5f), R %.5f +- %.5f (closed form %.5f)\n", below.total_flux_w,
              below.total_flux_stderr_w, t_expected, above.total_flux_w, above.total_flux_stderr_w, r_expected);
  const EnergyBalance& e = r.energy;
  EXPECT_NEAR(below.total_flux_w + above.total_flux_w, e.escaped_w, 1e-12);
  EXPECT_NEAR(e.escaped_w + e.absorbed_w + e.roulette_w + e.depth_limited_w + e.failed_w, 1.0, 1e-12);
  EXPECT_EQ(e.failed_rays, 0u);
  EXPECT_NEAR(e.absorbed_w + e.roulette_w, 1.0 - t_expected - r_expected, 0.01);
}

// A point source, a reflector of `m` tilted in the middle and an absorbing plate, inside a closed box
// of sensors: what the sensors see plus what was absorbed is exactly the emitted power.
SensorRunResults boxWithReflector(const Material& m, std::uint64_t rays) {
  Fixture f;
  closeBox(f);
  f.add(quad(0.4, "reflector"), facing({0.3, 0.2, 1.0}, {0.0, 0.0, -0.4}), "reflector", m);
  f.add(quad(0.2, "plate"), facing({1, 0, 0}, {0.6, 0.0, 0.0}), "plate");
  const SensorScene scene = f.scene({pointLight({0.0, 0.1, 0.2}, 3.0)});
  SensorRun run(scene);
  (void)run.runUntil(rays);
  return run.results();
}

TEST(SensorMaterials, LambertianGaussianAndAbgReflectorsConserveEnergy) {
  const Material lambert = Lambertian{1.0};
  const Material gaussian = Mirror{1.0, {GaussianScatter{0.4, 1.0}}};
  const Material abg = Mirror{0.9, {AbgScatter{0.01, 0.005, 1.8}}};  // the scene sets its scattered fraction
  const Material rough_glass = Dielectric{1.5, 0.0, {GaussianScatter{0.2, 0.7}}};
  double reflected[2] = {0.0, 0.0};
  int k = 0;
  for (const Material& m : {lambert, gaussian, abg, rough_glass}) {
    const SensorRunResults r = boxWithReflector(m, 60000);
    const EnergyBalance& e = r.energy;
    EXPECT_NEAR(sensorSum(r) + e.absorbed_w, 3.0, 1e-12) << m;
    EXPECT_EQ(e.failed_rays, 0u) << m;
    EXPECT_EQ(e.depth_limited_w + e.roulette_w, 0.0) << m;
    if (k < 2) reflected[k] = 3.0 - e.absorbed_w;
    ++k;
  }
  // A white reflector of either kind absorbs nothing: only the plate does, so the two see similar
  // absorbed power (the same geometry), and the ABg mirror of reflectance 0.9 absorbs more.
  EXPECT_GT(reflected[0], 2.5);
  EXPECT_GT(reflected[1], 2.5);
}

// Chi-square of the radii |beta| of directions scattered about the normal (beta0 = 0) against the
// lobe truncated to the unit disk, whose radial CDF is `cdf` (cdf(1) = 1).
template <class Lobe, class Cdf>
double lobeChiSquare(const Lobe& m, Cdf cdf, int bins, int samples) {
  std::vector<int> count(static_cast<std::size_t>(bins), 0);
  const glm::dvec3 n(0.0, 0.0, 1.0);
  for (int i = 0; i < samples; ++i) {
    CounterRng rng(77, static_cast<std::uint64_t>(i));
    glm::dvec3 out;
    EXPECT_TRUE(detail::scatterAbout(m, n, n, rng, out));
    EXPECT_NEAR(glm::length(out), 1.0, 1e-12);
    EXPECT_GT(out.z, 0.0);
    const double r = std::hypot(out.x, out.y);
    ++count[std::min<std::size_t>(static_cast<std::size_t>(r * bins), static_cast<std::size_t>(bins - 1))];
  }
  double chi2 = 0.0;
  for (int b = 0; b < bins; ++b) {
    const double expected = samples * (cdf(static_cast<double>(b + 1) / bins) - cdf(static_cast<double>(b) / bins));
    chi2 +=
        (count[static_cast<std::size_t>(b)] - expected) * (count[static_cast<std::size_t>(b)] - expected) / expected;
  }
  return chi2;
}

TEST(SensorMaterials, GaussianAndAbgLobesAreSampledExactly) {
  // 20 bins: 19 degrees of freedom, whose chi-square exceeds 43.8 with probability 0.001.
  GaussianScatter gaussian;
  gaussian.sigma = 0.6;  // wide: the truncation to the unit disk matters
  const double s2 = gaussian.sigma * gaussian.sigma;
  const double chi_g = lobeChiSquare(
      gaussian, [s2](double r) { return (1.0 - std::exp(-r * r / s2)) / (1.0 - std::exp(-1.0 / s2)); }, 20, 100000);
  EXPECT_LT(chi_g, 43.8);
  std::printf("lobes: chi-square over 19 degrees of freedom, Gaussian %.1f", chi_g);
  const AbgScatter abg{0.05, 0.01, 1.5};
  // The radial CDF of r / (B + r^g) on [0, 1], by Simpson's rule.
  auto integral = [&](double x) {
    const int n = 2000;
    auto f = [&](double r) { return r / (abg.b + std::pow(r, abg.g)); };
    double sum = f(0.0) + f(x);
    for (int i = 1; i < n; ++i) sum += (i % 2 ? 4.0 : 2.0) * f(x * i / n);
    return sum * x / (3.0 * n);
  };
  const double total = integral(1.0);
  const double chi_abg = lobeChiSquare(
      abg, [&](double r) { return integral(r) / total; }, 20, 100000);
  EXPECT_LT(chi_abg, 43.8);
  std::printf(", ABg %.1f\n", chi_abg);
  // The ABg total integrated scatter is 2 pi A times that integral.
  EXPECT_NEAR(AbgScatter::totalIntegratedScatter(0.05, 0.01, 1.5), 2.0 * std::numbers::pi * 0.05 * total, 1e-9);
  // A lobe far wider than the disk is flat over it: never refused, directions uniform in beta
  // (the projected solid angle, a Lambertian), so |beta|^2 is uniform on [0, 1]: its mean is 1/2.
  GaussianScatter wide = gaussian;
  wide.sigma = 100.0;
  double mean_s2 = 0.0;
  for (int i = 0; i < 20000; ++i) {
    CounterRng rng(9, static_cast<std::uint64_t>(i));
    glm::dvec3 out;
    ASSERT_TRUE(detail::scatterAbout(wide, {0, 0, 1}, {0, 0, 1}, rng, out));
    mean_s2 += (out.x * out.x + out.y * out.y) / 20000.0;
  }
  EXPECT_NEAR(mean_s2, 0.5, 4.5 * std::sqrt(1.0 / 12.0 / 20000.0));
  // A narrow lobe about an oblique specular direction stays around it (mean of beta = beta0).
  GaussianScatter narrow = gaussian;
  narrow.sigma = 0.05;
  const glm::dvec3 spec = glm::normalize(glm::dvec3(0.5, 0.0, std::sqrt(0.75)));
  glm::dvec2 mean(0.0);
  for (int i = 0; i < 20000; ++i) {
    CounterRng rng(5, static_cast<std::uint64_t>(i));
    glm::dvec3 out;
    ASSERT_TRUE(detail::scatterAbout(narrow, spec, {0, 0, 1}, rng, out));
    mean += glm::dvec2(out.x, out.y) / 20000.0;
  }
  EXPECT_NEAR(glm::length(mean - glm::dvec2(0.5, 0.0)), 0.0, 0.002);
}

TEST(SensorMaterials, CoatingsSplitEachBandByTheirFractions) {
  // A beam onto a coating: band 0 reflects 0.3 and transmits 0.5, band 1 reflects 0.1 and
  // transmits 0.9 (absorbs nothing).
  Fixture f;
  const Material coat = Coating{{0.2, {0.3, 0.1}}, {0.7, {0.5, 0.9}}};
  f.add(quad(2.0, "coating"), Affine::identity(), "coating", coat);
  f.add(sensor(2.0, 2.0, 1, 1, false, "below"), translate(0, 0, -0.5), "below");
  f.add(sensor(2.0, 2.0, 1, 1, false, "above"), facing({0, 0, -1}, {0, 0, 0.5}), "above");
  Light l = beamLight({0, 0, 1.0}, {0, 0, -1}, 0.3, 2.0);
  l.spectrum = {1.0, 1.0};
  const SensorScene scene = f.scene({l}, {"a", "b"});
  SensorRun run(scene);
  (void)run.runUntil(100000);
  const SensorRunResults r = run.results();
  const SensorResult& below = r.sensors[scene.findSensor("below")];
  const SensorResult& above = r.sensors[scene.findSensor("above")];
  const double expect[2][2] = {{0.5, 0.3}, {0.9, 0.1}};  // [band][transmitted, reflected], of 1 W per band
  for (std::size_t b = 0; b < 2; ++b) {
    EXPECT_LT(std::abs(below.band_total_flux_w[b] - expect[b][0]), 4.5 * below.band_total_flux_stderr_w[b]) << b;
    EXPECT_LT(std::abs(above.band_total_flux_w[b] - expect[b][1]), 4.5 * above.band_total_flux_stderr_w[b]) << b;
  }
  EXPECT_NEAR(r.energy.escaped_w + r.energy.absorbed_w, 2.0, 1e-12);
  EXPECT_GT(r.energy.absorbed_rays, 0u);
}

TEST(SensorMaterials, BallLensFocusesAtTheParaxialBackFocalDistance) {
  // A ball lens of radius R and index n focuses a paraxial collimated beam at f = n R / (2 (n - 1))
  // from its centre. Sensors across the focus measure the beam's mean square radius, a quadratic
  // in z whose vertex is the best focus; a beam of 0.02 R has negligible spherical aberration.
  const double radius = 1.0, n = 1.5, f_centre = n * radius / (2.0 * (n - 1.0));  // 1.5
  Fixture fx;
  fx.add(std::make_shared<const example::AnalyticSphere>("ball", radius), Affine::identity(), "ball",
         Material{Dielectric{n}});
  std::vector<double> zs;
  for (int k = -6; k <= 6; ++k) {
    const double z = -f_centre + 0.01 * k;  // the beam travels along -z
    zs.push_back(z);
    fx.add(sensor(0.01, 0.01, 100, 100, true, "s" + std::to_string(k + 6)), translate(0, 0, z),
           "s" + std::to_string(k + 6));
  }
  const SensorScene scene = fx.scene({beamLight({0, 0, 3.0}, {0, 0, -1}, 0.02 * radius, 1.0)});
  SensorRunConfig cfg;
  cfg.seed = 3;
  cfg.max_depth = 4;
  SensorRun run(scene, cfg);
  (void)run.runUntil(100000);
  const SensorRunResults r = run.results();
  // Least squares of <rho^2>(z) = a z^2 + b z + c.
  double m[3][4] = {};
  for (std::size_t k = 0; k < zs.size(); ++k) {
    const SensorResult& s = r.sensors[scene.findSensor("s" + std::to_string(k))];
    double sum = 0.0, sum_r2 = 0.0;
    for (std::uint32_t b = 0; b < s.flux_w.size(); ++b) {
      const double x = -0.005 + (b % 100 + 0.5) * 1e-4, y = -0.005 + (b / 100 + 0.5) * 1e-4;
      sum += s.flux_w[b];
      sum_r2 += s.flux_w[b] * (x * x + y * y);
    }
    ASSERT_GT(sum, 0.5) << "the beam missed sensor " << k;
    const double rho2 = sum_r2 / sum, z = zs[k], row[3] = {z * z, z, 1.0};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) m[i][j] += row[i] * row[j];
      m[i][3] += row[i] * rho2;
    }
  }
  for (int i = 0; i < 3; ++i)  // Gauss-Jordan
    for (int j = 0; j < 3; ++j)
      if (j != i) {
        const double q = m[j][i] / m[i][i];
        for (int c = 0; c < 4; ++c) m[j][c] -= q * m[i][c];
      }
  const double a = m[0][3] / m[0][0], b = m[1][3] / m[1][1];
  const double focus = -b / (2.0 * a);
  std::printf("ball lens: best focus %.5f R from the centre, paraxial %.5f R\n", -focus, f_centre);
  EXPECT_NEAR(-focus, f_centre, 0.001 * f_centre)
      << "best focus " << -focus << " from the centre, paraxial " << f_centre;
}

TEST(SensorMaterials, InstancesMayHaveMaterialsOfTheirOwn) {
  const auto v1 = writeTestFile("v1.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "part", "mesh": {"positions": [0,0,0, 1,0,0, 0,1,0], "indices": [0,1,2]},
                 "material": {"type": "lambertian", "reflectance": 0.5}}],
    "instances": [{"object": "part", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]},
                  {"object": "part", "transform": [1,0,0,2, 0,1,0,0, 0,0,1,0],
                   "material": {"type": "mirror", "reflectance": 0.9, "scatter": {"model": "gaussian", "sigma": 0.1}}}],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 1}]})");
  const SensorScene a = SensorScene::load(v1);
  const SceneDocument& doc = *a.document();
  EXPECT_TRUE(a.materialOf(doc.instances[0]).is<Lambertian>());
  ASSERT_TRUE(a.materialOf(doc.instances[1]).is<Mirror>());
  EXPECT_TRUE(std::holds_alternative<GaussianScatter>(a.materialOf(doc.instances[1]).as<Mirror>()->rough.model));
  const auto own = writeTestFile("own.json", R"({"format": "duplex-scene-v1",
    "objects": [{"name": "part", "box": {"size": 1}, "material": {"type": "lambertian", "reflectance": 0.5}}],
    "nodes": [{"instance": "plain", "object": "part"},
              {"group": "g", "translate": [3, 0, 0], "children": [
                {"instance": "coated", "object": "part", "material": {"type": "coating", "reflect": 0.2, "transmit": 0.7}}]},
              {"instance": "glass", "object": "part", "transform": {"translate": [6, 0, 0]},
               "material": {"type": "dielectric", "ior": 1.5, "absorption": 0.2}}],
    "lights": [{"type": "point", "position": [0, 0, 3], "power": 1}]})");
  const SensorScene b = SensorScene::load(own);
  const SceneGraph& g = b.graph();
  EXPECT_TRUE(b.materialOf(*g.find("/plain")).is<Lambertian>());
  ASSERT_TRUE(b.materialOf(*g.find("/g/coated")).is<Coating>());
  EXPECT_EQ(b.materialOf(*g.find("/g/coated")).as<Coating>()->transmit.value, 0.7);
  ASSERT_TRUE(b.materialOf(*g.find("/glass")).is<Dielectric>());
  EXPECT_EQ(b.materialOf(*g.find("/glass")).as<Dielectric>()->absorption.value, 0.2);
}

TEST(SensorMaterials, ADiffuserSplitsABeamIntoLambertianReflectionAndTransmission) {
  // A narrow beam straight down onto a diffuser sheet at z = 0: the transmitted part leaves
  // cosine-distributed downwards, so a square sensor of half-width a at depth h under the spot
  // receives P t F, F the configuration factor from a point to a parallel square (exact); the
  // reflected part escapes upwards with the transmitted part that misses the sensor, the rest is
  // absorbed.
  const double r = 0.3, t = 0.5, a = 0.5, h = 1.0, power = 2.0;
  const std::uint64_t rays = 200000;
  Fixture f;
  f.add(quad(50.0, "sheet"), Affine::identity(), "sheet", Material{Diffuser{r, t}});
  f.add(sensor(2.0 * a, 2.0 * a, 1, 1, false, "below"), translate(0, 0, -h), "below");  // records rays going down
  const SensorScene scene = f.scene({beamLight({0, 0, 1.0}, {0, 0, -1}, 1e-4, power)});
  SensorRunConfig cfg;
  cfg.seed = 3;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  const SensorRunResults res = run.results();
  const SensorResult& below = res.sensors[0];
  const double expected = power * t * pointToParallelRectangle(-a, a, -a, a, h);
  std::printf("diffuser: %.5f +- %.5f W below (exact %.5f)\n", below.total_flux_w, below.total_flux_stderr_w, expected);
  EXPECT_LT(std::abs(below.total_flux_w - expected), 4.0 * below.total_flux_stderr_w + 5e-3 * expected);
  // Absorbed: each ray is absorbed with probability 1 - r - t, its power P (binomial error).
  const double p_abs = 1.0 - r - t, se_abs = power * std::sqrt(p_abs * (1.0 - p_abs) / static_cast<double>(rays));
  EXPECT_LT(std::abs(res.energy.absorbed_w - power * p_abs), 4.0 * se_abs);
  EXPECT_NEAR(res.energy.absorbed_w + res.energy.escaped_w, power, 1e-9);
  EXPECT_EQ(res.energy.failed_rays, 0u);
}

void expectError(const std::string& name, const std::string& body, const std::vector<std::string>& needles) {
  const auto path = writeTestFile(name, std::string(R"({"format": "duplex-scene-v1", )") + body +
                                            R"(, "lights": [{"type": "point", "position": [0,0,1], "power": 1}]})");
  expectLoadError(path, needles);
}

TEST(SensorMaterials, PerBandValuesMayNameTheirBands) {
  const auto path = writeTestFile("named.json", R"({"format": "duplex-scene-v1", "bands": ["vis", "nir"],
    "objects": [{"name": "filter", "box": {"size": 1},
                 "material": {"type": "coating", "reflect": {"nir": 0.6, "vis": 0.05}, "transmit": [0.9, 0.3]}}],
    "nodes": [{"instance": "f", "object": "filter"}],
    "lights": [{"type": "point", "position": [0, 0, 2], "power": 1}]})");
  const SensorScene scene = SensorScene::load(path);
  const Material& m = scene.materialOf(*scene.graph().find("/f"));
  ASSERT_TRUE(m.is<Coating>());
  EXPECT_EQ(m.as<Coating>()->reflect.bands, (std::vector<double>{0.05, 0.6}));
  EXPECT_EQ(m.as<Coating>()->transmit.bands, (std::vector<double>{0.9, 0.3}));
}

TEST(SensorMaterials, MalformedMaterialsNameTheFileAndTheObject) {
  auto object = [](const std::string& material) {
    return R"("objects": [{"name": "part", "box": {"size": 1}, "material": )" + material +
           R"(}], "nodes": [{"instance": "p", "object": "part"}])";
  };
  expectError("sigma.json", object(R"({"type": "mirror", "scatter": {"model": "gaussian", "sigma": -0.1}})"),
              {"/objects/0/material/scatter/sigma", "sigma must be > 0"});
  expectError("fraction.json",
              object(R"({"type": "mirror", "scatter": {"model": "gaussian", "sigma": 0.1, "fraction": 2}})"),
              {"/objects/0/material/scatter/fraction"});
  expectError("abg_b.json", object(R"({"type": "mirror", "scatter": {"model": "abg", "A": 0.1, "B": 0, "g": 2}})"),
              {"/objects/0/material/scatter/B", "B must be > 0"});
  expectError("abg_tis.json", object(R"({"type": "mirror", "scatter": {"model": "abg", "A": 5, "B": 0.01, "g": 2}})"),
              {"/objects/0/material/scatter", "total integrated scatter", "> 1"});
  expectError("abg_g.json", object(R"({"type": "mirror", "scatter": {"model": "abg", "A": 0.1, "B": 0.1, "g": -1}})"),
              {"/objects/0/material/scatter/g"});
  expectError("model.json", object(R"({"type": "mirror", "scatter": {"model": "harvey"}})"),
              {"/objects/0/material/scatter/model", "unknown scatter model"});
  expectError("lambert_scatter.json", object(R"({"type": "lambertian", "reflectance": 1, "scatter": {}})"),
              {"/objects/0/material", "scatter"});
  expectError("coating_sum.json", object(R"({"type": "coating", "reflect": 0.6, "transmit": 0.6})"),
              {"/objects/0/material", "reflect + transmit"});
  expectError("diffuser_sum.json", object(R"({"type": "diffuser", "reflect": 0.6, "transmit": 0.5})"),
              {"/objects/0/material", "reflect + transmit"});
  expectError("coating_absorb.json", object(R"({"type": "coating", "reflect": 0.2, "transmit": 0.3, "absorb": 0.4})"),
              {"/objects/0/material/absorb", "must be 1"});
  expectError("absorption.json", object(R"({"type": "dielectric", "ior": 1.5, "absorption": -1})"),
              {"/objects/0/material/absorption"});
  expectError("bands.json",
              R"("bands": ["a", "b"], )" + object(R"({"type": "dielectric", "ior": 1.5, "absorption": [1, 2, 3]})"),
              {"/objects/0/material/absorption", "3 per-band values"});
  expectError("unknown_band.json",
              R"("bands": ["vis", "nir"], )" + object(R"({"type": "coating", "transmit": {"vis": 0.9, "uv": 0.1}})"),
              {"/objects/0/material/transmit", "unknown band \"uv\""});
  expectError("missing_band.json",
              R"("bands": ["vis", "nir"], )" + object(R"({"type": "coating", "transmit": {"vis": 0.9}})"),
              {"/objects/0/material/transmit", "no value for band \"nir\""});
  expectError("band_value.json",
              R"("bands": ["vis", "nir"], )" + object(R"({"type": "coating", "reflect": {"vis": 0.2, "nir": 1.5}})"),
              {"/objects/0/material/reflect/nir"});
  expectError("instance.json",
              R"("objects": [{"name": "part", "box": {"size": 1}}],
                 "nodes": [{"group": "g", "children": [{"instance": "p", "object": "part",
                            "material": {"type": "coating", "reflect": 2}}]}])",
              {"/nodes/0/children/0/material/reflect"});
}

}  // namespace
}  // namespace duplex
