#pragma once
/// \file ViewCommand.h
/// `duplex view SCENE`: the scene live in a browser. Loads the scene, serves the page and the HTTP
/// interface of docs/viewer.md (cpp-httplib) on --bind:--port, prints one JSON line on stdout when
/// ready ({"url", "port", "token"}) and serves until SIGINT or SIGTERM.

#include "Command.h"

#include <filesystem>
#include <string>

namespace duplex::cli {

struct ViewOptions {
  std::filesystem::path scene;     ///< scene-json-v1 or duplex-scene-v1
  int port = 8765;                 ///< TCP port; 0 picks a free one
  std::string bind = "127.0.0.1";  ///< address to listen on (anything else is warned about)
  int threads = 0;                 ///< render, pick, commit and sensor-run workers; 0: all hardware threads
};

/// Runs the server until SIGINT / SIGTERM. Throws duplex::Error naming the file for a bad scene,
/// and InvalidArgument naming the option when the address cannot be bound.
void runView(const ViewOptions& options);

/// Adds `duplex view` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addViewCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
