// A sensor run's scheduling and its ordered, lock-free accumulation.
//
// Work: chunks of consecutive rays, traced in parallel (SensorPaths.cpp); each chunk writes its
// per-ray deposits and energy tallies to its own lists. After each batch the finished chunks are
// reduced strictly in ray order into the batch's tallies, which are then added to the run's in
// batch order, so every sum sees its terms in the same order whatever the thread count and
// whichever process traced the batch. Batch tallies for other processes: SensorRunBatch.cpp;
// saved run states: SensorRunState.cpp.

#include "duplex/sensors/SensorRun.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include "SensorRunChunk.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace duplex {

using detail::BinEvent;
using detail::SensorEvent;

struct SensorRun::Workers {
  explicit Workers(unsigned threads) : arena(static_cast<int>(threads)) {}
  tbb::task_arena arena;
  std::vector<Chunk> chunks;
};

SensorRun::SensorRun(const SensorScene& scene, const SensorRunConfig& config) : scene_(scene), config_(config) {
  if (config_.chunk_rays == 0 || config_.batch_rays == 0)
    throw InvalidArgument("SensorRun: chunk_rays and batch_rays must be > 0");
  // TBB's arena takes an int; more workers than that are a mistake, not a wish.
  if (config_.threads > 4096)
    throw InvalidArgument("SensorRun: threads above 4096 (" + std::to_string(config_.threads) + ")");
  if (!(config_.roulette_threshold >= 0.0 && config_.roulette_threshold < 1.0))
    throw InvalidArgument("SensorRun: roulette_threshold must be in [0, 1)");
  revision_ = scene_.revision();  // the scene as of the graph's last commit (derived now if it changed)
  scene_.checkMeterMaterials();
  double acc = 0.0;
  for (const Light& l : scene_.lights()) light_cdf_.push_back(acc += l.power_w);
  {
    // Spatial bins, then the angular bins, in one index space; the run's tallies and the open batch's.
    // Spatial bins, angular bins and meter points.
    const std::uint64_t all_bins = std::uint64_t{scene_.binCount()} + scene_.angleBinCount() + scene_.meterPointCount();
    const std::uint64_t nb = scene_.bands().empty() ? 0 : scene_.bandCount();
    const std::uint64_t cells = all_bins + scene_.sensors().size();
    const std::uint64_t nl = config_.per_light ? scene_.lights().size() : 0;
    const std::uint64_t bytes = 2 * cells * (3 * sizeof(double) + 2 * sizeof(double) * (nb + nl));
    if (bytes > config_.max_accumulator_bytes)
      throw InvalidArgument("SensorRun: the sensors' " + std::to_string(scene_.binCount()) + " bins and " +
                            std::to_string(scene_.angleBinCount()) + " angular bins" +
                            (nb ? " in " + std::to_string(nb) + " bands" : std::string()) +
                            (nl ? " for " + std::to_string(nl) + " lights each" : std::string()) + " need " +
                            std::to_string(bytes >> 20) + " MiB of accumulators, more than max_accumulator_bytes (" +
                            std::to_string(config_.max_accumulator_bytes >> 20) + " MiB)");
    // What the run will hold, against the process's memory limit: the run's tallies, the open
    // batch's and the copy results() sums them into (each bin's sums and its place in the list of
    // touched bins; per band two sums per bin and sensor), the arrays of results() (per spatial
    // bin five doubles and a count, per angular bin three and a count, per band three per spatial
    // bin and one per angular bin), and a batch's chunks with what each keeps per ray.
    const std::uint64_t spatial = scene_.binCount(), angular = scene_.angleBinCount();
    std::uint64_t need = arrayBytes(all_bins, sizeof(BinSums) + sizeof(std::uint32_t));
    need = saturatingAdd(need, arrayBytes(scene_.sensors().size(), sizeof(SensorSums)));
    need = saturatingAdd(need, arrayBytes(arrayBytes(cells, nb + nl), 2 * sizeof(double)));
    need = arrayBytes(need, 3);
    need = saturatingAdd(need, arrayBytes(spatial, 5 * sizeof(double) + sizeof(std::uint64_t)));
    need = saturatingAdd(need, arrayBytes(angular, 3 * sizeof(double) + sizeof(std::uint64_t)));
    need = saturatingAdd(need, arrayBytes(arrayBytes(spatial, 3 * sizeof(double)), nb));
    need = saturatingAdd(need, arrayBytes(arrayBytes(angular, sizeof(double)), nb));
    need = saturatingAdd(need, arrayBytes(arrayBytes(spatial, 4 * sizeof(double)), nl));
    const std::uint64_t chunks = config_.batch_rays / config_.chunk_rays + 1;
    need = saturatingAdd(need, arrayBytes(chunks, sizeof(Chunk)));
    const std::uint64_t per_ray = 2 * sizeof(std::uint32_t) + sizeof(EnergyBalance) +
                                  (nb > 1 ? sizeof(std::uint16_t) : 0) + (nl ? sizeof(std::uint32_t) : 0);
    need = saturatingAdd(need, arrayBytes(config_.batch_rays, per_ray));
    std::size_t largest = 0;
    for (std::size_t k = 1; k < scene_.sensors().size(); ++k)
      if (scene_.sensors()[k].object->binCount() > scene_.sensors()[largest].object->binCount()) largest = k;
    std::ostringstream what;
    what << "the sensor run";
    if (scene_.document()) what << " of '" << scene_.document()->file.string() << "'";
    what << " (sensors: " << scene_.sensors().size();
    if (!scene_.sensors().empty()) {
      const SensorSpec& spec = scene_.sensors()[largest].object->spec();
      what << ", the largest '" << scene_.sensors()[largest].name << "' with " << spec.nx << " x " << spec.ny
           << " bins";
    }
    what << "; " << spatial << " bins and " << angular << " angular bins in all";
    if (nb) what << " in " << nb << " bands";
    what << "; batches of " << config_.batch_rays << " rays)";
    requireMemory(need, what.str());
  }
  for (std::size_t k = 0; k < scene_.sensors().size(); ++k) {
    const SensorInstance& si = scene_.sensors()[k];
    if (si.node == kInvalidNode) continue;  // far field: deposits on escape, not at crossings
    if (si.node >= deposit_targets_.size()) deposit_targets_.resize(std::size_t{si.node} + 1);
    deposit_targets_[si.node] = {si.first_bin, static_cast<std::int32_t>(k), si.object->spec().theta_bins != 0};
  }
  closed_ = makeTally();
  open_ = makeTally();
  const unsigned threads =
      config_.threads ? config_.threads : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
  workers_ = std::make_unique<Workers>(threads);
}

