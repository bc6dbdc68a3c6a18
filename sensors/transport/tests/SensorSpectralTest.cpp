// Spectral bands in sensor runs (only when the scene asks for them):
// with equal reflectances the bands split the single-band run (same paths, same totals, each band
// its share of the power); a band-dependent mirror removes exactly its band; threads, resume and
// scene-file keys.

#include "duplex/accel/Error.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

Light spectralPoint(glm::dvec3 p, double power, std::vector<double> spectrum) {
  Light l = pointLight(p, power);
  l.spectrum = std::move(spectrum);
  return l;
}

// A closed box of sensors around two lights and a Lambertian floor.
SensorScene diffuseBox(Fixture& f, std::vector<std::string> bands, Material white) {
  closeBox(f);
  f.add(quad(0.6, "white"), translate(0, 0, -0.5), "white", white);
  Light second =
      spectralPoint({0.3, 0.1, 0.4}, 1.0, bands.empty() ? std::vector<double>{} : std::vector<double>{0, 0, 1});
  second.name = "blue";
  const Light first =
      spectralPoint({0, 0, 0.2}, 3.0, bands.empty() ? std::vector<double>{} : std::vector<double>{1, 2, 1});
  return f.scene({first, second}, std::move(bands));
}

// A run state file in the temporary folder, named for the test and the process.
std::filesystem::path tempState(const std::string& tag) {
  return std::filesystem::temp_directory_path() /
         ("duplex_spectral_" + tag + "_" + std::to_string(::getpid()) + ".bin");
}

// Runs `rays` rays of `scene` and saves the state to `state`; returns the run's results.
SensorRunResults savedRun(const SensorScene& scene, const SensorRunConfig& cfg, std::uint64_t rays,
                          const std::filesystem::path& state) {
  SensorRun r(scene, cfg);
  (void)r.runUntil(rays);
  r.saveState(state);
  return r.results();
}

SensorRunResults run(const SensorScene& scene, std::uint64_t rays, unsigned threads = 0) {
  SensorRunConfig cfg;
  cfg.seed = 21;
  cfg.threads = threads;
  SensorRun r(scene, cfg);
  (void)r.runUntil(rays);
  return r.results();
}

TEST(SensorSpectral, EqualReflectanceBandsSplitTheSingleBandRun) {
  const Material white = Lambertian{0.8};
  Fixture f1, f3;
  const SensorScene single = diffuseBox(f1, {}, white);
  const SensorScene spectral = diffuseBox(f3, {"b", "g", "r"}, white);
  EXPECT_EQ(single.bandCount(), 1u);
  EXPECT_EQ(spectral.bandCount(), 3u);
  const SensorRunResults a = run(single, 120000), b = run(spectral, 120000);
  EXPECT_TRUE(a.bands.empty());
  EXPECT_TRUE(a.sensors[0].band_flux_w.empty());
  ASSERT_EQ(b.bands, (std::vector<std::string>{"b", "g", "r"}));
  // Light 0 (3 W) splits 1:2:1, light 1 (1 W) is all in band 2.
  ASSERT_EQ(b.band_emitted_w.size(), 3u);
  EXPECT_NEAR(b.band_emitted_w[0], 0.75, 1e-15);
  EXPECT_NEAR(b.band_emitted_w[1], 1.5, 1e-15);
  EXPECT_NEAR(b.band_emitted_w[2], 1.75, 1e-15);
  // The same paths: the band-summed results are the single-band run's, bit for bit.
  for (std::size_t k = 0; k < a.sensors.size(); ++k) {
    EXPECT_EQ(a.sensors[k].flux_w, b.sensors[k].flux_w);
    EXPECT_EQ(a.sensors[k].total_flux_w, b.sensors[k].total_flux_w);
    EXPECT_EQ(a.sensors[k].stderr_w_m2, b.sensors[k].stderr_w_m2);
  }
  EXPECT_EQ(a.energy.absorbed_w, b.energy.absorbed_w);
  // The bands sum to the total, per bin and per sensor.
  for (const SensorResult& s : b.sensors) {
    ASSERT_EQ(s.band_total_flux_w.size(), 3u);
    const double sum = s.band_total_flux_w[0] + s.band_total_flux_w[1] + s.band_total_flux_w[2];
    EXPECT_NEAR(sum, s.total_flux_w, 1e-12 * s.total_flux_w);
    for (std::size_t bin = 0; bin < s.flux_w.size(); ++bin)
      EXPECT_NEAR(s.band_flux_w[0][bin] + s.band_flux_w[1][bin] + s.band_flux_w[2][bin], s.flux_w[bin],
                  1e-12 * (s.flux_w[bin] + 1e-300));
  }
  const SensorResult& top = b.sensors[4];  // face +z, above both lights
  // With equal reflectances each band gets its share of the power: light 1 is in band 2 only, so
  // bands 0 and 1 hold light 0's light in the ratio 1:2 (within the standard errors).
  EXPECT_LT(std::abs(top.band_total_flux_w[1] - 2.0 * top.band_total_flux_w[0]),
            4.5 * std::hypot(top.band_total_flux_stderr_w[1], 2.0 * top.band_total_flux_stderr_w[0]));
}

