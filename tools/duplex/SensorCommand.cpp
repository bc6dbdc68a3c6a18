#include "SensorCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "StructureOption.h"
#include "LoadScene.h"
#include "SensorExr.h"
#include "SensorImage.h"
#include "SensorOutput.h"
#include "SensorRanks.h"
#include "WorkerThreads.h"

#include <duplex/accel/AtomicFile.h>
#include <duplex/accel/Error.h>
#include <duplex/accel/InputFile.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/sensors/IesProfile.h>
#include <duplex/sensors/SensorRun.h>
#include <duplex/sensors/SensorScene.h>

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <numbers>
#include <optional>
#include <span>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::cli {

namespace {

// What a SIGINT / SIGTERM stops: the scene load (its cancel token) and then the run. Lock-free
// atomics only: the handler may run on any thread.
std::atomic<SensorRun*> g_running{nullptr};
std::atomic<CancelToken*> g_loading{nullptr};
std::atomic<int> g_stop_signal{0};
static_assert(std::atomic<SensorRun*>::is_always_lock_free && std::atomic<CancelToken*>::is_always_lock_free &&
              std::atomic<int>::is_always_lock_free);

extern "C" void onStopSignal(int sig) {
  g_stop_signal.store(sig, std::memory_order_relaxed);
  if (CancelToken* token = g_loading.load(std::memory_order_relaxed)) token->cancel();
  if (SensorRun* run = g_running.load(std::memory_order_relaxed)) run->cancel();
}

// While alive (from the command's start), SIGINT and SIGTERM stop the scene load, or the run after
// the chunks in flight (so that the rays traced so far are saved and can be resumed), instead of
// killing the process; a second signal kills it as usual (SA_RESETHAND). The previous handlers
// come back at the end of the scope.
class StopSignals {
 public:
  explicit StopSignals(CancelToken& loading) {
    g_stop_signal.store(0);
    g_loading.store(&loading);
    struct sigaction sa {};
    sa.sa_handler = onStopSignal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESETHAND;
    ::sigaction(SIGINT, &sa, &old_int_);
    ::sigaction(SIGTERM, &sa, &old_term_);
  }
  // From now on a signal stops `run` (the load is over); one that came in between stops it at once.
  void running(SensorRun& run) {
    g_loading.store(nullptr);
    g_running.store(&run);
    if (g_stop_signal.load() != 0) run.cancel();
  }
  // The previous handlers again (after the run: a signal while the results are written kills the
  // process as usual, since the state file is already saved).
  void release() {
    if (released_) return;
    released_ = true;
    ::sigaction(SIGINT, &old_int_, nullptr);
    ::sigaction(SIGTERM, &old_term_, nullptr);
    g_running.store(nullptr);
    g_loading.store(nullptr);
  }
  ~StopSignals() { release(); }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
  bool released_ = false;
};

// Every sensor writes DIR/<file name>.{json,csv,png,exr}, every camera DIR/<file name>.{png,exr},
// and the run writes DIR/run.json: two of them whose names map to one file name (or one called
// "run") would overwrite each other.
void checkOutputNames(const SensorScene& scene, const std::filesystem::path& scene_file) {
  std::map<std::string, std::string> owner;
  const auto claim = [&](const std::string& kind, const std::string& name, const char* extension) {
    const std::string base = sensorFileStem(name), what = kind + " '" + name + "'";
    // NAME_MAX of Linux file systems, for the longest of the files written (".json", ".png", ...).
    if (base.size() + 5 > 255)
      throw InvalidArgument(scene_file.string() + ": " + kind + " name '" + name.substr(0, 40) + "...' (" +
                            std::to_string(name.size()) +
                            " characters) is too long for its output files' names (at most 250); shorten it");
    if (base == "run")
      throw InvalidArgument(scene_file.string() + ": " + what + " would write run" + extension +
                            (kind == "sensor" ? "" : " beside run.json") + ", the run's report; rename the " + kind);
    const auto [it, fresh] = owner.emplace(base, what);
    if (!fresh)
      throw InvalidArgument(scene_file.string() + ": " + it->second + " and " + what + " would both write " + base +
                            extension + " (characters other than [A-Za-z0-9._-] become '_'); rename one");
  };
  for (const SensorInstance& s : scene.sensors()) claim("sensor", s.name, ".json");
  for (const PointMeter& m : scene.meters())
    if (m.image_width != 0) claim("camera", m.name, ".png");
}

// JSON has no infinity: a relative error with nothing measured is written as null.
nlohmann::ordered_json finiteOrNull(double v) {
  return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

// Every result file appears whole or not at all (a full disk is an error naming it, and an earlier
// run's file of the same name stays as it was).
void writeText(const std::filesystem::path& path, const std::string& text) {
  writeFileAtomically(path, {reinterpret_cast<const unsigned char*>(text.data()), text.size()}, "sensor result", false);
}

std::string duration(double s) {
  char buf[32];
  if (!std::isfinite(s)) return "?";
  if (s < 60) std::snprintf(buf, sizeof buf, "%.0f s", s);
  else if (s < 3600) std::snprintf(buf, sizeof buf, "%.0f min %02.0f s", std::floor(s / 60), std::fmod(s, 60));
  else std::snprintf(buf, sizeof buf, "%.0f h %02.0f min", std::floor(s / 3600), std::fmod(s / 60, 60));
  return buf;
}

// Progress on stderr: a bar redrawn in place on a terminal, a plain line at most every 2 s otherwise.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(std::string mode) {
    if (mode == "auto") mode = ::isatty(2) ? "bar" : "lines";
    bar_ = mode == "bar";
    lines_ = mode == "lines";
  }
  void operator()(const SensorProgress& p) {
    const double rate = p.seconds > 0 ? static_cast<double>(p.rays_this_call) / p.seconds : 0.0;
    const double left = rate > 0 ? static_cast<double>(p.rays_target - p.rays_done) / rate : INFINITY;
    const double frac = p.rays_target ? static_cast<double>(p.rays_done) / static_cast<double>(p.rays_target) : 1.0;
    char line[256];
    if (bar_) {
      const int width = 30, filled = static_cast<int>(frac * width);
      std::string bar(static_cast<std::size_t>(filled), '#');
      bar.resize(width, '.');
      std::snprintf(line, sizeof line, "\r[%s] %5.1f%%  %llu / %llu rays  %.3g rays/s  ETA %s   ", bar.c_str(),
                    100 * frac, static_cast<unsigned long long>(p.rays_done),
                    static_cast<unsigned long long>(p.rays_target), rate, duration(left).c_str());
      std::cerr << line << std::flush;
      drawn_ = true;
    } else if (lines_ && (p.seconds - last_ >= 2.0 || p.rays_done == p.rays_target)) {
      last_ = p.seconds;
      std::snprintf(line, sizeof line, "progress: %llu / %llu rays (%.1f%%), %.3g rays/s, ETA %s\n",
                    static_cast<unsigned long long>(p.rays_done), static_cast<unsigned long long>(p.rays_target),
                    100 * frac, rate, duration(left).c_str());
      std::cerr << line << std::flush;
    }
  }
  // A line of its own between progress reports (after a drawn bar: on the next line; the bar is
  // drawn again below it by the next report).
  void note(const std::string& text) {
    if (drawn_) std::cerr << '\n';
    drawn_ = false;
    std::cerr << text << '\n' << std::flush;
  }
  ~ProgressPrinter() {
    if (drawn_) std::cerr << '\n';
  }

