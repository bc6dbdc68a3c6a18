#include "duplex/accel/MemoryLimit.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace duplex {

namespace {

struct DefaultLimit {
  std::uint64_t bytes = kUncountableBytes;
  const char* source = "the default: the machine's physical memory";
};

// A number of bytes in a control group's file ("max" or a value past any machine reads as none).
std::optional<std::uint64_t> readLimitFile(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::string text;
  if (!(in >> text) || text == "max") return std::nullopt;
  const std::optional<std::uint64_t> value = parseByteSize(text);
  if (!value || *value >= (std::uint64_t{1} << 62)) return std::nullopt;  // cgroup v1 writes ~2^63 for "none"
  return value;
}

// The smallest limit of the process's control group and the groups above it (a parent's limit
// holds for its children too), cgroup v2 or v1.
std::optional<std::uint64_t> cgroupLimit() {
  std::ifstream in("/proc/self/cgroup");
  std::string line;
  std::optional<std::uint64_t> smallest;
  const auto consider = [&](std::filesystem::path dir, const std::filesystem::path& root, const char* name) {
    for (;;) {
      if (const auto v = readLimitFile(dir / name)) smallest = smallest ? std::min(*smallest, *v) : *v;
      if (dir == root || !dir.has_parent_path() || dir.parent_path() == dir) break;
      dir = dir.parent_path();
    }
  };
  while (std::getline(in, line)) {
    // "<id>:<controllers>:<path>": v2 is "0::<path>"; v1 lists "memory" among the controllers.
    const std::size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1), group = line.substr(b + 1);
    const std::string relative = group.empty() || group == "/" ? std::string() : group.substr(1);
    if (line.compare(0, a, "0") == 0 && controllers.empty()) {
      const std::filesystem::path root = "/sys/fs/cgroup";
      consider(relative.empty() ? root : root / relative, root, "memory.max");
    } else if (("," + controllers + ",").find(",memory,") != std::string::npos) {
      const std::filesystem::path root = "/sys/fs/cgroup/memory";
      consider(relative.empty() ? root : root / relative, root, "memory.limit_in_bytes");
    }
  }
  return smallest;
}

const DefaultLimit& defaults() {
  static const DefaultLimit limit = [] {
    DefaultLimit d;
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0)
      d.bytes = arrayBytes(static_cast<std::uint64_t>(pages), static_cast<std::uint64_t>(page));
    if (const auto group = cgroupLimit(); group && *group < d.bytes) {
      d.bytes = *group;
      d.source = "the default: the memory limit of the process's control group";
    }
    return d;
  }();
  return limit;
}

std::atomic<std::uint64_t> g_limit{0};  // 0: the default

}  // namespace

std::uint64_t defaultMemoryLimit() { return defaults().bytes; }

std::uint64_t memoryLimit() {
  const std::uint64_t set = g_limit.load(std::memory_order_relaxed);
  return set ? set : defaultMemoryLimit();
}

void setMemoryLimit(std::uint64_t bytes) { g_limit.store(bytes, std::memory_order_relaxed); }

void requireMemory(std::uint64_t bytes, std::string_view what) {
  const std::uint64_t set = g_limit.load(std::memory_order_relaxed);
  const std::uint64_t limit = set ? set : defaultMemoryLimit();
  if (bytes <= limit) return;
  std::ostringstream msg;
  msg << what << " needs " << formatBytes(bytes) << " of memory, more than the memory limit of " << formatBytes(limit)
      << " (" << (set ? "set by --max-memory or setMemoryLimit" : defaults().source)
      << "; raise it with --max-memory SIZE, duplex.set_max_memory() in Python or duplex::setMemoryLimit())";
  throw ResourceError(msg.str());
}

std::string formatBytes(std::uint64_t bytes) {
  if (bytes == kUncountableBytes) return "more than 16 EiB";
  if (bytes < 1024) return std::to_string(bytes) + " B";
  static constexpr const char* kUnits[] = {"KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double value = static_cast<double>(bytes) / 1024.0;
  std::size_t unit = 0;
  while (value >= 1023.95 && unit + 1 < std::size(kUnits)) {
    value /= 1024.0;
    ++unit;
  }
  char text[32];
  std::snprintf(text, sizeof text,
                value < 9.995   ? "%.2f %s"
                : value < 99.95 ? "%.1f %s"
                                : "%.0f %s",
                value, kUnits[unit]);
  return text;
}

std::optional<std::uint64_t> parseByteSize(std::string_view text) {
  std::size_t i = 0;
  std::uint64_t whole = 0;
  bool digits = false;
  for (; i < text.size() && text[i] >= '0' && text[i] <= '9'; ++i, digits = true) {
    const auto d = static_cast<std::uint64_t>(text[i] - '0');
    if (whole > (kUncountableBytes - d) / 10) return std::nullopt;
    whole = whole * 10 + d;
  }
  // The fraction as fraction_num / fraction_den, at most 18 digits (finer than a byte of 2^60).
  std::uint64_t fraction_num = 0, fraction_den = 1;
  if (i < text.size() && text[i] == '.') {
    ++i;
    for (; i < text.size() && text[i] >= '0' && text[i] <= '9'; ++i, digits = true) {
      if (fraction_den < 1000000000000000000ull) {
        fraction_num = fraction_num * 10 + static_cast<std::uint64_t>(text[i] - '0');
        fraction_den *= 10;
      }
    }
  }
  if (!digits) return std::nullopt;
  std::string_view suffix = text.substr(i);
  unsigned shift = 0;
  if (!suffix.empty() && suffix != "B") {
    static constexpr std::string_view kPrefixes = "KMGTP";
    const std::size_t p = kPrefixes.find(static_cast<char>(suffix[0] == 'k' ? 'K' : suffix[0]));
    if (p == std::string_view::npos) return std::nullopt;
    shift = 10 * static_cast<unsigned>(p + 1);
    suffix.remove_prefix(1);
    if (!(suffix.empty() || suffix == "B" || suffix == "iB")) return std::nullopt;
  }
  if (shift == 0 && fraction_num != 0) return std::nullopt;  // a fraction of a byte
  if (whole > (kUncountableBytes >> shift)) return std::nullopt;
  const std::uint64_t unit = std::uint64_t{1} << shift;
  // The fraction's bytes (below one unit, so no overflow); long double keeps 64 bits of it.
  const auto part = static_cast<std::uint64_t>(static_cast<long double>(fraction_num) / fraction_den * unit);
  const std::uint64_t base = whole << shift;
  if (part > kUncountableBytes - base) return std::nullopt;
  return base + part;
}

}  // namespace duplex