// A point light under a mirror and a one-sided sensor between them that records downward rays
// only: it sees the reflected light, not the direct.
SensorScene mirrorScene(Fixture& f, Material mirror) {
  f.add(quad(1.0, "mirror"), translate(0, 0, 1.0), "mirror", mirror);
  f.add(sensor(2.0, 2.0, 4, 4, /*two_sided=*/false, "floor"), translate(0, 0, 0.5), "floor");  // records downward rays
  return f.scene({spectralPoint({0, 0, 0.3}, 2.0, {1, 1, 1})}, {"b", "g", "r"});
}

TEST(SensorSpectral, ABandDependentMirrorRemovesExactlyItsBand) {
  const Material grey = Mirror{1.0};
  const Material magenta = Mirror{{1.0, {1.0, 0.0, 1.0}}};
  Fixture f1, f2;
  const SensorScene white_scene = mirrorScene(f1, grey), magenta_scene = mirrorScene(f2, magenta);
  const SensorRunResults w = run(white_scene, 60000), m = run(magenta_scene, 60000);
  const SensorResult &sw = w.sensors[0], &sm = m.sensors[0];
  // Band 1 is gone, exactly; bands 0 and 2 are untouched (the same paths, bit for bit).
  for (const double x : sm.band_flux_w[1]) EXPECT_EQ(x, 0.0);
  EXPECT_EQ(sm.band_total_flux_w[1], 0.0);
  EXPECT_GT(sw.band_total_flux_w[1], 0.05);
  EXPECT_EQ(sm.band_flux_w[0], sw.band_flux_w[0]);
  EXPECT_EQ(sm.band_flux_w[2], sw.band_flux_w[2]);
  // What the magenta mirror absorbed is exactly what no longer escapes.
  EXPECT_GT(m.energy.absorbed_w, 0.1);
  EXPECT_EQ(w.energy.absorbed_w, 0.0);
  EXPECT_NEAR(m.energy.absorbed_w, w.energy.escaped_w - m.energy.escaped_w, 1e-12);
  // The total is the sum of the remaining bands.
  EXPECT_NEAR(sm.total_flux_w, sw.band_total_flux_w[0] + sw.band_total_flux_w[2], 1e-12);
}

TEST(SensorSpectral, BitIdenticalForAnyThreadCountAndResumable) {
  const Material white = Lambertian{0.8};
  Fixture f;
  const SensorScene scene = diffuseBox(f, {"b", "g", "r"}, white);
  const SensorRunResults one = run(scene, 70000, 1);
  expectIdentical(one, run(scene, 70000, 2));
  const std::filesystem::path state = tempState("threads");
  SensorRunConfig cfg;
  cfg.seed = 21;
  savedRun(scene, cfg, 30000, state);
  SensorRun resumed(scene, cfg);
  resumed.loadState(state);
  (void)resumed.runUntil(70000);
  expectIdentical(one, resumed.results());
  // A state saved with other bands is refused.
  Fixture g;
  const SensorScene two = [&] {
    closeBox(g);
    return g.scene({spectralPoint({0, 0, 0}, 3.0, {1, 2})}, {"x", "y"});
  }();
  SensorRun other(two, cfg);
  EXPECT_THROW(other.loadState(state), FileError);
  std::filesystem::remove(state);
}