 private:
  bool bar_ = false, lines_ = false, drawn_ = false;
  double last_ = -1e9;
};

// The keys every sensor file has after its shape: the emitted power and the sensor's totals.
// A radiometric value or array, or null in a run that transports lumens (SensorRunResults::
// luminous_transport): its "_w" quantities hold lumens, which a "_w" key must never show.
template <class T>
nlohmann::ordered_json radiometric(const T& value, const SensorRunResults& r) {
  return r.luminous_transport ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(value);
}

void putTotals(nlohmann::ordered_json& j, const SensorResult& s, const SensorRunResults& r) {
  j["emitted_power_w"] = radiometric(r.energy.emitted_w, r);
  j["total_flux_w"] = radiometric(s.total_flux_w, r);
  j["total_flux_stderr_w"] = radiometric(s.total_flux_stderr_w, r);
  j["relative_stderr"] = finiteOrNull(s.relative_stderr);
  j["efficiency"] = s.efficiency;
}

// Spectral scenes: the band names and the sensor's per-band totals, before its per-band arrays.
void putBandTotals(nlohmann::ordered_json& j, const SensorResult& s, const SensorRunResults& r) {
  j["bands"] = r.bands;
  j["band_total_flux_w"] = radiometric(s.band_total_flux_w, r);
  j["band_total_flux_stderr_w"] = radiometric(s.band_total_flux_stderr_w, r);
}

// Runs with per-light results: "lights", one entry per light with its totals and, with `maps`, its
// per-bin arrays under the sensor's own key names (`value`, `value_stderr`: irradiance or, for a
// far field, intensity; `lum`, `lum_stderr`: their luminous keys).
void putPerLight(nlohmann::ordered_json& j, const SensorResult& s, const SensorRunResults& r, const char* value,
                 const char* value_stderr, const char* lum, const char* lum_stderr, bool maps) {
  if (r.light_names.empty()) return;
  nlohmann::ordered_json lights = nlohmann::ordered_json::array();
  for (std::size_t l = 0; l < r.light_names.size(); ++l) {
    nlohmann::ordered_json e;
    e["name"] = r.light_names[l];
    e["total_flux_w"] = radiometric(s.light_total_flux_w[l], r);
    e["total_flux_stderr_w"] = radiometric(s.light_total_flux_stderr_w[l], r);
    if (maps) {
      e[value] = radiometric(s.light_irradiance_w_m2[l], r);
      e[value_stderr] = radiometric(s.light_stderr_w_m2[l], r);
      e["flux_w"] = radiometric(s.light_flux_w[l], r);
      e["flux_stderr_w"] = radiometric(s.light_flux_stderr_w[l], r);
    }
    if (!s.light_luminous_flux_lm.empty()) {
      e["total_flux_lm"] = s.light_luminous_flux_lm[l];
      e["total_flux_stderr_lm"] = s.light_luminous_flux_stderr_lm[l];
      if (maps) {
        e[lum] = s.light_illuminance_lx[l];
        e[lum_stderr] = s.light_illuminance_stderr_lx[l];
      }
    }
    lights.push_back(std::move(e));
  }
  j["lights"] = std::move(lights);
}

// Three values of a CSV row ("a,b,c", 17 significant digits), or ",," when `empty` (a run that
// transports lumens leaves its "_w" columns empty).
std::string csvFields(double a, double b, double c, bool empty = false) {
  if (empty) return ",,";
  char text[96];
  std::snprintf(text, sizeof text, "%.17g,%.17g,%.17g", a, b, c);
  return text;
}

// run.json's "meters": per meter its points and normals (world space) and per point the
// irradiance on the plane of its normal, its standard error and the rays that connected, with
// the luminous and per-light values where the run has them.
nlohmann::ordered_json meterReport(const SensorRunResults& r, const std::filesystem::path& out) {
  const auto xyz = [](const std::vector<glm::dvec3>& v) {
    nlohmann::ordered_json out = nlohmann::ordered_json::array();
    for (const glm::dvec3& p : v) out.push_back({p.x, p.y, p.z});
    return out;
  };
  nlohmann::ordered_json meters = nlohmann::ordered_json::array();
  for (const MeterResult& m : r.meters) {
    nlohmann::ordered_json j;
    j["name"] = m.name;
    j["points"] = xyz(m.points);
    j["normals"] = xyz(m.normals);
    if (m.image_width != 0) {
      j["image_size"] = {m.image_width, m.image_height};  // pixels, row by row from the top left
      j["png"] = (out / (sensorFileStem(m.name) + ".png")).string();
      if (sensorExrAvailable()) j["exr"] = (out / (sensorFileStem(m.name) + ".exr")).string();
    }
    if (m.luminance()) {  // a luminance meter or a camera
      if (m.half_angle > 0.0) j["half_angle_deg"] = m.half_angle * 180.0 / std::numbers::pi;
      j["radiance_w_m2_sr"] = radiometric(m.radiance_w_m2_sr, r);
      j["radiance_stderr_w_m2_sr"] = radiometric(m.radiance_stderr_w_m2_sr, r);
    } else {
      j["irradiance_w_m2"] = radiometric(m.irradiance_w_m2, r);
      j["stderr_w_m2"] = radiometric(m.stderr_w_m2, r);
    }
    j["ray_count"] = m.ray_count;
    if (r.photometric && m.luminance()) {
      j["luminance_cd_m2"] = m.luminance_cd_m2;
      j["luminance_stderr_cd_m2"] = m.luminance_stderr_cd_m2;
    } else if (r.photometric) {
      j["illuminance_lx"] = m.illuminance_lx;
      j["illuminance_stderr_lx"] = m.illuminance_stderr_lx;
    }
    const bool cone = m.luminance();
    const auto& per_light = cone ? m.light_radiance_w_m2_sr : m.light_irradiance_w_m2;
    const auto& per_light_se = cone ? m.light_radiance_stderr_w_m2_sr : m.light_stderr_w_m2;
    const auto& per_light_lm = cone ? m.light_luminance_cd_m2 : m.light_illuminance_lx;
    if (!per_light.empty()) {
      nlohmann::ordered_json lights = nlohmann::ordered_json::array();
      for (std::size_t l = 0; l < per_light.size(); ++l) {
        nlohmann::ordered_json e{{"name", r.light_names[l]},
                                 {cone ? "radiance_w_m2_sr" : "irradiance_w_m2", radiometric(per_light[l], r)},
                                 {cone ? "stderr_w_m2_sr" : "stderr_w_m2", radiometric(per_light_se[l], r)}};
        if (!per_light_lm.empty()) e[cone ? "luminance_cd_m2" : "illuminance_lx"] = per_light_lm[l];
        lights.push_back(std::move(e));
      }
      j["lights"] = std::move(lights);
    }
    meters.push_back(std::move(j));
  }
  return meters;
}

