#pragma once
/// \file GaussianScatter.h
/// A Gaussian rough lobe: a fraction of the specular light spread about the specular direction in
/// direction-cosine space (beta: the direction's projection onto the surface plane), with BSDF
/// proportional to exp(-|beta - beta0|^2 / sigma^2).

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace duplex {

/// Gaussian lobe (a scene file's "scatter": {"model": "gaussian", "sigma", "fraction"}).
struct GaussianScatter {
  static constexpr std::string_view kName = "gaussian";  ///< its "model"
  double sigma = 0.1;                                    ///< width in direction-cosine space, > 0
  double fraction = 1.0;  ///< the fraction of the light scattered (the rest stays specular), in [0, 1]

  /// The probability that a ray meeting the surface is scattered.
  [[nodiscard]] double scatteredFraction() const { return fraction; }

  /// Reads "sigma" and "fraction" (default 1).
  static GaussianScatter read(const MaterialReader& r) {
    r.onlyKeys({"model", "sigma", "fraction"});
    GaussianScatter s;
    s.sigma = r.number("sigma");
    if (!(s.sigma > 0.0 && std::isfinite(s.sigma)))
      r.fail("sigma", "a Gaussian scatter's sigma must be > 0 (got " + std::to_string(s.sigma) + ")");
    s.fraction = r.has("fraction") ? r.number("fraction") : 1.0;
    if (!(s.fraction >= 0.0 && s.fraction <= 1.0)) r.fail("fraction", "expected a scattered fraction in [0, 1]");
    return s;
  }
  /// Throws InvalidArgument for sigma not > 0 (or not finite) or a fraction outside [0, 1].
  void validate(const std::string& what, std::uint32_t /*bands*/) {
    if (!(sigma > 0.0 && std::isfinite(sigma) && fraction >= 0.0 && fraction <= 1.0))
      throw InvalidArgument(what + ": a Gaussian scatter needs sigma > 0 and a fraction in [0, 1] (got sigma " +
                            std::to_string(sigma) + ", fraction " + std::to_string(fraction) + ")");
  }
  /// Adds sigma and the fraction.
  void hash(StateHash& h) const {
    h.add(sigma);
    h.add(fraction);
  }
  /// "gaussian sigma=... fraction=...".
  void print(std::ostream& os) const { os << "gaussian sigma=" << sigma << " fraction=" << fraction; }

  /// A radius of the lobe in direction-cosine space, from the radial density r exp(-r^2 / sigma^2)
  /// on [0, r_max]: exact by inversion of the truncated CDF (1 - exp(-r^2 / sigma^2)) / (1 -
  /// exp(-r_max^2 / sigma^2)), for any sigma (a wide lobe is nearly flat over the disk, never
  /// refused). One number of `rng`.
  template <class Rng>
  [[nodiscard]] double sampleRadius(double r_max, Rng& rng) const {
    const double s2 = sigma * sigma, mass = -std::expm1(-r_max * r_max / s2);
    return std::min(r_max, std::sqrt(-s2 * std::log1p(-rng.uniform() * mass)));
  }
};

}  // namespace duplex
