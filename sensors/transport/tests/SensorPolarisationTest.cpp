// Polarised Fresnel transport against exact formulas: the s and p amplitudes of an interface,
// Brewster's angle, the phase that total internal reflection puts between s and p, crossed
// Brewster reflections (the frame carried from one plane of incidence to the next), and a glass
// pane's transmittance and reflectance at 0-89 degrees, lossless and absorbing, against the
// two-polarisation slab formulas with all internal reflections.

#include "duplex/objects/ProceduralMesh.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "Polarisation.h"
#include "SlabRuns.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <cstdio>
#include <numbers>

namespace duplex {
namespace {

using namespace test;
constexpr double kDeg = std::numbers::pi / 180.0;

TEST(Polarisation, InterfaceMatchesTheFresnelEquationsForBothPolarisations) {
  for (const auto& [n1, n2] : {std::pair{1.0, 1.52}, std::pair{1.52, 1.0}, std::pair{1.0, 2.4}}) {
    for (double deg = 0.0; deg < 90.0; deg += 1.0) {
      const double th = deg * kDeg;
      const FresnelPair ref = fresnelReflectance(n1, n2, th);
      const detail::FresnelInterface f = detail::fresnelInterface(n1, n2, std::cos(th));
      EXPECT_NEAR(f.rs2, ref.rs, 1e-14) << n1 << "->" << n2 << " at " << deg;
      EXPECT_NEAR(f.rp2, ref.rp, 1e-14) << n1 << "->" << n2 << " at " << deg;
      if (!f.total_internal) {  // Ts Tp = t_sp^2 with Ts = 1 - Rs, Tp = 1 - Rp
        EXPECT_NEAR(f.t_sp * f.t_sp, (1.0 - ref.rs) * (1.0 - ref.rp), 1e-14);
        EXPECT_NEAR(f.cos_t, std::sqrt(1.0 - std::pow(n1 / n2 * std::sin(th), 2)), 1e-14);
      }
      // Unpolarised light is reflected by the mean, and the reflected part is s-polarised by the
      // difference over the sum.
      detail::Polarisation pol;
      EXPECT_NEAR(detail::reflectanceFor(pol, f), 0.5 * (ref.rs + ref.rp), 1e-14);
      detail::afterInterface(pol, f, false);
      if (ref.rs + ref.rp > 0.0) {
        EXPECT_NEAR(pol.q, (ref.rs - ref.rp) / (ref.rs + ref.rp), 1e-12);
      }
    }
  }
}

TEST(Polarisation, BrewsterAngleReflectsNoPLight) {
  const double n = 1.52, brewster = std::atan(n);
  const detail::FresnelInterface f = detail::fresnelInterface(1.0, n, std::cos(brewster));
  EXPECT_LT(f.rp2, 1e-30);
  EXPECT_GT(f.rs2, 0.1);
  // Pure p light (q = -1) is not reflected at all; the reflected part of unpolarised light is pure s.
  detail::Polarisation p_light;
  p_light.s = {0, 1, 0};
  p_light.q = -1.0;
  EXPECT_LT(detail::reflectanceFor(p_light, f), 1e-15);
  detail::Polarisation pol;
  detail::afterInterface(pol, f, false);
  EXPECT_NEAR(pol.q, 1.0, 1e-12);
  // Inside the glass, the internal Brewster angle atan(1/n) passes p light entirely too.
  const detail::FresnelInterface g = detail::fresnelInterface(n, 1.0, std::cos(std::atan(1.0 / n)));
  EXPECT_LT(g.rp2, 1e-30);
}

TEST(Polarisation, CrossedBrewsterReflectionsExtinguishTheBeam) {
  // Unpolarised light reflected at Brewster's angle by a surface of normal n1 is pure s light,
  // polarised along cross(d, n1). A second surface turned so that its plane of incidence contains
  // that direction sees it as pure p light at its own Brewster angle and reflects nothing; turned
  // the other way (planes parallel) it sees pure s light and reflects Rs.
  const double n = 1.52, b = std::atan(n);
  const glm::dvec3 d0(std::sin(b), 0.0, -std::cos(b));
  const glm::dvec3 n1(0, 0, 1);
  detail::Polarisation pol;
  detail::enterPlaneOfIncidence(pol, d0, n1);
  const detail::FresnelInterface f = detail::fresnelInterface(1.0, n, std::cos(b));
  detail::afterInterface(pol, f, false);
  const glm::dvec3 d1 = d0 - 2.0 * glm::dot(d0, n1) * n1;  // leaves along (sin b, 0, cos b)
  // A second surface whose normal makes angle b with d1, its plane of incidence holding the s axis (y).
  glm::dvec3 t, u;
  t = glm::dvec3(0, 1, 0);  // the first reflection's s axis
  const glm::dvec3 n_crossed = glm::normalize(-std::cos(b) * d1 + std::sin(b) * t);
  detail::Polarisation crossed = pol;
  detail::enterPlaneOfIncidence(crossed, d1, n_crossed);
  EXPECT_NEAR(std::abs(glm::dot(d1, n_crossed)), std::cos(b), 1e-12);
  EXPECT_LT(detail::reflectanceFor(crossed, f), 1e-14);
  // Parallel planes of incidence: the second normal in the first plane (x, z).
  u = glm::normalize(glm::cross(t, d1));  // in the (x, z) plane, perpendicular to d1
  const glm::dvec3 n_parallel = glm::normalize(-std::cos(b) * d1 + std::sin(b) * u);
  detail::Polarisation parallel = pol;
  detail::enterPlaneOfIncidence(parallel, d1, n_parallel);
  EXPECT_NEAR(detail::reflectanceFor(parallel, f), f.rs2, 1e-12);
  // At 45 degrees between the two, half of each: (Rs + Rp) / 2 = Rs / 2.
  const glm::dvec3 n_45 = glm::normalize(-std::cos(b) * d1 + std::sin(b) * glm::normalize(t + u));
  detail::Polarisation mid = pol;
  detail::enterPlaneOfIncidence(mid, d1, n_45);
  EXPECT_NEAR(detail::reflectanceFor(mid, f), 0.5 * f.rs2, 1e-12);
}

TEST(Polarisation, TotalInternalReflectionShiftsThePhaseBetweenSAndP) {
  // Linear light at 45 degrees to the plane of incidence (u = 1) keeps its power and becomes
  // elliptical: (u, v) = (cos delta, +-sin delta) with tan(delta / 2) = cos(th) sqrt(sin^2 th - m^2) /
  // sin^2 th, m = n2 / n1 (Born and Wolf, 1.5.4).
  const double n = 1.52, m = 1.0 / n;
  for (double deg : {42.0, 45.0, 50.0, 60.0, 75.0}) {
    const double th = deg * kDeg;
    const detail::FresnelInterface f = detail::fresnelInterface(n, 1.0, std::cos(th));
    ASSERT_TRUE(f.total_internal);
    detail::Polarisation pol;
    pol.s = {0, 1, 0};
    pol.u = 1.0;
    EXPECT_NEAR(detail::reflectanceFor(pol, f), 1.0, 1e-15);
    detail::afterInterface(pol, f, false);
    const double s2 = std::sin(th) * std::sin(th);
    const double delta = 2.0 * std::atan(std::cos(th) * std::sqrt(s2 - m * m) / s2);
    EXPECT_NEAR(pol.q, 0.0, 1e-12) << deg;
    EXPECT_NEAR(pol.u, std::cos(delta), 1e-12) << deg;
    EXPECT_NEAR(std::abs(pol.v), std::sin(delta), 1e-12) << deg;
  }
}

TEST(Polarisation, FrameRotationKeepsTheDegreeOfPolarisation) {
  const glm::dvec3 d(0, 0, 1);
  detail::Polarisation pol;
  pol.s = {1, 0, 0};
  pol.q = 0.6;
  pol.u = 0.3;
  pol.v = 0.2;
  for (double a : {0.1, 0.7, 1.5707963, 2.9}) {
    detail::Polarisation r = pol;
    detail::rotateFrame(r, d, {std::cos(a), std::sin(a), 0.0});
    EXPECT_NEAR(r.q * r.q + r.u * r.u, pol.q * pol.q + pol.u * pol.u, 1e-14);
    EXPECT_NEAR(r.q, std::cos(2 * a) * pol.q + std::sin(2 * a) * pol.u, 1e-14);
    EXPECT_EQ(r.v, pol.v);
    detail::rotateFrame(r, d, pol.s);  // and back
    EXPECT_NEAR(r.q, pol.q, 1e-14);
    EXPECT_NEAR(r.u, pol.u, 1e-14);
  }
}

TEST(Polarisation, PaneFollowsTheTwoPolarisationSlabFormulasAtEveryAngle) {
  const double n = 1.52, d = 0.006;
  for (const double alpha : {0.0, 20.0}) {  // lossless; absorbing (exp(-0.12) per normal pass)
    for (const double deg : {0.0, 30.0, 56.66, 70.0, 80.0, 89.0}) {
      const double th = deg * kDeg;
      const Material glass = Dielectric{n, alpha};
      const Measured got = slabRun({{0, 0, 0}, {0, 0, 1}, {1, 0, 0}}, d, glass, th, false, {}, 60000, 7);
      const SlabResponse scalar = slabScalarFresnel(n, d, alpha, th);
      std::printf("(a scalar Fresnel calculation: T %.5f, R %.5f)\n", scalar.t, scalar.r);
      expectSlab(got, slabUnpolarised(n, d, alpha, th),
                 "pane alpha " + std::to_string(alpha) + " at " + std::to_string(deg));
    }
  }
}

}  // namespace
}  // namespace duplex
