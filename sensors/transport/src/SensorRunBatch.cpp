// Batches of a sensor run traced in one process and added in another: a batch's tallies (sums over
// its rays only) serialised with the bins it reached, and added to a run's in batch order, exactly
// as runUntil adds the batches it traces itself.
//
// Layout (this machine's byte order): "DXBATCH2", then 64-bit fingerprint, first ray, rays, bins,
// sensors, bands (0: one radiometric band), reached bins R, segments, crossings, scatterings; then
// R bin indices (32-bit), their sums, squares and counts, per band their sums and squares
// (R * bands each), in runs with per-light results per light their sums and squares (R * lights
// each), the sensors' sums and squares, per band theirs, per light theirs, and the energy tallies
// (six powers, six ray counts). Per-light runs hash "per-light" into the fingerprint, so a tally
// with light sums is only ever added to a run that expects them.

#include "duplex/sensors/SensorRun.h"

#include "duplex/accel/Error.h"

#include "SensorRunChunk.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>

namespace duplex {

namespace {

constexpr char kBatchMagic[8] = {'D', 'X', 'B', 'A', 'T', 'C', 'H', '2'};
constexpr std::size_t kBatchHead = sizeof kBatchMagic + 10 * sizeof(std::uint64_t);

template <class T>
void put(std::vector<std::byte>& out, const T* data, std::size_t count) {
  const auto* p = reinterpret_cast<const std::byte*>(data);
  out.insert(out.end(), p, p + count * sizeof(T));
}

}  // namespace

SensorBatchTally SensorRun::traceBatch(std::uint64_t batch, std::uint64_t total_rays) {
  checkScene();
  if (scene_.lights().empty()) throw InvalidArgument("SensorRun: the scene has no light");
  const std::uint64_t first = batch * config_.batch_rays;
  if (batch > total_rays / config_.batch_rays || first >= total_rays)
    throw InvalidArgument("SensorRun::traceBatch: batch " + std::to_string(batch) + " starts after the run's " +
                          std::to_string(total_rays) + " rays");
  const std::uint64_t end = std::min(total_rays, first + config_.batch_rays);
  if (!scratch_) scratch_ = makeTally();
  Tally& t = *scratch_;
  const std::uint64_t traced = traceRange(first, end, t);

  SensorBatchTally out;
  out.batch = batch;
  out.first_ray = first;
  out.rays = traced;
  out.complete = traced == end - first;
  const std::size_t nb = t.band_bin_sum.empty() ? 0 : scene_.bandCount();
  const std::size_t nl = t.light_bin_sum.empty() ? 0 : scene_.lights().size();
  const std::uint64_t head[10] = {fingerprint(),
                                  first,
                                  traced,
                                  t.bins.size(),
                                  t.sensors.size(),
                                  nb,
                                  t.touched.size(),
                                  t.counters.segments,
                                  t.counters.crossings,
                                  t.counters.scatterings};
  std::vector<std::byte>& b = out.bytes;
  b.reserve(kBatchHead + t.touched.size() * (4 + 24 + 16 * (nb + nl)) + t.sensors.size() * 16 * (1 + nb + nl) +
            sizeof(detail::EnergyWords));
  put(b, kBatchMagic, sizeof kBatchMagic);
  put(b, head, 10);
  put(b, t.touched.data(), t.touched.size());
  for (const std::uint32_t i : t.touched) put(b, &t.bins[i].sum, 1);
  for (const std::uint32_t i : t.touched) put(b, &t.bins[i].sum2, 1);
  for (const std::uint32_t i : t.touched) put(b, &t.bins[i].count, 1);
  for (const std::vector<double>* v : {&t.band_bin_sum, &t.band_bin_sum2})
    for (const std::uint32_t i : t.touched)
      if (nb) put(b, v->data() + std::size_t{i} * nb, nb);
  for (const std::vector<double>* v : {&t.light_bin_sum, &t.light_bin_sum2})
    for (const std::uint32_t i : t.touched)
      if (nl) put(b, v->data() + std::size_t{i} * nl, nl);
  for (const std::uint64_t k : {0, 1})
    for (const SensorSums& s : t.sensors) put(b, k ? &s.sum2 : &s.sum, 1);
  put(b, t.band_sensor_sum.data(), t.band_sensor_sum.size());
  put(b, t.band_sensor_sum2.data(), t.band_sensor_sum2.size());
  put(b, t.light_sensor_sum.data(), t.light_sensor_sum.size());
  put(b, t.light_sensor_sum2.data(), t.light_sensor_sum2.size());
  const detail::EnergyWords energy = detail::energyWords(t.energy);
  put(b, &energy, 1);
  detail::clearTally(t, nb, nl);  // for the next batch: only what this one reached
  return out;
}

void SensorRun::addBatch(std::span<const std::byte> tally) {
  checkScene();
  const auto refuse = [](const std::string& why) { throw InvalidArgument("SensorRun::addBatch: " + why); };
  if (tally.size() < kBatchHead || std::memcmp(tally.data(), kBatchMagic, sizeof kBatchMagic) != 0)
    refuse("not a batch tally of this version (" + std::to_string(tally.size()) + " bytes)");
  std::uint64_t h[10];
  std::memcpy(h, tally.data() + sizeof kBatchMagic, sizeof h);
  const std::uint64_t first = h[1], rays = h[2], reached = h[6];
  const std::size_t nb = open_->band_bin_sum.empty() ? 0 : scene_.bandCount();
  const std::size_t nl = open_->light_bin_sum.empty() ? 0 : scene_.lights().size();
  if (h[0] != fingerprint() || h[3] != closed_->bins.size() || h[4] != closed_->sensors.size() || h[5] != nb)
    refuse("the batch is of another scene, seed or configuration");
  if (first != rays_done_ || rays_done_ % config_.batch_rays != 0)
    refuse("batch starting at ray " + std::to_string(first) + " added to a run of " + std::to_string(rays_done_) +
           " rays (batches are added in order, each from its start)");
  if (rays == 0 || rays > config_.batch_rays || reached > h[3])
    refuse("batch of " + std::to_string(rays) + " rays reaching " + std::to_string(reached) + " bins");
  const std::size_t ns = closed_->sensors.size();
  const std::size_t expected =
      kBatchHead + reached * (sizeof(std::uint32_t) + 2 * sizeof(double) + sizeof(std::uint64_t)) +
      reached * 2 * (nb + nl) * sizeof(double) + ns * 2 * (1 + nb + nl) * sizeof(double) + sizeof(detail::EnergyWords);
  if (tally.size() != expected)
    refuse("batch tally of " + std::to_string(tally.size()) + " bytes, expected " + std::to_string(expected));
  // Read into the spare tallies and check them: a refused batch leaves the run as it was.
  if (!incoming_) incoming_ = makeTally();
  Tally& t = *incoming_;
  std::size_t at = kBatchHead;
  const auto get = [&](void* dst, std::size_t bytes) {
    if (bytes) std::memcpy(dst, tally.data() + at, bytes);
    at += bytes;
  };
  t.touched.resize(reached);
  get(t.touched.data(), reached * sizeof(std::uint32_t));
  bool ok = true;
  std::size_t filled = 0;  // bins of t.touched written so far (emptied again on a refusal)
  const auto value = [&ok](double x) {
    ok = ok && std::isfinite(x) && x >= 0.0;
    return x;
  };
  for (; filled < reached && ok; ++filled) {
    const std::uint32_t i = t.touched[filled];
    ok = i < t.bins.size() && t.bins[i].count == 0;  // each bin once
    if (!ok) break;
    double sum, sum2;
    std::uint64_t count;
    std::memcpy(&sum, tally.data() + at + filled * sizeof(double), sizeof sum);
    std::memcpy(&sum2, tally.data() + at + (reached + filled) * sizeof(double), sizeof sum2);
    std::memcpy(&count, tally.data() + at + 2 * reached * sizeof(double) + filled * sizeof count, sizeof count);
    ok = count >= 1 && count <= rays;
    t.bins[i] = {value(sum), value(sum2), count};
  }
  at += reached * (2 * sizeof(double) + sizeof(std::uint64_t));
  for (std::vector<double>* v : {&t.band_bin_sum, &t.band_bin_sum2})
    for (std::size_t r = 0; ok && r < reached; ++r) {
      get(v->data() + std::size_t{t.touched[r]} * nb, nb * sizeof(double));
      for (std::size_t k = 0; k < nb; ++k) value((*v)[std::size_t{t.touched[r]} * nb + k]);
    }
  for (std::vector<double>* v : {&t.light_bin_sum, &t.light_bin_sum2})
    for (std::size_t r = 0; ok && r < reached; ++r) {
      get(v->data() + std::size_t{t.touched[r]} * nl, nl * sizeof(double));
      for (std::size_t k = 0; k < nl; ++k) value((*v)[std::size_t{t.touched[r]} * nl + k]);
    }
  if (ok) {
    for (std::size_t k = 0; k < 2; ++k)
      for (SensorSums& s : t.sensors) {
        double x;
        get(&x, sizeof x);
        (k ? s.sum2 : s.sum) = value(x);
      }
    get(t.band_sensor_sum.data(), t.band_sensor_sum.size() * sizeof(double));
    get(t.band_sensor_sum2.data(), t.band_sensor_sum2.size() * sizeof(double));
    get(t.light_sensor_sum.data(), t.light_sensor_sum.size() * sizeof(double));
    get(t.light_sensor_sum2.data(), t.light_sensor_sum2.size() * sizeof(double));
    for (const std::vector<double>* v :
         {&t.band_sensor_sum, &t.band_sensor_sum2, &t.light_sensor_sum, &t.light_sensor_sum2})
      for (const double x : *v) value(x);
    detail::EnergyWords energy;
    get(&energy, sizeof energy);
    ok = ok && detail::energyFromWords(energy, rays, t.energy);
    t.counters = {h[7], h[8], h[9]};
    t.rays = rays;
  }
  if (!ok) {
    // Empty the spare tallies again: the bins written so far (the others are zero).
    t.touched.resize(std::min(filled + 1, reached));
    std::erase_if(t.touched, [&t](std::uint32_t i) { return i >= t.bins.size(); });
    detail::clearTally(t, nb, nl);
    refuse("batch tally holds repeated or out-of-range bins, or negative, non-finite or impossible values");
  }
  rays_done_ += rays;
  if (rays == config_.batch_rays) {
    // A full batch: added to the finished ones, as closeBatch does.
    std::swap(open_, incoming_);
    closeBatch();
    std::swap(open_, incoming_);
  } else {
    std::swap(open_, incoming_);  // the run's last batch, shorter: open, as runUntil leaves it
  }
}

}  // namespace duplex
