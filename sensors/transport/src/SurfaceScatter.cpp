// Rough reflection and transmission: the Gaussian and ABg lobes in direction-cosine space.

#include "SurfaceScatter.h"

#include "OrthonormalBasis.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace duplex::detail {

double abgTotalIntegratedScatter(double a, double b, double g) {
  // Simpson's rule on [0, 1]: the integrand is smooth there for B > 0.
  const int n = 4096;
  auto f = [b, g](double r) { return r / (b + std::pow(r, g)); };
  double sum = f(0.0) + f(1.0);
  for (int i = 1; i < n; ++i) sum += (i % 2 ? 4.0 : 2.0) * f(static_cast<double>(i) / n);
  return 2.0 * std::numbers::pi * a * sum / (3.0 * n);
}

double sampleLobeRadius(const Material& m, double r_max, CounterRng& rng) {
  if (m.scatter == ScatterModel::Gaussian) {
    // Inversion of the CDF truncated to [0, r_max]: (1 - exp(-r^2 / sigma^2)) / (1 - exp(-r_max^2 / sigma^2)),
    // exact for any sigma (a wide lobe is nearly flat over the disk, never refused).
    const double s2 = m.sigma * m.sigma, mass = -std::expm1(-r_max * r_max / s2);
    return std::min(r_max, std::sqrt(-s2 * std::log1p(-rng.uniform() * mass)));
  }
  // ABg: h(r) = r / (B + r^g) <= e(r) = r / B below r_c = B^(1/g) and r^(1-g) above it; h / e >= 1/2.
  const double b = m.abg_b, g = m.abg_g, rc = std::pow(b, 1.0 / g), r1 = std::min(rc, r_max);
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

bool scatterAbout(const Material& m, const glm::dvec3& specular, const glm::dvec3& n_out, CounterRng& rng,
                  glm::dvec3& out) {
  glm::dvec3 t, b;
  orthonormalBasis(n_out, t, b);
  const glm::dvec2 beta0(glm::dot(specular, t), glm::dot(specular, b));
  // |beta0| <= 1, so every point of the unit disk lies within 2 of it.
  for (int k = 0; k < 64; ++k) {
    const double r = sampleLobeRadius(m, 2.0, rng);
    if (r < 0.0) return false;
    const double phi = 2.0 * std::numbers::pi * rng.uniform();
    const glm::dvec2 beta = beta0 + r * glm::dvec2(std::cos(phi), std::sin(phi));
    const double s2 = glm::dot(beta, beta);
    if (s2 >= 1.0) continue;
    out = beta.x * t + beta.y * b + std::sqrt(1.0 - s2) * n_out;
    return true;
  }
  return false;
}

}  // namespace duplex::detail
