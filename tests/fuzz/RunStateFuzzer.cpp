// libFuzzer target of the sensor run state (SensorRun::loadState, the run_state.bin of `duplex
// sensor --resume`) for one fixed scene: a spectral point light over a Lambertian floor, a flat
// sensor with angular bins and a far-field sensor. The input is the file; it is loaded as it is and
// again with its trailing checksum repaired, so that mutations reach the header, size, fingerprint
// and value checks behind the checksum. A FileError is the expected refusal, and leaves the run as
// it was; a state that loads must give finite, non-negative results and save back to the same
// bytes. Anything else (a crash, a sanitizer report, another exception) is a finding.
//
// The seeds (tests/fuzz/corpus/run_state) are this scene's states after runs that end inside the
// first batch, on a batch boundary and inside the second batch:
// DUPLEX_FUZZ_WRITE_SEEDS=DIR duplex_fuzz_run_state writes them to DIR and exits.

#include "FuzzInputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/Log.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

[[noreturn]] void violated(const char* what) {
  std::fprintf(stderr, "SensorRun::loadState property violated: %s\n", what);
  std::abort();
}

constexpr const char* kScene = R"({"format": "scene-json-v1", "bands": ["blue", "red"],
  "objects": [{"name": "floor", "mesh": {"positions": [-2,-2,0, 2,-2,0, 2,2,0, -2,2,0], "indices": [0,1,2, 0,2,3]},
               "material": {"type": "lambertian", "reflectance": [0.5, 0.2]}}],
  "instances": [{"object": "floor", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
  "lights": [{"type": "point", "position": [0, 0, 0.5], "power": 2, "spectrum": [1, 3]}],
  "sensors": [{"name": "plate", "size": [2, 2], "bins": [3, 2], "two_sided": true, "angular_bins": [2, 3],
               "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0.25]},
              {"name": "far", "shape": "farfield", "bins": [4, 3]}]})";

// Small batches, so that short runs still cross batch boundaries.
duplex::SensorRunConfig config() {
  duplex::SensorRunConfig c;
  c.threads = 1;
  c.batch_rays = 64;
  return c;
}

const duplex::SensorScene& scene() {
  static const std::optional<duplex::SensorScene> s = [] {
    const std::filesystem::path file = duplex::fuzz::inputFile(".scene.json");
    std::ofstream(file) << kScene;
    std::optional<duplex::SensorScene> loaded;
    loaded.emplace(duplex::SensorScene::load(file));
    return loaded;
  }();
  return *s;
}

bool finiteNonNegative(const std::vector<double>& values) {
  return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v) && v >= 0.0; });
}

void load(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& file = duplex::fuzz::writeInputFile(data, size, ".state");
  duplex::SensorRun run(scene(), config());
  try {
    run.loadState(file);
  } catch (const duplex::FileError&) {
    if (run.raysDone() != 0) violated("a refused state changed the run");
    return;
  }
  const duplex::SensorRunResults r = run.results();
  if (r.rays != run.raysDone()) violated("results() disagree with raysDone()");
  for (const duplex::SensorResult& s : r.sensors)
    if (!finiteNonNegative(s.flux_w) || !finiteNonNegative(s.irradiance_w_m2) || !finiteNonNegative(s.stderr_w_m2) ||
        !(std::isfinite(s.total_flux_w) && s.total_flux_w >= 0.0))
      violated("a loaded state gives negative or non-finite results");
  const std::filesystem::path again = duplex::fuzz::inputFile(".saved");
  run.saveState(again);
  const std::string saved = duplex::readWholeFile(again, "fuzz state");
  if (saved.size() != size || !std::equal(saved.begin(), saved.end(), reinterpret_cast<const char*>(data)))
    violated("a loaded state does not save back to its own bytes");
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  duplex::fuzz::writeSeedsIfAsked([](const std::filesystem::path& out) {
    for (const std::uint64_t rays : {40, 128, 200}) {
      duplex::SensorRun run(scene(), config());
      run.runUntil(rays);
      run.saveState(out / ("state_" + std::to_string(rays) + ".bin"));
    }
  });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  duplex::fuzz::loadAsIsAndRepaired(data, size, load);
  return 0;
}