SensorRun::~SensorRun() = default;

std::unique_ptr<SensorRun::Tally> SensorRun::makeTally() const {
  auto t = std::make_unique<Tally>();
  t->bins.assign(static_cast<std::size_t>(scene_.binCount()) + scene_.angleBinCount() + scene_.meterPointCount(),
                 BinSums{});
  t->sensors.assign(scene_.sensors().size(), SensorSums{});
  if (!scene_.bands().empty()) {
    const std::size_t nb = scene_.bandCount();
    t->band_bin_sum.assign(t->bins.size() * nb, 0.0);
    t->band_bin_sum2.assign(t->bins.size() * nb, 0.0);
    t->band_sensor_sum.assign(t->sensors.size() * nb, 0.0);
    t->band_sensor_sum2.assign(t->sensors.size() * nb, 0.0);
  }
  if (config_.per_light) {
    const std::size_t nl = scene_.lights().size();
    t->light_bin_sum.assign(t->bins.size() * nl, 0.0);
    t->light_bin_sum2.assign(t->bins.size() * nl, 0.0);
    t->light_sensor_sum.assign(t->sensors.size() * nl, 0.0);
    t->light_sensor_sum2.assign(t->sensors.size() * nl, 0.0);
  }
  return t;
}

void SensorRun::checkScene() const {
  if (scene_.graph().revision() != revision_)
    throw InvalidArgument(
        "SensorRun: the scene graph was committed since the run was made (its sensors, lights and paths may "
        "differ): make a new run");
}

