// duplex_bench_update: `duplex bench update` (BenchUpdateCommand.h) with the
// Embree baseline when the build found Embree 3, and the source revision in machine. Same options,
// same JSON on stdout (plus the Embree figures and ratios), same exit statuses as the tool.
//   duplex_bench_update --scene S.json [--moves M | --moves P%] [--repeat R] [--seed X] [--threads N]
//                       [--primary W] [--build-repeat B] [--baseline-repeat B]

#include "BenchUpdateCommand.h"

#include <duplex/accel/Error.h>

#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{
      "Time commits of moved, added and removed instances: ours incremental, ours with a full "
      "top-level rebuild, and Embree's two-level scenes when built with Embree 3.",
      "duplex_bench_update"};
  duplex::cli::BenchUpdateOptions options;
  duplex::cli::addBenchUpdateOptions(app, options);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  // The tool's exit statuses: 1 for input the library refused, 3 for anything else.
  try {
    std::cout << duplex::cli::runBenchUpdate(options).dump() << std::endl;
    return 0;
  } catch (const duplex::Error& e) {
    std::cerr << "duplex_bench_update: error: " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_update: internal error: " << e.what() << '\n';
    return 3;
  }
}
