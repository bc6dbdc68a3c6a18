#pragma once
/// \file PySensors.h
/// duplex.run_sensors: a light-tracing run of a scene file's lights and sensors (SensorRun, as
/// `duplex sensor` runs it), its results as NumPy arrays.

#include <duplex/sensors/SensorRun.h>

#include <pybind11/pybind11.h>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace duplex::python {

namespace py = pybind11;

/// The options of run_sensors() beyond the rays, the seed, the threads and the progress callback:
/// SensorRunConfig's path limits and the stop rule of `duplex sensor --target-error`.
struct SensorRunOptions {
  /// Surface interactions after which a path is cut (kNoDepthLimit, the default: none)
  std::uint32_t max_depth = SensorRunConfig{}.max_depth;
  std::uint32_t max_scatterings = SensorRunConfig{}.max_scatterings;  ///< fog collisions after which a path is cut
  double roulette_threshold = SensorRunConfig{}.roulette_threshold;   ///< fraction of a ray's power, [0, 1)
  double target_error = 0.0;  ///< > 0: stop once the target sensor's relative error is at most this
  std::string target_sensor;  ///< the sensor of target_error (empty: the first)
  std::string structure;      ///< the scene's default structure choice ("bvh", "kdtree", ...)
  /// Apply the scene's timed edits with time <= at (seconds) before the run, as `duplex sensor
  /// --at`; unset: none.
  std::optional<double> at;
  /// A UserWarning when numerical failures, or the path limits, carry more than this fraction of
  /// the emitted power (`duplex sensor --failure-threshold`).
  double failure_threshold = 0.001;
  /// Each light's contribution beside the totals (SensorRunConfig::per_light).
  bool per_light = false;
};

/// Runs `rays` light paths of `scene_file` with `seed` on `threads` threads (0: all) and returns a
/// dict sensor name -> dict of arrays (see the module's docstring). `progress(done, total)` is
/// called on this thread between batches; an exception raised in it (or Ctrl-C) cancels the run
/// and is raised again.
py::dict runSensors(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                    const py::object& progress, const SensorRunOptions& options);

/// The same run, returning {"sensors": what runSensors returns, "meters": meter name -> dict, and
/// the run's entries}; a scene may have meters and no sensors (duplex.run_lighting).
py::dict runLighting(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                     const py::object& progress, const SensorRunOptions& options);

/// What both run: `lighting` selects runLighting's result.
py::dict runScene(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                  const py::object& progress, const SensorRunOptions& options, bool lighting);

}  // namespace duplex::python
