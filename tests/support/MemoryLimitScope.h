#pragma once
/// \file MemoryLimitScope.h
/// A memory limit (duplex::setMemoryLimit) for the length of a test: set on construction, the
/// default restored on destruction, so that a failing assertion leaves no small limit behind for
/// the next test of the same executable.

#include "duplex/accel/MemoryLimit.h"

#include <cstdint>

namespace duplex::test {

/// Sets the process's memory limit to `bytes` while it lives.
class MemoryLimitScope {
 public:
  /// Sets the limit to `bytes` (0: the default).
  explicit MemoryLimitScope(std::uint64_t bytes) { setMemoryLimit(bytes); }
  ~MemoryLimitScope() { setMemoryLimit(0); }
  MemoryLimitScope(const MemoryLimitScope&) = delete;
  MemoryLimitScope& operator=(const MemoryLimitScope&) = delete;
};

}  // namespace duplex::test
