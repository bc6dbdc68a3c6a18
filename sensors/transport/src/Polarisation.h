#pragma once
// Private to sensors/transport/src: the polarisation a light path carries through specular
// interfaces (a Stokes vector normalised to its power, in a frame that travels with the ray), and
// the exact Fresnel equations of a smooth dielectric interface for the s and p components.
//
// Conventions (Jones calculus, fields E = Es s + Ep p with p = d x s, so (s, p, d) is right-handed):
// Q = |Es|^2 - |Ep|^2, U = 2 Re(Es Ep*), V = 2 Im(Es Ep*), all divided by I = |Es|^2 + |Ep|^2. At
// an interface s is the unit normal of the plane of incidence, cross(d, n); it is the same vector
// before and after, so only p turns with the direction. With p = d x s on both sides the Fresnel
// amplitudes below are the textbook ones, rs = (n1 cos i - n2 cos t) / (n1 cos i + n2 cos t),
// rp = (n2 cos i - n1 cos t) / (n2 cos i + n1 cos t).

#include <glm/vec3.hpp>

#include <complex>

namespace duplex::detail {

// The polarisation of a path's power: the Stokes vector (1, q, u, v) relative to its intensity, in
// the frame whose s-axis is `s` (unit, perpendicular to the ray's direction; zero before any frame
// was needed). Unpolarised light is (0, 0, 0) in any frame.
struct Polarisation {
  glm::dvec3 s{0.0};
  double q = 0.0, u = 0.0, v = 0.0;

  [[nodiscard]] bool unpolarised() const { return q == 0.0 && u == 0.0 && v == 0.0; }
};

// A smooth interface between indices eta_i (incident side) and eta_t met at cos_i = |cos| of the
// angle of incidence, in [0, 1]: power reflectances Rs, Rp; the products that carry the phase
// between s and p, reflected rs conj(rp) and transmitted (n2 cos t / n1 cos i) ts tp = sqrt(Ts Tp);
// the cosine of the refraction angle (0 under total internal reflection).
struct FresnelInterface {
  double rs2 = 1.0, rp2 = 1.0;
  std::complex<double> r_sp{1.0, 0.0};
  double t_sp = 0.0;
  double cos_t = 0.0;
  bool total_internal = true;
};

// The exact Fresnel equations for both polarisations; under total internal reflection Rs = Rp = 1
// and rs conj(rp) carries the phase difference of the two (cos t = i sqrt(sin^2 t - 1)).
[[nodiscard]] FresnelInterface fresnelInterface(double eta_i, double eta_t, double cos_i);

// Turns `pol` into the frame whose s-axis is the unit vector `s_new` (perpendicular to the ray's
// unit direction `d`, as pol.s is): a rotation of (q, u) by twice the angle between the frames.
void rotateFrame(Polarisation& pol, const glm::dvec3& d, const glm::dvec3& s_new);

// The frame of an interface of unit normal `n` met along unit direction `d`: cross(d, n)
// normalised, or (at normal incidence, where every frame is one) pol.s, or any unit vector
// perpendicular to d when pol has no frame yet. Turns pol into it.
void enterPlaneOfIncidence(Polarisation& pol, const glm::dvec3& d, const glm::dvec3& n);

// The fraction of the power reflected by interface `f` for polarisation `pol` (in its frame).
[[nodiscard]] double reflectanceFor(const Polarisation& pol, const FresnelInterface& f);

// The polarisation of the reflected (or, with `transmitted`, the refracted) part, renormalised to
// its own intensity; the frame's s-axis is unchanged. A part of zero power leaves pol unpolarised.
void afterInterface(Polarisation& pol, const FresnelInterface& f, bool transmitted);

// After an ideal, polarisation-blind specular reflection (a mirror or a coating: rs = -rp, the
// reflection of a perfect conductor in these frames): U and V change sign.
void afterIdealReflection(Polarisation& pol);

// Carries the frame to a new unit direction `d` that is not the specular one (rough scatter about
// it): the s-axis projected perpendicular to d; light whose frame cannot follow (s along d) is
// treated as unpolarised.
void followDirection(Polarisation& pol, const glm::dvec3& d);

}  // namespace duplex::detail
