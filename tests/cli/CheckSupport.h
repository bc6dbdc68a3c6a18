#pragma once
/// \file CheckSupport.h
/// What every CLI checker shares: a failed expectation, a run that must succeed, and main's report.

#include "Subprocess.h"

#include <exception>
#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

namespace duplex::clitest {

/// A failed expectation; reportFailures prints it and returns 1.
struct Failure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

inline void expect(bool ok, const std::string& what) {
  if (!ok) throw Failure(what);
}

/// run(), failing unless the program exited with 0 (the message names the command and its stderr).
inline RunResult runOk(const std::vector<std::string>& argv, const std::filesystem::path& dir) {
  RunResult r = run(argv, dir.string());
  std::string cmd;
  for (const std::string& a : argv) cmd += a + " ";
  expect(r.exited && r.exit_code == 0, "`" + cmd + "` ended with " + describe(r) + "; stderr:\n" + r.err);
  return r;
}

/// Runs a checker's body: a Failure prints "FAIL: ...", any other exception "ERROR: ...", both 1.
template <class Body>
int reportFailures(Body&& body) {
  try {
    return body();
  } catch (const Failure& f) {
    std::cerr << "FAIL: " << f.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace duplex::clitest
