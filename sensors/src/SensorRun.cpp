// The light-tracing loop of a sensor run and its ordered, lock-free accumulation.
//
// Work: chunks of consecutive rays, traced in parallel; each chunk writes its per-ray deposits
// (merged per bin within the path, so that a bin's sum of squares is over emitted rays) and energy
// tallies to its own lists. After each batch the finished chunks are reduced strictly in ray order,
// so every sum sees its terms in the same order whatever the thread count.

#include "duplex/sensors/SensorRun.h"

#include "duplex/accel/AtomicFile.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/Xxh64.h"
#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/HenyeyGreenstein.h"

#include "OrthonormalBasis.h"

#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <type_traits>

namespace duplex {

namespace {

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

// Cosine-weighted direction about unit normal n.
glm::dvec3 cosineDirection(const glm::dvec3& n, double u0, double u1) {
  glm::dvec3 t, b;
  detail::orthonormalBasis(n, t, b);
  const double r = std::sqrt(u0), phi = 2.0 * std::numbers::pi * u1;
  return r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - u0)) * n;
}

glm::dvec3 reflect(const glm::dvec3& d, const glm::dvec3& n) { return d - 2.0 * glm::dot(d, n) * n; }

// A direction scattered from unit propagation direction d by phase function hg.
glm::dvec3 phaseDirection(const glm::dvec3& d, const HenyeyGreenstein& hg, double u0, double u1) {
  const double c = hg.sampleCos(u0), sn = std::sqrt(std::max(0.0, 1.0 - c * c)), phi = 2.0 * std::numbers::pi * u1;
  glm::dvec3 t, b;
  detail::orthonormalBasis(d, t, b);
  return glm::normalize(sn * std::cos(phi) * t + sn * std::sin(phi) * b + c * d);
}