// Per-bin pairs or triples of a flat array (index n * bin + c) as JSON rows, NaN as null.
nlohmann::ordered_json rows(const std::vector<double>& flat, std::size_t n) {
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  for (std::size_t b = 0; b + n <= flat.size(); b += n) {
    nlohmann::ordered_json row = nlohmann::ordered_json::array();
    for (std::size_t c = 0; c < n; ++c) row.push_back(finiteOrNull(flat[b + c]));
    out.push_back(row);
  }
  return out;
}

// Photometric runs: the sensor's luminous quantities after its radiometric keys (`value` and
// `value_stderr`: the per-bin keys, illuminance or, for a far field, intensity), and in colorimetric
// runs its CIE XYZ and chromaticities. maps: whether the per-bin arrays go into the JSON.
void putPhotometry(nlohmann::ordered_json& j, const SensorResult& s, const SensorRunResults& r, const char* value,
                   const char* value_stderr, bool maps) {
  if (!r.photometric) return;
  j["luminous_flux_lm"] = s.luminous_flux_lm;
  j["luminous_flux_stderr_lm"] = s.luminous_flux_stderr_lm;
  j["emitted_flux_lm"] = r.emitted_lm;
  j["total_flux_lm"] = s.luminous_flux_lm;
  j["total_flux_stderr_lm"] = s.luminous_flux_stderr_lm;
  if (maps) {
    j[value] = s.illuminance_lx;
    j[value_stderr] = s.illuminance_stderr_lx;
    j["flux_lm"] = s.flux_lm;
    j["flux_stderr_lm"] = s.flux_stderr_lm;
  }
  if (!r.colorimetric) return;
  j["total_cie_xyz"] = rows(s.total_cie_xyz, 3)[0];
  j["total_chromaticity_xy"] = rows(s.total_chromaticity_xy, 2)[0];
  if (maps) {
    j["cie_xyz"] = rows(s.cie_xyz, 3);
    j["chromaticity_xy"] = rows(s.chromaticity_xy, 2);
  }
}

// A far-field sensor: DIR/<name>.json (intensity per C-gamma cell, gamma fastest), .csv and an
// LM-63-2002 .ies file of the measured table. Without photometry the values are W/sr, which the
// .ies file's keywords say.
void writeFarFieldFiles(const std::filesystem::path& dir, const SensorResult& s, const SensorInstance& inst,
                        const SensorRunResults& r) {
  const std::string base = sensorFileStem(s.name);
  const SensorObject& object = *inst.object;
  const std::uint32_t nc = s.nx, ng = s.ny;
  std::vector<double> c_deg, gamma_deg;
  for (std::uint32_t ic = 0; ic < nc; ++ic) c_deg.push_back(object.farFieldC(ic));
  for (std::uint32_t ig = 0; ig < ng; ++ig) gamma_deg.push_back(object.farFieldGamma(ig));
  nlohmann::ordered_json j;
  j["name"] = s.name;
  j["rays"] = r.rays;
  j["seed"] = r.seed;
  j["shape"] = "farfield";
  j["bins"] = {nc, ng};
  putTotals(j, s, r);
  j["c_deg"] = c_deg;
  j["gamma_deg"] = gamma_deg;
  // The run's "irradiance" of a far-field cell is its flux per unit solid angle: the intensity.
  j["intensity_w_sr"] = radiometric(s.irradiance_w_m2, r);
  j["intensity_stderr_w_sr"] = radiometric(s.stderr_w_m2, r);
  j["flux_w"] = radiometric(s.flux_w, r);
  j["ray_count"] = s.ray_count;
  j["solid_angle_sr"] = s.bin_area_m2;
  if (!r.bands.empty()) {
    putBandTotals(j, s, r);
    j["band_intensity_w_sr"] = radiometric(s.band_irradiance_w_m2, r);
    j["band_intensity_stderr_w_sr"] = radiometric(s.band_stderr_w_m2, r);
    j["band_flux_w"] = radiometric(s.band_flux_w, r);
  }
  putPhotometry(j, s, r, "intensity_cd", "intensity_stderr_cd", true);
  putPerLight(j, s, r, "intensity_w_sr", "intensity_stderr_w_sr", "intensity_cd", "intensity_stderr_cd", true);
  writeText(dir / (base + ".json"), j.dump() + "\n");

  // Photometric runs append the luminous columns, so the earlier ones keep their places.
  std::string csv = "ic,ig,c_deg,gamma_deg,flux_w,intensity_w_sr,intensity_stderr_w_sr,ray_count";
  csv += r.photometric ? ",flux_lm,intensity_cd,intensity_stderr_cd\n" : "\n";
  char row[128];
  for (std::uint32_t ic = 0; ic < nc; ++ic) {
    for (std::uint32_t ig = 0; ig < ng; ++ig) {
      const std::size_t b = static_cast<std::size_t>(ic) * ng + ig;
      std::snprintf(row, sizeof row, "%u,%u,%.9g,%.9g,", ic, ig, c_deg[ic], gamma_deg[ig]);
      csv += row;
      csv += csvFields(s.flux_w[b], s.irradiance_w_m2[b], s.stderr_w_m2[b], r.luminous_transport);
      csv += "," + std::to_string(s.ray_count[b]);
      if (r.photometric) csv += "," + csvFields(s.flux_lm[b], s.illuminance_lx[b], s.illuminance_stderr_lx[b]);
      csv += '\n';
    }
  }
  writeText(dir / (base + ".csv"), csv);

  writeIes(dir / (base + ".ies"), farFieldIesTable(s, r.rays, r.seed));
}

