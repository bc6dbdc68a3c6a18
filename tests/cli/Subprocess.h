#pragma once
/// \file Subprocess.h
/// Running a program the way a tool outside the project would, capturing what it prints.

#include <string>
#include <vector>

namespace duplex::clitest {

struct RunResult {
  bool exited = false;   ///< ended through exit() (false: killed by a signal, e.g. a crash)
  int exit_code = -1;    ///< valid when `exited`
  int signal = 0;        ///< valid when !exited
  std::string out;       ///< everything written to stdout
  std::string err;       ///< everything written to stderr
};

/// Runs argv[0] (a path, no PATH lookup) with argv, stdin from /dev/null, stdout and stderr
/// captured through files in `scratch_dir`. Throws std::runtime_error when it cannot start.
[[nodiscard]] RunResult run(const std::vector<std::string>& argv, const std::string& scratch_dir);

/// "exit 3" / "killed by signal 11", for messages.
[[nodiscard]] std::string describe(const RunResult& r);

}  // namespace duplex::clitest
