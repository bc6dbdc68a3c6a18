#pragma once
/// \file QueryContext.h
/// Per-thread mutable state for queries. Acceleration structures and objects are immutable after
/// build; anything a query must mutate (counters, caches such as OpenVDB accessors, scratch
/// buffers) lives here, one context per thread.

#include <cstdint>

namespace duplex {

/// Counters a test or benchmark can read. Plain integers: a context belongs to one thread.
struct QueryStats {
  std::uint64_t rays = 0;
  std::uint64_t instance_visits = 0;  ///< top-level leaf tests that reached an object
};

/// One per thread; cheap to create. Not thread-safe by design.
class QueryContext {
 public:
  QueryStats stats;
};

}  // namespace duplex