// How many deposits ahead the reduction prefetches their accumulators.
constexpr std::size_t kReduceAhead = 16;

void SensorRun::reduce(const Chunk& chunk, Tally& into) const {
  std::size_t b = 0, s = 0;
  const bool spectral = !into.band_bin_sum.empty(), per_light = !into.light_bin_sum.empty();
  const std::size_t nb = scene_.bandCount(), nl = scene_.lights().size();
  for (std::uint64_t k = 0; k < chunk.count; ++k) {
    // A ray carries one band and comes from one light: its deposits are also that band's and that
    // light's samples (zeros in the others).
    const std::size_t band = chunk.band.empty() ? 0 : chunk.band[k];
    const std::size_t light = chunk.light.empty() ? 0 : chunk.light[k];
    for (; b < chunk.bin_end[k]; ++b) {
      // The bins a chunk deposits in are scattered over the accumulators (far more than the
      // caches hold with 10,000 sensors): ask for a later deposit's line now.
      if (b + kReduceAhead < chunk.bins.size()) __builtin_prefetch(&into.bins[chunk.bins[b + kReduceAhead].bin], 1);
      const BinEvent& ev = chunk.bins[b];
      BinSums& acc = into.bins[ev.bin];
      if (acc.count++ == 0) into.touched.push_back(ev.bin);
      acc.sum += ev.value;
      acc.sum2 += ev.value * ev.value;
      if (spectral) {
        into.band_bin_sum[ev.bin * nb + band] += ev.value;
        into.band_bin_sum2[ev.bin * nb + band] += ev.value * ev.value;
      }
      if (per_light) {
        into.light_bin_sum[ev.bin * nl + light] += ev.value;
        into.light_bin_sum2[ev.bin * nl + light] += ev.value * ev.value;
      }
    }
    for (; s < chunk.sensor_end[k]; ++s) {
      if (s + kReduceAhead < chunk.sensors.size())
        __builtin_prefetch(&into.sensors[chunk.sensors[s + kReduceAhead].sensor], 1);
      const SensorEvent& ev = chunk.sensors[s];
      SensorSums& acc = into.sensors[ev.sensor];
      acc.sum += ev.value;
      acc.sum2 += ev.value * ev.value;
      if (spectral) {
        into.band_sensor_sum[ev.sensor * nb + band] += ev.value;
        into.band_sensor_sum2[ev.sensor * nb + band] += ev.value * ev.value;
      }
      if (per_light) {
        into.light_sensor_sum[ev.sensor * nl + light] += ev.value;
        into.light_sensor_sum2[ev.sensor * nl + light] += ev.value * ev.value;
      }
    }
    detail::addEnergy(into.energy, chunk.energy[k]);
  }
  into.rays += chunk.count;
  into.counters.segments += chunk.counters.segments;
  into.counters.crossings += chunk.counters.crossings;
  into.counters.scatterings += chunk.counters.scatterings;
}

void SensorRun::closeBatch() {
  detail::addTally(*closed_, *open_, scene_.bandCount(), scene_.lights().size());
  detail::clearTally(*open_, scene_.bandCount(), scene_.lights().size());
}

std::uint64_t SensorRun::traceRange(std::uint64_t first, std::uint64_t end, Tally& into) {
  std::vector<Chunk>& chunks = workers_->chunks;
  chunks.resize((end - first + config_.chunk_rays - 1) / config_.chunk_rays);
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    chunks[c].first = first + c * config_.chunk_rays;
    chunks[c].count = std::min<std::uint64_t>(config_.chunk_rays, end - chunks[c].first);
    chunks[c].done = false;
  }
  workers_->arena.execute(
      [&] { tbb::parallel_for(std::size_t{0}, chunks.size(), [&](std::size_t c) { traceChunk(chunks[c]); }); });
  // Reduce the finished prefix in ray order (after a cancel, later finished chunks are dropped).
  std::uint64_t reduced = 0;
  for (const Chunk& c : chunks) {
    if (!c.done) break;
    reduce(c, into);
    reduced += c.count;
  }
  return reduced;
}

