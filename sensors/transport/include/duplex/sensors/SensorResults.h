#pragma once
/// \file SensorResults.h
/// What a sensor run measured, per sensor and per bin, with standard errors.
///
/// Estimator: every emitted ray i carries the scene's total power P (W) and deposits X_ib = P * w
/// into bin b at each crossing (w: the path's throughput through materials and media). A bin's flux
/// is the mean over the N emitted rays, F_b = (1/N) sum_i X_ib, where X_ib sums all crossings of
/// path i with bin b (so rays that never reach the bin count as zeros). Its standard error is that
/// of a mean of N independent samples: sqrt((sum X^2 - (sum X)^2 / N) / (N (N - 1))). Irradiance
/// divides both by the bin's world area. A sensor's total flux uses the per-ray sums over its bins
/// the same way.

#include "duplex/scenegraph/NodeId.h"
#include "duplex/sensors/IesProfile.h"
#include "duplex/sensors/SensorObject.h"

#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace duplex {

/// What one sensor measured (see the file comment for the estimator).
struct SensorResult {
  std::string name;                            ///< the sensor's name (its instance node's)
  NodeId node = kInvalidNode;                  ///< the sensor's instance node
  SensorShape shape = SensorShape::Rectangle;  ///< rectangle, disk, sphere or far field
  /// \var nx
  /// Bins along local x (spheres: azimuth steps).
  /// \var ny
  /// Bins along local y (spheres: steps of n.z).
  std::uint32_t nx = 0, ny = 0;
  bool two_sided = true;  ///< records both faces
  /// Row-major nx * ny arrays, bin (0, 0) at local (-w/2, -h/2), x fastest.
  std::vector<double> flux_w;           ///< W
  std::vector<double> flux_stderr_w;    ///< standard error of flux_w
  std::vector<double> irradiance_w_m2;  ///< W per square scene unit (0 for bins of zero area)
  std::vector<double> stderr_w_m2;      ///< standard error of irradiance_w_m2
  std::vector<double> bin_area_m2;      ///< world area of each bin
  std::vector<std::uint64_t>
      ray_count;  ///< emitted rays whose path crossed the bin (far field: escaped through the cell)
  // Far-field sensors (shape FarField; row-major ic * n_gamma + ig, nx = n_c, ny = n_gamma): the
  // arrays hold per direction cell its flux, the cell's solid angle (sr) in bin_area_m2, and the
  // radiant intensity I = flux / solid angle (W/sr) and its standard error in irradiance_w_m2 and
  // stderr_w_m2 (per-band arrays likewise): flux per unit of the bin's measure, as for areas.
  double total_flux_w = 0.0;         ///< flux over all bins, W
  double total_flux_stderr_w = 0.0;  ///< standard error of total_flux_w, W
  double relative_stderr = 0.0;      ///< total_flux_stderr_w / total_flux_w (infinity when nothing arrived)
  double efficiency = 0.0;           ///< total_flux_w / emitted power
  /// Angular bins of the incoming direction (SensorSpec::theta_bins; empty without): index
  /// iphi * theta_bins + itheta. Flux (W) that arrived from directions in the bin, its standard
  /// error, the bin's solid angle on one face, and the emitted rays that crossed with such a direction.
  /// \var theta_bins
  /// Angular bins of the angle to the normal (0: no angular bins).
  /// \var phi_bins
  /// Angular bins of the azimuth.
  std::uint32_t theta_bins = 0, phi_bins = 0;
  std::vector<double> angular_flux_w;            ///< [angular bin], W
  std::vector<double> angular_stderr_w;          ///< [angular bin], standard error of angular_flux_w, W
  std::vector<double> angular_solid_angle_sr;    ///< [angular bin], solid angle on one face, sr
  std::vector<std::uint64_t> angular_ray_count;  ///< [angular bin], emitted rays that crossed from such a direction
  /// Spectral scenes with angular bins: [band][angular bin], W.
  std::vector<std::vector<double>> band_angular_flux_w;
  /// Spectral scenes (SensorRunResults::bands not empty): per band, the same quantities; the
  /// arrays above are their sums over the bands (the standard errors are each band's own).
  std::vector<std::vector<double>> band_flux_w;           ///< [band][bin], W
  std::vector<std::vector<double>> band_irradiance_w_m2;  ///< [band][bin]
  std::vector<std::vector<double>> band_stderr_w_m2;      ///< [band][bin]
  std::vector<double> band_total_flux_w;                  ///< [band]
  std::vector<double> band_total_flux_stderr_w;           ///< [band]
  /// Photometric scenes (SensorRunResults::photometric): the same quantities weighted by the bands'
  /// luminous efficacy (683 lm/W times V(lambda); 1 when luminous flux is transported directly).
  /// A ray carries one band, so each ray's luminous sample is its deposit times its band's weight
  /// and the standard errors are those of these samples. Far-field sensors: illuminance_lx holds
  /// the luminous intensity (cd) and illuminance_stderr_lx its standard error.
  double luminous_flux_lm = 0.0;              ///< over all bins, lm
  double luminous_flux_stderr_lm = 0.0;       ///< standard error of luminous_flux_lm
  std::vector<double> flux_lm;                ///< [bin], lm (far field: the cell's luminous flux)
  std::vector<double> flux_stderr_lm;         ///< [bin], standard error of flux_lm
  std::vector<double> illuminance_lx;         ///< [bin], lm per square scene unit (far field: cd)
  std::vector<double> illuminance_stderr_lx;  ///< [bin], standard error of illuminance_lx
  /// Colorimetric scenes (the bands have wavelengths): per bin the CIE 1931 tristimulus values X, Y,
  /// Z in the units of illuminance_lx (Y = illuminance_lx), index 3 * bin + c, and the chromaticity
  /// x, y (index 2 * bin + c; NaN where X + Y + Z = 0); and the same over the whole sensor.
  std::vector<double> cie_xyz;                ///< [3 * bin + c], X, Y, Z
  std::vector<double> chromaticity_xy;        ///< [2 * bin + c], x, y
  std::vector<double> total_cie_xyz;          ///< [3], X, Y, Z of the total flux (Y = luminous_flux_lm)
  std::vector<double> total_chromaticity_xy;  ///< [2], or NaN when no light arrived
  /// Runs with per-light results (SensorRunConfig::per_light): what each light contributed, index
  /// [light][bin] in the order of SensorRunResults::light_names, estimated from the same rays as
  /// the totals (a ray's deposits are its light's samples, zeros for the others), so that the
  /// per-light values sum to the totals above. Units as flux_w, irradiance_w_m2 (far field: W/sr).
  std::vector<std::vector<double>> light_flux_w;           ///< [light][bin], W
  std::vector<std::vector<double>> light_flux_stderr_w;    ///< [light][bin], W
  std::vector<std::vector<double>> light_irradiance_w_m2;  ///< [light][bin]
  std::vector<std::vector<double>> light_stderr_w_m2;      ///< [light][bin]
  std::vector<double> light_total_flux_w;                  ///< [light], W
  std::vector<double> light_total_flux_stderr_w;           ///< [light], W
  /// Per-light luminous quantities, in photometric runs without bands of different weights (every
  /// ray's luminous weight the same); empty otherwise.
  std::vector<std::vector<double>> light_illuminance_lx;         ///< [light][bin] (far field: cd)
  std::vector<std::vector<double>> light_illuminance_stderr_lx;  ///< [light][bin]
  std::vector<double> light_luminous_flux_lm;                    ///< [light], lm
  std::vector<double> light_luminous_flux_stderr_lm;             ///< [light], lm
};