// Whether the segment origin + t dir, t in [0, t_max], meets the box [lo, hi] (slab test; an
// infinite t_max is a ray).
bool segmentMeetsBox(const glm::dvec3& origin, const glm::dvec3& dir, double t_max, const glm::dvec3& lo,
                     const glm::dvec3& hi) {
  double t0 = 0.0, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    const double inv = 1.0 / dir[a];
    double ta = (lo[a] - origin[a]) * inv, tb = (hi[a] - origin[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    if (!(ta <= t1 && tb >= t0)) {
      if (std::isnan(ta) || std::isnan(tb)) continue;  // dir[a] == 0 with the origin on a face: keep
      return false;
    }
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1;
}

// Sorts a path's deposits by bin, keeping the path order within a bin. Most paths deposit in a
// handful of bins: a stable insertion sort, where std::stable_sort would allocate a buffer per path.
void sortByBin(std::vector<BinEvent>& events) {
  if (events.size() > 32) {
    std::stable_sort(events.begin(), events.end(), [](const BinEvent& a, const BinEvent& b) { return a.bin < b.bin; });
    return;
  }
  for (std::size_t i = 1; i < events.size(); ++i) {
    const BinEvent e = events[i];
    std::size_t j = i;
    for (; j > 0 && events[j - 1].bin > e.bin; --j) events[j] = events[j - 1];
    events[j] = e;
  }
}

}  // namespace

struct SensorRun::Chunk {
  std::uint64_t first = 0, count = 0;
  bool done = false;
  // Per ray (path order): its merged bin and sensor deposits, delimited by offsets; its energy.
  std::vector<BinEvent> bins;
  std::vector<std::uint32_t> bin_end;  // per ray: end offset in bins
  std::vector<SensorEvent> sensors;
  std::vector<std::uint32_t> sensor_end;
  std::vector<EnergyBalance> energy;  // per ray (emitted_w unused)
  std::vector<std::uint16_t> band;    // per ray, when the scene has several bands
  SensorRunCounters counters;
};

SensorRun::SensorRun(const SensorScene& scene, const SensorRunConfig& config) : scene_(scene), config_(config) {
  if (config_.chunk_rays == 0 || config_.batch_rays == 0)
    throw InvalidArgument("SensorRun: chunk_rays and batch_rays must be > 0");
  if (config_.max_depth > 1000) throw InvalidArgument("SensorRun: max_depth above 1000");
  // TBB's arena takes an int; more workers than that are a mistake, not a wish.
  if (config_.threads > 4096)
    throw InvalidArgument("SensorRun: threads above 4096 (" + std::to_string(config_.threads) + ")");
  if (!(config_.roulette_threshold >= 0.0 && config_.roulette_threshold < 1.0))
    throw InvalidArgument("SensorRun: roulette_threshold must be in [0, 1)");
  double acc = 0.0;
  for (const Light& l : scene_.lights()) light_cdf_.push_back(acc += l.power_w);
  // Spatial bins, then the angular bins, in one index space.
  const std::size_t all_bins = static_cast<std::size_t>(scene_.binCount()) + scene_.angleBinCount();
  {
    const std::uint64_t nb = scene_.bands().empty() ? 0 : scene_.bandCount();
    const std::uint64_t cells = all_bins + scene_.sensors().size();
    const std::uint64_t bytes = cells * (3 * sizeof(double) + 2 * sizeof(double) * nb);
    if (bytes > config_.max_accumulator_bytes)
      throw InvalidArgument("SensorRun: the sensors' " + std::to_string(scene_.binCount()) + " bins and " +
                            std::to_string(scene_.angleBinCount()) + " angular bins" +
                            (nb ? " in " + std::to_string(nb) + " bands" : std::string()) + " need " +
                            std::to_string(bytes >> 20) + " MiB of accumulators, more than max_accumulator_bytes (" +
                            std::to_string(config_.max_accumulator_bytes >> 20) + " MiB)");
  }
  bins_.assign(all_bins, BinSums{});
  for (std::size_t k = 0; k < scene_.sensors().size(); ++k) {
    const SensorInstance& si = scene_.sensors()[k];
    if (si.node >= deposit_targets_.size()) deposit_targets_.resize(std::size_t{si.node} + 1);
    deposit_targets_[si.node] = {si.first_bin, static_cast<std::int32_t>(k), si.object->spec().theta_bins != 0};
  }
  sensor_sums_.assign(scene_.sensors().size(), SensorSums{});
  if (!scene_.bands().empty()) {
    const std::size_t nb = scene_.bandCount();
    band_bin_sum_.assign(bins_.size() * nb, 0.0);
    band_bin_sum2_.assign(bins_.size() * nb, 0.0);
    band_sensor_sum_.assign(sensor_sums_.size() * nb, 0.0);
    band_sensor_sum2_.assign(sensor_sums_.size() * nb, 0.0);
  }
}

void SensorRun::traceChunk(Chunk& chunk) const {
  const TopLevel& top = scene_.tracer().topLevel();
  const auto& lights = scene_.lights();
  const auto& sensors = scene_.sensors();
  const double power = scene_.totalPower();
  const double rr_level = config_.roulette_threshold * power;
  const std::uint32_t bands = scene_.bandCount();
  const std::uint32_t angle_base = scene_.binCount();  // angular bins follow the spatial ones
  // In a scene whose fogs scatter, every fog acts through sampled free flights, not through the
  // crossing query's transmittance.
  const bool scatter = scene_.scatters();
  CrossingQuery query = config_.query;
  if (scatter) query.medium_mask = 0;
  QueryContext ctx;
  std::vector<Crossing> crossings;
  std::vector<BinEvent> path_bins;  // this path's deposits before merging
  chunk.bins.clear();
  chunk.bin_end.clear();
  chunk.sensors.clear();
  chunk.sensor_end.clear();
  chunk.band.assign(bands > 1 ? chunk.count : 0, 0);
  chunk.energy.assign(chunk.count, EnergyBalance{});
  chunk.counters = {};

  for (std::uint64_t k = 0; k < chunk.count; ++k) {
    if (cancel_.load(std::memory_order_relaxed)) return;  // chunk stays not done
    CounterRng rng(config_.seed, chunk.first + k);
    EnergyBalance& e = chunk.energy[k];
    // Light by power, then a ray of it.
    const double pick = rng.uniform() * power;
    const std::size_t li = std::min<std::size_t>(
        lights.size() - 1,
        static_cast<std::size_t>(std::upper_bound(light_cdf_.begin(), light_cdf_.end(), pick) - light_cdf_.begin()));
    // The band by the light's spectrum, from where `pick` fell inside the light's share: the path's
    // other random numbers stay those of a single-band run (equal reflectances: equal paths).
    std::uint32_t band = 0;
    if (bands > 1) {
      const double lo = li ? light_cdf_[li - 1] : 0.0;
      const double ub = std::clamp((pick - lo) / lights[li].power_w, 0.0, 1.0);
      const std::vector<double>& cdf = scene_.bandCdf(li);
      band =
          std::min(bands - 1, static_cast<std::uint32_t>(std::upper_bound(cdf.begin(), cdf.end(), ub) - cdf.begin()));
      // ub rounded up to 1 lands past the end: never in a band of zero share.
      while (band > 0 && cdf[band] == cdf[band - 1]) --band;
      chunk.band[k] = static_cast<std::uint16_t>(band);
    }
    double u[4] = {rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform()};
    const EmittedRay emitted = sampleLight(lights[li], u);
    glm::dvec3 origin = emitted.origin, dir = emitted.dir;
    double w = power * emitted.weight;
    path_bins.clear();

    std::uint32_t depth = 0, scatterings = 0;
    for (;;) {
      Ray ray;
      ray.origin = glm::vec3(origin);
      ray.dir = glm::vec3(dir);
      ++chunk.counters.segments;
      SegmentEnd end;
      if (config_.closest_hit_only) end.hit = top.intersect(ray, ctx, config_.query.surface_mask);
      else end = top.intersectWithCrossings(ray, crossings, ctx, query);
      // A collision in a scattering fog before the blocking hit ends the segment there.
      const MediumInstance* collided = nullptr;
      double t_collision = std::numeric_limits<double>::infinity();
      if (scatter) {
        collided = sampleCollision(origin, dir, end.hit.valid() ? end.hit.t : std::numeric_limits<float>::infinity(),
                                   rng, ctx, t_collision);
      }
      if (!config_.closest_hit_only) {
        for (const Crossing& c : crossings) {
          if (c.hit.t > t_collision) break;  // sorted by t
          if (c.hit.instance_id >= deposit_targets_.size()) continue;
          const DepositTarget target = deposit_targets_[c.hit.instance_id];
          const int s = target.sensor;
          if (s < 0) continue;
          const double value = w * c.transmittance;
          path_bins.push_back({target.first_bin + c.hit.prim_id, static_cast<std::uint32_t>(s), value});
          if (target.angular) {  // the incoming direction, in the sensor's world frame
            const SensorInstance& si = sensors[static_cast<std::size_t>(s)];
            const glm::dvec3 in = -dir;
            const std::uint32_t ab = si.object->angleBinAt(
                glm::dot(in, si.normal), std::atan2(glm::dot(in, si.frame_y), glm::dot(in, si.frame_x)));
            path_bins.push_back({angle_base + si.first_angle_bin + ab, kInvalidId, value});
          }
          ++chunk.counters.crossings;
        }
      }
      if (collided) {
        ++chunk.counters.scatterings;
        if (scatterings == config_.max_scatterings) {
          e.depth_limited_w += w;
          break;
        }
        ++scatterings;
        const double albedo =
            collided->material.type == MaterialType::Medium ? collided->material.reflectanceIn(band) : 0.0;
        if (!(rng.uniform() < albedo)) {
          e.medium_absorbed_w += w;
          break;
        }
        const glm::dvec3 d = glm::normalize(dir);
        origin = origin + t_collision * dir;
        dir = phaseDirection(d, HenyeyGreenstein{collided->material.g}, rng.uniform(), rng.uniform());
        continue;
      }
      const double w_after = w * end.transmittance;
      e.medium_absorbed_w += w - w_after;
      w = w_after;
      if (!end.hit.valid()) {
        e.escaped_w += w;
        break;
      }
      if (depth == config_.max_depth) {
        e.depth_limited_w += w;
        break;
      }
      ++depth;
      // Scatter by the material; a path ends in an absorber or by the albedo's roulette.
      const Material& m = scene_.materialOf(end.hit.instance_id);
      const glm::dvec3 p = origin + static_cast<double>(end.hit.t) * dir;
      glm::dvec3 n = glm::normalize(glm::dvec3(end.hit.ng));
      const glm::dvec3 d = glm::normalize(dir);
      const bool front = glm::dot(d, n) < 0.0;
      const glm::dvec3 nf = front ? n : -n;  // faces the incoming ray
      glm::dvec3 next;
      if (m.type == MaterialType::Absorber || m.type == MaterialType::Medium) {
        e.absorbed_w += w;
        break;
      } else if (m.type == MaterialType::Lambertian || m.type == MaterialType::Mirror) {
        if (rng.uniform() >= m.reflectanceIn(band)) {
          e.absorbed_w += w;
          break;
        }
        next = m.type == MaterialType::Mirror ? reflect(d, nf) : cosineDirection(nf, rng.uniform(), rng.uniform());
      } else {  // dielectric: exact Fresnel for unpolarised light, reflect or refract by it
        const double eta_i = front ? 1.0 : m.ior, eta_t = front ? m.ior : 1.0;
        const double cos_i = std::min(1.0, std::abs(glm::dot(d, n)));
        const double sin_t2 = (eta_i / eta_t) * (eta_i / eta_t) * (1.0 - cos_i * cos_i);
        double fresnel = 1.0, cos_t = 0.0;
        if (sin_t2 < 1.0) {
          cos_t = std::sqrt(1.0 - sin_t2);
          const double rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
          const double rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
          fresnel = 0.5 * (rs * rs + rp * rp);
        }
        if (rng.uniform() < fresnel) next = reflect(d, nf);
        else next = (eta_i / eta_t) * d + ((eta_i / eta_t) * cos_i - cos_t) * nf;
      }
      // Russian roulette on power lost to media (materials keep a surviving path's power).
      if (w < rr_level) {
        if (rng.uniform() * rr_level >= w) {
          e.roulette_w += w;
          break;
        }
        e.roulette_w -= rr_level - w;
        w = rr_level;
      }
      // Leave the surface on the side the new direction points to. The float hit's error grows
      // with the magnitude of the primitive's coordinates (a few ulps of them, not of the hit
      // point: a large triangle hit near the origin is off by ulps of its far vertices), so the
      // offset scales with the hit instance's world box as well as with the point.
      const Box box = top.instanceBounds(end.hit.instance_id);
      const double scale = std::max({1.0, std::abs(p.x), std::abs(p.y), std::abs(p.z), std::abs(double(box.lo.x)),
                                     std::abs(double(box.lo.y)), std::abs(double(box.lo.z)), std::abs(double(box.hi.x)),
                                     std::abs(double(box.hi.y)), std::abs(double(box.hi.z))});
      origin = p + (glm::dot(next, n) >= 0.0 ? n : -n) * (1e-5 * scale);
      dir = glm::normalize(next);
    }

    // Merge this path's deposits per bin (in path order within a bin) and per sensor.
    sortByBin(path_bins);
    const std::size_t sensor_first = chunk.sensors.size();
    for (std::size_t i = 0; i < path_bins.size();) {
      BinEvent merged = path_bins[i];
      for (++i; i < path_bins.size() && path_bins[i].bin == merged.bin; ++i) merged.value += path_bins[i].value;
      chunk.bins.push_back(merged);
    }
    // Sensor totals: bins are sorted, and a sensor's spatial bins are contiguous, so its sum follows.
    for (std::size_t i = chunk.bin_end.empty() ? 0 : chunk.bin_end.back(); i < chunk.bins.size(); ++i) {
      const BinEvent& b = chunk.bins[i];
      if (b.bin >= angle_base) break;  // angular bins (sorted after the spatial ones) repeat the same power
      const std::uint32_t s = b.sensor;
      if (chunk.sensors.size() > sensor_first && chunk.sensors.back().sensor == s)
        chunk.sensors.back().value += b.value;
      else chunk.sensors.push_back({s, b.value});
    }
    chunk.bin_end.push_back(static_cast<std::uint32_t>(chunk.bins.size()));
    chunk.sensor_end.push_back(static_cast<std::uint32_t>(chunk.sensors.size()));
  }
  chunk.done = true;
}

const MediumInstance* SensorRun::sampleCollision(const glm::dvec3& origin, const glm::dvec3& dir, float t_max,
                                                 CounterRng& rng, QueryContext& ctx, double& t_collision) const {
  // The first collision among independent free flights is a free flight through the summed
  // density; each later medium only needs to be sampled up to the best collision so far.
  const MediumInstance* found = nullptr;
  float t_best = t_max;
  for (const MediumInstance& m : scene_.scatteringMedia()) {
    const std::uint64_t seed = rng.next();  // drawn for every medium: the stream does not depend on the geometry
    if ((m.mask & config_.query.medium_mask) == 0) continue;
    if (!segmentMeetsBox(origin, dir, t_best, m.world_lo, m.world_hi)) continue;
    Ray ray_os;  // object space, direction not renormalised: t is the world t
    ray_os.origin = glm::vec3(m.object_from_world.point(origin));
    ray_os.dir = glm::vec3(m.object_from_world.vector(dir));
    ray_os.tnear = 0.0f;
    ray_os.tfar = t_best;
    if (const std::optional<float> t = m.volume->sampleFreeFlight(ray_os, ctx, seed); t && *t < t_best) {
      t_best = *t;
      found = &m;
    }
  }
  t_collision = found ? static_cast<double>(t_best) : std::numeric_limits<double>::infinity();
  return found;
}

// How many deposits ahead the reduction prefetches their accumulators.
constexpr std::size_t kReduceAhead = 16;

void SensorRun::reduce(const Chunk& chunk) {
  std::size_t b = 0, s = 0;
  const bool spectral = !band_bin_sum_.empty();
  const std::size_t nb = scene_.bandCount();
  for (std::uint64_t k = 0; k < chunk.count; ++k) {
    // A ray carries one band: its deposits are also that band's samples (zeros in the others).
    const std::size_t band = chunk.band.empty() ? 0 : chunk.band[k];
    for (; b < chunk.bin_end[k]; ++b) {
      // The bins a chunk deposits in are scattered over the accumulators (far more than the
      // caches hold with 10,000 sensors): ask for a later deposit's line now.
      if (b + kReduceAhead < chunk.bins.size()) __builtin_prefetch(&bins_[chunk.bins[b + kReduceAhead].bin], 1);
      const BinEvent& ev = chunk.bins[b];
      BinSums& acc = bins_[ev.bin];
      acc.sum += ev.value;
      acc.sum2 += ev.value * ev.value;
      ++acc.count;
      if (spectral) {
        band_bin_sum_[ev.bin * nb + band] += ev.value;
        band_bin_sum2_[ev.bin * nb + band] += ev.value * ev.value;
      }
    }
    for (; s < chunk.sensor_end[k]; ++s) {
      if (s + kReduceAhead < chunk.sensors.size())
        __builtin_prefetch(&sensor_sums_[chunk.sensors[s + kReduceAhead].sensor], 1);
      const SensorEvent& ev = chunk.sensors[s];
      SensorSums& acc = sensor_sums_[ev.sensor];
      acc.sum += ev.value;
      acc.sum2 += ev.value * ev.value;
      if (spectral) {
        band_sensor_sum_[ev.sensor * nb + band] += ev.value;
        band_sensor_sum2_[ev.sensor * nb + band] += ev.value * ev.value;
      }
    }
    const EnergyBalance& e = chunk.energy[k];
    energy_sum_.escaped_w += e.escaped_w;
    energy_sum_.absorbed_w += e.absorbed_w;
    energy_sum_.medium_absorbed_w += e.medium_absorbed_w;
    energy_sum_.depth_limited_w += e.depth_limited_w;
    energy_sum_.roulette_w += e.roulette_w;
  }
  rays_done_ += chunk.count;
  counters_.segments += chunk.counters.segments;
  counters_.crossings += chunk.counters.crossings;
  counters_.scatterings += chunk.counters.scatterings;
}

SensorRunStatus SensorRun::runUntil(std::uint64_t total_rays,
                                    const std::function<void(const SensorProgress&)>& progress,
                                    const SensorStopRule& stop) {
  if (scene_.lights().empty()) throw InvalidArgument("SensorRun: the scene has no light");
  if (stop.sensor >= static_cast<int>(scene_.sensors().size()))
    throw InvalidArgument("SensorRun: stop rule names sensor " + std::to_string(stop.sensor) + ", the scene has " +
                          std::to_string(scene_.sensors().size()));
  cancel_.store(false, std::memory_order_relaxed);
  const auto t0 = std::chrono::steady_clock::now();
  const std::uint64_t start = rays_done_;
  const unsigned threads =
      config_.threads ? config_.threads : static_cast<unsigned>(tbb::this_task_arena::max_concurrency());
  tbb::task_arena arena(static_cast<int>(threads));
  std::vector<Chunk> chunks;
  while (rays_done_ < total_rays) {
    if (stop.sensor >= 0 && rays_done_ >= stop.min_rays && relativeStderr(stop.sensor) <= stop.target)
      return SensorRunStatus::TargetReached;
    // One batch: the rays up to the next multiple of batch_rays (so batches do not depend on how
    // the run was split into calls), cut into chunks.
    const std::uint64_t batch_end = std::min(total_rays, (rays_done_ / config_.batch_rays + 1) * config_.batch_rays);
    chunks.resize((batch_end - rays_done_ + config_.chunk_rays - 1) / config_.chunk_rays);
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      chunks[c].first = rays_done_ + c * config_.chunk_rays;
      chunks[c].count = std::min<std::uint64_t>(config_.chunk_rays, batch_end - chunks[c].first);
      chunks[c].done = false;
    }
    arena.execute(
        [&] { tbb::parallel_for(std::size_t{0}, chunks.size(), [&](std::size_t c) { traceChunk(chunks[c]); }); });
    // Reduce the finished prefix in ray order (after a cancel, later finished chunks are dropped).
    for (const Chunk& c : chunks) {
      if (!c.done) break;
      reduce(c);
    }
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

}  // namespace

double SensorRun::relativeStderr(int sensor) const {
  if (sensor < 0 || static_cast<std::size_t>(sensor) >= sensor_sums_.size())
    throw InvalidArgument("SensorRun::relativeStderr: sensor " + std::to_string(sensor) + " (the scene has " +
                          std::to_string(sensor_sums_.size()) + ")");
  double mean, se;
  const SensorSums& acc = sensor_sums_[static_cast<std::size_t>(sensor)];
  meanAndStderr(acc.sum, acc.sum2, rays_done_, mean, se);
  return mean > 0.0 ? se / mean : std::numeric_limits<double>::infinity();
}

SensorRunResults SensorRun::results() const {
  SensorRunResults r;
  r.rays = rays_done_;
  r.seed = config_.seed;
  const double n = rays_done_ ? static_cast<double>(rays_done_) : 1.0;
  r.energy.emitted_w = rays_done_ ? scene_.totalPower() : 0.0;
  r.energy.escaped_w = energy_sum_.escaped_w / n;
  r.energy.absorbed_w = energy_sum_.absorbed_w / n;
  r.energy.medium_absorbed_w = energy_sum_.medium_absorbed_w / n;
  r.energy.depth_limited_w = energy_sum_.depth_limited_w / n;
  r.energy.roulette_w = energy_sum_.roulette_w / n;
  const bool spectral = !band_bin_sum_.empty();
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
      const BinSums& acc = bins_[s.first_bin + b];
      meanAndStderr(acc.sum, acc.sum2, rays_done_, mean, se);
      const double area = s.binAreaWorld(b);
      out.flux_w.push_back(mean);
      out.flux_stderr_w.push_back(se);
      out.bin_area_m2.push_back(area);
      out.irradiance_w_m2.push_back(area > 0.0 ? mean / area : 0.0);
      out.stderr_w_m2.push_back(area > 0.0 ? se / area : 0.0);
      out.ray_count.push_back(acc.count);
    }
    meanAndStderr(sensor_sums_[k].sum, sensor_sums_[k].sum2, rays_done_, out.total_flux_w, out.total_flux_stderr_w);
    out.theta_bins = spec.theta_bins;
    out.phi_bins = spec.theta_bins ? spec.phi_bins : 0;
    const std::size_t angle_first = static_cast<std::size_t>(scene_.binCount()) + s.first_angle_bin;
    for (std::uint32_t a = 0; a < spec.angleBinCount(); ++a) {
      double mean, se;
      const BinSums& acc = bins_[angle_first + a];
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
        for (std::uint32_t b = 0; b < bins; ++b) {
          const std::size_t i = (s.first_bin + b) * nb + band;
          double mean, se;
          meanAndStderr(band_bin_sum_[i], band_bin_sum2_[i], rays_done_, mean, se);
          const double area = out.bin_area_m2[b];
          out.band_flux_w[band].push_back(mean);
          out.band_irradiance_w_m2[band].push_back(area > 0.0 ? mean / area : 0.0);
          out.band_stderr_w_m2[band].push_back(area > 0.0 ? se / area : 0.0);
        }
        if (spec.angleBinCount() != 0) out.band_angular_flux_w.resize(nb);
        for (std::uint32_t a = 0; a < spec.angleBinCount(); ++a)
          out.band_angular_flux_w[band].push_back(band_bin_sum_[(angle_first + a) * nb + band] / n);
        meanAndStderr(band_sensor_sum_[k * nb + band], band_sensor_sum2_[k * nb + band], rays_done_,
                      out.band_total_flux_w[band], out.band_total_flux_stderr_w[band]);
      }
    }
    out.relative_stderr =
        out.total_flux_w > 0.0 ? out.total_flux_stderr_w / out.total_flux_w : std::numeric_limits<double>::infinity();
    out.efficiency = scene_.totalPower() > 0.0 ? out.total_flux_w / scene_.totalPower() : 0.0;
    r.sensors.push_back(std::move(out));
  }
  return r;
}

