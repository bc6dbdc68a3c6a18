#pragma once
/// \file OpticsReference.h
/// Closed forms the light-transport tests and the validation cases compare with, written from the
/// textbook formulas independently of the library: Fresnel reflectances of a smooth interface for
/// s and p light, a plane-parallel slab's transmittance and reflectance with all its internal
/// reflections (per polarisation, then averaged for unpolarised light), and configuration factors.

#include <cmath>
#include <numbers>

namespace duplex::test {

/// Power reflectances (s, p) of a smooth interface from index n1 to n2 at angle of incidence
/// theta (radians); 1 under total internal reflection.
struct FresnelPair {
  double rs = 1.0, rp = 1.0;
};
inline FresnelPair fresnelReflectance(double n1, double n2, double theta) {
  const double ci = std::cos(theta), si = std::sin(theta), st = n1 / n2 * si;
  if (st >= 1.0) return {};
  const double ct = std::sqrt(1.0 - st * st);
  const double rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct), rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct);
  return {rs * rs, rp * rp};
}

/// What a slab does to a collimated beam: fractions transmitted and reflected (the rest absorbed).
struct SlabResponse {
  double t = 0.0, r = 0.0;
};

/// One polarisation through a slab of index n, thickness d (scene units) and internal absorption
/// coefficient alpha (per scene unit) in air, lit at angle theta: with R the interface reflectance
/// (the same from both sides) and tau = exp(-alpha d / cos theta_t) one pass's transmittance, the
/// incoherent sum of the multiply reflected beams: T = (1-R)^2 tau / (1 - R^2 tau^2),
/// R_slab = R + (1-R)^2 R tau^2 / (1 - R^2 tau^2).
inline SlabResponse slabOnePolarisation(double rf, double tau) {
  const double den = 1.0 - rf * rf * tau * tau;
  return {(1.0 - rf) * (1.0 - rf) * tau / den, rf + (1.0 - rf) * (1.0 - rf) * rf * tau * tau / den};
}

/// The slab lit by unpolarised light: s and p follow their own series, and the result is their mean.
inline SlabResponse slabUnpolarised(double n, double d, double alpha, double theta) {
  const FresnelPair f = fresnelReflectance(1.0, n, theta);
  const double st = std::sin(theta) / n, ct = std::sqrt(1.0 - st * st);
  const double tau = std::exp(-alpha * d / ct);
  const SlabResponse s = slabOnePolarisation(f.rs, tau), p = slabOnePolarisation(f.rp, tau);
  return {0.5 * (s.t + p.t), 0.5 * (s.r + p.r)};
}

/// The slab as an unpolarised calculation would have it (each interface the mean (Rs + Rp) / 2):
/// what the tests show the code no longer does.
inline SlabResponse slabScalarFresnel(double n, double d, double alpha, double theta) {
  const FresnelPair f = fresnelReflectance(1.0, n, theta);
  const double st = std::sin(theta) / n, ct = std::sqrt(1.0 - st * st);
  return slabOnePolarisation(0.5 * (f.rs + f.rp), std::exp(-alpha * d / ct));
}

/// Configuration factor from a differential area to a parallel rectangle of sides a x b with one
/// corner straight above it at distance h (the standard form, e.g. Howell's catalogue, case B-3).
inline double pointToParallelRectangleCorner(double a, double b, double h) {
  const double x = a / h, y = b / h;
  const double sx = std::sqrt(1.0 + x * x), sy = std::sqrt(1.0 + y * y);
  return (x / sx * std::atan(y / sx) + y / sy * std::atan(x / sy)) / (2.0 * std::numbers::pi);
}

/// The same for a rectangle [x0, x1] x [y0, y1] of the parallel plane at height h, the
/// differential area at the origin (signed corners: the rectangle may straddle the axis).
inline double pointToParallelRectangle(double x0, double x1, double y0, double y1, double h) {
  auto corner = [h](double x, double y) {
    const double s = (x < 0 ? -1.0 : 1.0) * (y < 0 ? -1.0 : 1.0);
    return x == 0.0 || y == 0.0 ? 0.0 : s * pointToParallelRectangleCorner(std::abs(x), std::abs(y), h);
  };
  return corner(x1, y1) - corner(x0, y1) - corner(x1, y0) + corner(x0, y0);
}

/// A1 F12 (area times configuration factor, the exchange area) between the rectangles
/// [x0, x1] x [y0, y1] and [u0, u1] x [v0, v1] of two parallel planes a distance z apart: the
/// contour-integral closed form summed over the corners (Howell's catalogue, case C-11). The flux
/// a Lambertian rectangle of luminance L sends to the other is pi L times it.
inline double parallelRectanglesExchange(double x0, double x1, double y0, double y1, double u0, double u1, double v0,
                                         double v1, double z) {
  auto g = [z](double x, double y) {
    const double a = std::sqrt(y * y + z * z), b = std::sqrt(x * x + z * z);
    return x * a * std::atan(x / a) + y * b * std::atan(y / b) - 0.5 * z * z * std::log(x * x + y * y + z * z);
  };
  const double xs[2] = {x0, x1}, ys[2] = {y0, y1}, us[2] = {u0, u1}, vs[2] = {v0, v1};
  double sum = 0.0;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j)
      for (int k = 0; k < 2; ++k)
        for (int l = 0; l < 2; ++l) sum += ((i + j + k + l) % 2 ? -1.0 : 1.0) * g(xs[i] - us[k], ys[j] - vs[l]);
  return sum / (2.0 * std::numbers::pi);
}

/// Solid angle (sr) of the rectangle [x0, x1] x [y0, y1] of a plane seen from a point at distance
/// h from that plane, the coordinates measured from the foot of the perpendicular.
inline double rectangleSolidAngleFrom(double x0, double x1, double y0, double y1, double h) {
  auto f = [h](double x, double y) { return std::atan(x * y / (h * std::sqrt(x * x + y * y + h * h))); };
  return f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0);
}

/// The CIE 171:2006 clear-glass curve: directional transmittance of 6 mm clear float glass as a
/// polynomial of the cosine of the angle of incidence (a fit to measurements).
inline double cieClearGlassTransmittance(double cos_theta) {
  const double c = cos_theta;
  return -0.028378 + c * (3.156075 + c * (-3.058376 + c * (-1.428919 + c * (4.014235 + c * -1.775827))));
}

}  // namespace duplex::test
