// The `duplex` command-line tool: the interchange contract used by tools outside the project
// (docs/cli.md). Each command lives in its own <Name>Command.h/.cpp, which declares its options
// and its callback (Command.h); this file holds the tool's own flags, the list of commands and
// the mapping of errors to exit statuses. Each command prints one JSON object on stdout;
// diagnostics go to stderr. Bad input gives a message naming the file and the problem and a
// non-zero exit status.

#include "BenchDeformCommand.h"
#include "BenchFrameCommand.h"
#include "BenchUpdateCommand.h"
#include "ClosestCommand.h"
#include "InfoCommand.h"
#include "PrepareCommand.h"
#include "RaysCommand.h"
#include "SceneInstancesCommand.h"
#include "SceneRobotCommand.h"
#include "SceneSplitCommand.h"
#include "SensorCommand.h"
#include "SensorRanks.h"
#include "TraceCommand.h"
#include "ViewCommand.h"

#include "Command.h"
#include "MemoryOption.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/Log.h>
#include <duplex/accel/MemoryLimit.h>

#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdint>
#include <exception>
#include <iostream>
#include <string>

namespace {

// Exit statuses besides CLI11's own (which are non-zero for every parse error).
constexpr int kExitBadInput = 1;  // duplex::Error: a file or argument the library refused
constexpr int kExitInternal = 3;  // anything else: a bug, reported rather than crashing

// Adds --max-memory to every command of `app` (the leaves of its tree: every command loads
// scenes, meshes or ray files, or runs).
void addMaxMemoryToCommands(CLI::App& app, std::uint64_t& bytes) {
  for (CLI::App* cmd : app.get_subcommands([](const CLI::App*) { return true; })) {
    if (cmd->get_subcommands([](const CLI::App*) { return true; }).empty())
      duplex::cli::addMaxMemoryOption(*cmd, bytes);
    else addMaxMemoryToCommands(*cmd, bytes);
  }
}

// A group of commands (`duplex scene ...`, `duplex bench ...`): a command of `app` whose own
// commands `add(group)` declares; one of them must be given.
template <class AddCommands>
void addGroup(CLI::App& app, const std::string& name, const std::string& description, AddCommands add) {
  CLI::App* group = app.add_subcommand(name, description);
  group->require_subcommand(1);
  add(*group);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace duplex::cli;
  // Past a file-size limit (ulimit -f) a write then fails with EFBIG, reported as an error naming
  // the file, instead of the signal killing the tool with a half-written temporary file.
  std::signal(SIGXFSZ, SIG_IGN);

  CLI::App app{
      "Two-level kd-tree ray tracing of scene-json-v1 and duplex-scene-v1 scenes (ray and hit files in, "
      "JSON figures out).",
      "duplex"};
  app.require_subcommand(1);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Log the library's info messages to stderr (before or after the command)");
  app.fallthrough();  // options of the tool itself (-v) are also accepted after a command's name

  // The commands, in the order of `duplex --help`.
  ChosenCommand chosen;
  addTraceCommand(app, chosen);
  addRaysCommand(app, chosen);
  addGroup(app, "scene", "Write benchmark scenes as scene-json-v1 (split, instances, robot)", [&](CLI::App& scene) {
    addSceneSplitCommand(scene, chosen);
    addSceneInstancesCommand(scene, chosen);
    addSceneRobotCommand(scene, chosen);
  });
  addPrepareCommand(app, chosen);
  addClosestCommand(app, chosen);
  addGroup(app, "bench", "Benchmarks (update, frame, deform)", [&](CLI::App& bench) {
    addBenchUpdateCommand(bench, chosen);
    addBenchFrameCommand(bench, chosen);
    addBenchDeformCommand(bench, chosen);
  });
  addSensorCommand(app, chosen);
  addInfoCommand(app, chosen);
  addViewCommand(app, chosen);

  std::uint64_t max_memory = 0;
  addMaxMemoryToCommands(app, max_memory);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);  // help to stdout with status 0; errors to stderr with a non-zero status
  }
  if (verbose) duplex::logger()->set_level(spdlog::level::info);
  if (max_memory != 0) duplex::setMemoryLimit(max_memory);

  try {
    const nlohmann::ordered_json result = chosen.run();
    if (!result.is_null()) std::cout << result.dump() << std::endl;
    // A run stopped by SIGINT / SIGTERM saved its state and wrote its files; the exit status still
    // says it was stopped, as a shell expects (128 + the signal).
    if (result.is_object() && result.contains("signal")) return 128 + result["signal"].get<int>();
    return 0;
  } catch (const Interrupted& e) {
    std::cerr << chosen.name << ": " << e.what() << " (signal " << e.signal() << ")\n";
    return 128 + e.signal();
  } catch (const AllRanksFailedReported&) {
    return kExitBadInput;  // written by every rank before any ended (runSensor)
  } catch (const duplex::Error& e) {
    std::cerr << chosen.name << ": error: " << e.what() << '\n';
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << chosen.name << ": internal error: " << e.what() << '\n';
    return kExitInternal;
  } catch (...) {
    std::cerr << chosen.name << ": internal error: unknown exception\n";
    return kExitInternal;
  }
}
