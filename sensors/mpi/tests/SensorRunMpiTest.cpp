// runUntilMpi and agreeOnRanks through the library, as an embedding application calls them: run
// under `mpirun -np 3` (every rank runs every test, in the same order; the tests are collective).
// The world is split into communicators of its own, and each one's rank 0 must hold the saved
// state of a one-process run, byte for byte.

#include "duplex/sensors/CieSky.h"
#include "duplex/sensors/SensorRunMpi.h"

#include "SensorFixture.h"

#include <gtest/gtest.h>
#include <mpi.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace duplex {
namespace {

using namespace test;

int worldRank() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

SensorScene reflectingBox(Fixture& f) {
  closeBox(f);
  Material white = Lambertian{0.9};
  f.add(quad(0.5, "white"), translate(0, 0, -0.5), "white", white);
  return f.scene({pointLight({0, 0, 0.2}, 1.0)});
}

std::string stateBytes(const SensorRun& run) {
  const auto file = std::filesystem::temp_directory_path() /
                    ("duplex_mpi_state_" + std::to_string(::getpid()) + "_" + std::to_string(worldRank()) + ".bin");
  run.saveState(file);
  std::ifstream in(file, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::remove(file);
  return bytes;
}

SensorRunConfig config(unsigned threads) {
  SensorRunConfig cfg;
  cfg.seed = 99;
  cfg.batch_rays = 10000;
  cfg.threads = threads;
  return cfg;
}

TEST(SensorRunMpi, EveryCommunicatorEndsWithTheOneProcessRun) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  SensorRun reference(scene, config(2));
  (void)reference.runUntil(55000);  // five full batches and a shorter one
  // The world (3 ranks), and the world split into {0, 1} and {2}: the application's communicators.
  MPI_Comm halves;
  ASSERT_EQ(MPI_Comm_split(MPI_COMM_WORLD, worldRank() < 2 ? 0 : 1, 0, &halves), MPI_SUCCESS);
  for (MPI_Comm comm : {MPI_COMM_WORLD, halves}) {
    int rank = 0, ranks = 0;
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &ranks);
    SensorRun run(scene, config(1 + static_cast<unsigned>(worldRank() % 2)));
    std::uint64_t reports = 0;
    SensorMpiStats stats;
    EXPECT_EQ(runUntilMpi(
                  run, comm, 55000, [&](const SensorProgress& p) { reports += p.rays_done > 0 ? 1 : 0; }, {}, &stats),
              SensorRunStatus::Completed);
    EXPECT_EQ(stats.ranks, ranks);
    if (rank == 0) {
      EXPECT_EQ(run.raysDone(), 55000u);
      EXPECT_EQ(reports, 6u);  // one report per batch, on rank 0
      EXPECT_EQ(stateBytes(run), stateBytes(reference)) << ranks << " ranks";
      EXPECT_EQ(run.counters().segments, reference.counters().segments);
    } else {
      EXPECT_EQ(run.raysDone(), 0u);  // the other ranks only trace
      EXPECT_EQ(reports, 0u);
      EXPECT_GT(stats.tally_bytes_sent, 0u);
    }
  }
  MPI_Comm_free(&halves);
}

TEST(SensorRunMpi, ResumesAStateEndingInsideABatchAndStopsOnTheTarget) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  // Rank 0 starts from a run of 23,456 rays (inside the third batch), as a loaded state would.
  SensorRun run(scene, config(1));
  if (worldRank() == 0) (void)run.runUntil(23456);
  EXPECT_EQ(runUntilMpi(run, MPI_COMM_WORLD, 61000), SensorRunStatus::Completed);
  SensorRun reference(scene, config(2));
  (void)reference.runUntil(61000);
  if (worldRank() == 0) {
    EXPECT_EQ(stateBytes(run), stateBytes(reference));
  }
  // The stop rule: every rank count stops after the batch where the one-process run stops.
  SensorStopRule stop;
  stop.sensor = 4;
  stop.target = 0.03;
  stop.min_rays = 10000;
  SensorRun alone(scene, config(2)), shared(scene, config(1));
  EXPECT_EQ(alone.runUntil(10000000, {}, stop), SensorRunStatus::TargetReached);
  EXPECT_EQ(runUntilMpi(shared, MPI_COMM_WORLD, 10000000, {}, stop), SensorRunStatus::TargetReached);
  if (worldRank() == 0) {
    EXPECT_EQ(shared.raysDone(), alone.raysDone());
    EXPECT_EQ(stateBytes(shared), stateBytes(alone));
  }
}