// ---- saved state: "DXSENSR4", fingerprint, seed, rays, sizes, the raw accumulators, XXH64 checksum ----

std::uint64_t SensorRun::fingerprint() const {
  std::call_once(fingerprint_once_, [this] { fingerprint_ = computeFingerprint(); });
  return fingerprint_;
}

std::uint64_t SensorRun::computeFingerprint() const {
  // FNV-1a over what the accumulators' meaning depends on.
  std::uint64_t h = 1469598103934665603ull;
  auto add = [&h](const void* p, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) h = (h ^ static_cast<const unsigned char*>(p)[i]) * 1099511628211ull;
  };
  for (const SensorInstance& s : scene_.sensors()) {
    add(s.name.data(), s.name.size());
    const std::uint32_t bins = s.object->binCount();
    add(&bins, sizeof bins);
  }
  for (const Light& l : scene_.lights()) add(&l.power_w, sizeof l.power_w);
  add(&config_.seed, sizeof config_.seed);
  add(&config_.max_depth, sizeof config_.max_depth);
  add(&config_.roulette_threshold, sizeof config_.roulette_threshold);
  // Bands, angular bins and free flights are added only where a scene uses them.
  for (std::size_t l = 0; !scene_.bands().empty() && l < scene_.lights().size(); ++l) {
    const std::vector<double>& cdf = scene_.bandCdf(l);
    add(cdf.data(), cdf.size() * sizeof(double));
  }
  for (const std::string& b : scene_.bands()) add(b.data(), b.size() + 1);
  for (const SensorInstance& s : scene_.sensors()) {
    const SensorSpec& spec = s.object->spec();
    if (spec.theta_bins != 0) {
      add(s.name.data(), s.name.size());
      add(&spec.theta_bins, sizeof spec.theta_bins);
      add(&spec.phi_bins, sizeof spec.phi_bins);
    }
  }
  if (scene_.scatters()) add(&config_.max_scatterings, sizeof config_.max_scatterings);
  // What the paths depend on: every visible instance's object name and content (a mesh's positions
  // and triangles; hashed once per object), placement, mask and material, the sensors' shapes and
  // the lights' geometry (a state of a scene where any of these changed would be mixed silently
  // into the continued run). Objects hash their contents (meshes, volume grids: Object::contentHash).
  auto addAffine = [&add](const Affine& a) {
    const std::array<double, 12> m = a.toRowMajor3x4();
    add(m.data(), sizeof m);
  };
  auto addDouble = [&add](double x) { add(&x, sizeof x); };
  std::vector<NodeId> instances = scene_.graph().visibleInstances();
  std::sort(instances.begin(), instances.end());
  std::unordered_map<ObjectId, std::uint64_t> content;  // per object: copies share it
  for (const NodeId node : instances) {
    const NodeInfo info = scene_.graph().node(node);
    const std::string_view object = scene_.graph().library().name(info.object);
    add(object.data(), object.size() + 1);
    auto [it, fresh] = content.try_emplace(info.object, 0);
    if (fresh) it->second = scene_.graph().library().get(info.object)->contentHash();
    add(&it->second, sizeof it->second);
    addAffine(scene_.graph().worldTransform(node));
    add(&info.mask, sizeof info.mask);
    const Material& m = scene_.materialOf(node);
    add(&m.type, sizeof m.type);
    for (const double x : {m.reflectance, m.ior, m.g}) addDouble(x);
    add(m.band_reflectance.data(), m.band_reflectance.size() * sizeof(double));
  }
  for (const SensorInstance& s : scene_.sensors()) {
    const SensorSpec& spec = s.object->spec();
    add(&spec.shape, sizeof spec.shape);
    for (const double x : {spec.width, spec.height}) addDouble(x);
    const std::uint32_t grid[3] = {spec.nx, spec.ny, spec.two_sided ? 1u : 0u};
    add(grid, sizeof grid);
  }
  for (const Light& l : scene_.lights()) {
    add(&l.type, sizeof l.type);
    for (const glm::dvec3& v : {l.position, l.direction}) addDouble(v.x), addDouble(v.y), addDouble(v.z);
    for (const double x : {l.cone_angle, l.radius, l.width, l.height}) addDouble(x);
    addAffine(l.world_from_light);
    const std::uint8_t two_sided = l.two_sided ? 1 : 0;
    add(&two_sided, 1);
    if (l.profile) addDouble(l.profile->integral());
  }
  return h;
}

