// Saved states of a sensor run (checkpoints and resume): the raw accumulators with the run's
// fingerprint, written atomically and checked on reading.

#include "duplex/sensors/SensorRun.h"

#include "duplex/accel/AtomicFile.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/Xxh64.h"

#include "SensorRunChunk.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace duplex {

// ---- saved state: "DXSENSR6", fingerprint, seed, rays, sizes, the raw accumulators of the finished
// batches (and of the open batch when the rays end inside one), XXH64 checksum ----

std::uint64_t SensorRun::fingerprint() const {
  std::call_once(fingerprint_once_, [this] { fingerprint_ = computeFingerprint(); });
  return fingerprint_;
}

std::uint64_t SensorRun::computeFingerprint() const {
  // FNV-1a over what the accumulators' meaning depends on.
  StateHash h;
  auto add = [&h](const void* p, std::size_t n) { h.bytes(p, n); };
  for (const SensorInstance& s : scene_.sensors()) {
    add(s.name.data(), s.name.size());
    const std::uint32_t bins = s.object->binCount();
    add(&bins, sizeof bins);
  }
  for (const Light& l : scene_.lights()) add(&l.power_w, sizeof l.power_w);
  add(&config_.seed, sizeof config_.seed);
  add(&config_.batch_rays, sizeof config_.batch_rays);  // the grouping of the sums
  add(&config_.max_depth, sizeof config_.max_depth);
  add(&config_.roulette_depth, sizeof config_.roulette_depth);
  // The transport model: a state traced by another (unpolarised Fresnel, other restart offsets)
  // must not be mixed into this run's sums.
  static constexpr char kModel[] = "polarised-fresnel, triangle-error restarts, deep roulette";
  add(kModel, sizeof kModel);
  add(&config_.roulette_threshold, sizeof config_.roulette_threshold);
  // Bands, angular bins and free flights are added only where a scene uses them.
  for (std::size_t l = 0; !scene_.bands().empty() && l < scene_.lights().size(); ++l) {
    const std::vector<double>& cdf = scene_.bandCdf(l);
    add(cdf.data(), cdf.size() * sizeof(double));
  }
  for (const std::string& b : scene_.bands()) add(b.data(), b.size() + 1);
  for (const PointMeter& m : scene_.meters()) {  // meters: their points are bins of the state
    add(m.name.data(), m.name.size() + 1);
    add(m.points.data(), m.points.size() * sizeof(glm::dvec3));
    add(m.normals.data(), m.normals.size() * sizeof(glm::dvec3));
    if (m.half_angle > 0.0) add(&m.half_angle, sizeof m.half_angle);  // a luminance meter
    if (m.image_width != 0) add(m.pixel_solid_angle.data(), m.pixel_solid_angle.size() * sizeof(double));
  }
  if (config_.per_light) {  // the state then holds per-light sums
    static constexpr char kPerLight[] = "per-light";
    add(kPerLight, sizeof kPerLight);
  }
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
    // Each material adds its type and parameters (a type cannot leave out its hash: Material.h).
    scene_.materialOf(node).hash(h);
  }
  for (const SensorInstance& s : scene_.sensors()) {
    const SensorSpec& spec = s.object->spec();
    if (spec.shape == SensorShape::FarField) addAffine(s.world_from_object);  // not an instance of the graph
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
    const std::uint8_t shape[2] = {static_cast<std::uint8_t>(l.two_sided ? 1 : 0),
                                   static_cast<std::uint8_t>(l.disk ? 1 : 0)};  // a disk or its square
    add(shape, sizeof shape);
    add(l.polygon.data(), l.polygon.size() * sizeof(glm::dvec2));
    add(l.triangles.data(), l.triangles.size() * sizeof(l.triangles[0]));
    if (l.profile) addDouble(l.profile->integral());
    if (l.sky) {  // its shape: the type and the sun it follows
      addDouble(l.sky->type());
      for (int k = 0; k < 3; ++k) addDouble(l.sky->sun()[k]);
    }
  }
  return h.value;
}

namespace {

// The format is "DXSENSR" and one version character. A 0.x library owes no compatibility with its
// own earlier states: any other magic or version is refused, naming both.
constexpr char kStateMagic[8] = {'D', 'X', 'S', 'E', 'N', 'S', 'R', '6'};

// The first bytes of a file as a quoted string, non-printable bytes as \xNN.
std::string quotedPrefix(std::span<const char> bytes) {
  std::string out = "\"";
  for (const char c : bytes) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u < 0x7f && c != '"' && c != '\\') {
      out += c;
    } else {
      constexpr char kHex[] = "0123456789abcdef";
      out += {'\\', 'x', kHex[u >> 4], kHex[u & 15]};
    }
  }
  return out + "\"";
}