// A saved state holds sums whose meaning depends on the whole scene: a state of a scene with
// another reflectance, per-band albedo, light position or sensor placement must be refused (it
// would otherwise be silently mixed into the continued run).
TEST(SensorSpectral, ResumeRefusesAStateOfAChangedScene) {
  const Material white = Lambertian{0.8};
  const std::filesystem::path state = tempState("changed");
  SensorRunConfig cfg;
  cfg.seed = 21;
  {
    Fixture f;
    const SensorScene scene = diffuseBox(f, {"b", "g", "r"}, white);
    savedRun(scene, cfg, 5000, state);
    SensorRun same(scene, cfg);
    EXPECT_NO_THROW(same.loadState(state));
  }
  auto refused = [&](const SensorScene& scene) {
    SensorRun other(scene, cfg);
    try {
      other.loadState(state);
    } catch (const FileError&) {
      return other.raysDone() == 0;
    }
    return false;
  };
  {
    Fixture f;  // another reflectance
    EXPECT_TRUE(refused(diffuseBox(f, {"b", "g", "r"}, Material{Lambertian{0.5}})));
  }
  {
    Fixture f;  // the same mean, other per-band values
    const Material m = Lambertian{{0.8, {0.8, 0.8, 0.5}}};
    EXPECT_TRUE(refused(diffuseBox(f, {"b", "g", "r"}, m)));
  }
  {
    Fixture f;  // a mirror instead of the Lambertian floor
    EXPECT_TRUE(refused(diffuseBox(f, {"b", "g", "r"}, Material{Mirror{0.8}})));
  }
  // diffuseBox with the floor at height z and the blue light at p (and the floor mesh of half size
  // `half`, under the same object name).
  auto moved = [&](double z, glm::dvec3 p, double half = 0.6) {
    Fixture f;
    closeBox(f);
    f.add(quad(half, "white"), translate(0, 0, z), "white", white);
    Light second = spectralPoint(p, 1.0, {0, 0, 1});
    second.name = "blue";
    return refused(f.scene({spectralPoint({0, 0, 0.2}, 3.0, {1, 2, 1}), second}, {"b", "g", "r"}));
  };
  EXPECT_FALSE(moved(-0.5, {0.3, 0.1, 0.4}));       // the same scene again: accepted
  EXPECT_TRUE(moved(-0.4, {0.3, 0.1, 0.4}));        // the floor moved
  EXPECT_TRUE(moved(-0.5, {0.3, 0.1, 0.3}));        // a light moved
  EXPECT_TRUE(moved(-0.5, {0.3, 0.1, 0.4}, 0.55));  // the floor's mesh changed, not its name
  std::filesystem::remove(state);
}

