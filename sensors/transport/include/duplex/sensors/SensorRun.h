#pragma once
/// \file SensorRun.h
/// A light-tracing run that accumulates the power crossing the sensors of a SensorScene.
///
/// Rays start at the lights (chosen in proportion to their power), are traced with the top level's
/// crossing query (closest blocking hit + every sensor crossing before it, media transmittance),
/// and scatter at surfaces by their material with Russian roulette (and a depth limit on request);
/// smooth dielectrics carry each path's polarisation (s and p, a Stokes vector) from interface to
/// interface, lights emit unpolarised light, diffuse surfaces and fogs depolarise. In a scene
/// whose fogs scatter (SensorScene::scatters), free flights are sampled through the fogs and rays
/// scatter inside them by the Henyey-Greenstein phase function, or are absorbed by the albedo.
///
/// Determinism: ray i draws its random numbers from a CounterRng keyed by (seed, i); rays are
/// grouped in batches of batch_rays, batch k holding rays [k * batch_rays, (k + 1) * batch_rays).
/// A batch is split into chunks of consecutive rays traced in parallel (TBB, lock-free: each chunk
/// writes its own event list); the chunks' per-ray deposits are added strictly in ray order into the
/// batch's own tallies (starting from zero), and a finished batch's tallies are added to the run's
/// in batch order. The results are therefore bit-identical for any thread count and chunk size, for
/// any number of processes sharing the batches (traceBatch() / addBatch(): a batch's tallies do not
/// depend on where it was traced), and a run extended to N rays in several calls (or resumed from a
/// saved state) equals one run of N rays. They depend on the seed and batch_rays.
///
/// Threading: runUntil() runs on the caller's thread (using `threads` workers); cancel() may be
/// called from any thread, including the progress callback.

#include "duplex/accel/Crossing.h"
#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/SensorResults.h"
#include "duplex/sensors/SensorScene.h"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace duplex {

/// SensorRunConfig::max_depth: no cap on a path's surface interactions (the default).
inline constexpr std::uint32_t kNoDepthLimit = 0xFFFFFFFFu;
/// Beyond SensorRunConfig::roulette_depth surface interactions, the probability that a path goes
/// on at each further one (its power then divided by it).
inline constexpr double kDeepSurvival = 0.95;

/// Parameters of a sensor run (validated by SensorRun's constructor).
struct SensorRunConfig {
  std::uint64_t seed = 1;  ///< seed of every ray's random stream (CounterRng)
  unsigned threads = 0;    ///< worker threads; 0 = all hardware threads
  /// Surface interactions after which a path is cut, its power counted in depth_limited_w (a bias:
  /// what it would still have deposited is lost). kNoDepthLimit (the default): no cap, a path ends
  /// only by absorption, escape or Russian roulette, and the results are unbiased.
  std::uint32_t max_depth = kNoDepthLimit;
  /// Surface interactions after which each further one lets the path go on with probability
  /// kDeepSurvival, its power divided by it (Russian roulette: unbiased). Materials that absorb
  /// end paths by their albedo already; this ends those that lose nothing (glass trapping light by
  /// total internal reflection, ideal mirrors facing each other) in finite time.
  std::uint32_t roulette_depth = 32;
  /// Scattering fogs: collisions after which a path is cut (depth_limited_w); 1 keeps single
  /// scattering only.
  std::uint32_t max_scatterings = 100000;
  /// Russian roulette: a path whose power falls below this fraction of an emitted ray's power (by
  /// media or materials) survives with probability power / threshold and is then raised to it.
  double roulette_threshold = 0.05;
  std::uint32_t chunk_rays = 1024;  ///< rays per parallel work item (results do not depend on it)
  /// Rays per batch: the unit of the ordered reduction (a batch's tallies are summed on their own,
  /// then added to the run's), of work shared between processes, of progress reports and of
  /// stop-rule checks. The results and the stop point depend on it (not on the thread count or the
  /// number of processes).
  std::uint64_t batch_rays = 1u << 16;
  CrossingQuery query;  ///< which instances block, record, attenuate
  /// Benchmark baseline: trace the same paths with the plain closest-hit query, record nothing.
  /// Paths are identical when the scene has no media (sensors never change a path).
  bool closest_hit_only = false;
  /// Upper bound on the accumulators' memory (sums, squares and counts of every spatial and
  /// angular bin, and per band in spectral scenes; twice, for the run's tallies and the open
  /// batch's): a run above it is refused at construction rather than failing to allocate (or being
  /// killed) part-way.
  std::uint64_t max_accumulator_bytes = std::uint64_t{4} << 30;
  /// Results per light beside the totals (SensorResult::light_flux_w, ...): each ray's deposits are
  /// also tallied under the light that emitted it, which costs two sums per bin, sensor and light.
  /// The per-light results of one run add up to its totals. Batch tallies carry them (traceBatch /
  /// addBatch), so runs shared between processes keep them too.
  bool per_light = false;
};

