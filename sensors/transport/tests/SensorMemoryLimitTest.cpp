// Sensor bins against the memory limit: a sensor whose bins do not fit is refused when the scene
// is read, naming the sensor and the bytes; a run whose accumulators (and batches) do not fit is
// refused when it is made, before anything is traced; counts whose products overflow are refused
// with a message. The same scenes load and run under a larger limit.

#include "MemoryLimitScope.h"
#include "TestSupport.h"

#include "duplex/accel/MemoryLimit.h"
#include "duplex/sensors/SensorObject.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"

#include <gtest/gtest.h>

#include <sstream>
#include <string>

namespace duplex::test {
namespace {

// A point light and the sensors `sensors` (JSON objects) in a scene-json-v1 file.
std::filesystem::path sensorScene(const TempDir& dir, const std::string& sensors) {
  const auto file = dir / "sensors.json";
  writeTextFile(file, R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 1}], "sensors": [)" +
                          sensors + "]}");
  return file;
}

template <class E, class F>
std::string messageOf(F&& f) {
  try {
    f();
  } catch (const E& e) {
    return e.what();
  }
  return "no exception of the expected type";
}

TEST(SensorMemoryLimit, ASensorWithTooManyBinsIsRefusedNamingItAndTheBytes) {
  TempDir dir;
  const auto file = sensorScene(dir, R"({"name": "small", "size": [1, 1], "bins": [16, 16]},
                                       {"name": "screen", "size": [1, 1], "bins": [4096, 4096]})");
  {
    MemoryLimitScope limit(std::uint64_t{64} << 20);
    const std::string m = messageOf<ResourceError>([&] { (void)SensorScene::load(file); });
    // The bin areas of both sensors: (16 * 16 + 4096 * 4096) doubles.
    EXPECT_NE(m.find(file.string() +
                     ": /sensors/1: sensor 'screen' (4096 x 4096 bins; 16777472 bins with the "
                     "sensors listed before it) needs " +
                     formatBytes((256 + 16777216) * 8)),
              std::string::npos)
        << m;
    EXPECT_NE(m.find("more than the memory limit of 64.0 MiB"), std::string::npos) << m;
    // The sensor object on its own checks the same.
    SensorSpec spec;
    spec.nx = spec.ny = 4096;
    const std::string m_object = messageOf<ResourceError>([&] { (void)SensorObject("screen", spec); });
    EXPECT_NE(m_object.find("sensor 'screen' (4096 x 4096 bins) needs 128 MiB"), std::string::npos) << m_object;
  }
  const SensorScene scene = SensorScene::load(file);
  EXPECT_EQ(scene.binCount(), 256u + 4096u * 4096u);
}

TEST(SensorMemoryLimit, ARunWhoseAccumulatorsDoNotFitIsRefusedBeforeTracing) {
  TempDir dir;
  const auto file = sensorScene(dir, R"({"name": "screen", "size": [1, 1], "bins": [1024, 1024]})");
  MemoryLimitScope limit(std::uint64_t{16} << 20);  // the bin areas (8 MiB) fit, the run does not
  const SensorScene scene = SensorScene::load(file);
  const std::string m = messageOf<ResourceError>([&] { SensorRun run(scene, SensorRunConfig{}); });
  EXPECT_NE(m.find("the sensor run of '" + file.string() +
                   "' (sensors: 1, the largest 'screen' with 1024 x 1024 bins; 1048576 bins and 0 angular "
                   "bins in all; batches of 65536 rays) needs "),
            std::string::npos)
      << m;
  EXPECT_NE(m.find("memory limit of 16.0 MiB"), std::string::npos) << m;
  // The run holds at least three tallies (the run's, the open batch's, the copy of results())
  // of 1048576 bins of 32-byte sums and a 4-byte index: a limit of that much refuses it too.
  setMemoryLimit(3 * 1048576 * 36);
  EXPECT_THROW(SensorRun(scene, SensorRunConfig{}), ResourceError);

  setMemoryLimit(std::uint64_t{1} << 30);
  SensorRunConfig cfg;
  cfg.threads = 2;
  SensorRun run(scene, cfg);
  (void)run.runUntil(1000);
  EXPECT_EQ(run.results().sensors[0].flux_w.size(), 1024u * 1024u);
}

TEST(SensorMemoryLimit, HugeBatchesAndBinCountsAreRefusedWithAMessage) {
  TempDir dir;
  const SensorScene scene = SensorScene::load(sensorScene(dir, R"({"name": "s", "size": [1, 1], "bins": [4, 4]})"));
  SensorRunConfig cfg;
  cfg.batch_rays = std::uint64_t{1} << 40;  // per-ray records of a batch: tens of TiB
  const std::string m = messageOf<ResourceError>([&] { SensorRun run(scene, cfg); });
  EXPECT_NE(m.find("batches of 1099511627776 rays) needs"), std::string::npos) << m;

  // 2^31 x 2^31 bins: the product does not fit 32 bits (nor the bin areas 64): a message, never a
  // wrapped count.
  SensorSpec spec;
  spec.nx = spec.ny = 1u << 31;
  EXPECT_NE(
      messageOf<InvalidArgument>([&] { (void)SensorObject("huge", spec); }).find("sensor 'huge': more than 2^26 bins"),
      std::string::npos);
  const auto file = sensorScene(dir, R"({"name": "huge", "size": [1, 1], "bins": [2147483648, 2147483648]})");
  EXPECT_NE(messageOf<FileError>([&] { (void)SensorScene::load(file); }).find("/sensors/0/bins/0"), std::string::npos);
}

}  // namespace
}  // namespace duplex::test
