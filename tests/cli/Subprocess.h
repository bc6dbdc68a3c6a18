#pragma once
/// \file Subprocess.h
/// Running a program the way a tool outside the project would, capturing what it prints.

#include <string>
#include <vector>

namespace duplex::clitest {

struct RunResult {
  bool exited = false;  ///< ended through exit() (false: killed by a signal, e.g. a crash)
  int exit_code = -1;   ///< valid when `exited`
  int signal = 0;       ///< valid when !exited
  std::string out;      ///< everything written to stdout
  std::string err;      ///< everything written to stderr
};

/// Runs argv[0] (a path, no PATH lookup) with argv, stdin from /dev/null, stdout and stderr
/// captured through files in `scratch_dir`. Throws std::runtime_error when it cannot start.
[[nodiscard]] RunResult run(const std::vector<std::string>& argv, const std::string& scratch_dir);

/// As run(), but sends `signal` to the program once `after_stderr` appears in what it has written
/// to stderr (polled every 10 ms). If the text does not appear within `timeout_s` seconds the
/// program is killed (SIGKILL) and the result says so in `err`; if it ends first, the result is
/// how it ended.
[[nodiscard]] RunResult runAndSignal(const std::vector<std::string>& argv, const std::string& scratch_dir, int signal,
                                     const std::string& after_stderr, double timeout_s);

/// "exit 3" / "killed by signal 11", for messages.
[[nodiscard]] std::string describe(const RunResult& r);

}  // namespace duplex::clitest
