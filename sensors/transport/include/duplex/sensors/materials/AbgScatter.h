#pragma once
/// \file AbgScatter.h
/// The ABg rough lobe: BSDF A / (B + |beta - beta0|^g) about the specular direction in
/// direction-cosine space; the fraction scattered is its total integrated scatter at normal
/// incidence, the rest stays specular.

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <cmath>
#include <numbers>
#include <string>

namespace duplex {

/// ABg lobe (a scene file's "scatter": {"model": "abg", "A", "B", "g"}).
struct AbgScatter {
  static constexpr std::string_view kName = "abg";  ///< its "model"
  double a = 0.0;                                   ///< A >= 0
  double b = 1.0;                                   ///< B > 0
  double g = 2.0;                                   ///< g in (0, 8]
  /// The total integrated scatter, set by read() and validate() from A, B and g.
  double tis = 0.0;

  /// The total integrated scatter at normal incidence, 2 pi A int_0^1 r / (B + r^g) dr (the
  /// fraction of the light the model scatters), by Simpson's rule (the integrand is smooth on
  /// [0, 1] for B > 0).
  [[nodiscard]] static double totalIntegratedScatter(double a, double b, double g) {
    const int n = 4096;
    auto f = [b, g](double r) { return r / (b + std::pow(r, g)); };
    double sum = f(0.0) + f(1.0);
    for (int i = 1; i < n; ++i) sum += (i % 2 ? 4.0 : 2.0) * f(static_cast<double>(i) / n);
    return 2.0 * std::numbers::pi * a * sum / (3.0 * n);
  }
  /// The probability that a ray meeting the surface is scattered.
  [[nodiscard]] double scatteredFraction() const { return tis; }

  /// Reads "A", "B" and "g"; refuses parameters that scatter more than all the light.
  static AbgScatter read(const MaterialReader& r) {
    r.onlyKeys({"model", "A", "B", "g"});
    AbgScatter s;
    s.a = r.number("A");
    s.b = r.number("B");
    s.g = r.number("g");
    if (!(s.a >= 0.0)) r.fail("A", "ABg's A must be >= 0");
    if (!(s.b > 0.0)) r.fail("B", "ABg's B must be > 0");
    if (!(s.g > 0.0 && s.g <= 8.0)) r.fail("g", "ABg's g must be in (0, 8]");
    s.tis = totalIntegratedScatter(s.a, s.b, s.g);
    if (!(s.tis <= 1.0))
      r.fail("", "ABg parameters scatter more than all the light (total integrated scatter " + std::to_string(s.tis) +
                     " > 1): not energy conserving");
    return s;
  }
  /// Throws InvalidArgument for parameters out of range or a total integrated scatter above 1;
  /// sets `tis`.
  void validate(const std::string& what, std::uint32_t /*bands*/) {
    if (!(a >= 0.0 && b > 0.0 && g > 0.0 && g <= 8.0 && std::isfinite(a) && std::isfinite(b)))
      throw InvalidArgument(what + ": ABg needs A >= 0, B > 0 and g in (0, 8]");
    tis = totalIntegratedScatter(a, b, g);
    if (!(tis <= 1.0))
      throw InvalidArgument(what + ": ABg parameters scatter more than all the light (total integrated scatter " +
                            std::to_string(tis) + " > 1)");
  }
  /// Adds A, B, g and the total integrated scatter.
  void hash(StateHash& h) const {
    for (const double x : {a, b, g, tis}) h.add(x);
  }
  /// "ABg A=... B=... g=... TIS=...".
  void print(std::ostream& os) const { os << "ABg A=" << a << " B=" << b << " g=" << g << " TIS=" << tis; }

  /// A radius of the lobe from the radial density h(r) = r / (B + r^g) on [0, r_max], exact by
  /// rejection from the envelope e(r) = r / B below r_c = B^(1/g) and r^(1-g) above it (which
  /// inverts in closed form; h / e >= 1/2). Negative when 256 draws were all rejected.
  template <class Rng>
  [[nodiscard]] double sampleRadius(double r_max, Rng& rng) const {
    const double rc = std::pow(b, 1.0 / g), r1 = std::min(rc, r_max);
    const double m1 = r1 * r1 / (2.0 * b);
    double m2 = 0.0;
    if (rc < r_max)
      m2 = std::abs(g - 2.0) < 1e-12 ? std::log(r_max / rc)
                                     : (std::pow(r_max, 2.0 - g) - std::pow(rc, 2.0 - g)) / (2.0 - g);
    for (int k = 0; k < 256; ++k) {
      const double u = rng.uniform() * (m1 + m2), v = rng.uniform();
      double r, envelope;
      if (u < m1) {
        r = r1 * std::sqrt(u / m1);
        envelope = r / b;
      } else {
        const double t = (u - m1) / m2;
        r = std::abs(g - 2.0) < 1e-12
                ? rc * std::pow(r_max / rc, t)
                : std::pow(std::pow(rc, 2.0 - g) + t * (std::pow(r_max, 2.0 - g) - std::pow(rc, 2.0 - g)),
                           1.0 / (2.0 - g));
        envelope = std::pow(r, 1.0 - g);
      }
      if (v * envelope <= r / (b + std::pow(r, g))) return r;
    }
    return -1.0;
  }
};

}  // namespace duplex