namespace {

// Version 4's fingerprint hashes volume grids too; version 3's hashed mesh contents only; version 2
// ended with the same checksum of every byte before it; version 1 had none. Older versions are
// refused by name, saying what they lack.
constexpr char kStateMagic[8] = {'D', 'X', 'S', 'E', 'N', 'S', 'R', '4'};
struct OlderState {
  char magic[8];
  const char* lacks;
};
constexpr OlderState kOlderStates[] = {{{'D', 'X', 'S', 'E', 'N', 'S', 'R', '1'}, "no checksum"},
                                       {{'D', 'X', 'S', 'E', 'N', 'S', 'R', '2'}, "mesh contents not fingerprinted"},
                                       {{'D', 'X', 'S', 'E', 'N', 'S', 'R', '3'}, "volume grids not fingerprinted"}};

// The checksum of the state: XXH64 of every byte before it.
std::uint64_t stateChecksum(std::span<const char> bytes) {
  return xxh64({reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size()});
}

template <class T>
void append(std::vector<char>& out, const T* data, std::size_t count) {
  const auto* p = reinterpret_cast<const char*>(data);
  out.insert(out.end(), p, p + count * sizeof(T));
}

}  // namespace

void SensorRun::saveState(const std::filesystem::path& file) const {
  std::vector<char> bytes;
  const std::uint64_t header[5] = {fingerprint(), config_.seed, rays_done_, bins_.size(), sensor_sums_.size()};
  append(bytes, kStateMagic, sizeof kStateMagic);
  append(bytes, header, 5);
  // The file keeps one array per quantity (the layout of states saved before the accumulators
  // became structures).
  auto put = [&bytes](const auto& v) { append(bytes, v.data(), v.size()); };
  auto column = [](const auto& v, auto field) {
    std::vector<std::remove_cvref_t<decltype(v[0].*field)>> out(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) out[i] = v[i].*field;
    return out;
  };
  put(column(bins_, &BinSums::sum));
  put(column(bins_, &BinSums::sum2));
  put(column(bins_, &BinSums::count));
  put(column(sensor_sums_, &SensorSums::sum));
  put(column(sensor_sums_, &SensorSums::sum2));
  const double energy[5] = {energy_sum_.escaped_w, energy_sum_.absorbed_w, energy_sum_.medium_absorbed_w,
                            energy_sum_.depth_limited_w, energy_sum_.roulette_w};
  append(bytes, energy, 5);
  put(band_bin_sum_);  // empty unless the scene has bands
  put(band_bin_sum2_);
  put(band_sensor_sum_);
  put(band_sensor_sum2_);
  const std::uint64_t checksum = stateChecksum(bytes);
  append(bytes, &checksum, 1);
  // Written beside the file and renamed over it: a process killed while saving leaves the previous
  // state intact, never a half-written one.
  writeFileAtomically(file, {reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size()}, "run state",
                      /*sync=*/true);
}