/// What one illuminance meter (PointMeter) measured: per point the irradiance on the plane of its
/// normal (W per square scene unit) by next-event connections from every emission and diffuse
/// reflection, each ray's connections one sample, so the standard errors are of a mean of the rays.
struct MeterResult {
  std::string name;                           ///< the meter's name
  std::vector<glm::dvec3> points;             ///< world space, as given
  std::vector<glm::dvec3> normals;            ///< world space, unit length
  std::vector<double> irradiance_w_m2;        ///< [point]
  std::vector<double> stderr_w_m2;            ///< [point]
  std::vector<std::uint64_t> ray_count;       ///< [point]: emitted rays that connected to it
  std::vector<double> illuminance_lx;         ///< [point], photometric runs
  std::vector<double> illuminance_stderr_lx;  ///< [point], photometric runs
  /// Runs with per-light results: [light][point], and the luminous values where they exist (as
  /// SensorResult's light_illuminance_lx).
  std::vector<std::vector<double>> light_irradiance_w_m2;
  std::vector<std::vector<double>> light_stderr_w_m2;     ///< [light][point], as stderr_w_m2
  std::vector<std::vector<double>> light_illuminance_lx;  ///< [light][point], photometric runs
  /// Luminance meters (half_angle > 0, radians): the mean radiance over the cone about each
  /// normal (W/(m^2 sr) per square scene unit), in these arrays instead of the irradiance ones
  /// above, which stay empty; the luminance (cd/m^2) in photometric runs.
  double half_angle = 0.0;
  /// \var image_width
  /// Pinhole cameras (PointMeter::image_width > 0): the image's width in pixels; the points are
  /// its pixels, row by row from the top left, with luminance results too.
  /// \var image_height
  /// The camera image's height in pixels (0: not a camera).
  std::uint32_t image_width = 0, image_height = 0;
  /// Whether the results are radiances (a luminance meter or a camera) rather than irradiances.
  [[nodiscard]] bool luminance() const { return half_angle > 0.0 || image_width > 0; }
  std::vector<double> radiance_w_m2_sr;                            ///< [point]
  std::vector<double> radiance_stderr_w_m2_sr;                     ///< [point]
  std::vector<double> luminance_cd_m2;                             ///< [point], photometric runs
  std::vector<double> luminance_stderr_cd_m2;                      ///< [point], photometric runs
  std::vector<std::vector<double>> light_radiance_w_m2_sr;         ///< [light][point]
  std::vector<std::vector<double>> light_radiance_stderr_w_m2_sr;  ///< [light][point]
  std::vector<std::vector<double>> light_luminance_cd_m2;          ///< [light][point], as light_illuminance_lx
};