// A NumPy .npy file (format 1.0) of one array of the given `shape` ("ny, nx"), row-major, little
// endian: what numpy.load reads, written at disk speed. `descr` is the NumPy type of T ("<f8", "<u8").
template <class T>
void writeNpy(const std::filesystem::path& path, std::span<const T> values, const std::string& shape,
              const char* descr) {
  std::ostringstream dict;
  dict << "{'descr': '" << descr << "', 'fortran_order': False, 'shape': (" << shape << "), }";
  std::string header = dict.str();
  // Magic, version, header length, header: the data start at a multiple of 64 bytes.
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header += '\n';
  std::string bytes = "\x93NUMPY";
  bytes += '\x01';
  bytes += '\x00';
  const auto len = static_cast<std::uint16_t>(header.size());
  bytes += static_cast<char>(len & 0xff);
  bytes += static_cast<char>(len >> 8);
  bytes += header;
  AtomicFileWriter out(path, "sensor map");
  out.write({reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size()});
  out.write({reinterpret_cast<const unsigned char*>(values.data()), values.size_bytes()});
  out.commit();
}

void writeSensorFiles(const std::filesystem::path& dir, const SensorResult& s, const SensorInstance& inst,
                      const SensorRunResults& r, std::uint64_t text_map_limit) {
  if (s.shape == SensorShape::FarField) {
    writeFarFieldFiles(dir, s, inst, r);
    return;
  }
  const std::string base = sensorFileStem(s.name);
  const SensorSpec& spec = inst.object->spec();
  nlohmann::ordered_json j;
  j["name"] = s.name;
  j["rays"] = r.rays;
  j["seed"] = r.seed;
  j["shape"] = spec.shape == SensorShape::Disk ? "disk" : spec.shape == SensorShape::Sphere ? "sphere" : "rectangle";
  j["size"] = {spec.width, spec.height};
  if (spec.shape != SensorShape::Rectangle) j["radius"] = 0.5 * spec.width;  // beside "size" (the diameter)
  j["bins"] = {s.nx, s.ny};
  j["two_sided"] = s.two_sided;
  putTotals(j, s, r);
  // Large maps: binary files instead of JSON arrays and CSV rows (--text-map-limit).
  const bool text_maps = static_cast<std::uint64_t>(s.nx) * s.ny <= text_map_limit;
  if (text_maps) {
    j["irradiance_w_m2"] = radiometric(s.irradiance_w_m2, r);
    j["stderr_w_m2"] = radiometric(s.stderr_w_m2, r);
    j["flux_w"] = radiometric(s.flux_w, r);
    j["ray_count"] = s.ray_count;
    j["bin_area_m2"] = s.bin_area_m2;
  } else {
    nlohmann::ordered_json files;
    std::ostringstream shape;
    shape << s.ny << ", " << s.nx;
    auto map = [&](const char* key, const auto& values, const char* descr, const std::string& dims) {
      const std::string file = base + "." + key + ".npy";
      writeNpy(dir / file, std::span(values.data(), values.size()), dims, descr);
      files[key] = file;
    };
    // A run that transports lumens knows no radiometric value: its "_w" maps are NaN.
    auto rad = [&r](const std::vector<double>& values) {
      return r.luminous_transport ? std::vector<double>(values.size(), std::numeric_limits<double>::quiet_NaN())
                                  : values;
    };
    map("irradiance_w_m2", rad(s.irradiance_w_m2), "<f8", shape.str());
    map("stderr_w_m2", rad(s.stderr_w_m2), "<f8", shape.str());
    map("flux_w", rad(s.flux_w), "<f8", shape.str());
    map("ray_count", s.ray_count, "<u8", shape.str());
    map("bin_area_m2", s.bin_area_m2, "<f8", shape.str());
    if (!r.bands.empty()) {  // [band][row][column]
      std::ostringstream dims_text;
      dims_text << r.bands.size() << ", " << shape.str();
      const std::string dims = dims_text.str();
      auto flat = [](const std::vector<std::vector<double>>& per_band) {
        std::vector<double> all;
        for (const auto& b : per_band) all.insert(all.end(), b.begin(), b.end());
        return all;
      };
      map("band_irradiance_w_m2", rad(flat(s.band_irradiance_w_m2)), "<f8", dims);
      map("band_stderr_w_m2", rad(flat(s.band_stderr_w_m2)), "<f8", dims);
      map("band_flux_w", rad(flat(s.band_flux_w)), "<f8", dims);
    }
    if (r.photometric) {
      map("illuminance_lx", s.illuminance_lx, "<f8", shape.str());
      map("illuminance_stderr_lx", s.illuminance_stderr_lx, "<f8", shape.str());
      map("flux_lm", s.flux_lm, "<f8", shape.str());
    }
    if (r.colorimetric) {  // [row][column][component]
      map("cie_xyz", s.cie_xyz, "<f8", shape.str() + ", 3");
      map("chromaticity_xy", s.chromaticity_xy, "<f8", shape.str() + ", 2");
    }
    j["map_files"] = files;
  }
  // Only what the scene asked for: per-band arrays (the keys above are their sums) and angular bins.
  if (!r.bands.empty()) {
    putBandTotals(j, s, r);
    if (text_maps) {
      j["band_irradiance_w_m2"] = radiometric(s.band_irradiance_w_m2, r);
      j["band_stderr_w_m2"] = radiometric(s.band_stderr_w_m2, r);
      j["band_flux_w"] = radiometric(s.band_flux_w, r);
    }
  }
  if (s.theta_bins != 0) {
    j["angular_bins"] = {s.theta_bins, s.phi_bins};
    j["angular_flux_w"] = radiometric(s.angular_flux_w, r);
    j["angular_stderr_w"] = radiometric(s.angular_stderr_w, r);
    j["angular_solid_angle_sr"] = s.angular_solid_angle_sr;
    j["angular_ray_count"] = s.angular_ray_count;
    if (!r.bands.empty()) j["band_angular_flux_w"] = radiometric(s.band_angular_flux_w, r);
    if (r.luminous_transport) {  // the angular flux is then luminous flux
      j["angular_flux_lm"] = s.angular_flux_w;
      j["angular_stderr_lm"] = s.angular_stderr_w;
    }
  }
  putPhotometry(j, s, r, "illuminance_lx", "illuminance_stderr_lx", text_maps);
  putPerLight(j, s, r, "irradiance_w_m2", "stderr_w_m2", "illuminance_lx", "illuminance_stderr_lx", text_maps);
  writeText(dir / (base + ".json"), j.dump() + "\n");

  // CSV: one row per bin with its centre in sensor-local coordinates (a sphere: its direction).
  if (!text_maps) {
    demo::writePng(dir / (base + ".png"), falseColourImage(s.irradiance_w_m2, s.nx, s.ny));
    if (sensorExrAvailable())
      writeSensorExr(dir / (base + ".exr"), s.name, s.irradiance_w_m2, s.stderr_w_m2, s.nx, s.ny);
    return;
  }
  // The bin centre in the sensor's local coordinates (x, y), and in world coordinates (world_x,
  // world_y, world_z: on the sensor's surface, scene units), appended so the earlier columns keep
  // their places.
  std::string csv = "ix,iy,x,y,flux_w,irradiance_w_m2,stderr_w_m2,ray_count,world_x,world_y,world_z";
  csv += r.photometric ? ",flux_lm,illuminance_lx,illuminance_stderr_lx\n" : "\n";
  char row[384];
  for (std::uint32_t iy = 0; iy < s.ny; ++iy) {
    for (std::uint32_t ix = 0; ix < s.nx; ++ix) {
      const std::size_t b = static_cast<std::size_t>(iy) * s.nx + ix;
      // A sphere's bin centre: azimuth in degrees and the normal's z.
      const bool sphere = spec.shape == SensorShape::Sphere;
      const double x = sphere ? (ix + 0.5) * 360.0 / s.nx : -0.5 * spec.width + (ix + 0.5) * spec.width / s.nx;
      const double y = sphere ? -1.0 + (iy + 0.5) * 2.0 / s.ny : -0.5 * spec.height + (iy + 0.5) * spec.height / s.ny;
      glm::dvec3 local(x, y, 0.0);
      if (sphere) {
        const double phi = x * std::numbers::pi / 180.0, rho = std::sqrt(std::max(0.0, 1.0 - y * y));
        local = 0.5 * spec.width * glm::dvec3(rho * std::cos(phi), rho * std::sin(phi), y);
      }
      const glm::dvec3 world = inst.world_from_object.point(local);
      std::snprintf(row, sizeof row, "%u,%u,%.9g,%.9g,", ix, iy, x, y);
      csv += row;
      csv += csvFields(s.flux_w[b], s.irradiance_w_m2[b], s.stderr_w_m2[b], r.luminous_transport);
      std::snprintf(row, sizeof row, ",%llu,%.9g,%.9g,%.9g", static_cast<unsigned long long>(s.ray_count[b]), world.x,
                    world.y, world.z);
      csv += row;
      if (r.photometric) csv += "," + csvFields(s.flux_lm[b], s.illuminance_lx[b], s.illuminance_stderr_lx[b]);
      csv += '\n';
    }
  }
  writeText(dir / (base + ".csv"), csv);
  demo::writePng(dir / (base + ".png"), falseColourImage(s.irradiance_w_m2, s.nx, s.ny));
  if (sensorExrAvailable()) writeSensorExr(dir / (base + ".exr"), s.name, s.irradiance_w_m2, s.stderr_w_m2, s.nx, s.ny);
}

