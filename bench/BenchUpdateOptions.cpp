#include "BenchUpdateCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "StructureOption.h"

#include <CLI/CLI.hpp>

namespace duplex::cli {

void addBenchUpdateOptions(CLI::App& cmd, BenchUpdateOptions& options) {
  cmd.footer("The seeded edit plan is described in bench/BenchUpdateCommand.h.");
  cmd.add_option("--scene", options.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  addStructureOption(cmd, options.structure);
  cmd.add_option("--moves", options.moves,
                 "Instances moved per commit: a count or a percentage such as 1% (default 1)");
  cmd.add_option("--repeat", options.repeat, "Commits per measurement, medians reported (default 50)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  cmd.add_option("--seed", options.seed, "Seed of the edit plan (default 1)")->transform(kDecimal);
  addThreadsOption(cmd, options.threads);
  addPrimaryOption(cmd, options.primary);
  cmd.add_option("--baseline-repeat", options.baseline_repeat,
                 "Commits per measurement of the baselines, a prefix of the same plan (default: --repeat)")
      ->transform(kDecimal)
      ->check(CLI::Range(0, 1000000));
  cmd.add_option("--build-repeat", options.build_repeat,
                 "Rounds of full builds, ours and Embree's interleaved (default 7)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 100));
}

void addBenchUpdateCommand(CLI::App& bench, ChosenCommand& chosen) {
  auto options = std::make_shared<BenchUpdateOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "update",
      "Time commits of moved, added and removed instances (ours incremental, ours full rebuild; the Embree "
      "baseline is in the benchmark duplex_bench_update)");
  addBenchUpdateOptions(*cmd, *options);
  onParsed(*cmd, chosen, options, runBenchUpdate);
}

}  // namespace duplex::cli