/// Where the emitted power went (W, estimates over the rays traced). Sensors never absorb, so
/// emitted = escaped + absorbed + medium_absorbed + depth_limited + roulette + failed up to rounding.
/// medium_absorbed counts attenuation (fogs that do not scatter) and absorbing collisions (fogs
/// that do); depth_limited also paths cut after SensorRunConfig::max_scatterings collisions.
/// Beside each power, the emitted rays whose path ended that way (each path ends one way, so the
/// counts sum to the rays traced; attenuation by fogs that do not scatter ends no path).
struct EnergyBalance {
  double emitted_w = 0.0;          ///< the lights' total power (0 before any ray is traced)
  double escaped_w = 0.0;          ///< left the scene (no blocking hit)
  double absorbed_w = 0.0;         ///< absorbed by surfaces
  double medium_absorbed_w = 0.0;  ///< attenuated by media
  double depth_limited_w = 0.0;    ///< still travelling when the depth limit cut the path
  double roulette_w = 0.0;         ///< net power removed by Russian roulette (zero in expectation)
  /// Power of paths ended by a numerical failure: a non-finite direction or power, a scattered
  /// direction that does not leave the surface to the side its material sends it (tangent, or on
  /// the wrong side), or a direction a material's sampling refused.
  double failed_w = 0.0;
  std::uint64_t escaped_rays = 0;          ///< paths that left the scene
  std::uint64_t absorbed_rays = 0;         ///< paths absorbed by a surface
  std::uint64_t medium_absorbed_rays = 0;  ///< paths absorbed at a collision in a scattering fog
  std::uint64_t depth_limited_rays = 0;    ///< paths cut by max_depth or max_scatterings
  std::uint64_t roulette_rays = 0;         ///< paths killed by Russian roulette
  std::uint64_t failed_rays = 0;           ///< paths ended by a numerical failure (failed_w)
};

