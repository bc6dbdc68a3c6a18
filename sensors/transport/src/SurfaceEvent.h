#pragma once
// Private to sensors/transport/src: what a material's path step (materials/MaterialModel.h) is
// given when a ray meets its surface. It holds the path's state by reference (power, polarisation,
// random numbers, energy balance) and gives the materials the directions and interface physics
// they compose, so that each material is its parameters plus a few lines of decisions.

#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/SensorResults.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include "OrthonormalBasis.h"
#include "Polarisation.h"
#include "SurfaceScatter.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace duplex::detail {

// The methods are forced inline: the path loop used to hold this code, and a call per surface
// event for each of them costs more than the material's own decisions.
struct SurfaceEvent {
  // World space, unit length: the incoming direction, the geometric normal and the normal facing
  // the incoming ray.
  glm::dvec3 d, n, nf;
  bool front;             // met from the side the geometric normal points to
  std::uint32_t band;     // the path's spectral band
  double travelled;       // world distance from the ray's origin to the hit
  double& w;              // the path's power (W)
  Polarisation& pol;      // the path's polarisation
  CounterRng& rng;        // the path's random numbers
  EnergyBalance& energy;  // where the path's power went

  [[gnu::always_inline]] double uniform() { return rng.uniform(); }

  // Keeps a fraction `keep` of the power; the rest is absorbed.
  [[gnu::always_inline]] void attenuate(double keep) {
    energy.absorbed_w += w * (1.0 - keep);
    w *= keep;
  }

  // Specular reflection about the facing normal (an ideal, polarisation-blind reflection: a mirror
  // or a coating treats s and p alike).
  [[gnu::always_inline]] glm::dvec3 mirror() {
    enterPlaneOfIncidence(pol, d, nf);
    afterIdealReflection(pol);
    return reflect(d, nf);
  }

  // A cosine-distributed direction about the facing normal (two random numbers); diffuse
  // reflection depolarises.
  [[gnu::always_inline]] glm::dvec3 diffuse() {
    // Random numbers are drawn in statements of their own: a call's arguments are evaluated in
    // an order each compiler picks, and a run must give the same paths whichever built it.
    const double u0 = rng.uniform(), u1 = rng.uniform();
    glm::dvec3 t, b;
    orthonormalBasis(nf, t, b);
    const double r = std::sqrt(u0), phi = 2.0 * std::numbers::pi * u1;
    pol = {};
    return r * std::cos(phi) * t + r * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - u0)) * nf;
  }

  // The incoming direction, undeviated (passing through changes no polarisation).
  [[gnu::always_inline, nodiscard]] glm::dvec3 straight() const { return d; }

  // A smooth interface from index eta_i (the incoming side) to eta_t: the exact Fresnel equations
  // for the path's s and p powers decide (one random number) between reflection and refraction
  // (`transmits`), and the polarisation follows the part taken.
  [[gnu::always_inline]] glm::dvec3 refractOrReflect(double eta_i, double eta_t, bool& transmits) {
    const double cos_i = std::min(1.0, std::abs(glm::dot(d, n)));
    const FresnelInterface f = fresnelInterface(eta_i, eta_t, cos_i);
    enterPlaneOfIncidence(pol, d, n);
    const double reflectance = reflectanceFor(pol, f);
    transmits = !(rng.uniform() < reflectance);
    afterInterface(pol, f, transmits);
    return transmits ? (eta_i / eta_t) * d + ((eta_i / eta_t) * cos_i - f.cos_t) * nf : reflect(d, nf);
  }

  // The step's direction redrawn from a rough lobe about it (the specular direction), to the side
  // the step sends the ray; zero when the lobe yields none (a numerical failure).
  template <class Lobe>
  [[gnu::always_inline]] void scatterAbout(const Lobe& lobe, SurfaceStep& step) {
    const glm::dvec3 specular = glm::normalize(step.next);
    if (!detail::scatterAbout(lobe, specular, step.transmits ? -nf : nf, rng, step.next)) step.next = glm::dvec3(0.0);
    else followDirection(pol, glm::normalize(step.next));
  }

  [[gnu::always_inline]] static glm::dvec3 reflect(const glm::dvec3& v, const glm::dvec3& m) {
    return v - 2.0 * glm::dot(v, m) * m;
  }
};

}  // namespace duplex::detail
