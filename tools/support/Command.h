#pragma once
/// \file Command.h
/// How a command plugs into the `duplex` tool. Each command's `add<Name>Command(parent, chosen)`
/// declares its subcommand of `parent` with its options and sets a callback (onParsed). CLI11 runs
/// the callback of the command given once the whole command line has parsed; it only stores in
/// `chosen` what to run. main() then applies the global flags (--verbose, --max-memory), runs the
/// command, prints its report and maps its exceptions to exit statuses.

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <functional>
#include <memory>
#include <string>
#include <utility>

namespace duplex::cli {

/// The command given on the command line, as its callback chose it.
struct ChosenCommand {
  /// Its path from the tool, e.g. "duplex scene split": the prefix of its error messages.
  std::string name;
  /// Runs it and returns its report, the one JSON object printed on stdout; null when there is
  /// nothing to print (the command wrote its own output, or another MPI rank reports).
  std::function<nlohmann::ordered_json()> run;
};

/// The path of `cmd` from the root application, e.g. "duplex scene split".
[[nodiscard]] inline std::string commandPath(const CLI::App& cmd) {
  const CLI::App* parent = cmd.get_parent();
  return parent ? commandPath(*parent) + " " + cmd.get_name() : cmd.get_name();
}

/// Sets `cmd`'s callback: when `cmd` is the command given, `chosen` becomes `run(*options)`.
/// `options` is the struct the option declarations write into; the callback shares it, so it
/// lives as long as the application. `run` takes `const Options&` and returns the report.
template <class Options, class Run>
void onParsed(CLI::App& cmd, ChosenCommand& chosen, std::shared_ptr<Options> options, Run run) {
  cmd.callback([&cmd, &chosen, options = std::move(options), run = std::move(run)] {
    chosen.name = commandPath(cmd);
    chosen.run = [options, run] { return nlohmann::ordered_json(run(*options)); };
  });
}

}  // namespace duplex::cli
