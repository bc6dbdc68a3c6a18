#pragma once
/// \file IesProfile.h
/// A goniometric intensity table read from an IES LM-63 photometric file (the 1986, 1991, 1995,
/// 2002 and 2019 layouts), for point lights whose emission is not isotropic; and the writer of
/// LM-63-2002 files (far-field sensors' measured tables).
///
/// Model: type C photometry. A direction of the luminaire's frame is given by the vertical angle
/// gamma from the nadir (gamma = 0 looks down the luminaire's -z axis, 180 degrees up +z) and the
/// horizontal (C-plane) angle phi from +x towards +y:
///   direction = (sin(gamma) cos(phi), sin(gamma) sin(phi), -cos(gamma)).
/// Between the tabulated angles the intensity is bilinear in (gamma, phi); outside the tabulated
/// vertical range it is 0 (a file with angles 0-90 emits nothing upwards). The file's symmetries
/// (one C-plane: rotationally symmetric; 0-90: quadrant; 0-180 and 90-270: bilateral) are unfolded
/// into a table over the full circle at load, so every query uses one code path.
///
/// Intensities are the file's values times its candela multiplier and ballast factor (candela for
/// absolute files). A light scales the shape to its own power in watts, so only the shape matters
/// for transport; intensity() and integral() report the file's units.
/// Not modelled: TILT data (lamp-tilt factors; parsed and validated, not applied: record in tilt()),
/// the luminous opening's size (the luminaire is a point), photometric types A and B (rejected).

#include <glm/vec3.hpp>

#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace duplex {

/// A goniometric intensity table of type C photometry (see the file comment); immutable, shareable between lights.
class IesProfile {
 public:
  /// How the file treats lamp tilt.
  enum class Tilt {
    None,     ///< TILT=NONE
    Include,  ///< TILT=INCLUDE: tilt data follow in the file (parsed, not applied)
    File      ///< TILT= a file name: tilt data in another file (not read)
  };

  /// Reads an LM-63 file. Throws FileError "<file>: line N: <problem>" for anything malformed:
  /// no TILT line, a missing, non-numeric or non-finite number, counts < 1, fewer than 2 vertical
  /// angles, angles not increasing or out of range, a horizontal range without a known symmetry,
  /// negative candela, an all-zero table, photometric type A or B, data after the table.
  [[nodiscard]] static IesProfile load(const std::filesystem::path& file);
  /// The same from text in memory; `source` names it in messages.
  [[nodiscard]] static IesProfile parse(std::string_view text, const std::string& source);
  /// From a type C table: vertical angles (degrees, increasing, in [0, 180]), horizontal angles
  /// (degrees, increasing, one of the symmetric ranges above), candela[h * vertical.size() + v]
  /// (the file's order). Throws InvalidArgument as parse() would throw FileError.
  [[nodiscard]] static IesProfile fromTable(std::vector<double> vertical_deg, std::vector<double> horizontal_deg,
                                            std::vector<double> candela, std::string source);

  /// Intensity towards `direction_lf` (luminaire frame, need not be normalised; zero vector: 0),
  /// in the file's units (candela).
  [[nodiscard]] double intensity(const glm::dvec3& direction_lf) const;
  /// Intensity at vertical angle gamma and horizontal angle phi (radians; phi any real number).
  [[nodiscard]] double intensityAt(double gamma, double phi) const;
  /// The integral of intensity() over the sphere (candela * steradian = lumen for absolute files),
  /// exact for the bilinear model.
  [[nodiscard]] double integral() const { return total_; }

  /// A direction drawn for emission, with its weight intensity / (pdf * integral()): the expected
  /// weight is 1 and the weighted directions are distributed exactly as intensity() (unbiased; the
  /// weight stays near 1 where the table is smooth).
  struct Sample {
    glm::dvec3 direction_lf;  ///< unit vector, luminaire frame
    double weight;            ///< intensity / (pdf * integral()): mean 1 over sample()'s directions
  };
  /// From two uniform numbers in [0, 1). Chooses a table cell by its share of integral(), then a
  /// direction uniform in the cell's solid angle.
  [[nodiscard]] Sample sample(double u1, double u2) const;
  /// Density (per steradian) of sample()'s directions.
  [[nodiscard]] double pdf(const glm::dvec3& direction_lf) const;

