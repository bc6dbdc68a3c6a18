// libFuzzer target of the scene files (scene-json-v1 and duplex-scene-v1, SensorScene::load: the
// graph, the objects with inline meshes and procedural shapes, lights, sensors, materials, timed
// edits). The input is the file, written to a temporary folder (files it names relative to itself
// are not there, so such references are refused). A scene that loads gets its timed edits applied
// and, when it has lights and sensors, a short light-tracing run, whose tallies must be finite and
// non-negative. A duplex::Error (FileError, InvalidArgument) is the expected refusal; anything else
// (a crash, a sanitizer report, another exception, a hang) is a finding.

#include "FuzzInputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"

#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>

namespace {

[[noreturn]] void violated(const char* what) {
  std::fprintf(stderr, "scene loading property violated: %s\n", what);
  std::abort();
}

void loadAndRun(const std::filesystem::path& file) {
  duplex::SensorScene scene = duplex::SensorScene::load(file);
  if (duplex::SceneDocument* doc = scene.document(); doc && !doc->edits.empty())
    (void)duplex::applyEditsUntil(*doc, std::numeric_limits<double>::infinity());
  if (scene.lights().empty() || scene.sensors().empty()) return;
  duplex::SensorRunConfig config;
  config.threads = 1;
  config.batch_rays = 32;
  duplex::SensorRun run(scene, config);
  run.runUntil(64);
  for (const duplex::SensorResult& s : run.results().sensors)
    if (!(std::isfinite(s.total_flux_w) && s.total_flux_w >= 0.0) ||
        !std::all_of(s.flux_w.begin(), s.flux_w.end(), [](double v) { return std::isfinite(v) && v >= 0.0; }))
      violated("a run gave negative or non-finite tallies");
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& file = duplex::fuzz::writeInputFile(data, size, ".json");
  // One thread: the builds a scene starts in parallel run on this thread, so a finding replays
  // the same way.
  tbb::task_arena arena(1);
  arena.execute([&] {
    try {
      loadAndRun(file);
    } catch (const duplex::Error&) {
    }
  });
  return 0;
}
