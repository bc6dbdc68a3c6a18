// The `duplex` command-line tool: the interchange contract used by tools outside the project.
//   duplex trace --scene S.json --rays R.bin --hits H.bin [--threads N] [--any-hit] [--repeat R]
//   duplex rays  --scene S.json (--primary W H | --random N --seed X) --out R.bin
// Each command prints one JSON object on stdout; diagnostics go to stderr. Bad input gives a
// message naming the file and the problem and a non-zero exit status.

#include "RaysCommand.h"
#include "TraceCommand.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/Log.h>

#include <CLI/CLI.hpp>

#include <cstdint>
#include <exception>
#include <iostream>
#include <vector>

namespace {

// Exit statuses besides CLI11's own (which are non-zero for every parse error).
constexpr int kExitBadInput = 1;     // duplex::Error: a file or argument the library refused
constexpr int kExitInternal = 3;     // anything else: a bug, reported rather than crashing

// CLI11 would wrap "-1" around for an unsigned 64-bit option.
const CLI::Validator kNotNegative(
    [](std::string& value) { return value.starts_with('-') ? std::string("must not be negative") : std::string(); },
    "UINT");

}  // namespace

int main(int argc, char** argv) {
  using duplex::cli::RaysOptions;
  using duplex::cli::TraceOptions;

  CLI::App app{"Two-level kd-tree ray tracing of scene-json-v1 scenes (ray and hit files in, JSON figures out).",
               "duplex"};
  app.require_subcommand(1);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Log the library's info messages to stderr");

  // duplex trace
  TraceOptions trace;
  CLI::App* trace_cmd = app.add_subcommand("trace", "Trace a ray file against a scene and write a hit file");
  trace_cmd->add_option("--scene", trace.scene, "scene-json-v1 file")->required();
  trace_cmd->add_option("--rays", trace.rays, "Ray file: 32-byte records ox oy oz tnear dx dy dz tfar")->required();
  trace_cmd->add_option("--hits", trace.hits, "Hit file to write: 20-byte records t u v instance_id prim_id")
      ->required();
  trace_cmd->add_option("--threads", trace.threads, "Worker threads (default: all hardware threads)")
      ->check(CLI::Range(1, 4096));
  trace_cmd->add_flag("--any-hit", trace.any_hit,
                      "Occlusion queries: blocked -> {0, 0, 0, instance 0, prim 0xFFFFFFFF}, free -> miss");
  trace_cmd->add_option("--repeat", trace.repeat, "Trace R times and report the median time")
      ->check(CLI::Range(1, 1000000));

  // duplex rays
  RaysOptions rays;
  std::vector<std::uint32_t> primary;
  std::uint64_t random_count = 0, seed = 0;
  CLI::App* rays_cmd = app.add_subcommand("rays", "Write primary or random rays for a scene");
  rays_cmd->add_option("--scene", rays.scene, "scene-json-v1 file (its world bounds place the rays)")->required();
  rays_cmd->add_option("--out", rays.out, "Ray file to write")->required();
  CLI::Option* primary_opt =
      rays_cmd->add_option("--primary", primary, "W H: primary rays of a W x H image, row-major from the top left")
          ->expected(2)
          ->check(CLI::Range(1u, 65536u));
  CLI::Option* random_opt = rays_cmd->add_option("--random", random_count, "N random rays (origins in the world box)")
                                ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 32));
  CLI::Option* seed_opt =
      rays_cmd->add_option("--seed", seed, "Seed of the random rays (0 to 2^64-1)")->check(kNotNegative);
  primary_opt->excludes(random_opt);
  primary_opt->excludes(seed_opt);
  random_opt->needs(seed_opt);
  seed_opt->needs(random_opt);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);  // help to stdout with status 0; errors to stderr with a non-zero status
  }
  if (verbose) duplex::logger()->set_level(spdlog::level::info);

  const char* command = *trace_cmd ? "duplex trace" : "duplex rays";
  try {
    nlohmann::ordered_json result;
    if (*trace_cmd) {
      result = duplex::cli::runTrace(trace);
    } else {
      if (*primary_opt) {
        rays.width = primary[0];
        rays.height = primary[1];
      }
      if (*random_opt) {
        rays.random_count = random_count;
        rays.seed = seed;
      }
      result = duplex::cli::runRays(rays);
    }
    std::cout << result.dump() << std::endl;
    return 0;
  } catch (const duplex::Error& e) {
    std::cerr << command << ": error: " << e.what() << '\n';
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << command << ": internal error: " << e.what() << '\n';
    return kExitInternal;
  } catch (...) {
    std::cerr << command << ": internal error: unknown exception\n";
    return kExitInternal;
  }
}
