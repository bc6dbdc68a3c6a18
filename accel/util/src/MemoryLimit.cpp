#include "duplex/accel/MemoryLimit.h"

#include "MemoryLimitDetail.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <sstream>

namespace duplex {

namespace {

struct DefaultLimit {
  std::uint64_t bytes = kUncountableBytes;
  const char* source = "the default: the machine's physical memory";
};

// The start of a small file (at most sizeof(buffer) - 1 bytes), read without a stream: the first
// check may run inside a reader that must not allocate more than its input justifies.
template <std::size_t N>
std::string_view readSmallFile(const std::string& file, char (&buffer)[N]) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return {};
  std::size_t size = 0;
  for (;;) {
    const ::ssize_t got = ::read(fd, buffer + size, N - 1 - size);
    if (got <= 0) break;
    size += static_cast<std::size_t>(got);
    if (size == N - 1) break;
  }
  ::close(fd);
  return {buffer, size};
}

// A number of bytes in a control group's file ("max" or a value past any machine reads as none).
std::optional<std::uint64_t> readLimitFile(const std::string& file) {
  char buffer[64];
  std::string_view text = readSmallFile(file, buffer);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.remove_suffix(1);
  if (text.empty() || text == "max") return std::nullopt;
  const std::optional<std::uint64_t> value = parseByteSize(text);
  if (!value || *value >= (std::uint64_t{1} << 62)) return std::nullopt;  // cgroup v1 writes ~2^63 for "none"
  return value;
}

}  // namespace

std::optional<std::uint64_t> detail::cgroupMemoryLimit(std::string_view lines, const std::string& cgroup_root) {
  std::optional<std::uint64_t> smallest;
  // A parent's limit holds for its children too: the group's file and those above it.
  const auto consider = [&](const std::string& root, std::string_view group, const char* name) {
    // group: "/a/b" or "/"; the files root/a/b/name, root/a/name, root/name.
    std::string dir = root;
    if (group.size() > 1) dir.append(group);
    for (;;) {
      if (const auto v = readLimitFile(dir + "/" + name)) smallest = smallest ? std::min(*smallest, *v) : *v;
      if (dir.size() <= root.size()) break;
      dir.resize(dir.rfind('/'));
    }
  };
  while (!lines.empty()) {
    const std::size_t end = std::min(lines.find('\n'), lines.size());
    const std::string_view line = lines.substr(0, end);
    lines.remove_prefix(std::min(end + 1, lines.size()));
    // "<id>:<controllers>:<path>": v2 is "0::<path>"; v1 lists "memory" among the controllers.
    const std::size_t a = line.find(':'), b = a == std::string_view::npos ? a : line.find(':', a + 1);
    if (b == std::string_view::npos) continue;
    const std::string_view id = line.substr(0, a), controllers = line.substr(a + 1, b - a - 1),
                           group = line.substr(b + 1);
    if (group.empty() || group.front() != '/') continue;
    if (id == "0" && controllers.empty()) {
      consider(cgroup_root, group, "memory.max");
    } else {
      for (std::string_view rest = controllers; !rest.empty();) {
        const std::size_t comma = std::min(rest.find(','), rest.size());
        if (rest.substr(0, comma) == "memory") consider(cgroup_root + "/memory", group, "memory.limit_in_bytes");
        rest.remove_prefix(std::min(comma + 1, rest.size()));
      }
    }
  }
  return smallest;
}

namespace {

const DefaultLimit& defaults() {
  static const DefaultLimit limit = [] {
    DefaultLimit d;
    const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0)
      d.bytes = arrayBytes(static_cast<std::uint64_t>(pages), static_cast<std::uint64_t>(page));
    char cgroup[8192];
    if (const auto group = detail::cgroupMemoryLimit(readSmallFile("/proc/self/cgroup", cgroup), "/sys/fs/cgroup");
        group && *group < d.bytes) {
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