// A camera's image as DIR/<file name>.png (false colour with a scale bar, as a sensor's map) and
// .exr (Y and stderr): luminance in cd/m^2 in photometric runs, else radiance in W/(m^2 sr). The
// camera's pixels run from the top row down, a sensor's bins from the bottom row up: the rows
// are flipped so that both writers show the view upright.
void writeCameraImages(const std::filesystem::path& dir, const MeterResult& m, const SensorRunResults& r) {
  const bool lum = r.photometric;
  const std::vector<double>& value = lum ? m.luminance_cd_m2 : m.radiance_w_m2_sr;
  const std::vector<double>& error = lum ? m.luminance_stderr_cd_m2 : m.radiance_stderr_w_m2_sr;
  const std::uint32_t w = m.image_width, h = m.image_height;
  std::vector<double> up(value.size()), up_error(error.size());
  for (std::uint32_t row = 0; row < h && value.size() == std::size_t{w} * h && error.size() == value.size(); ++row)
    for (std::uint32_t x = 0; x < w; ++x) {
      up[std::size_t{h - 1 - row} * w + x] = value[std::size_t{row} * w + x];
      up_error[std::size_t{h - 1 - row} * w + x] = error[std::size_t{row} * w + x];
    }
  const std::string base = sensorFileStem(m.name);
  demo::writePng(dir / (base + ".png"), falseColourImage(up, w, h));
  if (sensorExrAvailable())
    writeSensorExr(dir / (base + ".exr"), m.name, up, up_error, w, h, lum ? "cd/m^2" : "W/(m^2 sr)");
}

// Whether light from `l` can arrive at the front (the side its normal points to) of the plane
// through `centre` with unit normal `normal`, ignoring what lies between: a point source in front
// of it, a beam travelling against the normal, an area light with a corner in front.
bool reachesFront(const Light& l, const glm::dvec3& centre, const glm::dvec3& normal) {
  if (l.type == LightType::Directional) return glm::dot(l.direction, normal) < 0.0;
  if (l.type == LightType::Sky) return normal.z > -1.0;  // some of the sky is in front of all but a floor's underside
  if (l.type != LightType::Area) return glm::dot(l.position - centre, normal) > 0.0;
  for (const double x : {-0.5 * l.width, 0.5 * l.width})
    for (const double y : {-0.5 * l.height, 0.5 * l.height})
      if (glm::dot(l.world_from_light.point({x, y, 0.0}) - centre, normal) > 0.0) return true;
  return false;
}