SensorRunStatus SensorRun::runUntil(std::uint64_t total_rays,
                                    const std::function<void(const SensorProgress&)>& progress,
                                    const SensorStopRule& stop) {
  checkScene();
  if (scene_.lights().empty()) throw InvalidArgument("SensorRun: the scene has no light");
  if (stop.sensor >= static_cast<int>(scene_.sensors().size()))
    throw InvalidArgument("SensorRun: stop rule names sensor " + std::to_string(stop.sensor) + ", the scene has " +
                          std::to_string(scene_.sensors().size()));
  cancel_.store(false, std::memory_order_relaxed);
  const auto t0 = std::chrono::steady_clock::now();
  const std::uint64_t start = rays_done_;
  while (rays_done_ < total_rays) {
    if (stop.sensor >= 0 && rays_done_ >= stop.min_rays && relativeStderr(stop.sensor) <= stop.target)
      return SensorRunStatus::TargetReached;
    // One batch: the rays up to the next multiple of batch_rays (so batches do not depend on how
    // the run was split into calls), reduced into the open batch's tallies.
    const std::uint64_t batch_end = std::min(total_rays, (rays_done_ / config_.batch_rays + 1) * config_.batch_rays);
    rays_done_ += traceRange(rays_done_, batch_end, *open_);
    if (rays_done_ % config_.batch_rays == 0) closeBatch();
    if (progress) {
      SensorProgress p;
      p.rays_done = rays_done_;
      p.rays_target = total_rays;
      p.rays_this_call = rays_done_ - start;
      p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      progress(p);
    }
    if (cancel_.load(std::memory_order_relaxed)) return SensorRunStatus::Cancelled;
  }
  if (stop.sensor >= 0 && rays_done_ >= stop.min_rays && relativeStderr(stop.sensor) <= stop.target)
    return SensorRunStatus::TargetReached;
  return SensorRunStatus::Completed;
}

SensorRunCounters SensorRun::counters() const {
  SensorRunCounters c = closed_->counters;
  c.segments += open_->counters.segments;
  c.crossings += open_->counters.crossings;
  c.scatterings += open_->counters.scatterings;
  return c;
}

namespace {

// Mean and standard error of the mean of N samples given their sum and sum of squares.
void meanAndStderr(double sum, double sum2, std::uint64_t n, double& mean, double& se) {
  if (n == 0) {
    mean = se = 0.0;
    return;
  }
  const double nd = static_cast<double>(n);
  mean = sum / nd;
  se = n > 1 ? std::sqrt(std::max(0.0, (sum2 - sum * sum / nd) / (nd * (nd - 1.0)))) : 0.0;
}

// One channel's (a band's or a light's) per-bin results of a sensor: from the per-(bin, channel)
// sums (index bin * channels + channel, the sensor's bins from first_bin), appended to flux, its
// standard error (when flux_se is not null), and the irradiance and its standard error over the bins'
// world areas.
void channelBins(const std::vector<double>& sum, const std::vector<double>& sum2, std::size_t first_bin,
                 std::size_t channels, std::size_t channel, std::uint64_t rays, const std::vector<double>& area,
                 std::vector<double>& flux, std::vector<double>* flux_se, std::vector<double>& irradiance,
                 std::vector<double>& irradiance_se) {
  for (std::size_t b = 0; b < area.size(); ++b) {
    const std::size_t i = (first_bin + b) * channels + channel;
    double mean, se;
    meanAndStderr(sum[i], sum2[i], rays, mean, se);
    flux.push_back(mean);
    if (flux_se) flux_se->push_back(se);
    irradiance.push_back(area[b] > 0.0 ? mean / area[b] : 0.0);
    irradiance_se.push_back(area[b] > 0.0 ? se / area[b] : 0.0);
  }
}

}  // namespace