/// One way a path ends, as EnergyBalance tallies it: the name (the keys of run.json's "energy" and
/// of the Python result are name + "_w" and name + "_rays"), the member with its power (W) and the
/// member with its path count. kEnergyEndings lists every one, in the order run states store them.
struct EnergyEnding {
  const char* name;                    ///< e.g. "escaped"
  double EnergyBalance::*power;        ///< e.g. &EnergyBalance::escaped_w (W)
  std::uint64_t EnergyBalance::*rays;  ///< e.g. &EnergyBalance::escaped_rays
};
/// Every way a path ends (EnergyEnding), in the order run states and batch tallies store them.
inline constexpr std::array<EnergyEnding, 6> kEnergyEndings{{
    {"escaped", &EnergyBalance::escaped_w, &EnergyBalance::escaped_rays},
    {"absorbed", &EnergyBalance::absorbed_w, &EnergyBalance::absorbed_rays},
    {"medium_absorbed", &EnergyBalance::medium_absorbed_w, &EnergyBalance::medium_absorbed_rays},
    {"depth_limited", &EnergyBalance::depth_limited_w, &EnergyBalance::depth_limited_rays},
    {"roulette", &EnergyBalance::roulette_w, &EnergyBalance::roulette_rays},
    {"failed", &EnergyBalance::failed_w, &EnergyBalance::failed_rays},
}};

/// What a sensor run measured: every sensor's result and the energy balance, over the rays traced so far.
struct SensorRunResults {
  std::uint64_t rays = 0;              ///< emitted rays
  std::uint64_t seed = 0;              ///< the run's seed (SensorRunConfig::seed)
  EnergyBalance energy;                ///< where the emitted power went
  std::vector<std::string> bands;      ///< the scene's band names (empty: one radiometric band)
  std::vector<double> band_emitted_w;  ///< per band: the lights' power in it (exact, from their spectra)
  /// Whether the photometric quantities of the sensors are filled (a light given in lumens, or
  /// bands with wavelengths); then emitted_lm is the lights' luminous flux (exact, from their spectra).
  bool photometric = false;
  bool colorimetric = false;  ///< whether the sensors' CIE XYZ and chromaticities are filled
  double emitted_lm = 0.0;    ///< the lights' luminous flux, lm (photometric runs)
  /// Photometric runs without wavelengths (every light in lumens): the transported unit is the
  /// lumen, so the "_w" quantities above and in the sensors hold lumens and no radiometric value is
  /// known; outputs then give the photometric keys and leave the radiometric ones empty.
  bool luminous_transport = false;
  /// Runs with per-light results: the lights' names (Light::name), their power (W, lumens when
  /// luminous_transport) and, in photometric runs, their luminous flux (lm), in the order of the
  /// sensors' per-light arrays.
  std::vector<std::string> light_names;
  std::vector<double> light_emitted_w;         ///< [light] W (lumens when luminous_transport)
  std::vector<double> light_emitted_lm;        ///< [light] lm, photometric runs
  std::vector<std::array<double, 2>> band_nm;  ///< the bands' wavelengths [lo, hi] nm (colorimetric runs)
  std::vector<SensorResult> sensors;           ///< in the scene's sensor order
  std::vector<MeterResult> meters;             ///< in the scene's meter order (SensorScene::meters)
};

/// The IES type C table of a far-field sensor's result (shape FarField): vertical angles gamma_g =
/// g 180 / (n_gamma - 1), horizontal angles C_c = c 360 / n_c and 360 repeating C = 0 (one C-plane:
/// just 0, rotational symmetry), values the measured intensity (W/sr; candela when the run
/// is photometric, illuminance_lx filled; said by the keywords "_UNITS" and "OTHER", with the rays
/// and the seed), absolute photometry. Throws InvalidArgument
/// for a result of another shape.
[[nodiscard]] IesTable farFieldIesTable(const SensorResult& far_field, std::uint64_t rays, std::uint64_t seed);

}  // namespace duplex
