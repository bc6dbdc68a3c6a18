#include "Subprocess.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace duplex::clitest {

namespace {

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The files a child's stdout and stderr go to.
struct Capture {
  std::string out_path, err_path;
  explicit Capture(const std::string& scratch_dir) {
    static std::atomic<int> counter{0};
    const std::string stem = scratch_dir + "/run." + std::to_string(::getpid()) + "." + std::to_string(counter++);
    out_path = stem + ".out";
    err_path = stem + ".err";
  }
};

pid_t spawn(const std::vector<std::string>& argv, const Capture& capture) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);

  const pid_t pid = ::fork();
  if (pid < 0) throw std::runtime_error(std::string("fork failed: ") + std::strerror(errno));
  if (pid == 0) {
    // Child: only async-signal-safe calls until exec.
    const int in = ::open("/dev/null", O_RDONLY);
    const int out = ::open(capture.out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open(capture.err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (in < 0 || out < 0 || err < 0) ::_exit(126);
    ::dup2(in, 0);
    ::dup2(out, 1);
    ::dup2(err, 2);
    ::execv(args[0], args.data());
    ::_exit(127);
  }
  return pid;
}

// What an ended child (its waitpid status) did and wrote; removes the capture files.
RunResult finish(int status, const std::vector<std::string>& argv, const Capture& capture) {
  RunResult r;
  r.exited = WIFEXITED(status);
  if (r.exited) r.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  r.out = slurp(capture.out_path);
  r.err = slurp(capture.err_path);
  ::unlink(capture.out_path.c_str());
  ::unlink(capture.err_path.c_str());
  if (r.exited && r.exit_code == 127 && r.out.empty() && r.err.empty())
    throw std::runtime_error("cannot execute '" + argv[0] + "'");
  return r;
}

RunResult collect(pid_t pid, const std::vector<std::string>& argv, const Capture& capture) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) throw std::runtime_error(std::string("waitpid failed: ") + std::strerror(errno));
  return finish(status, argv, capture);
}

}  // namespace

RunResult run(const std::vector<std::string>& argv, const std::string& scratch_dir) {
  const Capture capture(scratch_dir);
  return collect(spawn(argv, capture), argv, capture);
}

RunResult runAndSignal(const std::vector<std::string>& argv, const std::string& scratch_dir, int signal,
                       const std::string& after_stderr, double timeout_s) {
  const Capture capture(scratch_dir);
  const pid_t pid = spawn(argv, capture);
  const auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      // Ended before the signal could be sent: report it as it ended (the caller's checks fail).
      RunResult r = finish(status, argv, capture);
      r.err += "\n(ended before '" + after_stderr + "' appeared on stderr)";
      return r;
    }
    if (slurp(capture.err_path).find(after_stderr) != std::string::npos) break;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) {
      ::kill(pid, SIGKILL);
      RunResult r = collect(pid, argv, capture);
      r.err += "\n('" + after_stderr + "' did not appear on stderr within the timeout)";
      return r;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ::kill(pid, signal);
  return collect(pid, argv, capture);
}

std::string describe(const RunResult& r) {
  return r.exited ? "exit " + std::to_string(r.exit_code) : "killed by signal " + std::to_string(r.signal);
}

}  // namespace duplex::clitest
