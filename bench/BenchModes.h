#pragma once
/// \file BenchModes.h
/// The three things duplex_bench_mesh can do; each returns the JSON document it measured.

#include "BenchCommon.h"

#include <nlohmann/json.hpp>

namespace duplex::bench {

/// Per mesh: build time, tree figures, bytes per triangle, Mrays/s for random and primary rays,
/// closest and any hit, per thread count; the same for Embree medium and high; ratios; hit agreement.
[[nodiscard]] nlohmann::json runMainBench(const Options& options);

/// Build time against trace time over heuristics and cost settings (1 thread), Embree as reference.
[[nodiscard]] nlohmann::json runSweep(const Options& options);

/// Closest-point queries per mesh, ours against Embree's rtcPointQuery (ClosestBench.cpp).
[[nodiscard]] nlohmann::json runClosestBench(const Options& options);

/// A fixed small workload whose trace loops alone are instrumented under callgrind.
[[nodiscard]] nlohmann::json runCallgrind(const Options& options);

}  // namespace duplex::bench
