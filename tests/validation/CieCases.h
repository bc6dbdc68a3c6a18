#pragma once
/// \file CieCases.h
/// The CIE 171:2006 test cases Duplex can express ("Test cases to assess the accuracy of lighting
/// computer programs"), each built as a sensor scene and run, every measured value beside its
/// exact reference: configuration factors and the inverse-square cosine law for direct light,
/// the closed-enclosure balance for inter-reflection, the two-polarisation slab formulas for
/// glass. The short versions run in CTest (ValidationTest.cpp); `duplex_validate` runs them at
/// full length for scripts/validate, which writes docs/validation.md.
///
/// Units: metres, and a radiometric run read as photometric (the sources are given in lumens
/// transported as such: W in the run are lm, W/m^2 are lx).

#include "duplex/sensors/SensorRun.h"

#include <cstdint>
#include <string>
#include <vector>

namespace duplex::validation {

/// One measured value: what it is, the exact reference, Duplex's estimate and its standard error.
struct CaseRow {
  std::string label;       ///< e.g. "floor bin (3, 4)", "T at 60 deg"
  double reference = 0.0;  ///< exact value (lx, or a fraction)
  double value = 0.0;      ///< Duplex's estimate
  double stderr_value = 0.0;
  /// Another published reference for information (the CIE curve where the report uses a fit); NaN: none.
  double other = 0.0;
  /// |value - reference| must be within 4 standard errors plus this fraction of the reference.
  double relative_tolerance = 0.005;

  [[nodiscard]] double z() const;
  [[nodiscard]] bool passes() const;
};

/// A case: its name, what it checks, its rows and what the run cost.
struct CaseResult {
  std::string name;        ///< short id, e.g. "point-source"
  std::string title;       ///< the case as the report states it, in our words
  std::string reference;   ///< where the reference values come from
  std::string unit;        ///< "lx", "fraction"
  std::uint64_t rays = 0;  ///< emitted rays per run
  double seconds = 0.0;    ///< wall time of its runs
  std::vector<CaseRow> rows;
  std::vector<std::string> notes;  ///< extra measured facts (timings, ratios), one line each
};

/// How long to run: `scale` multiplies every case's ray count (1: the short CTest version).
struct CaseOptions {
  double scale = 1.0;
  unsigned threads = 0;  ///< 0: all hardware threads
};

/// An isotropic point source of 1000 lm, 3 m above the centre of a 4 m x 4 m floor of 8 x 8
/// cells, with a 4 m x 3 m wall at 2 m (8 x 6 cells): each cell's mean illuminance is I times the
/// solid angle of the cell over its area (the inverse-square cosine law integrated exactly).
[[nodiscard]] CaseResult pointSourceCase(const CaseOptions& o);

/// A 1 m x 1 m Lambertian panel of luminance 1000 cd/m^2 facing down, 3 m above the centre of a
/// 4 m x 4 m floor of 8 x 8 cells: each cell's mean illuminance is pi L times the exchange area
/// between the cell and the panel (parallel rectangles, closed form) over the cell's area.
[[nodiscard]] CaseResult areaSourceCase(const CaseOptions& o);

/// The same panel with the illuminance read at 64 points of the floor (the centres of the 8 x 8
/// cells, meters by next-event connections): pi L times the configuration factor from the point
/// to the panel (closed form), the values the report tabulates at points.
[[nodiscard]] CaseResult areaSourcePointsCase(const CaseOptions& o);

/// The point source of pointSourceCase with an opaque, black 1 m x 1 m square obstruction 1.5 m
/// above the floor's centre: at 64 floor points, I cos / d^2 outside its shadow (a 2 m x 2 m
/// square) and 0 inside (no point lies on the shadow's edge).
[[nodiscard]] CaseResult obstructionCase(const CaseOptions& o);

/// A closed cube of edge 4 m with black (absorbing) faces, an isotropic 1000 lm source off its
/// centre at (0.5, -0.3, 0.2): each face in 4 x 4 cells, each cell's mean illuminance I times its
/// solid angle seen from the source over its area (no inter-reflection).
[[nodiscard]] CaseResult blackCubeCase(const CaseOptions& o);

/// A closed cube of edge 4 m, every face Lambertian of reflectance `rho`, an isotropic 1000 lm
/// source at its centre: by symmetry each face receives a sixth of the flux incident on all the
/// faces, which is exactly Phi / (1 - rho) (every incidence reflects rho, nothing escapes), so the
/// mean illuminance of a face is Phi / (6 a^2 (1 - rho)), direct part Phi / (6 a^2). With
/// `also_capped`, the same run with max_depth 1000 is timed beside the default for the ratio.
[[nodiscard]] CaseResult diffuseCubeCase(double rho, const CaseOptions& o, bool also_capped = false);

/// A 6 mm pane of clear glass (n = 1.52; absorption chosen so that it transmits the CIE curve's
/// 0.8788 at normal incidence) lit by a collimated beam at 0-85 degrees: transmittance and
/// reflectance against the exact two-polarisation slab formulas with all internal reflections,
/// the CIE 171 clear-glass curve beside them.
[[nodiscard]] CaseResult clearGlassCase(const CaseOptions& o);

/// Daylight, the sky component of the report's unglazed-opening cases (5.9 onward) with geometry
/// chosen here: a black 4 m x 4 m x 3 m room with a 2 m x 2 m roof opening (`roof`) or a 2 m x
/// 1.5 m south window (sill 1 m), 25 floor points read by meters, under the CIE standard overcast
/// sky and the CIE general skies 8 and 12 (sun at altitude 30, azimuth 180, not emitted), 10,000 lx
/// horizontal: each point against the sky's luminance integrated over the opening by quadrature
/// (the formulas written out apart from the library's CieSky).
[[nodiscard]] CaseResult daylightOpeningCase(bool roof, const CaseOptions& o);

/// Direct sunlight (50,000 lx normal, altitude 60, azimuth 180) through the roof opening: E_n sin
/// 60 at the floor points inside the sunlit patch, 0 outside.
[[nodiscard]] CaseResult daylightSunCase(const CaseOptions& o);

/// Every case above (the cube at reflectances 0.2, 0.5, 0.8 and 0.95).
[[nodiscard]] std::vector<CaseResult> allCases(const CaseOptions& o);

}  // namespace duplex::validation
