#include "BenchFrameCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "StructureOption.h"

#include <CLI/CLI.hpp>

namespace duplex::cli {

void addBenchFrameOptions(CLI::App& cmd, BenchFrameOptions& options) {
  cmd.footer("The frames, camera and light are described in bench/BenchFrameCommand.h.");
  cmd.add_option("--scene", options.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  addStructureOption(cmd, options.structure);
  cmd.add_option("--moves", options.moves,
                 "Instances moved per frame, one run each: counts or percentages, e.g. 1,1%,10% (the default); "
                 "0: frames without edits")
      ->delimiter(',');
  cmd.add_option("--threads", options.threads, "Thread counts, one run each (default 1,2)")
      ->delimiter(',')
      ->transform(kDecimal)
      ->check(CLI::Range(1, 4096));
  cmd.add_option("--frames", options.frames, "Frames per run, medians reported (default 20)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  cmd.add_option(
         "--size",
         [&options](const CLI::results_t& values) {
           options.width = static_cast<std::uint32_t>(std::stoul(values.at(0)));
           options.height = static_cast<std::uint32_t>(std::stoul(values.at(1)));
           return true;
         },
         "W H: the image in pixels (default 1024 768)")
      ->expected(2)
      ->transform(kDecimal)
      ->check(CLI::Range(1u, 16384u));
  cmd.add_option("--seed", options.seed, "Seed of the moves (default 1)")->transform(kDecimal);
  cmd.add_option("--hit-tolerance", options.hit_tolerance,
                 "Largest per-frame difference of hit counts from Embree's, as a fraction of the primary rays, for "
                 "hits_agree (default 1e-4)")
      ->check(CLI::Range(0.0, 1.0));
#if DUPLEX_BENCH_HAVE_EMBREE
  cmd.add_option("--embree-top", options.embree_top, "Embree's top-level builds: default, dynamic_low (default: both)")
      ->delimiter(',')
      ->check(CLI::IsMember({"default", "dynamic_low"}));
  cmd.add_option("--embree-queries", options.embree_queries,
                 "Embree's queries: 1 (rtcIntersect1 / rtcOccluded1), 16 (rtcIntersect16 coherent / "
                 "rtcOccluded16) (default: both)")
      ->delimiter(',')
      ->check(CLI::IsMember({"1", "16"}));
#endif
}

void addBenchFrameCommand(CLI::App& bench, ChosenCommand& chosen) {
  auto options = std::make_shared<BenchFrameOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "frame",
      "Time interactive frames: move k instances, commit, trace a camera frame with shadow rays (the Embree "
      "baseline is in the benchmark duplex_bench_frame)");
  addBenchFrameOptions(*cmd, *options);
  onParsed(*cmd, chosen, options, runBenchFrame);
}

}  // namespace duplex::cli