  /// Tabulated horizontal angles in degrees after unfolding (0 ... 360).
  [[nodiscard]] const std::vector<double>& horizontalAngles() const { return horizontal_deg_; }
  /// Tabulated vertical angles in degrees (as in the file).
  [[nodiscard]] const std::vector<double>& verticalAngles() const { return vertical_deg_; }
  /// The unfolded table: [h * verticalAngles().size() + v] over horizontalAngles(), in the file's
  /// units times its multiplier and ballast factor.
  [[nodiscard]] const std::vector<double>& table() const { return candela_; }
  /// Keywords of the header ("[TEST]" -> "TEST"), [MORE] lines appended with a newline.
  [[nodiscard]] const std::map<std::string, std::string>& keywords() const { return keywords_; }
  /// The file's TILT line (recorded; tilt factors are not applied).
  [[nodiscard]] Tilt tilt() const { return tilt_; }
  /// Lumens per lamp as written (-1: absolute photometry), and the number of lamps.
  [[nodiscard]] double lumensPerLamp() const { return lumens_per_lamp_; }
  /// Number of lamps, as written.
  [[nodiscard]] int lamps() const { return lamps_; }
  /// The file (or the `source` given to parse() or fromTable()), as messages name it.
  [[nodiscard]] const std::string& source() const { return source_; }

 private:
  IesProfile() = default;
  void finish(const std::vector<double>& horizontal_in, const std::vector<double>& candela_in,
              const std::string& where);
  [[nodiscard]] std::size_t cellOf(double gamma, double phi, double& s, double& t) const;

  std::string source_;
  std::map<std::string, std::string> keywords_;
  Tilt tilt_ = Tilt::None;
  double lumens_per_lamp_ = -1.0;
  int lamps_ = 1;
  std::vector<double> vertical_deg_, horizontal_deg_;
  std::vector<double> vertical_rad_, horizontal_rad_;
  std::vector<double> candela_;   // [h * nv + v], unfolded, scaled
  std::vector<double> cell_cdf_;  // cumulative cell integrals, cell = h * (nv - 1) + v
  double total_ = 0.0;
};

/// A type C intensity table to write as an IES LM-63-2002 file (writeIes).
struct IesTable {
  /// Vertical angles gamma (degrees from the nadir, increasing; type C: from 0 or 90 to 90 or 180).
  std::vector<double> vertical_deg;
  /// Horizontal angles C (degrees, increasing): one (rotationally symmetric), or 0 ... 90, 180 or
  /// 360 (a full table ends with 360, repeating 0).
  std::vector<double> horizontal_deg;
  std::vector<double> values;  ///< [h * vertical_deg.size() + v], >= 0 (candela, or W/sr: say so in `keywords`)
  /// Header keywords in order, written "[KEY] value" ("TEST", "MANUFAC", ...; a value with newlines
  /// continues on [MORE] lines). The LM-63-2002 required keywords missing here are written empty.
  std::vector<std::pair<std::string, std::string>> keywords;
  double lumens_per_lamp = -1.0;  ///< -1: absolute photometry (the values are the luminaire's own)
};

/// The LM-63-2002 text of `table`: "IESNA:LM-63-2002", the keywords, TILT=NONE, one lamp,
/// multiplier 1, type C, metres, no luminous opening, then the angles and values, shortest
/// round-trip decimal forms (IesProfile::parse reads the same numbers back). Throws
/// InvalidArgument for a table IesProfile::fromTable would refuse, or a keyword with ']' or a
/// line break in its name.
[[nodiscard]] std::string formatIes(const IesTable& table);
/// Writes formatIes(table) to `file` (through a temporary file renamed over it). Throws FileError
/// naming the file, InvalidArgument as formatIes.
void writeIes(const std::filesystem::path& file, const IesTable& table);

}  // namespace duplex