// One-sided flat sensors that recorded nothing while every light is behind them: most likely
// turned the wrong way, which the results alone would not show.
void warnBackFacingSensors(const SensorScene& scene, const SensorRunResults& r) {
  for (std::size_t k = 0; k < r.sensors.size(); ++k) {
    const SensorResult& s = r.sensors[k];
    const SensorInstance& inst = scene.sensors()[k];
    if (s.two_sided || s.shape == SensorShape::FarField || s.shape == SensorShape::Sphere || s.total_flux_w != 0.0)
      continue;
    const glm::dvec3 centre = inst.world_from_object.translation;
    bool any = false;
    for (const Light& l : scene.lights()) any = any || reachesFront(l, centre, inst.normal);
    if (!any)
      std::cerr << "duplex sensor: warning: one-sided sensor '" << s.name
                << "' recorded nothing: it records light arriving on its front (normal " << inst.normal.x << ", "
                << inst.normal.y << ", " << inst.normal.z
                << ") and every light is behind it; turn it round or make it two-sided (\"two_sided\": true)\n";
  }
}

nlohmann::ordered_json runSensorOn(SensorRanks& ranks, const SensorOptions& o) {
  if (o.rays == 0) throw InvalidArgument("--rays must be at least 1");
  if (o.target_error < 0.0 || !std::isfinite(o.target_error))
    throw InvalidArgument("--target-error must be a finite number >= 0");
  if (!(o.checkpoint_s >= 0.0 && std::isfinite(o.checkpoint_s)))
    throw InvalidArgument("--checkpoint must be a finite number of seconds >= 0 (0: save only at the end)");
  if (!(o.failure_threshold >= 0.0 && o.failure_threshold <= 1.0))
    throw InvalidArgument("--failure-threshold must be in [0, 1] (got " + std::to_string(o.failure_threshold) + ")");
  if (!(o.roulette >= 0.0 && o.roulette < 1.0))
    throw InvalidArgument("--roulette must be in [0, 1) (got " + std::to_string(o.roulette) + ")");
  // Shared runs: rank 0 reads and writes the files and reports progress; every rank traces.
  const bool files = ranks.rank() == 0;
  const std::string progress = files ? o.progress : "none";
  WorkerThreads workers(o.threads);
  CancelToken loading;
  StopSignals signals(loading);
  SceneDocumentOptions load_options = documentOptions(o.structure);
  load_options.control.cancel = &loading;
  std::optional<SensorScene> loaded;
  std::optional<SensorRun> running;
  std::size_t edit_count = 0, edits_applied = 0;
  std::vector<std::string> stems;  // the sensors' file stems
  const std::filesystem::path state = o.out / "run_state.bin";
  // What may fail on one rank only (its scene, rank 0's state file) fails on every rank together.
  ranks.together([&] {
    if (progress != "none") std::cerr << "loading " << o.scene.string() << '\n' << std::flush;
    try {
      loaded.emplace(workers.arena.execute([&] { return SensorScene::load(o.scene, load_options); }));
    } catch (const Cancelled&) {
      if (g_stop_signal.load() == 0) throw;
    }
    if (g_stop_signal.load() != 0)
      throw Interrupted(g_stop_signal.load(), "stopped while loading the scene; nothing written");
    SensorScene& scene = *loaded;
    // Timed edits: those up to --at T, one commit per time as a player applies them (the scene
    // follows the commits); the others are said on stderr, never silently left out.
    edit_count = scene.document() ? scene.document()->edits.size() : 0;
    if (o.at) {
      if (!(*o.at >= 0.0 && std::isfinite(*o.at))) throw InvalidArgument("--at must be a finite time >= 0 (seconds)");
      if (edit_count != 0)
        edits_applied = workers.arena.execute([&] { return applyEditsUntil(*scene.document(), *o.at); });
    }
    if (edits_applied < edit_count && files) {
      const std::vector<SceneEdit>& edits = scene.document()->edits;
      std::ostringstream note;
      note << "duplex sensor: " << o.scene.string() << " has " << edit_count
           << " timed edit(s) (t = " << edits.front().time << " to " << edits.back().time << " s); ";
      if (o.at)
        note << "--at " << *o.at << " applied " << edits_applied << ", the " << edit_count - edits_applied
             << " after it are not applied";
      else note << "none is applied (--at T applies those with time <= T)";
      std::cerr << note.str() << '\n' << std::flush;
    }
    if (scene.lights().empty()) throw FileError(o.scene.string() + ": the scene has no lights (\"lights\": [...])");
    if (scene.sensors().empty() && scene.meters().empty())
      throw FileError(o.scene.string() +
                      ": the scene has no sensors (\"sensors\": [...]) or meters (\"meters\": [...])");
    checkOutputNames(scene, o.scene);
    for (const SensorInstance& s : scene.sensors()) stems.push_back(sensorFileStem(s.name));
    for (const PointMeter& m : scene.meters())
      if (m.image_width != 0) stems.push_back(sensorFileStem(m.name));
    if (files) checkOutputFolder(o.out, stems, o.resume, o.overwrite);

    SensorRunConfig cfg;
    cfg.seed = o.seed;
    cfg.threads = static_cast<unsigned>(workers.count);
    cfg.max_depth = o.max_depth;
    cfg.roulette_depth = o.roulette_depth;
    cfg.max_scatterings = o.max_scatterings;
    cfg.roulette_threshold = o.roulette;
    cfg.batch_rays = o.batch_rays;
    cfg.per_light = o.per_light;
    running.emplace(scene, cfg);
    if (!files) return;
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec) throw FileError(o.out.string() + ": cannot create the output folder (" + ec.message() + ")");
    // Refused now rather than after the run, when the state is saved.
    if (std::filesystem::exists(state))
      if (const std::string problem = notRegularFile(state); !problem.empty())
        throw FileError(state.string() + ": cannot hold the run state: " + problem);
    if (o.resume) running->loadState(state);
    if (running->raysDone() > o.rays)
      throw InvalidArgument(state.string() + " holds " + std::to_string(running->raysDone()) +
                            " rays, more than --rays " + std::to_string(o.rays));
  });
  const SensorScene& scene = *loaded;
  SensorRun& run = *running;

  SensorStopRule stop;
  if (o.target_error > 0.0) {
    stop.sensor = o.target_sensor.empty() ? 0 : scene.findSensor(o.target_sensor);
    if (stop.sensor < 0)
      throw InvalidArgument("--target-sensor: the scene has no sensor named '" + o.target_sensor + "'");
    stop.target = o.target_error;
    stop.min_rays = std::min<std::uint64_t>(10000, o.rays);
  }
  const std::uint64_t start = run.raysDone();
  const auto t0 = std::chrono::steady_clock::now();
  SensorRunStatus status;
  {
    signals.running(run);
    ProgressPrinter printer(progress);
    // Periodic saves between batches (the accumulators are whole there). A failed save is reported
    // and the run goes on: the previous state file stays intact (saveState writes and renames).
    double last_save = 0.0;
    const auto checkpoint = [&](const SensorProgress& p) {
      if (o.checkpoint_s <= 0.0 || p.seconds - last_save < o.checkpoint_s || p.rays_done >= p.rays_target) return;
      last_save = p.seconds;
      try {
        run.saveState(state);
        if (progress != "none")
          printer.note("checkpoint: " + std::to_string(p.rays_done) + " rays saved to " + state.string());
      } catch (const std::exception& e) {  // FileError (disk full), or bad_alloc for a huge state
        printer.note(std::string("duplex sensor: checkpoint failed (the run goes on): ") + e.what());
      }
    };
    status = ranks.runUntil(
        run, o.rays,
        [&](const SensorProgress& p) {
          printer(p);
          checkpoint(p);
        },
        stop);
    signals.release();
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!files) return nullptr;  // rank 0 saves, writes and reports
  run.saveState(state);
  if (status == SensorRunStatus::Cancelled)
    std::cerr << "duplex sensor: stopped by signal " << g_stop_signal.load() << " after " << run.raysDone()
              << " rays; saved to " << state.string() << " (continue with --resume)\n";

  const SensorRunResults r = run.results();
  nlohmann::ordered_json report;
  report["rays"] = r.rays;
  report["seed"] = r.seed;
  report["threads"] = workers.count;
  report["ranks"] = ranks.size();
  report["max_depth"] =
      o.max_depth == kNoDepthLimit ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(o.max_depth);
  report["roulette_depth"] = o.roulette_depth;
  report["max_scatterings"] = o.max_scatterings;
  report["roulette_threshold"] = o.roulette;
  report["batch_rays"] = o.batch_rays;
  report["status"] = status == SensorRunStatus::TargetReached ? "target_reached"
                     : status == SensorRunStatus::Cancelled   ? "interrupted"
                                                              : "completed";
  if (status == SensorRunStatus::Cancelled) report["signal"] = g_stop_signal.load();
  report["resumed_from"] = start;
  if (o.at) {
    report["at"] = *o.at;
    report["edits_applied"] = edits_applied;
  }
  report["seconds"] = seconds;
  report["rays_per_s"] = seconds > 0 ? static_cast<double>(r.rays - start) / seconds : 0.0;
  report["emitted_power_w"] = radiometric(r.energy.emitted_w, r);
  const EnergyBalance& e = r.energy;
  nlohmann::ordered_json energy = nlohmann::ordered_json::object();
  for (const EnergyEnding& k : kEnergyEndings) {
    energy[std::string(k.name) + "_w"] = radiometric(e.*k.power, r);
    energy[std::string(k.name) + "_rays"] = e.*k.rays;
  }
  // A run that transports lumens: the same balance in lumens, after the existing keys.
  for (const EnergyEnding& k : kEnergyEndings)
    if (r.luminous_transport) energy[std::string(k.name) + "_lm"] = e.*k.power;
  report["energy"] = std::move(energy);
  report["failure_threshold"] = o.failure_threshold;
  const char* unit = r.luminous_transport ? " lm, " : " W, ";  // what the run transports
  if (e.failed_rays != 0 && e.failed_w > o.failure_threshold * e.emitted_w)
    std::cerr << "duplex sensor: warning: numerical failures ended " << e.failed_rays << " of " << r.rays
              << " paths, carrying " << e.failed_w << unit << 100.0 * e.failed_w / e.emitted_w
              << "% of the emitted power (above --failure-threshold " << 100.0 * o.failure_threshold
              << "%): the results miss that power\n";
  // A cap on the path length loses what the cut paths would still have deposited: a bias that the
  // standard errors do not show, so it is said whenever it is not negligible.
  if (e.depth_limited_rays != 0 && e.depth_limited_w > o.failure_threshold * e.emitted_w)
    std::cerr << "duplex sensor: warning: the path limits cut " << e.depth_limited_rays << " of " << r.rays
              << " paths, carrying " << e.depth_limited_w << unit << 100.0 * e.depth_limited_w / e.emitted_w
              << "% of the emitted power (above --failure-threshold " << 100.0 * o.failure_threshold
              << "%): the results miss what those paths would still have deposited; "
              << (scene.scatters() ? "--max-depth none (the default) and a larger --max-scatterings remove it\n"
                                   : "--max-depth none (the default) removes it\n");
  warnBackFacingSensors(scene, r);
  if (!r.bands.empty()) {
    report["bands"] = r.bands;
    report["band_emitted_w"] = radiometric(r.band_emitted_w, r);
  }
  if (r.colorimetric) report["band_nm"] = r.band_nm;
  if (r.photometric) {
    report["emitted_luminous_flux_lm"] = r.emitted_lm;
    report["emitted_flux_lm"] = r.emitted_lm;
  }
  if (!r.light_names.empty()) {
    nlohmann::ordered_json lights = nlohmann::ordered_json::array();
    for (std::size_t l = 0; l < r.light_names.size(); ++l) {
      nlohmann::ordered_json entry{{"name", r.light_names[l]},
                                   {"emitted_power_w", radiometric(r.light_emitted_w[l], r)}};
      if (r.photometric) entry["emitted_flux_lm"] = r.light_emitted_lm[l];
      lights.push_back(std::move(entry));
    }
    report["lights"] = std::move(lights);
  }
  if (scene.scatters()) report["scatterings"] = run.counters().scatterings;
  nlohmann::ordered_json sensors = nlohmann::ordered_json::array();
  for (std::size_t k = 0; k < r.sensors.size(); ++k) {
    const SensorResult& s = r.sensors[k];
    nlohmann::ordered_json entry{{"name", s.name},
                                 {"file", (o.out / (sensorFileStem(s.name) + ".json")).string()},
                                 {"total_flux_w", radiometric(s.total_flux_w, r)},
                                 {"relative_stderr", finiteOrNull(s.relative_stderr)},
                                 {"efficiency", s.efficiency}};
    if (r.photometric) entry["total_flux_lm"] = s.luminous_flux_lm;
    sensors.push_back(std::move(entry));
  }
  report["sensors"] = sensors;
  if (!r.meters.empty()) report["meters"] = meterReport(r, o.out);
  if (ranks.shared()) report["mpi"] = ranks.report();
  // All result files or none: written into a staging folder, moved into --out when complete.
  try {
    SensorOutputSet output(o.out);
    for (std::size_t k = 0; k < r.sensors.size(); ++k)
      writeSensorFiles(output.staging(), r.sensors[k], scene.sensors()[k], r, o.text_map_limit);
    for (const MeterResult& m : r.meters)
      if (m.image_width != 0) writeCameraImages(output.staging(), m, r);
    writeText(output.staging() / "run.json", report.dump() + "\n");
    output.commit(stems);
  } catch (const Error& e) {
    throw FileError(std::string(e.what()) + "; " + o.out.string() +
                    " keeps the files it held before, and the run is saved in " + state.string() +
                    " (--resume --rays " + std::to_string(r.rays) + " writes its results)");
  }
  return report;
}

}  // namespace

