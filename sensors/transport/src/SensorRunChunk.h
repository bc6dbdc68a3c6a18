#pragma once
// Private to sensors/transport/src: what a chunk of a sensor run's rays records while it is traced
// (SensorPaths.cpp) and hands to the ordered reduction (SensorRun.cpp).

#include "duplex/sensors/SensorRun.h"

#include <glm/vec3.hpp>

#include <algorithm>
#include <array>
#include <cmath>
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
  std::vector<std::uint32_t> light;   // per ray: the light that emitted it (runs with per-light results)
  SensorRunCounters counters;
};

// Sums over a set of rays (a batch, or the finished batches of a run).
struct SensorRun::Tally {
  std::vector<BinSums> bins;        // spatial bins, then angular bins
  std::vector<SensorSums> sensors;  // per sensor
  // Spectral scenes only: the same per (bin, band) and (sensor, band), index * bands + band.
  std::vector<double> band_bin_sum, band_bin_sum2, band_sensor_sum, band_sensor_sum2;
  // Runs with per-light results only: the same per (bin, light) and (sensor, light).
  std::vector<double> light_bin_sum, light_bin_sum2, light_sensor_sum, light_sensor_sum2;
  EnergyBalance energy;  // sums over rays (emitted_w unused)
  SensorRunCounters counters;
  // A batch's tallies: the bins whose count is not zero, in order of first deposit (so that adding
  // a batch, emptying it and sending it cost what it reached, not the scene's bins).
  std::vector<std::uint32_t> touched;
  std::uint64_t rays = 0;
};