/// Passed to runUntil()'s progress callback after each batch.
struct SensorProgress {
  std::uint64_t rays_done = 0;       ///< emitted rays finished (the whole run, resumed rays included)
  std::uint64_t rays_target = 0;     ///< the total asked of runUntil
  double seconds = 0.0;              ///< wall time of this runUntil call so far
  std::uint64_t rays_this_call = 0;  ///< emitted rays finished by this runUntil call
};

/// Stop when sensor `sensor`'s total-flux relative standard error is at most `target` (checked
/// after each batch, once at least `min_rays` rays were traced). sensor < 0: no rule.
struct SensorStopRule {
  int sensor = -1;                 ///< index into SensorScene::sensors(); < 0: no rule
  double target = 0.0;             ///< relative standard error to reach
  std::uint64_t min_rays = 10000;  ///< rays traced before the rule is checked
};

/// Why runUntil() returned.
enum class SensorRunStatus : std::uint8_t {
  Completed,      ///< the total number of rays is traced
  TargetReached,  ///< the stop rule holds
  Cancelled       ///< cancel() was called
};

/// Counters of the traced segments (for benchmarks).
struct SensorRunCounters {
  std::uint64_t segments = 0;     ///< crossing (or closest-hit) queries
  std::uint64_t crossings = 0;    ///< sensor crossings recorded
  std::uint64_t scatterings = 0;  ///< collisions in scattering fogs
};

/// The tallies of one batch of a run (sums over its rays only, started from zero), made by
/// SensorRun::traceBatch in one process and added by SensorRun::addBatch in another (or the same):
/// the unit of work of runs shared between processes (see SensorRunMpi.h for MPI).
struct SensorBatchTally {
  std::uint64_t batch = 0;      ///< the batch's index: its rays start at batch * batch_rays
  std::uint64_t first_ray = 0;  ///< batch * batch_rays
  /// Rays traced: the batch's size (batch_rays, or fewer for the last batch of a run), or fewer when
  /// the tracing was cancelled (complete is then false).
  std::uint64_t rays = 0;
  bool complete = false;  ///< every ray asked of traceBatch was traced
  /// The sums serialised (the run's fingerprint, first_ray, rays, then the bins the batch reached
  /// and their sums, squares and counts, the sensors' sums, the energy tallies and the counters) in
  /// this machine's byte order: what a process sends to the one that accumulates. Its size grows
  /// with the bins the batch reached, not with the scene's bins.
  std::vector<std::byte> bytes;
};

/// A light-tracing run over a SensorScene (see the file comment for the transport, determinism and threading).
class SensorRun {
 public:
  /// The scene must outlive the run. The run takes the scene as of its graph's last commit (the
  /// sensors, lights and materials SensorScene derives from it); once the graph is committed again
  /// the run refuses to go on (runUntil, results, relativeStderr, saveState and loadState throw
  /// InvalidArgument): make a new run. Throws InvalidArgument for a bad config (chunk_rays or
  /// batch_rays 0, roulette_threshold outside [0, 1)), and as the scene's
  /// accessors for a committed graph that makes no valid scene.
  SensorRun(const SensorScene& scene, const SensorRunConfig& config = {});
  ~SensorRun();
  SensorRun(const SensorRun&) = delete;
  SensorRun& operator=(const SensorRun&) = delete;

