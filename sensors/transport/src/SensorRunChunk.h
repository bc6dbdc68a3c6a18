#pragma once
// Private to sensors/transport/src: what a chunk of a sensor run's rays records while it is traced
// (SensorPaths.cpp) and hands to the ordered reduction (SensorRun.cpp).

#include "duplex/sensors/SensorRun.h"

#include <cstdint>
#include <vector>

namespace duplex {

namespace detail {

// A deposit: global bin, the sensor it belongs to (kInvalidId for an angular bin, which repeats
// a spatial bin's power), and the power.
struct BinEvent {
  std::uint32_t bin;
  std::uint32_t sensor;
  double value;
};
struct SensorEvent {
  std::uint32_t sensor;
  double value;
};

}  // namespace detail

struct SensorRun::Chunk {
  std::uint64_t first = 0, count = 0;
  bool done = false;
  // Per ray (path order): its merged bin and sensor deposits, delimited by offsets; its energy.
  std::vector<detail::BinEvent> bins;
  std::vector<std::uint32_t> bin_end;  // per ray: end offset in bins
  std::vector<detail::SensorEvent> sensors;
  std::vector<std::uint32_t> sensor_end;
  std::vector<EnergyBalance> energy;  // per ray (emitted_w unused)
  std::vector<std::uint16_t> band;    // per ray, when the scene has several bands
  SensorRunCounters counters;
};

}  // namespace duplex
