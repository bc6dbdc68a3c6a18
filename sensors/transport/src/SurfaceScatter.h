#pragma once
// Private to sensors/transport/src: a direction drawn from a rough lobe (materials/Roughness.h)
// about the specular direction, in direction-cosine space, for the path loop and its tests.

#include "OrthonormalBasis.h"

#include <glm/geometric.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cmath>
#include <numbers>

namespace duplex::detail {

// The direction scattered about the specular direction `specular` (unit) that leaves the surface
// towards the side of unit normal `n_out`: beta = beta0 + an offset drawn from `lobe`
// (lobe.sampleRadius), redrawn until |beta| < 1 (the lobe truncated to real directions and
// renormalised: every draw leaves the surface, so the model conserves energy). False when no draw
// fell inside in 64 tries or the lobe yielded no radius (the material refuses the path: a
// numerical failure).
template <class Lobe, class Rng>
[[nodiscard]] bool scatterAbout(const Lobe& lobe, const glm::dvec3& specular, const glm::dvec3& n_out, Rng& rng,
                                glm::dvec3& out) {
  glm::dvec3 t, b;
  orthonormalBasis(n_out, t, b);
  const glm::dvec2 beta0(glm::dot(specular, t), glm::dot(specular, b));
  // |beta0| <= 1, so every point of the unit disk lies within 2 of it.
  for (int k = 0; k < 64; ++k) {
    const double r = lobe.sampleRadius(2.0, rng);
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