double SensorRun::relativeStderr(int sensor) const {
  checkScene();
  if (sensor < 0 || static_cast<std::size_t>(sensor) >= closed_->sensors.size())
    throw InvalidArgument("SensorRun::relativeStderr: sensor " + std::to_string(sensor) + " (the scene has " +
                          std::to_string(scene_.sensors().size()) + ")");
  double mean, se;
  const SensorSums& c = closed_->sensors[static_cast<std::size_t>(sensor)];
  const SensorSums& o = open_->sensors[static_cast<std::size_t>(sensor)];
  meanAndStderr(c.sum + o.sum, c.sum2 + o.sum2, rays_done_, mean, se);
  return mean > 0.0 ? se / mean : std::numeric_limits<double>::infinity();
}

SensorRunResults SensorRun::results() const {
  checkScene();
  // The finished batches and the open one (empty at batch boundaries: adding its zeros changes nothing).
  Tally all = *closed_;
  detail::addTally(all, *open_, scene_.bandCount(), scene_.lights().size());
  SensorRunResults r;
  r.rays = rays_done_;
  r.seed = config_.seed;
  const double n = rays_done_ ? static_cast<double>(rays_done_) : 1.0;
  r.energy.emitted_w = rays_done_ ? scene_.totalPower() : 0.0;
  for (const EnergyEnding& k : kEnergyEndings) {
    r.energy.*k.power = all.energy.*k.power / n;
    r.energy.*k.rays = all.energy.*k.rays;
  }
  const bool spectral = !all.band_bin_sum.empty();
  const std::size_t nb = scene_.bandCount();
  if (spectral) {
    r.bands = scene_.bands();
    r.band_emitted_w.assign(nb, 0.0);
    for (std::size_t l = 0; l < scene_.lights().size(); ++l) {
      const std::vector<double>& cdf = scene_.bandCdf(l);
      for (std::size_t k = 0; k < nb; ++k)
        r.band_emitted_w[k] += scene_.lights()[l].power_w * (cdf[k] - (k ? cdf[k - 1] : 0.0));
    }
  }
  r.photometric = scene_.photometric();
  r.colorimetric = scene_.colorimetric();
  r.band_nm = scene_.bandWavelengths();
  if (r.photometric && rays_done_) {
    if (spectral)
      for (std::size_t k = 0; k < nb; ++k)
        r.emitted_lm += r.band_emitted_w[k] * scene_.luminousWeight(static_cast<std::uint32_t>(k));
    else r.emitted_lm = scene_.totalPower() * scene_.luminousWeight(0);
  }
  r.luminous_transport = r.photometric && !r.colorimetric;
  const bool per_light = !all.light_bin_sum.empty();
  const std::size_t nl = scene_.lights().size();
  // Per-light luminous values need one luminous weight for every ray: no bands of different weights.
  const bool light_lm = per_light && r.photometric && !spectral;
  for (std::size_t l = 0; per_light && l < nl; ++l) {
    const Light& light = scene_.lights()[l];
    r.light_names.push_back(light.name);
    r.light_emitted_w.push_back(rays_done_ ? light.power_w : 0.0);
    if (!r.photometric) continue;
    double lm = 0.0;
    if (spectral) {
      const std::vector<double>& cdf = scene_.bandCdf(l);
      for (std::size_t k = 0; k < nb; ++k)
        lm += light.power_w * (cdf[k] - (k ? cdf[k - 1] : 0.0)) * scene_.luminousWeight(static_cast<std::uint32_t>(k));
    } else {
      lm = light.power_w * scene_.luminousWeight(0);
    }
    r.light_emitted_lm.push_back(rays_done_ ? lm : 0.0);
  }
  for (std::size_t k = 0; k < scene_.sensors().size(); ++k) {
    const SensorInstance& s = scene_.sensors()[k];
    const SensorSpec& spec = s.object->spec();
    SensorResult out;
    out.name = s.name;
    out.node = s.node;
    out.shape = spec.shape;
    out.nx = spec.nx;
    out.ny = spec.ny;
    out.two_sided = spec.two_sided;
    const std::uint32_t bins = s.object->binCount();
    for (std::uint32_t b = 0; b < bins; ++b) {
      double mean, se;
      const BinSums& acc = all.bins[s.first_bin + b];
      meanAndStderr(acc.sum, acc.sum2, rays_done_, mean, se);
      const double area = s.binAreaWorld(b);
      out.flux_w.push_back(mean);
      out.flux_stderr_w.push_back(se);
      out.bin_area_m2.push_back(area);
      out.irradiance_w_m2.push_back(area > 0.0 ? mean / area : 0.0);
      out.stderr_w_m2.push_back(area > 0.0 ? se / area : 0.0);
      out.ray_count.push_back(acc.count);
    }
    meanAndStderr(all.sensors[k].sum, all.sensors[k].sum2, rays_done_, out.total_flux_w, out.total_flux_stderr_w);
    out.theta_bins = spec.theta_bins;
    out.phi_bins = spec.theta_bins ? spec.phi_bins : 0;
    const std::size_t angle_first = static_cast<std::size_t>(scene_.binCount()) + s.first_angle_bin;
    for (std::uint32_t a = 0; a < spec.angleBinCount(); ++a) {
      double mean, se;
      const BinSums& acc = all.bins[angle_first + a];
      meanAndStderr(acc.sum, acc.sum2, rays_done_, mean, se);
      out.angular_flux_w.push_back(mean);
      out.angular_stderr_w.push_back(se);
      out.angular_solid_angle_sr.push_back(s.object->angleBinSolidAngle(a));
      out.angular_ray_count.push_back(acc.count);
    }
    if (spectral) {
      out.band_flux_w.assign(nb, {});
      out.band_irradiance_w_m2.assign(nb, {});
      out.band_stderr_w_m2.assign(nb, {});
      out.band_total_flux_w.assign(nb, 0.0);
      out.band_total_flux_stderr_w.assign(nb, 0.0);
      for (std::size_t band = 0; band < nb; ++band) {
        channelBins(all.band_bin_sum, all.band_bin_sum2, s.first_bin, nb, band, rays_done_, out.bin_area_m2,
                    out.band_flux_w[band], nullptr, out.band_irradiance_w_m2[band], out.band_stderr_w_m2[band]);
        if (spec.angleBinCount() != 0) out.band_angular_flux_w.resize(nb);
        for (std::uint32_t a = 0; a < spec.angleBinCount(); ++a)
          out.band_angular_flux_w[band].push_back(all.band_bin_sum[(angle_first + a) * nb + band] / n);
        meanAndStderr(all.band_sensor_sum[k * nb + band], all.band_sensor_sum2[k * nb + band], rays_done_,
                      out.band_total_flux_w[band], out.band_total_flux_stderr_w[band]);
      }
    }
    if (per_light) perLightResults(all, s, k, light_lm, out);
    if (r.photometric) photometricResults(all, s, k, out);
    out.relative_stderr =
        out.total_flux_w > 0.0 ? out.total_flux_stderr_w / out.total_flux_w : std::numeric_limits<double>::infinity();
    out.efficiency = scene_.totalPower() > 0.0 ? out.total_flux_w / scene_.totalPower() : 0.0;
    r.sensors.push_back(std::move(out));
  }
  meterResults(all, light_lm, r);
  return r;
}