  /// Traces rays until raysDone() == total_rays (extend: call again with a larger total), the
  /// stop rule holds, or cancel() is called (the rays traced so far are kept; a cancelled run can
  /// be continued). `progress` is called on this thread after each batch. Throws InvalidArgument
  /// when the scene has no light; resets a pending cancel() at its start.
  SensorRunStatus runUntil(std::uint64_t total_rays, const std::function<void(const SensorProgress&)>& progress = {},
                           const SensorStopRule& stop = {});
  /// Asks a running runUntil (or traceBatch) to stop after the chunks in flight. Thread-safe.
  void cancel() { cancel_.store(true, std::memory_order_relaxed); }
  /// Whether cancel() was called since the last runUntil / traceBatch started (a signal handler's
  /// cancel between two batches of a shared run is seen by the next one's caller).
  [[nodiscard]] bool cancelled() const { return cancel_.load(std::memory_order_relaxed); }

  /// Runs shared between processes, the worker's half: traces batch `batch` (its rays up to
  /// total_rays) with this run's threads into tallies of its own and returns them serialised; this
  /// run's accumulators and raysDone() are unchanged. A cancel() during the call stops it after the
  /// chunks in flight (the tally is then incomplete: traced rays are a prefix of the batch). Throws
  /// InvalidArgument when the batch starts at or after total_rays or the scene has no light.
  [[nodiscard]] SensorBatchTally traceBatch(std::uint64_t batch, std::uint64_t total_rays);
  /// Runs shared between processes, the accumulating half: adds a batch's tallies (from traceBatch
  /// of a run over the same scene and configuration, in any process of this build) to this run's,
  /// exactly as runUntil would have. Batches must come in order: the tally must start at raysDone(),
  /// which must be the start of a batch. Throws InvalidArgument for a tally of another scene,
  /// seed or batch size (fingerprint), out of order, or damaged (sizes, indices); the run is then
  /// unchanged. traceBatch and addBatch share no state: one thread may trace a batch while another
  /// adds batches (and reads results or saves the state), never two traces or two additions at once.
  void addBatch(std::span<const std::byte> tally);
  /// Hash of what the accumulators' meaning depends on (the sensors, bins, lights, instances,
  /// materials, contents of meshes and grids, seed, path limits and batch size): equal in two
  /// processes whose runs may share batches or run states. Computed once.
  [[nodiscard]] std::uint64_t fingerprint() const;

  /// Emitted rays finished (resumed rays included).
  [[nodiscard]] std::uint64_t raysDone() const { return rays_done_; }
  /// The configuration, as validated.
  [[nodiscard]] const SensorRunConfig& config() const { return config_; }
  /// Fluxes, irradiances (per square scene unit) and standard errors over the rays done so far.
  [[nodiscard]] SensorRunResults results() const;
  /// Relative standard error of sensor `sensor`'s total flux now (infinity before any power arrived).
  /// Throws InvalidArgument for a sensor index outside [0, sensor count).
  [[nodiscard]] double relativeStderr(int sensor) const;
  /// Counters of the segments traced so far.
  [[nodiscard]] SensorRunCounters counters() const;

  /// Saves the accumulators (exact binary doubles, then a checksum) so that a later process can
  /// resume; written to "<file>.tmp" and renamed over `file`, so a process killed while saving
  /// leaves the previous state intact. Throws FileError naming the file.
  void saveState(const std::filesystem::path& file) const;
  /// Loads a saved state into this run (whose scene and seed must match the saved ones: checked by
  /// a fingerprint of the sensors, bins, lights, instances, materials and the contents of meshes
  /// and volume grids). Throws FileError naming the file for another scene or configuration, a
  /// size that disagrees with the scene (truncated, extended), a checksum mismatch (damaged), a
  /// state of an older format (without checksum, or without mesh or volume contents in its
  /// fingerprint), or negative / non-finite sums; the run is then unchanged.
  void loadState(const std::filesystem::path& file);