// The checksum of the state: XXH64 of every byte before it.
std::uint64_t stateChecksum(std::span<const char> bytes) {
  return xxh64({reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size()});
}

template <class T>
void append(std::vector<char>& out, const T* data, std::size_t count) {
  const auto* p = reinterpret_cast<const char*>(data);
  out.insert(out.end(), p, p + count * sizeof(T));
}

// One tally's accumulators, one array per quantity.
template <class Tally>
void putTally(std::vector<char>& bytes, const Tally& t) {
  auto put = [&bytes](const auto& v) { append(bytes, v.data(), v.size()); };
  auto column = [](const auto& v, auto field) {
    std::vector<std::remove_cvref_t<decltype(v[0].*field)>> out(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) out[i] = v[i].*field;
    return out;
  };
  using Bin = typename decltype(t.bins)::value_type;
  using Sensor = typename decltype(t.sensors)::value_type;
  put(column(t.bins, &Bin::sum));
  put(column(t.bins, &Bin::sum2));
  put(column(t.bins, &Bin::count));
  put(column(t.sensors, &Sensor::sum));
  put(column(t.sensors, &Sensor::sum2));
  const detail::EnergyWords energy = detail::energyWords(t.energy);
  append(bytes, &energy, 1);
  put(t.band_bin_sum);  // empty unless the scene has bands
  put(t.band_bin_sum2);
  put(t.band_sensor_sum);
  put(t.band_sensor_sum2);
  put(t.light_bin_sum);  // empty unless the run keeps per-light results
  put(t.light_bin_sum2);
  put(t.light_sensor_sum);
  put(t.light_sensor_sum2);
}

// The bytes putTally writes for a tally shaped like `t`.
template <class Tally>
std::size_t tallyBytes(const Tally& t) {
  return t.bins.size() * (2 * sizeof(double) + sizeof(std::uint64_t)) + t.sensors.size() * 2 * sizeof(double) +
         sizeof(detail::EnergyWords) +
         (t.band_bin_sum.size() + t.band_bin_sum2.size() + t.band_sensor_sum.size() + t.band_sensor_sum2.size() +
          t.light_bin_sum.size() + t.light_bin_sum2.size() + t.light_sensor_sum.size() + t.light_sensor_sum2.size()) *
             sizeof(double);
}

// Reads what putTally wrote at `at` into `t` (shaped as the scene's) and advances `at`; false for
// negative or non-finite sums or counts above `rays` (not a state this code wrote: a checksum is
// no proof against a forged file).
template <class Tally>
bool getTally(const std::vector<char>& bytes, std::size_t& at, Tally& t, std::uint64_t rays) {
  auto get = [&bytes, &at](auto& v) {
    if (v.empty()) return;  // an empty vector's data() may be null, which memcpy must not get
    std::memcpy(v.data(), bytes.data() + at, v.size() * sizeof(v[0]));
    at += v.size() * sizeof(v[0]);
  };
  const std::size_t nb = t.bins.size(), ns = t.sensors.size();
  std::vector<double> b1(nb), b2(nb), s1(ns), s2(ns);
  std::vector<std::uint64_t> bc(nb);
  get(b1);
  get(b2);
  get(bc);
  get(s1);
  get(s2);
  std::array<detail::EnergyWords, 1> energy;
  get(energy);
  get(t.band_bin_sum);
  get(t.band_bin_sum2);
  get(t.band_sensor_sum);
  get(t.band_sensor_sum2);
  get(t.light_bin_sum);
  get(t.light_bin_sum2);
  get(t.light_sensor_sum);
  get(t.light_sensor_sum2);
  const auto valid = [](std::span<const double> v) {
    return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x) && x >= 0.0; });
  };
  const bool counts_ok = std::all_of(bc.begin(), bc.end(), [&](std::uint64_t c) { return c <= rays; });
  EnergyBalance e;
  const bool energy_ok = detail::energyFromWords(energy[0], rays, e);
  if (!valid(b1) || !valid(b2) || !valid(s1) || !valid(s2) || !valid(t.band_bin_sum) || !valid(t.band_bin_sum2) ||
      !valid(t.band_sensor_sum) || !valid(t.band_sensor_sum2) || !valid(t.light_bin_sum) || !valid(t.light_bin_sum2) ||
      !valid(t.light_sensor_sum) || !valid(t.light_sensor_sum2) || !energy_ok || !counts_ok)
    return false;
  t.touched.clear();
  for (std::size_t i = 0; i < nb; ++i) {
    t.bins[i] = {b1[i], b2[i], bc[i]};
    if (bc[i] != 0) t.touched.push_back(static_cast<std::uint32_t>(i));
  }
  for (std::size_t i = 0; i < ns; ++i) t.sensors[i] = {s1[i], s2[i]};
  t.energy = e;
  t.rays = rays;
  return true;
}

}  // namespace