double SensorRun::luminousSamples(const Tally& all, std::size_t bin, double& sum2) const {
  // A ray carries one band: its luminous sample is its deposit times that band's weight, so the
  // samples' sums and squares follow from the per-band ones (zeros in the other bands).
  if (all.band_bin_sum.empty()) {
    const double w = scene_.luminousWeight(0);
    sum2 = w * w * all.bins[bin].sum2;
    return w * all.bins[bin].sum;
  }
  const std::size_t nb = scene_.bandCount();
  double y = 0.0;
  sum2 = 0.0;
  for (std::size_t k = 0; k < nb; ++k) {
    const double w = scene_.luminousWeight(static_cast<std::uint32_t>(k));
    y += w * all.band_bin_sum[bin * nb + k];
    sum2 += w * w * all.band_bin_sum2[bin * nb + k];
  }
  return y;
}

void SensorRun::meterResults(const Tally& all, bool light_lm, SensorRunResults& r) const {
  std::size_t bin = static_cast<std::size_t>(scene_.binCount()) + scene_.angleBinCount();
  const std::size_t nl = all.light_bin_sum.empty() ? 0 : scene_.lights().size();
  for (const PointMeter& m : scene_.meters()) {
    MeterResult out;
    out.name = m.name;
    out.points = m.points;
    out.normals = m.normals;
    if (nl) {
      out.light_irradiance_w_m2.assign(nl, {});
      out.light_stderr_w_m2.assign(nl, {});
    }
    for (std::size_t i = 0; i < m.points.size(); ++i, ++bin) {
      double mean, se;
      meanAndStderr(all.bins[bin].sum, all.bins[bin].sum2, rays_done_, mean, se);
      out.irradiance_w_m2.push_back(mean);
      out.stderr_w_m2.push_back(se);
      out.ray_count.push_back(all.bins[bin].count);
      if (r.photometric) {
        double y2;
        const double y = luminousSamples(all, bin, y2);
        meanAndStderr(y, y2, rays_done_, mean, se);
        out.illuminance_lx.push_back(mean);
        out.illuminance_stderr_lx.push_back(se);
      }
      for (std::size_t l = 0; l < nl; ++l) {
        meanAndStderr(all.light_bin_sum[bin * nl + l], all.light_bin_sum2[bin * nl + l], rays_done_, mean, se);
        out.light_irradiance_w_m2[l].push_back(mean);
        out.light_stderr_w_m2[l].push_back(se);
      }
    }
    if (light_lm) {  // one luminous weight for every ray
      out.light_illuminance_lx = out.light_irradiance_w_m2;
      for (auto& v : out.light_illuminance_lx)
        for (double& x : v) x *= scene_.luminousWeight(0);
    }
    out.half_angle = m.half_angle;
    out.image_width = m.image_width;
    out.image_height = m.image_height;
    if (out.luminance()) {  // a luminance meter or a camera: the same estimates are radiances
      out.radiance_w_m2_sr = std::exchange(out.irradiance_w_m2, {});
      out.radiance_stderr_w_m2_sr = std::exchange(out.stderr_w_m2, {});
      out.luminance_cd_m2 = std::exchange(out.illuminance_lx, {});
      out.luminance_stderr_cd_m2 = std::exchange(out.illuminance_stderr_lx, {});
      out.light_radiance_w_m2_sr = std::exchange(out.light_irradiance_w_m2, {});
      out.light_radiance_stderr_w_m2_sr = std::exchange(out.light_stderr_w_m2, {});
      out.light_luminance_cd_m2 = std::exchange(out.light_illuminance_lx, {});
    }
    r.meters.push_back(std::move(out));
  }
}

