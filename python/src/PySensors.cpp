#include "PySensors.h"

#include "Arrays.h"

#include <duplex/accel/Error.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/sensors/SensorRun.h>
#include <duplex/sensors/SensorScene.h>

#include <pybind11/stl.h>

#include <glm/vec3.hpp>

#include <cmath>
#include <exception>
#include <numbers>
#include <optional>
#include <sstream>
#include <vector>

namespace duplex::python {

namespace {

template <class T>
py::array_t<T> grid(const std::vector<T>& values, py::ssize_t rows, py::ssize_t cols) {
  py::array_t<T> a(std::vector<py::ssize_t>{rows, cols});
  std::copy(values.begin(), values.end(), a.mutable_data());
  return a;
}

template <class T>
py::array_t<T> bandGrids(const std::vector<std::vector<T>>& bands, py::ssize_t rows, py::ssize_t cols) {
  py::array_t<T> a(std::vector<py::ssize_t>{static_cast<py::ssize_t>(bands.size()), rows, cols});
  T* p = a.mutable_data();
  for (const std::vector<T>& b : bands) p = std::copy(b.begin(), b.end(), p);
  return a;
}

py::object finiteOrNone(double v) { return std::isfinite(v) ? py::object(py::float_(v)) : py::object(py::none()); }

const char* shapeName(SensorShape s) {
  return s == SensorShape::Disk       ? "disk"
         : s == SensorShape::Sphere   ? "sphere"
         : s == SensorShape::FarField ? "farfield"
                                      : "rectangle";
}

// The per-light arrays of a sensor or meter result ([light][bin or point]) as (lights, rows, cols).
py::array_t<double> lightGrids(const std::vector<std::vector<double>>& v, py::ssize_t rows, py::ssize_t cols) {
  return bandGrids(v, rows, cols);
}

// (N, 3) of world-space points or directions.
py::array_t<double> rows3(const std::vector<glm::dvec3>& v) {
  py::array_t<double> a(std::vector<py::ssize_t>{static_cast<py::ssize_t>(v.size()), 3});
  double* p = a.mutable_data();
  for (const glm::dvec3& x : v) p = std::copy(&x.x, &x.x + 3, p);
  return a;
}

// A meter's dict (see run_lighting's docstring).
py::dict meterDict(const MeterResult& m, const SensorRunResults& r) {
  const auto n = static_cast<py::ssize_t>(m.points.size());
  const auto flat = [](const std::vector<double>& v) {
    return py::array_t<double>(static_cast<py::ssize_t>(v.size()), v.data());
  };
  const bool cone = m.luminance();
  py::dict d;
  d["points"] = rows3(m.points);
  d["normals"] = rows3(m.normals);
  d["ray_count"] = py::array_t<std::uint64_t>(n, m.ray_count.data());
  if (m.half_angle > 0.0) d["half_angle_deg"] = m.half_angle * 180.0 / std::numbers::pi;
  if (m.image_width != 0) d["image_size"] = py::make_tuple(m.image_width, m.image_height);
  d[cone ? "radiance" : "irradiance"] = flat(cone ? m.radiance_w_m2_sr : m.irradiance_w_m2);
  d[cone ? "radiance_stderr" : "stderr"] = flat(cone ? m.radiance_stderr_w_m2_sr : m.stderr_w_m2);
  if (r.photometric) {
    d[cone ? "luminance" : "illuminance"] = flat(cone ? m.luminance_cd_m2 : m.illuminance_lx);
    d[cone ? "luminance_stderr" : "illuminance_stderr"] =
        flat(cone ? m.luminance_stderr_cd_m2 : m.illuminance_stderr_lx);
  }
  const auto& per_light = cone ? m.light_radiance_w_m2_sr : m.light_irradiance_w_m2;
  if (!per_light.empty()) {
    d["light_names"] = r.light_names;
    d[cone ? "light_radiance" : "light_irradiance"] =
        lightGrids(per_light, 1, n).reshape({static_cast<py::ssize_t>(per_light.size()), n});
    const auto& se = cone ? m.light_radiance_stderr_w_m2_sr : m.light_stderr_w_m2;
    d[cone ? "light_radiance_stderr" : "light_stderr"] =
        lightGrids(se, 1, n).reshape({static_cast<py::ssize_t>(se.size()), n});
    const auto& lm = cone ? m.light_luminance_cd_m2 : m.light_illuminance_lx;
    if (!lm.empty())
      d[cone ? "light_luminance" : "light_illuminance"] =
          lightGrids(lm, 1, n).reshape({static_cast<py::ssize_t>(lm.size()), n});
  }
  return d;
}

}  // namespace

py::dict runSensors(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                    const py::object& progress, const SensorRunOptions& options) {
  return runScene(scene_file, rays, seed, threads, progress, options, false);
}

py::dict runLighting(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                     const py::object& progress, const SensorRunOptions& options) {
  return runScene(scene_file, rays, seed, threads, progress, options, true);
}

py::dict runScene(const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                  const py::object& progress, const SensorRunOptions& options, bool lighting) {
  if (rays == 0) throw InvalidArgument("rays must be at least 1");
  if (threads < 0) throw InvalidArgument("threads must be >= 0 (0: all hardware threads)");
  if (!(options.target_error >= 0.0 && std::isfinite(options.target_error)))
    throw InvalidArgument("target_error must be a finite number >= 0");
  if (!(options.failure_threshold >= 0.0 && options.failure_threshold <= 1.0))
    throw InvalidArgument("failure_threshold must be in [0, 1]");
  if (!progress.is_none() && !PyCallable_Check(progress.ptr()))
    throw InvalidArgument("progress must be None or a callable (done, total)");

  std::optional<SensorScene> scene;
  withThreads(threads, [&] {
    py::gil_scoped_release nogil;
    SceneDocumentOptions doc_options;
    doc_options.structure = options.structure;
    scene.emplace(SensorScene::load(scene_file, doc_options));
  });
  std::size_t edits_applied = 0;
  if (options.at) {
    if (!(*options.at >= 0.0 && std::isfinite(*options.at))) throw InvalidArgument("at must be a finite time >= 0");
    withThreads(threads, [&] {
      py::gil_scoped_release nogil;
      if (scene->document()) edits_applied = applyEditsUntil(*scene->document(), *options.at);
    });
  }
  // As the tool says on stderr: edits of the scene that this run leaves out are never silent.
  if (const std::size_t edits = scene->document() ? scene->document()->edits.size() : 0; edits_applied < edits) {
    std::ostringstream note;
    note << scene_file.string() << " has " << edits << " timed edit(s); " << edits - edits_applied
         << (options.at ? " after at are not applied" : " not applied (at=T applies those with time <= T)");
    if (PyErr_WarnEx(PyExc_UserWarning, note.str().c_str(), 1) != 0) throw py::error_already_set();
  }
  if (scene->lights().empty()) throw FileError(scene_file.string() + ": the scene has no lights (\"lights\": [...])");
  if (!lighting && scene->sensors().empty())
    throw FileError(scene_file.string() + ": the scene has no sensors (\"sensors\": [...])");
  if (lighting && scene->sensors().empty() && scene->meters().empty())
    throw FileError(scene_file.string() +
                    ": the scene has no sensors (\"sensors\": [...]) or meters (\"meters\": [...])");

  SensorRunConfig config;
  config.seed = seed;
  config.threads = static_cast<unsigned>(threads);
  config.max_depth = options.max_depth;
  config.max_scatterings = options.max_scatterings;
  config.roulette_threshold = options.roulette_threshold;
  config.per_light = options.per_light;
  SensorRun run(*scene, config);
  SensorStopRule stop;
  if (options.target_error > 0.0) {
    stop.sensor = options.target_sensor.empty() ? 0 : scene->findSensor(options.target_sensor);
    if (stop.sensor < 0)
      throw InvalidArgument("target_sensor: the scene has no sensor named '" + options.target_sensor + "'");
    stop.target = options.target_error;
    stop.min_rays = std::min<std::uint64_t>(10000, rays);
  }

  // The callback runs on this thread between batches: it takes the GIL, checks for Ctrl-C and calls
  // `progress`; an exception from either cancels the run and is raised once the run has stopped.
  std::optional<py::error_already_set> raised;
  SensorRunStatus status;
  {
    py::gil_scoped_release nogil;
    status = run.runUntil(
        rays,
        [&](const SensorProgress& p) {
          py::gil_scoped_acquire gil;
          try {
            if (PyErr_CheckSignals() != 0) throw py::error_already_set();
            if (!progress.is_none()) progress(p.rays_done, p.rays_target);
          } catch (py::error_already_set& e) {
            raised.emplace(std::move(e));
            run.cancel();
          }
        },
        stop);
  }
  if (raised) throw std::move(*raised);

  const SensorRunResults r = run.results();
  if (r.energy.failed_rays != 0 && r.energy.failed_w > options.failure_threshold * r.energy.emitted_w) {
    std::ostringstream note;
    note << "numerical failures ended " << r.energy.failed_rays << " of " << r.rays << " paths, carrying "
         << r.energy.failed_w << " W, " << 100.0 * r.energy.failed_w / r.energy.emitted_w
         << "% of the emitted power (above failure_threshold " << 100.0 * options.failure_threshold << "%)";
    if (PyErr_WarnEx(PyExc_UserWarning, note.str().c_str(), 1) != 0) throw py::error_already_set();
  }
  if (r.energy.depth_limited_rays != 0 && r.energy.depth_limited_w > options.failure_threshold * r.energy.emitted_w) {
    std::ostringstream note;
    note << "the path limits cut " << r.energy.depth_limited_rays << " of " << r.rays << " paths, carrying "
         << r.energy.depth_limited_w << " W, " << 100.0 * r.energy.depth_limited_w / r.energy.emitted_w
         << "% of the emitted power (above failure_threshold " << 100.0 * options.failure_threshold
         << "%): the results miss what they would still have deposited; max_depth=None (the default)"
         << " and a larger max_scatterings remove it";
    if (PyErr_WarnEx(PyExc_UserWarning, note.str().c_str(), 1) != 0) throw py::error_already_set();
  }
  py::dict energy;
  energy["emitted_w"] = r.energy.emitted_w;
  for (const EnergyEnding& k : kEnergyEndings) {
    energy[(std::string(k.name) + "_w").c_str()] = r.energy.*k.power;
    energy[(std::string(k.name) + "_rays").c_str()] = r.energy.*k.rays;
  }
  const char* status_name = status == SensorRunStatus::TargetReached ? "target_reached"
                            : status == SensorRunStatus::Cancelled   ? "cancelled"
                                                                     : "completed";
  // The run's entries, in every sensor's dict and in run_lighting's.
  const auto runEntries = [&](py::dict& d) {
    d["rays"] = r.rays;
    d["seed"] = r.seed;
    d["status"] = status_name;
    d["emitted_power"] = r.energy.emitted_w;
    d["energy"] = energy;
    d["edits_applied"] = edits_applied;
  };
  py::dict out;
  for (const SensorResult& s : r.sensors) {
    const auto ny = static_cast<py::ssize_t>(s.ny), nx = static_cast<py::ssize_t>(s.nx);
    py::dict d;
    // A far-field sensor's arrays are (n_c, n_gamma), its per-measure values intensities (W/sr).
    const bool far = s.shape == SensorShape::FarField;
    const py::ssize_t rows = far ? nx : ny, cols = far ? ny : nx;
    d[far ? "intensity" : "irradiance"] = grid(s.irradiance_w_m2, rows, cols);
    d[far ? "intensity_stderr" : "stderr"] = grid(s.stderr_w_m2, rows, cols);
    d["flux"] = grid(s.flux_w, rows, cols);
    d["flux_stderr"] = grid(s.flux_stderr_w, rows, cols);
    d["ray_count"] = grid(s.ray_count, rows, cols);
    d[far ? "solid_angle" : "bin_area"] = grid(s.bin_area_m2, rows, cols);
    if (far) {
      const SensorObject& object = *scene->sensors()[static_cast<std::size_t>(scene->findSensor(s.name))].object;
      std::vector<double> c_deg, gamma_deg;
      for (std::uint32_t ic = 0; ic < s.nx; ++ic) c_deg.push_back(object.farFieldC(ic));
      for (std::uint32_t ig = 0; ig < s.ny; ++ig) gamma_deg.push_back(object.farFieldGamma(ig));
      d["c_deg"] = c_deg;
      d["gamma_deg"] = gamma_deg;
    }
    d["total_flux"] = s.total_flux_w;
    d["total_flux_stderr"] = s.total_flux_stderr_w;
    d["relative_stderr"] = finiteOrNone(s.relative_stderr);
    d["efficiency"] = s.efficiency;
    d["shape"] = shapeName(s.shape);
    d["bins"] = py::make_tuple(s.nx, s.ny);
    d["two_sided"] = s.two_sided;
    d["node"] = s.node;
    if (s.theta_bins != 0) {
      const auto nphi = static_cast<py::ssize_t>(s.phi_bins), ntheta = static_cast<py::ssize_t>(s.theta_bins);
      d["angular_flux"] = grid(s.angular_flux_w, nphi, ntheta);
      d["angular_stderr"] = grid(s.angular_stderr_w, nphi, ntheta);
      d["angular_solid_angle"] = grid(s.angular_solid_angle_sr, nphi, ntheta);
      d["angular_ray_count"] = grid(s.angular_ray_count, nphi, ntheta);
    }
    if (!r.bands.empty() && s.shape != SensorShape::FarField) {
      d["bands"] = r.bands;
      d["band_irradiance"] = bandGrids(s.band_irradiance_w_m2, ny, nx);
      d["band_stderr"] = bandGrids(s.band_stderr_w_m2, ny, nx);
      d["band_flux"] = bandGrids(s.band_flux_w, ny, nx);
      d["band_total_flux"] = s.band_total_flux_w;
      d["band_total_flux_stderr"] = s.band_total_flux_stderr_w;
    }
    if (r.photometric) {  // the CLI's photometric keys, named like the dict's others (no units)
      d["luminous_flux"] = s.luminous_flux_lm;
      d["luminous_flux_stderr"] = s.luminous_flux_stderr_lm;
      d[far ? "intensity_cd" : "illuminance"] = grid(s.illuminance_lx, rows, cols);
      d[far ? "intensity_cd_stderr" : "illuminance_stderr"] = grid(s.illuminance_stderr_lx, rows, cols);
      d["emitted_luminous_flux"] = r.emitted_lm;
    }
    if (r.colorimetric) {  // (rows, cols, 3) and (rows, cols, 2); chromaticity NaN where no light arrived
      py::array_t<double> xyz = grid(s.cie_xyz, rows * cols, 3), xy = grid(s.chromaticity_xy, rows * cols, 2);
      d["cie_xyz"] = xyz.reshape({rows, cols, py::ssize_t{3}});
      d["chromaticity_xy"] = xy.reshape({rows, cols, py::ssize_t{2}});
      d["total_cie_xyz"] = s.total_cie_xyz;
      d["total_chromaticity_xy"] = s.total_chromaticity_xy;
      d["band_nm"] = r.band_nm;
    }
    runEntries(d);
    if (!r.light_names.empty()) {  // per-light results: (lights, rows, cols)
      d["light_names"] = r.light_names;
      d["light_emitted_power"] = r.light_emitted_w;
      d[far ? "light_intensity" : "light_irradiance"] = lightGrids(s.light_irradiance_w_m2, rows, cols);
      d[far ? "light_intensity_stderr" : "light_stderr"] = lightGrids(s.light_stderr_w_m2, rows, cols);
      d["light_flux"] = lightGrids(s.light_flux_w, rows, cols);
      d["light_flux_stderr"] = lightGrids(s.light_flux_stderr_w, rows, cols);
      d["light_total_flux"] = s.light_total_flux_w;
      d["light_total_flux_stderr"] = s.light_total_flux_stderr_w;
      if (r.photometric) d["light_emitted_luminous_flux"] = r.light_emitted_lm;
      if (!s.light_illuminance_lx.empty()) {
        d[far ? "light_intensity_cd" : "light_illuminance"] = lightGrids(s.light_illuminance_lx, rows, cols);
        d[far ? "light_intensity_cd_stderr" : "light_illuminance_stderr"] =
            lightGrids(s.light_illuminance_stderr_lx, rows, cols);
        d["light_luminous_flux"] = s.light_luminous_flux_lm;
        d["light_luminous_flux_stderr"] = s.light_luminous_flux_stderr_lm;
      }
    }
    out[py::str(s.name)] = d;
  }
  if (!lighting) return out;
  py::dict meters;
  for (const MeterResult& m : r.meters) meters[py::str(m.name)] = meterDict(m, r);
  py::dict all;
  all["sensors"] = out;
  all["meters"] = meters;
  runEntries(all);
  if (r.photometric) all["emitted_luminous_flux"] = r.emitted_lm;
  if (!r.light_names.empty()) {
    all["light_names"] = r.light_names;
    all["light_emitted_power"] = r.light_emitted_w;
    if (r.photometric) all["light_emitted_luminous_flux"] = r.light_emitted_lm;
  }
  return all;
}

}  // namespace duplex::python
