#pragma once
/// \file SensorCommand.h
/// `duplex sensor --scene S.json --rays N [--threads T] [--seed X] [--out DIR]`:
/// a light-tracing run over the scene's lights and sensors (SensorRun). Writes for each sensor
/// DIR/<name>.json (keys: name, rays, seed, shape, size, bins, two_sided, emitted_power_w,
/// total_flux_w, total_flux_stderr_w, relative_stderr, efficiency, and row-major nx * ny arrays
/// irradiance_w_m2, stderr_w_m2, flux_w, ray_count, bin_area_m2; band_* and angular_* arrays
/// when the scene asks for them), DIR/<name>.csv (one row per bin) and
/// DIR/<name>.png (false-colour irradiance with a scale bar); a far-field sensor DIR/<name>.json
/// (c_deg, gamma_deg, intensity_w_sr, intensity_stderr_w_sr, ...), DIR/<name>.csv and
/// DIR/<name>.ies (LM-63-2002, values in W/sr); plus DIR/run_state.bin (the exact
/// accumulators, for --resume) and DIR/run.json (the report printed on stdout). Characters of a
/// sensor name other than [A-Za-z0-9._-] become '_' in file names; sensors whose file names would
/// collide (with each other, or "run" with run.json) are refused before the run. The result files
/// appear together or not at all (SensorOutputSet): a failure while writing them (a full disk)
/// leaves DIR's earlier files as they were and the run saved in run_state.bin. A DIR holding an
/// earlier run's results is refused unless --resume or --overwrite (checkOutputFolder).
/// SIGINT / SIGTERM stop the run after the chunks in flight: the rays traced so far are saved to
/// run_state.bin and written out as usual, the report's status is "interrupted", and the process
/// exits with 128 + the signal (a second signal kills it at once).

#include "Command.h"

#include "duplex/sensors/SensorRun.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

namespace duplex::cli {

struct SensorOptions {
  std::filesystem::path scene;
  /// --structure: the structure choice of the entries that choose none (SceneDocumentOptions::structure);
  /// empty: each type's default.
  std::string structure;
  std::uint64_t rays = 0;  ///< total emitted rays of the run (with --resume: including the saved ones)
  int threads = 0;         ///< 0: all hardware threads
  std::uint64_t seed = 1;
  std::filesystem::path out = ".";
  bool resume = false;  ///< continue from DIR/run_state.bin (same scene and seed) up to `rays`
  /// replace an earlier run's results in DIR; without it (or `resume`) a folder holding run.json,
  /// run_state.bin or a file of one of the sensors' names is refused before the run
  bool overwrite = false;
  double target_error = 0.0;  ///< > 0: stop once the target sensor's relative standard error is at most this
  std::string target_sensor;  ///< the sensor of target_error (default: the first)
  // Path limits: SensorRunConfig's fields and defaults (surface interactions; fog collisions; the
  // Russian-roulette threshold, a fraction of a ray's emitted power in [0, 1)).
  std::uint32_t max_depth = SensorRunConfig{}.max_depth;  ///< kNoDepthLimit ("none"): no cap
  std::uint32_t roulette_depth = SensorRunConfig{}.roulette_depth;
  std::uint32_t max_scatterings = SensorRunConfig{}.max_scatterings;
  double roulette = SensorRunConfig{}.roulette_threshold;
  /// "auto": a progress bar when stderr is a terminal, plain lines otherwise; "bar", "lines", "none".
  std::string progress = "auto";
  /// Seconds between saves of DIR/run_state.bin while the run goes on (0: only at the end), so that
  /// a run killed outright (SIGKILL, power loss) loses about this much work (saves happen between
  /// batches of --batch-rays rays, so at most this plus one batch): --resume continues from the last save
  /// and gives the files of one uninterrupted run.
  double checkpoint_s = 60.0;
  /// --at T: apply the scene's timed edits with time <= T before the run (applyEditsUntil); unset:
  /// none (stderr then says how many the scene has).
  std::optional<double> at;
  /// --text-map-limit N: a flat or spherical sensor of more than N bins keeps its per-bin maps out
  /// of the JSON and writes no CSV: they go to NumPy files DIR/<name>.<map>.npy (and the PNG/EXR
  /// images as always), named in the JSON's "map_files". Text for 10^7 bins takes minutes and
  /// gigabytes; the binary files are written at disk speed.
  std::uint64_t text_map_limit = std::uint64_t{1} << 20;
  /// Rays per batch (SensorRunConfig::batch_rays): the unit of the ordered sums (results depend on
  /// it), of the work dealt to MPI ranks, of checkpoints and of --target-error checks.
  std::uint64_t batch_rays = SensorRunConfig{}.batch_rays;
  /// --failure-threshold F: a run whose numerical failures (EnergyBalance::failed_w) carry more than
  /// this fraction of the emitted power says so on stderr (the results are written all the same).
  double failure_threshold = 0.001;
  /// --per-light: each light's contribution beside the totals (SensorRunConfig::per_light): run.json
  /// "lights", each sensor file's "lights"; refused under mpirun.
  bool per_light = false;
};

/// Thrown when SIGINT or SIGTERM stopped the command before the run started (while the scene
/// loaded): nothing was written; the tool exits with 128 + the signal.
class Interrupted : public std::runtime_error {
 public:
  /// `signal`: the signal's number; `what`: what was stopped.
  Interrupted(int signal, const std::string& what) : std::runtime_error(what), signal_(signal) {}
  /// The signal's number.
  [[nodiscard]] int signal() const { return signal_; }

 private:
  int signal_;
};

/// Runs the command; returns the report (keys: rays, seed, threads, ranks (processes sharing the
/// run: 1, or the MPI ranks), max_depth, max_scatterings, roulette_threshold, batch_rays, status
/// ("completed", "target_reached", "interrupted" with the signal's number in `signal`),
/// resumed_from (rays already done when the run started: 0, or the saved count with --resume),
/// seconds, rays_per_s, emitted_power_w, energy {escaped_w, escaped_rays, absorbed_w, absorbed_rays,
/// medium_absorbed_w, medium_absorbed_rays, depth_limited_w, depth_limited_rays, roulette_w,
/// roulette_rays, failed_w, failed_rays}, failure_threshold, bands and band_emitted_w (spectral scenes only),
/// scatterings (scenes whose fog scatters only), sensors [{name, file, total_flux_w, relative_stderr, efficiency}
/// and in photometric runs total_flux_lm], in photometric runs emitted_luminous_flux_lm and emitted_flux_lm (the
/// same value), in runs whose lights are all in lumens without wavelengths the "_w" keys null and the energy's
/// "_lm" keys beside them, with --per-light lights [{name, emitted_power_w, emitted_flux_lm}],
/// with --at also at and edits_applied, and for a run under mpirun mpi {ranks, batches, rank0_batches,
/// tally_bytes_received, tally_bytes_max, rank0_trace_seconds, rank0_comm_seconds, rank0_reduce_seconds,
/// max_trace_seconds}). Under mpirun every rank runs it; rank 0 reads and writes the files and
/// returns the report, the others return null. Throws duplex::Error for bad input.
[[nodiscard]] nlohmann::ordered_json runSensor(const SensorOptions& options);

/// Adds `duplex sensor` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addSensorCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