void SensorRun::perLightResults(const Tally& all, const SensorInstance& s, std::size_t sensor, bool luminous,
                                SensorResult& out) const {
  const std::size_t nl = scene_.lights().size();
  const double w = luminous ? scene_.luminousWeight(0) : 0.0;
  for (auto* v : {&out.light_flux_w, &out.light_flux_stderr_w, &out.light_irradiance_w_m2, &out.light_stderr_w_m2})
    v->assign(nl, {});
  out.light_total_flux_w.assign(nl, 0.0);
  out.light_total_flux_stderr_w.assign(nl, 0.0);
  for (std::size_t l = 0; l < nl; ++l) {
    channelBins(all.light_bin_sum, all.light_bin_sum2, s.first_bin, nl, l, rays_done_, out.bin_area_m2,
                out.light_flux_w[l], &out.light_flux_stderr_w[l], out.light_irradiance_w_m2[l],
                out.light_stderr_w_m2[l]);
    meanAndStderr(all.light_sensor_sum[sensor * nl + l], all.light_sensor_sum2[sensor * nl + l], rays_done_,
                  out.light_total_flux_w[l], out.light_total_flux_stderr_w[l]);
  }
  if (!luminous) return;
  // One luminous weight for every ray: the luminous values are the radiometric ones scaled by it.
  auto scaled = [w](const std::vector<std::vector<double>>& per_light) {
    std::vector<std::vector<double>> to = per_light;
    for (auto& v : to)
      for (double& x : v) x *= w;
    return to;
  };
  out.light_illuminance_lx = scaled(out.light_irradiance_w_m2);
  out.light_illuminance_stderr_lx = scaled(out.light_stderr_w_m2);
  out.light_luminous_flux_lm = scaled({out.light_total_flux_w})[0];
  out.light_luminous_flux_stderr_lm = scaled({out.light_total_flux_stderr_w})[0];
}