void SensorRun::saveState(const std::filesystem::path& file) const {
  checkScene();
  std::vector<char> bytes;
  const std::uint64_t header[5] = {fingerprint(), config_.seed, rays_done_, closed_->bins.size(),
                                   closed_->sensors.size()};
  append(bytes, kStateMagic, sizeof kStateMagic);
  append(bytes, header, 5);
  putTally(bytes, *closed_);
  if (rays_done_ % config_.batch_rays != 0) putTally(bytes, *open_);
  const std::uint64_t checksum = stateChecksum(bytes);
  append(bytes, &checksum, 1);
  // Written beside the file and renamed over it: a process killed while saving leaves the previous
  // state intact, never a half-written one.
  writeFileAtomically(file, {reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size()}, "run state",
                      /*sync=*/true);
}

void SensorRun::loadState(const std::filesystem::path& file) {
  checkScene();
  if (const std::string problem = notRegularFile(file); !problem.empty())
    throw FileError(file.string() + ": cannot open the run state: " + problem);
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) throw FileError(file.string() + ": cannot open the run state");
  const std::streamoff size = in.tellg();
  in.seekg(0);
  std::vector<char> bytes(static_cast<std::size_t>(std::max<std::streamoff>(size, 0)));
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!in) throw FileError(file.string() + ": cannot read the run state");
  constexpr std::size_t kHead = sizeof kStateMagic + 5 * sizeof(std::uint64_t);
  if (bytes.size() < sizeof kStateMagic || std::memcmp(bytes.data(), kStateMagic, sizeof kStateMagic) != 0)
    throw FileError(file.string() + ": not a run state of this version (found " +
                    quotedPrefix(std::span<const char>(bytes).first(std::min(bytes.size(), sizeof kStateMagic))) +
                    ", expected " + quotedPrefix(kStateMagic) + "): run again without resuming");
  if (bytes.size() < kHead)
    throw FileError(file.string() + ": run state of " + std::to_string(bytes.size()) + " bytes, truncated");
  std::uint64_t header[5];
  std::memcpy(header, bytes.data() + sizeof kStateMagic, sizeof header);
  if (header[0] != fingerprint() || header[1] != config_.seed || header[3] != closed_->bins.size() ||
      header[4] != closed_->sensors.size())
    throw FileError(file.string() + ": the saved run is of another scene, seed or configuration (seed " +
                    std::to_string(header[1]) + ", " + std::to_string(header[3]) + " bins)");
  // Rays in the open batch: its accumulators follow the finished batches'.
  const std::uint64_t open_rays = header[2] % config_.batch_rays;
  const std::size_t expected = kHead + tallyBytes(*closed_) * (open_rays ? 2 : 1) + sizeof(std::uint64_t);
  if (bytes.size() != expected)
    throw FileError(file.string() + ": run state of " + std::to_string(bytes.size()) + " bytes, expected " +
                    std::to_string(expected) + " (truncated or extended)");
  std::uint64_t stored;
  std::memcpy(&stored, bytes.data() + expected - sizeof stored, sizeof stored);
  if (stateChecksum(std::span<const char>(bytes).first(expected - sizeof stored)) != stored)
    throw FileError(file.string() + ": run state checksum mismatch (damaged file)");
  // Read into copies and check them: a refused file leaves this run as it was.
  std::size_t at = kHead;
  std::unique_ptr<Tally> closed = makeTally(), open = makeTally();
  if (!getTally(bytes, at, *closed, header[2] - open_rays) || (open_rays && !getTally(bytes, at, *open, open_rays)))
    throw FileError(file.string() + ": run state holds negative, non-finite or impossible values");
  closed->touched.clear();  // the run's tallies are added to, never sent or emptied
  closed_ = std::move(closed);
  open_ = std::move(open);
  rays_done_ = header[2];
}

}  // namespace duplex