 private:
  struct Chunk;
  struct Tally;
  struct Workers;
  void traceChunk(Chunk& chunk) const;
  void reduce(const Chunk& chunk, Tally& into) const;
  // Traces rays [first, end) (within one batch) in chunks on the run's workers and reduces the
  // finished prefix into `into` in ray order; returns the rays reduced (fewer after a cancel).
  std::uint64_t traceRange(std::uint64_t first, std::uint64_t end, Tally& into);
  // Adds the open batch's tallies to the run's (the batch is full) and empties them.
  void closeBatch();
  // Photometric scenes: sensor `sensor`'s (s's) luminous and colorimetric quantities, from `all`
  // (the run's tallies) and the radiometric ones already in `out`.
  void photometricResults(const Tally& all, const SensorInstance& s, std::size_t sensor, SensorResult& out) const;
  // Runs with per-light results: sensor `sensor`'s (s's) per-light arrays from `all`, with their
  // luminous values when `luminous` (one luminous weight for every ray); bin areas already in `out`.
  void perLightResults(const Tally& all, const SensorInstance& s, std::size_t sensor, bool luminous,
                       SensorResult& out) const;
  // Photometric scenes: the sum of bin `bin`'s luminous samples (over all rays), and in `sum2` the
  // sum of their squares.
  double luminousSamples(const Tally& all, std::size_t bin, double& sum2) const;
  // The meters' results into r.meters (per-light arrays when the tallies keep them; their luminous
  // values when `light_lm`).
  void meterResults(const Tally& all, bool light_lm, SensorRunResults& r) const;
  [[nodiscard]] std::unique_ptr<Tally> makeTally() const;
  /// The first collision in the scene's scattering fogs along world-space origin + t dir, t in
  /// [0, t_max] (t_max infinite: the whole ray): the medium, with t_collision, or nullptr.
  const MediumInstance* sampleCollision(const glm::dvec3& origin, const glm::dvec3& dir, float t_max, CounterRng& rng,
                                        QueryContext& ctx, double& t_collision) const;
  // fingerprint() is computed on the first call and kept: the scene is unchanged for the run's
  // life, and hashing every mesh and grid again at each periodic checkpoint would stall the workers.
  [[nodiscard]] std::uint64_t computeFingerprint() const;

  // Throws InvalidArgument when the scene's graph was committed since the run was made.
  void checkScene() const;

  const SensorScene& scene_;
  std::uint64_t revision_ = 0;  // the graph's revision (its commit) that the run traces
  mutable std::once_flag fingerprint_once_;
  mutable std::uint64_t fingerprint_ = 0;
  SensorRunConfig config_;
  std::vector<double> light_cdf_;
  std::atomic<bool> cancel_{false};
  std::uint64_t rays_done_ = 0;
  // Accumulators, per bin and per sensor sums of X and X^2, crossing counts. One structure per bin
  // (one cache line per deposit in the reduction, where three arrays took three misses; 32 bytes so
  // that none straddles two lines).
  struct alignas(32) BinSums {
    double sum = 0.0, sum2 = 0.0;
    std::uint64_t count = 0;
  };
  struct SensorSums {
    double sum = 0.0, sum2 = 0.0;
  };
  // By instance node (a crossing's instance_id): what its deposit needs, in one small record
  // (SensorScene's node-to-sensor table and the SensorInstance would be two cache misses).
  struct DepositTarget {
    std::uint32_t first_bin = 0;
    std::int32_t sensor = -1;  // index in SensorScene::sensors(), -1: not a sensor
    bool angular = false;      // has angular bins
  };
  std::vector<DepositTarget> deposit_targets_;
  // closed_: the sums of the finished batches, added in batch order; open_: the batch under way
  // (empty at batch boundaries), its rays added in ray order. Results are closed_ + open_.
  // scratch_: traceBatch's tallies, incoming_: addBatch's (each allocated on its first call; two,
  // so that one thread may trace a batch while another adds one).
  std::unique_ptr<Tally> closed_, open_, scratch_, incoming_;
  std::unique_ptr<Workers> workers_;  // the task arena and the chunks of a batch
};

}  // namespace duplex