TEST(SensorRunMpi, PerLightResultsAndMetersUnderASkyMergeBitForBit) {
  // A CIE clear sky with its sun and a point light over the reflecting box's floor, illuminance and
  // luminance meters, per-light results: rank 0 ends with the one-process run's state, and its
  // per-light and meter values, bit for bit.
  Fixture f;
  closeBox(f);
  f.add(quad(0.5, "white"), translate(0, 0, -0.5), "white", Material{Lambertian{0.9}});
  Light sky;
  sky.type = LightType::Sky;
  sky.name = "sky";
  sky.sky = std::make_shared<const CieSky>(CieSky::general(12, {0.3, -0.5, 0.6}));
  sky.radius = 2.0;
  sky.power_w = 3.0;
  Light sun;
  sun.type = LightType::Directional;
  sun.name = "sky/sun";
  sun.direction = {-0.3, 0.5, -0.6};
  sun.position = -2.0 * glm::normalize(sun.direction);
  sun.radius = 2.0;
  sun.power_w = 5.0;
  SensorScene scene = f.scene({sky, sun, pointLight({0, 0, 0.2}, 1.0)});
  PointMeter lum{"eye", {{0, 0, 0}}, {{0, 0, -1}}};
  lum.half_angle = 0.3;
  scene.setMeters({{"floor", {{0.1, 0, -0.4}, {0, 0, 0}}, {{0, 0, 1}, {0, 0, 1}}}, lum});
  SensorRunConfig cfg = config(2);
  cfg.per_light = true;
  SensorRun reference(scene, cfg);
  (void)reference.runUntil(45000);
  cfg.threads = 1;
  SensorRun run(scene, cfg);
  EXPECT_EQ(runUntilMpi(run, MPI_COMM_WORLD, 45000), SensorRunStatus::Completed);
  if (worldRank() == 0) {
    EXPECT_EQ(stateBytes(run), stateBytes(reference));
    const SensorRunResults a = run.results(), b = reference.results();
    EXPECT_EQ(a.sensors[4].light_flux_w, b.sensors[4].light_flux_w);
    EXPECT_EQ(a.meters[0].light_irradiance_w_m2, b.meters[0].light_irradiance_w_m2);
    EXPECT_EQ(a.meters[1].light_radiance_w_m2_sr, b.meters[1].light_radiance_w_m2_sr);
    EXPECT_GT(a.meters[0].light_irradiance_w_m2[0][0], 0.0);  // the sky reached the floor meter
  }
}

TEST(SensorRunMpi, RanksThatDisagreeOrFailEndTogether) {
  Fixture f;
  const SensorScene scene = reflectingBox(f);
  // Rank 2 has another seed: every rank refuses the run, naming rank 2.
  SensorRunConfig cfg = config(1);
  if (worldRank() == 2) cfg.seed = 5;
  SensorRun run(scene, cfg);
  try {
    (void)runUntilMpi(run, MPI_COMM_WORLD, 30000);
    ADD_FAILURE() << "ranks with other seeds shared a run";
  } catch (const MpiError& e) {
    EXPECT_NE(std::string(e.what()).find("rank 2 of 3 runs another scene, seed or configuration"), std::string::npos)
        << e.what();
  }
  // A failure on rank 1 before the run: every rank learns it, with rank 1's message.
  try {
    agreeOnRanks(MPI_COMM_WORLD, worldRank() == 1 ? "scene.json: cannot open scene file" : "");
    ADD_FAILURE() << "a failing rank went unnoticed";
  } catch (const MpiError& e) {
    EXPECT_EQ(std::string(e.what()), "rank 1 of 3: scene.json: cannot open scene file");
  }
  EXPECT_NO_THROW(agreeOnRanks(MPI_COMM_WORLD, ""));
}

}  // namespace
}  // namespace duplex

int main(int argc, char** argv) {
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  ::testing::InitGoogleTest(&argc, argv);
  const int failed = RUN_ALL_TESTS();
  int any = 0;
  MPI_Allreduce(&failed, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);  // a failure on any rank fails all
  MPI_Finalize();
  return any;
}