// A damaged, truncated, extended or old-version state is refused naming the file, the run keeps
// its accumulators, and saving over a state never leaves a half-written file behind.
TEST(SensorSpectral, DamagedRunStatesAreRefusedAndSavesAreAtomic) {
  const std::filesystem::path state = tempState("damaged");
  SensorRunConfig cfg;
  cfg.seed = 5;
  Fixture f;
  const SensorScene scene = diffuseBox(f, {"b", "g", "r"}, Material{Lambertian{0.8}});
  const SensorRunResults saved = savedRun(scene, cfg, 3000, state);
  savedRun(scene, cfg, 3000, state);  // again, over an existing state
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::path(state) += ".tmp"));
  std::vector<char> clean;
  {
    std::ifstream in(state, std::ios::binary);
    clean.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_GT(clean.size(), 100u);
  const auto refusedWith = [&](const std::vector<char>& bytes, const std::string& needle) {
    {
      std::ofstream out(state, std::ios::binary | std::ios::trunc);
      out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    SensorRun other(scene, cfg);
    (void)other.runUntil(1000);
    const double before = other.results().sensors[0].total_flux_w;
    try {
      other.loadState(state);
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(state.filename().string()), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
    EXPECT_EQ(other.raysDone(), 1000u);
    EXPECT_EQ(other.results().sensors[0].total_flux_w, before);
  };
  std::vector<char> b = clean;
  b[b.size() / 2] ^= 0x10;  // one flipped bit in the sums
  refusedWith(b, "checksum");
  refusedWith(std::vector<char>(clean.begin(), clean.end() - 9), "truncated");
  b = clean;
  b.push_back(0);
  refusedWith(b, "truncated or extended");
  // Any other version, older or newer, and any other file: one message with what was found and
  // what this build reads.
  b = clean;
  for (const char version : {'1', '5', '7'}) {
    b[7] = version;
    refusedWith(b, std::string("found \"DXSENSR") + version + "\", expected \"DXSENSR6\"");
  }
  refusedWith(std::vector<char>{'P', 'K', '\x03', '\x04'}, "found \"PK\\x03\\x04\", expected \"DXSENSR6\"");
  refusedWith(std::vector<char>(clean.begin(), clean.begin() + 12), "12 bytes, truncated");
  // The clean file still resumes to the same accumulators.
  {
    std::ofstream out(state, std::ios::binary | std::ios::trunc);
    out.write(clean.data(), static_cast<std::streamsize>(clean.size()));
  }
  SensorRun resumed(scene, cfg);
  resumed.loadState(state);
  EXPECT_EQ(resumed.raysDone(), 3000u);
  EXPECT_EQ(resumed.results().sensors[0].total_flux_w, saved.sensors[0].total_flux_w);
  std::filesystem::remove(state);
}

TEST(SensorSpectral, BandCountsMustAgree) {
  {
    Fixture f;
    closeBox(f);
    EXPECT_THROW((void)f.scene({spectralPoint({0, 0, 0}, 1.0, {1, 2})}, {"a", "b", "c"}), InvalidArgument);
  }
  {
    Fixture f;
    closeBox(f);
    EXPECT_THROW((void)f.scene({spectralPoint({0, 0, 0}, 1.0, {1, 2})}), InvalidArgument);  // no bands
  }
  {
    Fixture f;
    const Material m = Lambertian{{0.5, {0.5, 0.5}}};
    f.add(quad(1.0, "wall"), Affine::identity(), "wall", m);
    EXPECT_THROW((void)f.scene({pointLight({0, 0, 1}, 1.0)}, {"a", "b", "c"}), InvalidArgument);
  }
  {
    Fixture f;
    closeBox(f);
    EXPECT_THROW((void)f.scene({pointLight({0, 0, 0}, 1.0)}, {"a", "a"}), InvalidArgument);
    EXPECT_THROW((void)f.scene({spectralPoint({0, 0, 0}, 1.0, {0, 0})}, {"a", "b"}), InvalidArgument);
    EXPECT_THROW((void)f.scene({spectralPoint({0, 0, 0}, 1.0, {1, -1})}, {"a", "b"}), InvalidArgument);
    // Finite entries whose sum overflows would give a spectrum of NaN shares.
    EXPECT_THROW((void)f.scene({spectralPoint({0, 0, 0}, 1.0, {1e308, 1e308})}, {"a", "b"}), InvalidArgument);
  }
}

TEST(SensorSpectral, MaterialsMadeInCodeAreCheckedAsFilesAre) {
  // The file reader refuses these; a scene made in code must too (a reflectance of 1.5 acted as 1,
  // a NaN one never absorbed, a NaN index of refraction fed NaN into Fresnel).
  const auto refused = [](Material m, const std::string& needle) {
    Fixture f;
    f.add(quad(1.0, "wall"), Affine::identity(), "wall", m);
    try {
      (void)f.scene({pointLight({0, 0, 1}, 1.0)});
      ADD_FAILURE() << "accepted: " << needle;
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find("'wall'"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  refused(Material{Lambertian{1.5}}, "reflectance");
  refused(Material{Mirror{std::nan("")}}, "reflectance");
  refused(Material{Lambertian{-0.1}}, "reflectance");
  refused(Material{Dielectric{std::nan("")}}, "index of refraction");
  refused(Material{Dielectric{-1.5}}, "index of refraction");
  Fixture ok;
  ok.add(quad(1.0, "wall"), Affine::identity(), "wall", Material{Lambertian{1.0}});
  EXPECT_NO_THROW((void)ok.scene({pointLight({0, 0, 1}, 1.0)}));
}

TEST(SensorSpectral, SceneFilesDeclareBandsSpectraAndPerBandReflectance) {
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("duplex_bands_" + std::to_string(::getpid()) + ".json");
  auto load = [&](const std::string& bands, const std::string& spectrum, const std::string& reflectance) {
    std::ofstream(file) << R"({"format": "scene-json-v1", )" << bands << R"(
      "objects": [{"name": "wall", "mesh": {"positions": [-1,-1,0, 1,-1,0, 1,1,0], "indices": [0,1,2]},
                   "material": {"type": "lambertian", "reflectance": )"
                        << reflectance << R"(}}],
      "instances": [{"object": "wall", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
      "lights": [{"type": "point", "position": [0, 0, 1], "power": 2)"
                        << spectrum << R"(}],
      "sensors": [{"name": "s", "size": [1, 1]}]})";
    return SensorScene::load(file);
  };
  auto error = [&](const std::string& bands, const std::string& spectrum, const std::string& reflectance) {
    try {
      (void)load(bands, spectrum, reflectance);
    } catch (const FileError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  {
    const SensorScene scene = load(R"("bands": ["400-500nm", "500-600nm"],)", R"(, "spectrum": [1, 3])", "[0.2, 0.9]");
    EXPECT_EQ(scene.bands(), (std::vector<std::string>{"400-500nm", "500-600nm"}));
    EXPECT_NEAR(scene.bandCdf(0)[0], 0.25, 1e-15);
    const Material& m = scene.materialOf(scene.graph().visibleInstances()[0]);
    ASSERT_TRUE(m.is<Lambertian>());
    EXPECT_EQ(m.as<Lambertian>()->reflectance.bands, (std::vector<double>{0.2, 0.9}));
    EXPECT_EQ(m.as<Lambertian>()->reflectance.in(1), 0.9);
  }
  {
    const SensorScene scene = load("", "", "0.5");  // no bands: one radiometric band
    EXPECT_TRUE(scene.bands().empty());
    EXPECT_EQ(scene.bandCount(), 1u);
  }
  EXPECT_NE(error(R"("bands": ["a", "b"],)", R"(, "spectrum": [1, 2, 3])", "0.5").find("/lights/0/spectrum"),
            std::string::npos);
  EXPECT_NE(error("", R"(, "spectrum": [1, 2])", "0.5").find("/lights/0/spectrum"), std::string::npos);
  EXPECT_NE(error(R"("bands": ["a", "b"],)", "", "[0.5]").find("/objects/0/material/reflectance"), std::string::npos);
  EXPECT_NE(error(R"("bands": ["a", "b"],)", "", "[0.5, 1.5]").find("/objects/0/material/reflectance/1"),
            std::string::npos);
  EXPECT_NE(error(R"("bands": ["a", "a"],)", "", "0.5").find("/bands/1"), std::string::npos);
  EXPECT_NE(error(R"("bands": [],)", "", "0.5").find("/bands"), std::string::npos);
  {
    std::string many = R"("bands": [)";
    for (int b = 0; b < 257; ++b) many += (b ? ", \"b" : "\"b") + std::to_string(b) + "\"";
    EXPECT_NE(error(many + "],", "", "0.5").find("/bands: 257 bands, at most 256"), std::string::npos)
        << error(many + "],", "", "0.5");
  }
  EXPECT_NE(error(R"("bands": ["a", "b"],)", R"(, "spectrum": [0, -1])", "0.5").find("/lights/0"), std::string::npos);
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace duplex
