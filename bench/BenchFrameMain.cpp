// duplex_bench_frame: `duplex bench frame` (BenchFrameCommand.h) with Embree's
// two-level scenes as the baseline when the build found Embree 3, and the source revision in
// machine. Same options (plus --embree-top and --embree-queries), same JSON on stdout (plus the
// Embree sides, the ratios and the hit-count agreement), same exit statuses as the tool.
//   duplex_bench_frame --scene S.json [--moves 1,1%,10%] [--threads 1,2] [--frames N] [--size W H]
//                      [--seed X] [--hit-tolerance F] [--embree-top default,dynamic_low] [--embree-queries 1,16]

#include "BenchFrameCommand.h"

#include <duplex/accel/Error.h>

#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

int main(int argc, char** argv) {
  CLI::App app{
      "Time interactive frames (move k instances, commit, trace a camera frame with shadow rays): ours and, when "
      "built with Embree 3, Embree's two-level scenes, interleaved frame by frame.",
      "duplex_bench_frame"};
  duplex::cli::BenchFrameOptions options;
  duplex::cli::addBenchFrameOptions(app, options);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  // The tool's exit statuses: 1 for input the library refused, 3 for anything else.
  try {
    std::cout << duplex::cli::runBenchFrame(options).dump() << std::endl;
    return 0;
  } catch (const duplex::Error& e) {
    std::cerr << "duplex_bench_frame: error: " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_frame: internal error: " << e.what() << '\n';
    return 3;
  }
}