void SensorRun::loadState(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) throw FileError(file.string() + ": cannot open the run state");
  const std::streamoff size = in.tellg();
  in.seekg(0);
  std::vector<char> bytes(static_cast<std::size_t>(std::max<std::streamoff>(size, 0)));
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!in) throw FileError(file.string() + ": cannot read the run state");
  constexpr std::size_t kHead = sizeof kStateMagic + 5 * sizeof(std::uint64_t);
  for (const OlderState& older : kOlderStates)
    if (bytes.size() >= sizeof older.magic && std::memcmp(bytes.data(), older.magic, sizeof older.magic) == 0)
      throw FileError(file.string() + ": a run state of an older version (" + older.lacks +
                      "): run again without resuming");
  if (bytes.size() < kHead || std::memcmp(bytes.data(), kStateMagic, sizeof kStateMagic) != 0)
    throw FileError(file.string() + ": not a sensor run state");
  std::uint64_t header[5];
  std::memcpy(header, bytes.data() + sizeof kStateMagic, sizeof header);
  if (header[0] != fingerprint() || header[1] != config_.seed || header[3] != bins_.size() ||
      header[4] != sensor_sums_.size())
    throw FileError(file.string() + ": the saved run is of another scene, seed or configuration (seed " +
                    std::to_string(header[1]) + ", " + std::to_string(header[3]) + " bins)");
  const std::size_t nb = bins_.size(), ns = sensor_sums_.size();
  const std::size_t expected =
      kHead + nb * (2 * sizeof(double) + sizeof(std::uint64_t)) + ns * 2 * sizeof(double) + 5 * sizeof(double) +
      (band_bin_sum_.size() + band_bin_sum2_.size() + band_sensor_sum_.size() + band_sensor_sum2_.size()) *
          sizeof(double) +
      sizeof(std::uint64_t);
  if (bytes.size() != expected)
    throw FileError(file.string() + ": run state of " + std::to_string(bytes.size()) + " bytes, expected " +
                    std::to_string(expected) + " (truncated or extended)");
  std::uint64_t stored;
  std::memcpy(&stored, bytes.data() + expected - sizeof stored, sizeof stored);
  if (stateChecksum(std::span<const char>(bytes).first(expected - sizeof stored)) != stored)
    throw FileError(file.string() + ": run state checksum mismatch (damaged file)");
  // Read into copies and check them: a refused file leaves this run as it was.
  std::size_t at = kHead;
  auto get = [&bytes, &at](auto& v) {
    if (v.empty()) return;  // an empty vector's data() may be null, which memcpy must not get
    std::memcpy(v.data(), bytes.data() + at, v.size() * sizeof(v[0]));
    at += v.size() * sizeof(v[0]);
  };
  std::vector<double> b1(nb), b2(nb), s1(ns), s2(ns);
  std::vector<std::uint64_t> bc(nb);
  get(b1);
  get(b2);
  get(bc);
  get(s1);
  get(s2);
  std::array<double, 5> energy;
  get(energy);
  auto bb1 = band_bin_sum_, bb2 = band_bin_sum2_, bs1 = band_sensor_sum_, bs2 = band_sensor_sum2_;
  get(bb1);
  get(bb2);
  get(bs1);
  get(bs2);
  // Powers are finite and non-negative, counts at most the rays done: anything else is not a
  // state this code wrote (a checksum is no proof against a forged file).
  const auto valid = [](std::span<const double> v) {
    return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x) && x >= 0.0; });
  };
  const bool counts_ok = std::all_of(bc.begin(), bc.end(), [&](std::uint64_t c) { return c <= header[2]; });
  if (!valid(b1) || !valid(b2) || !valid(s1) || !valid(s2) || !valid(bb1) || !valid(bb2) || !valid(bs1) ||
      !valid(bs2) || !valid(energy) || !counts_ok)
    throw FileError(file.string() + ": run state holds negative, non-finite or impossible values");
  band_bin_sum_ = std::move(bb1);
  band_bin_sum2_ = std::move(bb2);
  band_sensor_sum_ = std::move(bs1);
  band_sensor_sum2_ = std::move(bs2);
  for (std::size_t i = 0; i < nb; ++i) bins_[i] = {b1[i], b2[i], bc[i]};
  for (std::size_t i = 0; i < ns; ++i) sensor_sums_[i] = {s1[i], s2[i]};
  energy_sum_ = {0.0, energy[0], energy[1], energy[2], energy[3], energy[4]};
  rays_done_ = header[2];
}

}  // namespace duplex
