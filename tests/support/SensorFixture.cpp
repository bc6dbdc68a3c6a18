// The non-template functions of SensorFixture.h, compiled once into the test support library rather than
// into every test file that includes the header.
#include "SensorFixture.h"

namespace duplex::test {

std::shared_ptr<const Object> quad(double half, const std::string& name, double z) {
  const float h = static_cast<float>(half), zf = static_cast<float>(z);
  const std::vector<float> p = {-h, -h, zf, h, -h, zf, h, h, zf, -h, h, zf};
  const std::vector<std::uint32_t> i = {0, 1, 2, 0, 2, 3};
  return buildChecked(TriangleMesh::fromArrays(p, i, name));
}

std::filesystem::path writeTestFile(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / ("duplex_sensor_tests_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::ofstream(path) << text;
  return path;
}

void expectLoadError(const std::filesystem::path& path, const std::vector<std::string>& needles) {
  try {
    (void)SensorScene::load(path);
    ADD_FAILURE() << path << ": no error";
  } catch (const FileError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path.string()), std::string::npos) << what;
    for (const std::string& needle : needles) EXPECT_NE(what.find(needle), std::string::npos) << what;
  }
}

void closeBox(Fixture& f) {
  const glm::dvec3 normals[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (int k = 0; k < 6; ++k) {
    const std::string name = "face" + std::to_string(k);
    f.add(sensor(2.0, 2.0, 3, 3, true, name), facing(normals[k], normals[k]), name);
  }
}

SensorRunResults runWith(const SensorScene& scene, unsigned threads, std::uint32_t chunk, std::uint64_t rays,
                         SensorRunConfig cfg) {
  cfg.threads = threads;
  cfg.chunk_rays = chunk;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  return run.results();
}

void expectIdentical(const SensorRunResults& a, const SensorRunResults& b) {
  ASSERT_EQ(a.rays, b.rays);
  ASSERT_EQ(a.sensors.size(), b.sensors.size());
  for (std::size_t k = 0; k < a.sensors.size(); ++k) {
    EXPECT_EQ(a.sensors[k].flux_w, b.sensors[k].flux_w);
    EXPECT_EQ(a.sensors[k].stderr_w_m2, b.sensors[k].stderr_w_m2);
    EXPECT_EQ(a.sensors[k].ray_count, b.sensors[k].ray_count);
    EXPECT_EQ(a.sensors[k].total_flux_w, b.sensors[k].total_flux_w);
  }
  EXPECT_EQ(a.energy.absorbed_w, b.energy.absorbed_w);
  EXPECT_EQ(a.energy.escaped_w, b.energy.escaped_w);
  EXPECT_EQ(a.energy.medium_absorbed_w, b.energy.medium_absorbed_w);
  EXPECT_EQ(a.energy.depth_limited_w, b.energy.depth_limited_w);
  EXPECT_EQ(a.energy.roulette_w, b.energy.roulette_w);
  EXPECT_EQ(a.bands, b.bands);
  EXPECT_EQ(a.band_emitted_w, b.band_emitted_w);
  for (std::size_t k = 0; k < a.sensors.size(); ++k) {
    EXPECT_EQ(a.sensors[k].band_flux_w, b.sensors[k].band_flux_w);
    EXPECT_EQ(a.sensors[k].band_stderr_w_m2, b.sensors[k].band_stderr_w_m2);
    EXPECT_EQ(a.sensors[k].band_total_flux_w, b.sensors[k].band_total_flux_w);
    EXPECT_EQ(a.sensors[k].angular_flux_w, b.sensors[k].angular_flux_w);
    EXPECT_EQ(a.sensors[k].angular_stderr_w, b.sensors[k].angular_stderr_w);
    EXPECT_EQ(a.sensors[k].band_angular_flux_w, b.sensors[k].band_angular_flux_w);
  }
}

}  // namespace duplex::test
