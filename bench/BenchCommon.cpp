#include "BenchCommon.h"

#include <oneapi/tbb/version.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <unistd.h>

namespace duplex::bench {

double median(std::vector<double> samples) {
  if (samples.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(samples.begin(), samples.end());
  const std::size_t n = samples.size();
  return n % 2 == 1 ? samples[n / 2] : 0.5 * (samples[n / 2 - 1] + samples[n / 2]);
}

tbb::task_arena& Arenas::get(int threads) {
  auto& slot = arenas_[threads];
  if (!slot) {
    slot = std::make_unique<tbb::task_arena>(threads);
    // Start the workers now, so that no measurement pays for thread creation.
    slot->execute([] { tbb::parallel_for(0, 1 << 16, [](int) { setFtzDaz(); }); });
  }
  return *slot;
}

namespace {

std::string cpuModel() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) return line.substr(line.find_first_not_of(" \t", colon + 1));
    }
  }
  return "unknown";
}

bool cpuHasFlag(const std::string& flag) {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("flags", 0) == 0) return (line + " ").find(" " + flag + " ") != std::string::npos;
  }
  return false;
}

}  // namespace

std::string loadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string one, five, fifteen;
  in >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

nlohmann::json machineInfo(const BuildFacts& build) {
  nlohmann::json m;
  // Other engineers share the two cores: the load average says how much of the machine we had.
  m["loadavg_at_start"] = loadAverage();
  m["nproc"] = static_cast<long>(::sysconf(_SC_NPROCESSORS_ONLN));
  m["hardware_concurrency"] = std::thread::hardware_concurrency();
  m["cpu_model"] = cpuModel();
  m["avx2"] = cpuHasFlag("avx2");
  m["avx512f"] = cpuHasFlag("avx512f");
  m["compiler"] = std::string(__VERSION__);
#ifdef NDEBUG
  m["ndebug"] = true;
#else
  m["ndebug"] = false;
#endif
  m["tbb_version"] = std::string(TBB_VERSION_STRING);
  const auto orNull = [](const std::string& s) { return s.empty() ? nlohmann::json(nullptr) : nlohmann::json(s); };
  m["duplex_git_revision"] = orNull(build.git_revision);
  m["duplex_library_dirty"] = build.library_dirty ? nlohmann::json(*build.library_dirty) : nlohmann::json(nullptr);
  // What was compiled is what the scripts saw right before `make` (DUPLEX_BENCH_BUILD_INFO: revision,
  // "+dirty:<hash of the diff>" for uncommitted changes in accel/ or objects/), the one to trust
  // while someone edits the library.
  const char* built = std::getenv("DUPLEX_BENCH_BUILD_INFO");
  m["duplex_library_at_build"] = built ? nlohmann::json(built) : nlohmann::json(nullptr);
  m["embree_version"] = orNull(build.embree_version);
  const std::time_t now = std::time(nullptr);
  char stamp[64];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  m["date_utc"] = stamp;
  return m;
}

void writeJson(const std::string& path, const nlohmann::json& doc) {
  const std::filesystem::path p(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path());
  std::ofstream out(p);
  if (!out) throw std::runtime_error("cannot write " + path);
  out << doc.dump(2) << '\n';
  if (!out) throw std::runtime_error("error while writing " + path);
}

std::string fmt(double value, int decimals) {
  if (!std::isfinite(value)) return "-";
  std::ostringstream os;
  os << std::fixed << std::setprecision(decimals) << value;
  return os.str();
}

std::string pad(const std::string& s, std::size_t width) {
  return s.size() >= width ? s : s + std::string(width - s.size(), ' ');
}

std::string lpad(const std::string& s, std::size_t width) {
  return s.size() >= width ? s : std::string(width - s.size(), ' ') + s;
}

std::string thousands(std::uint64_t n) {
  const std::string digits = std::to_string(n);
  std::string s;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s.push_back(',');
    s.push_back(digits[i]);
  }
  return s;
}

}  // namespace duplex::bench
