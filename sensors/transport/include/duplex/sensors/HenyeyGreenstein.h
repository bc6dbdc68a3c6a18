#pragma once
/// \file HenyeyGreenstein.h
/// The Henyey-Greenstein phase function of scattering fog (Henyey, Greenstein 1941, "Diffuse
/// radiation in the galaxy"): one parameter g in (-1, 1), the mean cosine of the scattering angle
/// (g > 0 forward, g < 0 backward, 0 isotropic). Angles are between the propagation directions
/// before and after the event (not pbrt's convention of the reversed incoming direction).

#include <algorithm>
#include <cmath>
#include <numbers>

namespace duplex {

/// The phase function with asymmetry `g` (see the file comment).
struct HenyeyGreenstein {
  double g = 0.0;  ///< mean cosine of the scattering angle, in (-1, 1)

  /// Density per steradian of the new direction at scattering-angle cosine `cos_theta`:
  /// (1 - g^2) / (4 pi (1 + g^2 - 2 g cos_theta)^1.5). Integrates to 1 over the sphere.
  [[nodiscard]] double pdf(double cos_theta) const {
    const double d = 1.0 + g * g - 2.0 * g * cos_theta;
    return (1.0 - g * g) / (4.0 * std::numbers::pi * d * std::sqrt(d));
  }

  /// A scattering-angle cosine with density 2 pi pdf(cos) from a uniform u in [0, 1), by inverting
  /// the closed-form CDF (increasing in u). The usual form (1 + g^2 - s^2) / (2g) cancels for
  /// small |g|; multiplied out it is, with x = 2u - 1,
  ///   (x + g/2 (3 - g^2 + 2 g x + (1 + g^2) x^2)) / (1 + g x)^2,
  /// which has no division by g (g = 0 gives x exactly) but loses digits as |g| -> 1, where the
  /// usual form is accurate: each is used where it is (both within ~1e-15 at |g| = 0.3).
  [[nodiscard]] double sampleCos(double u) const {
    if (std::abs(g) < 0.3) {
      const double x = 2.0 * u - 1.0, d = 1.0 + g * x;
      return std::clamp((x + 0.5 * g * (3.0 - g * g + 2.0 * g * x + (1.0 + g * g) * x * x)) / (d * d), -1.0, 1.0);
    }
    const double s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    return std::clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
  }
};

}  // namespace duplex