void SensorRun::photometricResults(const Tally& all, const SensorInstance& s, std::size_t sensor,
                                   SensorResult& out) const {
  const std::uint32_t bins = s.object->binCount();
  const std::size_t nb = scene_.bandCount();
  const bool spectral = !all.band_bin_sum.empty();
  // A ray carries one band: its luminous sample is its deposit times that band's weight, so the
  // samples' sums and squares follow from the per-band ones (zeros in the other bands).
  auto luminous = [&](const double* sum, const double* sum2, const double* plain_sum, const double* plain_sum2,
                      double& mean, double& se) {
    double y = 0.0, y2 = 0.0;
    if (spectral) {
      for (std::size_t k = 0; k < nb; ++k) {
        const double w = scene_.luminousWeight(static_cast<std::uint32_t>(k));
        y += w * sum[k];
        y2 += w * w * sum2[k];
      }
    } else {
      const double w = scene_.luminousWeight(0);
      y = w * *plain_sum;
      y2 = w * w * *plain_sum2;
    }
    meanAndStderr(y, y2, rays_done_, mean, se);
  };
  for (std::uint32_t b = 0; b < bins; ++b) {
    double mean, se, y2;
    const double y = luminousSamples(all, s.first_bin + b, y2);
    meanAndStderr(y, y2, rays_done_, mean, se);
    const double area = out.bin_area_m2[b];
    out.flux_lm.push_back(mean);
    out.flux_stderr_lm.push_back(se);
    out.illuminance_lx.push_back(area > 0.0 ? mean / area : 0.0);
    out.illuminance_stderr_lx.push_back(area > 0.0 ? se / area : 0.0);
  }
  luminous(spectral ? &all.band_sensor_sum[sensor * nb] : nullptr,
           spectral ? &all.band_sensor_sum2[sensor * nb] : nullptr, &all.sensors[sensor].sum, &all.sensors[sensor].sum2,
           out.luminous_flux_lm, out.luminous_flux_stderr_lm);
  if (!scene_.colorimetric()) return;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto chromaticity = [nan](const glm::dvec3& xyz, std::vector<double>& to) {
    const double sum = xyz.x + xyz.y + xyz.z;
    to.push_back(sum > 0.0 ? xyz.x / sum : nan);
    to.push_back(sum > 0.0 ? xyz.y / sum : nan);
  };
  glm::dvec3 total(0.0);
  for (std::size_t k = 0; k < nb; ++k)
    total += scene_.tristimulusWeight(static_cast<std::uint32_t>(k)) * out.band_total_flux_w[k];
  for (std::uint32_t b = 0; b < bins; ++b) {
    glm::dvec3 xyz(0.0);
    for (std::size_t k = 0; k < nb; ++k)
      xyz += scene_.tristimulusWeight(static_cast<std::uint32_t>(k)) * out.band_irradiance_w_m2[k][b];
    out.cie_xyz.insert(out.cie_xyz.end(), {xyz.x, xyz.y, xyz.z});
    chromaticity(xyz, out.chromaticity_xy);
  }
  out.total_cie_xyz = {total.x, total.y, total.z};
  chromaticity(total, out.total_chromaticity_xy);
}

}  // namespace duplex
