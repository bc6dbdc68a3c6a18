#pragma once
// Private to sensors/transport/src: rough reflection and transmission (Gaussian and ABg scatter)
// in direction-cosine space, sampled exactly, for the path loop and its tests.

#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/Material.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace duplex::detail {

// The ABg model's total integrated scatter at normal incidence: 2 pi A int_0^1 r / (B + r^g) dr
// (the fraction of the light it scatters; the rest stays specular).
[[nodiscard]] double abgTotalIntegratedScatter(double a, double b, double g);

// A radius of the model's lobe in direction-cosine space, from the radial density
// r * BSDF(r) on [0, r_max] (Gaussian: r exp(-r^2 / sigma^2), exact by inversion of the truncated CDF; ABg:
// r / (B + r^g), exact by rejection from an envelope that inverts in closed form, accepting at
// least half of its draws). Returns a negative number when 256 draws were all rejected.
[[nodiscard]] double sampleLobeRadius(const Material& m, double r_max, CounterRng& rng);

// The direction scattered about the specular direction `specular` (unit) that leaves the surface
// towards the side of unit normal `n_out`: beta = beta0 + an offset drawn from the lobe, redrawn
// until |beta| < 1 (the lobe truncated to real directions and renormalised: every draw leaves the
// surface, so the model conserves energy). False when no draw fell inside in 64 tries (the
// material refuses the path: a numerical failure).
[[nodiscard]] bool scatterAbout(const Material& m, const glm::dvec3& specular, const glm::dvec3& n_out, CounterRng& rng,
                                glm::dvec3& out);

}  // namespace duplex::detail
