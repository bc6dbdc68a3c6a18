#pragma once
/// \file CieSky.h
/// Relative luminance distributions of the CIE standard skies (ISO 15469 / CIE S 011): the CIE
/// standard overcast sky, L = L_z (1 + 2 cos Z) / 3, and the fifteen types of the CIE standard
/// general sky, L = L_z f(chi) phi(Z) / (f(Z_s) phi(0)) with the gradation phi(Z) = 1 + a exp(b /
/// cos Z) and the indicatrix f(chi) = 1 + c (exp(d chi) - exp(d pi / 2)) + e cos^2 chi (Z: the
/// element's zenith angle, chi: its angle to the sun, Z_s: the sun's zenith angle). Type 12 is the
/// CIE standard clear sky, type 5 the sky of uniform luminance.
///
/// Frame: world space with +z the zenith; azimuths are measured from north (+y) towards east (+x).
/// Directions are unit vectors from the observer towards the sky element. Below the horizon (z <= 0)
/// the luminance is 0. All values are relative to the zenith luminance L_z (dimensionless, or sr for
/// the integrals).

#include <glm/vec3.hpp>

#include <string>
#include <vector>

namespace duplex {

/// One CIE standard sky, with a table for sampling directions by luminance.
class CieSky {
 public:
  /// The CIE standard overcast sky (its own formula, no sun).
  static CieSky overcast();
  /// Type `type` (1-15) of the CIE standard general sky with the sun towards world unit vector
  /// `sun_ws` (z >= 0; types without an indicatrix ignore it). Throws InvalidArgument for a type
  /// outside 1-15 or a sun direction that is not a finite vector with z >= 0.
  static CieSky general(int type, const glm::dvec3& sun_ws);

  /// L / L_z towards the unit world direction `dir_ws` (0 below the horizon).
  [[nodiscard]] double relativeLuminance(const glm::dvec3& dir_ws) const;
  /// The integral of L / L_z over the upper hemisphere (sr): the zenith luminance times it is the
  /// power per unit area crossing a plane perpendicular to every direction (the sky's emission).
  [[nodiscard]] double radianceIntegral() const { return radiance_integral_; }
  /// The integral of L / L_z cos Z over the upper hemisphere (sr): horizontal illuminance per zenith
  /// luminance (7 pi / 9 for the overcast sky).
  [[nodiscard]] double horizontalIntegral() const { return horizontal_integral_; }
  /// 0 for the overcast sky, else the general sky's type.
  [[nodiscard]] int type() const { return type_; }
  /// The sun's world unit direction (general skies).
  [[nodiscard]] const glm::dvec3& sun() const { return sun_; }

  /// A direction sampled from two uniform numbers in [0, 1): a cell of an equal-solid-angle grid
  /// over the hemisphere (cos Z by azimuth) picked by its luminance, then a uniform point in it;
  /// `weight` = (L / L_z) / (pdf * radianceIntegral()), of mean 1 over the samples, so that a ray
  /// carrying the sky's mean ray power times it is unbiased whatever the grid.
  struct Sample {
    glm::dvec3 dir_ws{0.0, 0.0, 1.0};  ///< towards the sky, world space, unit length
    double weight = 1.0;               ///< see above
  };
  /// Draws a Sample (see above) from uniform u0, u1 in [0, 1).
  [[nodiscard]] Sample sample(double u0, double u1) const;
  /// Probability density (per sr) of sample() drawing unit direction `dir_ws`.
  [[nodiscard]] double pdf(const glm::dvec3& dir_ws) const;

  /// "overcast" or "CIE general sky type N" (for messages).
  [[nodiscard]] std::string describe() const;

 private:
  CieSky() = default;
  void build();
  int type_ = 0;  // 0: overcast
  double a_ = 0, b_ = 0, c_ = 0, d_ = 0, e_ = 0;
  glm::dvec3 sun_{0.0, 0.0, 1.0};
  double norm_ = 1.0;  // f(Z_s) phi(0)
  double radiance_integral_ = 0.0, horizontal_integral_ = 0.0;
  std::vector<double> cell_cdf_;  // [kCosCells * kAzCells], cumulative, last 1
  std::vector<double> cell_p_;    // probability of each cell
};

}  // namespace duplex