nlohmann::ordered_json runSensor(const SensorOptions& o) {
  SensorRanks ranks;
  try {
    return runSensorOn(ranks, o);
  } catch (const AllRanksFailed& e) {
    // Every rank ends with it. Each writes it before any rank exits: a launcher ends the whole job
    // when the first process exits with an error, which could cut off a slower rank's message.
    std::cerr << "duplex sensor: error: " << e.what() << '\n' << std::flush;
    ranks.barrier();
    throw AllRanksFailedReported(e.what());
  } catch (const std::exception& e) {
    ranks.failed(e);  // shared: a failure of this rank alone ends every rank
    throw;
  }
}

void addSensorCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<SensorOptions>();
  SensorOptions& sensor = *options;
  CLI::App* cmd = parent.add_subcommand(
      "sensor", "Light-tracing run: power from the scene's lights arriving at its sensors (irradiance maps)");
  cmd->add_option("--scene", sensor.scene, "scene-json-v1 or duplex-scene-v1 file with \"lights\" and \"sensors\"")
      ->required();
  addStructureOption(*cmd, sensor.structure);
  cmd->add_option("--rays", sensor.rays, "Total emitted rays (with --resume: including the saved ones)")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 48));
  addThreadsOption(*cmd, sensor.threads);
  cmd->add_option("--seed", sensor.seed, "Seed (default 1); results do not depend on --threads")->transform(kDecimal);
  cmd->add_option(
      "--out", sensor.out,
      "Folder for <sensor>.json/.csv/.png (and .exr when built with OpenEXR), run.json, run_state.bin (default .)");
  CLI::Option* resume_opt = cmd->add_flag(
      "--resume", sensor.resume, "Continue the run saved in DIR/run_state.bin (same scene and seed) up to --rays");
  cmd->add_flag("--overwrite", sensor.overwrite,
                "Replace an earlier run's results in DIR (without it, or --resume, such a folder is refused)")
      ->excludes(resume_opt);
  CLI::Option* target_error_opt =
      cmd->add_option("--target-error", sensor.target_error,
                      "Stop once the target sensor's total flux has this relative standard error (e.g. 0.01)")
          ->check(CLI::Range(0.0, 1.0));
  cmd->add_option("--target-sensor", sensor.target_sensor, "Sensor of --target-error (default: the first)")
      ->needs(target_error_opt);
  cmd->add_option("--max-depth", sensor.max_depth,
                  "Surface interactions after which a path is cut, a bias (default none: unbiased)")
      ->transform(CLI::Transformer(std::map<std::string, std::string>{{"none", std::to_string(kNoDepthLimit)}}))
      ->transform(kDecimal);
  cmd->add_option("--roulette-depth", sensor.roulette_depth,
                  "Surface interactions after which each further one continues with probability 0.95, the "
                  "survivor's power divided by it (unbiased; default 32)")
      ->transform(kDecimal);
  cmd->add_option("--max-scatterings", sensor.max_scatterings,
                  "Fog collisions per path before it is cut (default 100000; 1: single scattering)")
      ->transform(kDecimal);
  cmd->add_option("--roulette", sensor.roulette,
                  "Russian roulette below this fraction of a ray's emitted power, in [0, 1) (default 0.05; 0: off)");
  cmd->add_flag("--per-light", sensor.per_light,
                "Also report each light's contribution (run.json's, each meter's and each sensor file's "
                "\"lights\"; under mpirun too)");
  cmd->add_option("--failure-threshold", sensor.failure_threshold,
                  "Warn on stderr when numerical failures, or the path limits, carry more than this fraction of the "
                  "emitted power, in [0, 1] (default 0.001)");
  cmd->add_option("--progress", sensor.progress, "auto (bar on a terminal, else lines), bar, lines or none")
      ->check(CLI::IsMember({"auto", "bar", "lines", "none"}));
  cmd->add_option("--checkpoint", sensor.checkpoint_s,
                  "Seconds between saves of DIR/run_state.bin during the run (default 60; 0: only at the end)")
      ->check(CLI::Range(0.0, 1e9));
  cmd->add_option("--text-map-limit", sensor.text_map_limit,
                  "Bins above which a sensor's maps go to .npy files instead of the JSON and CSV (default 1048576)")
      ->transform(kDecimal);
  cmd->add_option("--at", sensor.at,
                  "Apply the scene's timed edits with time <= T (seconds) before the run (default: none)")
      ->check(CLI::Range(0.0, std::numeric_limits<double>::max()));
  cmd->add_option("--batch-rays", sensor.batch_rays,
                  "Rays per batch: the unit of the ordered sums, of work dealt to MPI ranks, of checkpoints and "
                  "--target-error checks (default 65536; results depend on it, not on --threads or ranks)")
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 40));
  cmd->footer(
      "Files are described in docs/sensors.md; the run is bit-identical for any --threads, and for any number of "
      "ranks under mpirun (docs/distributed.md).");
  onParsed(*cmd, chosen, options, runSensor);
}

}  // namespace duplex::cli
