#pragma once
/// \file MemoryLimit.h
/// The process's memory limit: allocations whose size comes from input (sensor bins and their
/// accumulators, the instances and the JSON of a scene file, the arrays of a mesh file, ray and
/// point files read whole) are checked against it before they are made, so that too large an input
/// is refused with a ResourceError naming it, never left to std::bad_alloc (or the kernel's
/// out-of-memory killer) part-way through a load or a run.
///
/// The limit applies to each such request on its own (the memory one load or one run needs), not
/// to a running total of what the process holds. Default: the smaller of the machine's physical
/// memory and the memory limit of the process's control group (cgroup v2 `memory.max` of its group
/// and the groups above it, or cgroup v1 `memory.limit_in_bytes`), read once. The tool's commands
/// set it with `--max-memory SIZE`, Python with `duplex.set_max_memory(bytes)`.

#include "duplex/accel/Error.h"

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

namespace duplex {

/// An input that needs more memory than the limit (memoryLimit()); the message names the input,
/// the bytes it needs, the limit and how to raise it.
class ResourceError : public Error {
 public:
  using Error::Error;
};

/// Byte counts that cannot be represented: a request of this size is always refused.
inline constexpr std::uint64_t kUncountableBytes = std::numeric_limits<std::uint64_t>::max();

/// a + b, or kUncountableBytes when the sum does not fit (never wraps).
[[nodiscard]] constexpr std::uint64_t saturatingAdd(std::uint64_t a, std::uint64_t b) {
  return a > kUncountableBytes - b ? kUncountableBytes : a + b;
}

/// count * element_bytes (the bytes of an array), or kUncountableBytes when the product does not
/// fit (never wraps).
[[nodiscard]] constexpr std::uint64_t arrayBytes(std::uint64_t count, std::uint64_t element_bytes) {
  if (count == 0 || element_bytes == 0) return 0;
  return count > kUncountableBytes / element_bytes ? kUncountableBytes : count * element_bytes;
}

/// The default limit in bytes: min(physical memory, the control group's limit), computed on the
/// first call.
[[nodiscard]] std::uint64_t defaultMemoryLimit();

/// The limit in bytes requireMemory() checks against: the one set by setMemoryLimit(), else
/// defaultMemoryLimit(). Thread-safe.
[[nodiscard]] std::uint64_t memoryLimit();

/// Sets the limit to `bytes` for the whole process; 0 restores the default. Thread-safe; checks
/// already past their test are not affected.
void setMemoryLimit(std::uint64_t bytes);

/// Throws ResourceError when `bytes` is above memoryLimit(): "<what> needs <bytes> of memory, more
/// than the memory limit of <limit> (<where the limit comes from>; raise it with --max-memory ...)".
/// `what` names the input and the structure, e.g. "sensor 'screen': 4096 x 4096 bins".
void requireMemory(std::uint64_t bytes, std::string_view what);

/// `bytes` for a message, in binary units with three significant digits: "512 B", "3.21 GiB",
/// "16.0 EiB"; kUncountableBytes reads "more than 16 EiB".
[[nodiscard]] std::string formatBytes(std::uint64_t bytes);

/// A size as people write it: plain bytes ("1000000"), or a number (a decimal fraction allowed)
/// followed by K, M, G, T or P, each a power of 1024, optionally followed by "iB" or "B" ("4G",
/// "512M", "1.5GiB", "64KB"); a trailing "B" alone means bytes. Fractions of a byte are dropped.
/// Empty for anything else (signs, exponents, spaces, a size that does not fit 64 bits).
[[nodiscard]] std::optional<std::uint64_t> parseByteSize(std::string_view text);

}  // namespace duplex
