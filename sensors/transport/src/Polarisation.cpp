// The polarisation of a light path through specular interfaces: Fresnel amplitudes for s and p,
// Stokes vectors and the rotation between the planes of incidence of consecutive interfaces.

#include "Polarisation.h"

#include "OrthonormalBasis.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>

namespace duplex::detail {

FresnelInterface fresnelInterface(double eta_i, double eta_t, double cos_i) {
  using C = std::complex<double>;
  FresnelInterface f;
  cos_i = std::clamp(cos_i, 0.0, 1.0);
  const double sin_t2 = (eta_i / eta_t) * (eta_i / eta_t) * (1.0 - cos_i * cos_i);
  if (sin_t2 >= 1.0) {
    // Evanescent transmitted wave: cos t = i kappa. Both amplitudes have modulus 1; only their
    // phases differ, which turns linear into elliptical polarisation.
    const C cos_t(0.0, std::sqrt(sin_t2 - 1.0));
    const C rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    const C rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    f.r_sp = rs * std::conj(rp);
    return f;
  }
  const double cos_t = std::sqrt(1.0 - sin_t2);
  const double ds = eta_i * cos_i + eta_t * cos_t, dp = eta_t * cos_i + eta_i * cos_t;
  const double rs = (eta_i * cos_i - eta_t * cos_t) / ds, rp = (eta_t * cos_i - eta_i * cos_t) / dp;
  f.rs2 = rs * rs;
  f.rp2 = rp * rp;
  f.r_sp = rs * rp;
  // ts = 2 n1 cos i / ds, tp = 2 n1 cos i / dp; the power factor n2 cos t / (n1 cos i) makes
  // Ts = 1 - Rs and Tp = 1 - Rp exactly (up to rounding).
  f.t_sp = 4.0 * eta_i * cos_i * eta_t * cos_t / (ds * dp);
  f.cos_t = cos_t;
  f.total_internal = false;
  return f;
}

void rotateFrame(Polarisation& pol, const glm::dvec3& d, const glm::dvec3& s_new) {
  if (!pol.unpolarised()) {
    // s_new = cos(phi) s + sin(phi) p with p = d x s: (q, u) turn by 2 phi, v is unchanged.
    const double c = glm::dot(pol.s, s_new), sn = glm::dot(glm::cross(pol.s, s_new), d);
    const double c2 = c * c - sn * sn, s2 = 2.0 * sn * c, norm = c * c + sn * sn;
    const double q = (c2 * pol.q + s2 * pol.u) / norm, u = (-s2 * pol.q + c2 * pol.u) / norm;
    pol.q = q;
    pol.u = u;
  }
  pol.s = s_new;
}

void enterPlaneOfIncidence(Polarisation& pol, const glm::dvec3& d, const glm::dvec3& n) {
  const glm::dvec3 c = glm::cross(d, n);
  const double len = glm::length(c);
  // Below this the plane of incidence is lost in rounding; there Rs and Rp agree to ~len^2, so the
  // frame does not matter.
  if (len > 1e-12) {
    rotateFrame(pol, d, c / len);
  } else if (glm::dot(pol.s, pol.s) == 0.0) {
    glm::dvec3 t, b;
    orthonormalBasis(d, t, b);
    pol.s = t;
  }
}

double reflectanceFor(const Polarisation& pol, const FresnelInterface& f) {
  return std::clamp(0.5 * (f.rs2 + f.rp2) + 0.5 * (f.rs2 - f.rp2) * pol.q, 0.0, 1.0);
}

void afterInterface(Polarisation& pol, const FresnelInterface& f, bool transmitted) {
  // The part's Mueller matrix on (1, q, u, v): a = (Ms + Mp) / 2, b = (Ms - Mp) / 2 on (I, Q), and
  // the complex product c on (U, V): U' = Re c U - Im c V, V' = Re c V + Im c U.
  const double ms = transmitted ? 1.0 - f.rs2 : f.rs2, mp = transmitted ? 1.0 - f.rp2 : f.rp2;
  const std::complex<double> c = transmitted ? std::complex<double>(f.t_sp, 0.0) : f.r_sp;
  const double a = 0.5 * (ms + mp), b = 0.5 * (ms - mp);
  const double i = a + b * pol.q;
  if (!(i > 0.0)) {
    pol.q = pol.u = pol.v = 0.0;
    return;
  }
  const double q = (b + a * pol.q) / i;
  const double u = (c.real() * pol.u - c.imag() * pol.v) / i;
  const double v = (c.real() * pol.v + c.imag() * pol.u) / i;
  pol.q = std::clamp(q, -1.0, 1.0);
  pol.u = std::clamp(u, -1.0, 1.0);
  pol.v = std::clamp(v, -1.0, 1.0);
}

void afterIdealReflection(Polarisation& pol) {
  pol.u = -pol.u;
  pol.v = -pol.v;
}

void followDirection(Polarisation& pol, const glm::dvec3& d) {
  if (pol.unpolarised()) {
    pol.s = glm::dvec3(0.0);
    return;
  }
  const glm::dvec3 s = pol.s - glm::dot(pol.s, d) * d;
  const double len = glm::length(s);
  if (len < 1e-6) {
    pol = {};
    return;
  }
  pol.s = s / len;
}

}  // namespace duplex::detail