namespace detail {

// Whether a scattered direction `next` leaves a surface whose unit normal `n_in` faces the incoming
// ray: to the front (reflection) or, when `transmits`, to the back; false for a tangent or
// non-finite direction. A path whose next direction fails this is a numerical failure.
bool leavesSurface(const glm::dvec3& next, const glm::dvec3& n_in, bool transmits);

// Where a path restarts from a hit on triangle `tri` (object-space vertices) of mesh instance `si`
// at barycentrics (u, v), and how far along the hit's world-space unit normal it must leave: the
// point is rebuilt from the vertices in double (so it lies on the triangle's plane to rounding,
// however far the ray travelled: a float t would be off by ulps of t), and the offset bounds the
// rounding error of the next ray across that plane: its origin rounded to float in world space,
// mapped to object space and rounded again (transformed instances), and the triangle test's own
// arithmetic on the vertices relative to that origin. The bound follows the vertices' magnitudes
// and the transform, never the size of the object or the scene.
struct RestartPoint {
  glm::dvec3 p_ws{0.0};  // world space, scene units
  double offset = 0.0;   // world-space distance along the normal, scene units
};
[[nodiscard]] RestartPoint restartFromTriangle(const std::array<glm::vec3, 3>& tri, float u, float v,
                                               const SurfaceInstance& si, const glm::dvec3& n_ws);

// Adds the energy tallies of `from` (sums over rays; emitted_w unused) into `to`.
inline void addEnergy(EnergyBalance& to, const EnergyBalance& from) {
  for (const EnergyEnding& k : kEnergyEndings) {
    to.*k.power += from.*k.power;
    to.*k.rays += from.*k.rays;
  }
}

// The energy tallies as run states and batch tallies store them: six powers, then six ray counts.
struct EnergyWords {
  double power[6];
  std::uint64_t rays[6];
};
inline EnergyWords energyWords(const EnergyBalance& e) {
  EnergyWords w{};
  for (std::size_t k = 0; k < kEnergyEndings.size(); ++k) {
    w.power[k] = e.*kEnergyEndings[k].power;
    w.rays[k] = e.*kEnergyEndings[k].rays;
  }
  return w;
}
// Back from the stored words; false for values no run makes (negative or non-finite powers but the
// roulette's net term, which may be negative; ray counts summing to more than `rays`).
inline bool energyFromWords(const EnergyWords& w, std::uint64_t rays, EnergyBalance& e) {
  bool ok = std::isfinite(w.power[4]);
  std::uint64_t paths = 0;
  for (int k = 0; k < 6; ++k) {
    if (k != 4) ok = ok && std::isfinite(w.power[k]) && w.power[k] >= 0.0;
    ok = ok && w.rays[k] <= rays;
    paths += w.rays[k];
  }
  if (!ok || paths > rays) return false;
  e = {};
  for (std::size_t k = 0; k < kEnergyEndings.size(); ++k) {
    e.*kEnergyEndings[k].power = w.power[k];
    e.*kEnergyEndings[k].rays = w.rays[k];
  }
  return true;
}

// Adds the per-(bin, channel) sums of the touched bins and all per-(sensor, channel) sums of one
// kind of channel (bands or lights; index * channels + channel; empty vectors: none).
inline void addChannels(std::vector<double>& bin_sum, std::vector<double>& bin_sum2, std::vector<double>& sensor_sum,
                        std::vector<double>& sensor_sum2, const std::vector<double>& from_bin_sum,
                        const std::vector<double>& from_bin_sum2, const std::vector<double>& from_sensor_sum,
                        const std::vector<double>& from_sensor_sum2, const std::vector<std::uint32_t>& touched,
                        std::size_t channels) {
  for (std::size_t k = 0; !from_bin_sum.empty() && k < touched.size(); ++k)
    for (std::size_t c = 0; c < channels; ++c) {
      const std::size_t j = std::size_t{touched[k]} * channels + c;
      bin_sum[j] += from_bin_sum[j];
      bin_sum2[j] += from_bin_sum2[j];
    }
  for (std::size_t j = 0; j < from_sensor_sum.size(); ++j) {
    sensor_sum[j] += from_sensor_sum[j];
    sensor_sum2[j] += from_sensor_sum2[j];
  }
}

// Adds batch tallies `from` (its bins listed in from.touched: the others are zero, and adding a
// zero changes no sum) into `to`; `bands` and `lights` are the channels of its per-band and
// per-light sums.
template <class Tally>
void addTally(Tally& to, const Tally& from, std::size_t bands, std::size_t lights) {
  for (const std::uint32_t i : from.touched) {
    auto& t = to.bins[i];
    const auto& f = from.bins[i];
    t.sum += f.sum;
    t.sum2 += f.sum2;
    t.count += f.count;
  }
  for (std::size_t i = 0; i < from.sensors.size(); ++i) {
    to.sensors[i].sum += from.sensors[i].sum;
    to.sensors[i].sum2 += from.sensors[i].sum2;
  }
  addChannels(to.band_bin_sum, to.band_bin_sum2, to.band_sensor_sum, to.band_sensor_sum2, from.band_bin_sum,
              from.band_bin_sum2, from.band_sensor_sum, from.band_sensor_sum2, from.touched, bands);
  addChannels(to.light_bin_sum, to.light_bin_sum2, to.light_sensor_sum, to.light_sensor_sum2, from.light_bin_sum,
              from.light_bin_sum2, from.light_sensor_sum, from.light_sensor_sum2, from.touched, lights);
  addEnergy(to.energy, from.energy);
  to.counters.segments += from.counters.segments;
  to.counters.crossings += from.counters.crossings;
  to.counters.scatterings += from.counters.scatterings;
  to.rays += from.rays;
}

// Empties batch tallies (their bins listed in touched).
template <class Tally>
void clearTally(Tally& t, std::size_t bands, std::size_t lights) {
  for (const std::uint32_t i : t.touched) {
    t.bins[i] = {};
    if (!t.band_bin_sum.empty())
      for (std::size_t k = 0; k < bands; ++k)
        t.band_bin_sum[std::size_t{i} * bands + k] = t.band_bin_sum2[std::size_t{i} * bands + k] = 0.0;
    if (!t.light_bin_sum.empty())
      for (std::size_t k = 0; k < lights; ++k)
        t.light_bin_sum[std::size_t{i} * lights + k] = t.light_bin_sum2[std::size_t{i} * lights + k] = 0.0;
  }
  std::fill(t.sensors.begin(), t.sensors.end(), typename decltype(t.sensors)::value_type{});
  for (std::vector<double>* v : {&t.band_sensor_sum, &t.band_sensor_sum2, &t.light_sensor_sum, &t.light_sensor_sum2})
    std::fill(v->begin(), v->end(), 0.0);
  t.touched.clear();
  t.energy = {};
  t.counters = {};
  t.rays = 0;
}

}  // namespace detail

}  // namespace duplex
