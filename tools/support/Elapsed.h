#pragma once
/// \file Elapsed.h
/// The wall time the tool's commands report (build, trace, save, pick times in their JSON).

#include <chrono>

namespace duplex::cli {

/// Milliseconds of wall time (steady clock) since `t0`.
inline double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace duplex::cli
