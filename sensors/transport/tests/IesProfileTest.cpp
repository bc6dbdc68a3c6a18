/// \file IesProfileTest.cpp
/// IES LM-63 reading against hand-made files: symmetries, the exact integral against quadrature
/// of intensity(), unbiased sampling against quadrature, and every malformed-file error.

#include "duplex/accel/Error.h"
#include "duplex/sensors/IesProfile.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace duplex {
namespace {

constexpr double kPi = std::numbers::pi;

/// An LM-63-2002 file with the given angles and candela values (h-major), multiplier 1.
std::string iesText(const std::vector<double>& vertical, const std::vector<double>& horizontal,
                    const std::vector<double>& candela, const std::string& tilt = "TILT=NONE",
                    const std::string& type = "1", const std::string& multiplier = "1") {
  std::ostringstream os;
  os << "IESNA:LM-63-2002\n[TEST] unit test\n[MANUFAC] Duplex\n[MORE] second line\n" << tilt << "\n";
  os << "1 -1 " << multiplier << " " << vertical.size() << " " << horizontal.size() << " " << type << " 2 0 0 0\n";
  os << "1.0 1.0 100\n";
  for (const double a : vertical) os << a << " ";
  os << "\n";
  for (const double a : horizontal) os << a << " ";
  os << "\n";
  for (std::size_t i = 0; i < candela.size(); ++i) os << candela[i] << ((i + 1) % vertical.size() == 0 ? "\n" : " ");
  return os.str();
}

glm::dvec3 dirOf(double gamma, double phi) {
  return {std::sin(gamma) * std::cos(phi), std::sin(gamma) * std::sin(phi), -std::cos(gamma)};
}

/// Midpoint quadrature of f(direction) * intensity over the sphere, uniform in (cos gamma, phi).
template <class F>
double quadrature(const IesProfile& p, F&& f, int n = 1200) {
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const double cos_g = 1.0 - 2.0 * (i + 0.5) / n;  // gamma from the nadir
    const double gamma = std::acos(cos_g);
    for (int j = 0; j < 2 * n; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / (2 * n);
      const glm::dvec3 d = dirOf(gamma, phi);
      sum += p.intensity(d) * f(d);
    }
  }
  return sum * (2.0 / n) * (2.0 * kPi / (2 * n));
}

/// A full-circle table with uneven angles and random values (no symmetry to hide errors behind).
IesProfile asymmetricProfile() {
  const std::vector<double> vertical{0, 10, 35, 60, 90, 120, 150, 180};
  const std::vector<double> horizontal{0, 30, 90, 100, 200, 300, 360};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> value(0.0, 500.0);
  std::vector<double> candela(vertical.size() * horizontal.size());
  for (double& c : candela) c = value(rng);
  // The 360 plane repeats the 0 plane, as real files do.
  for (std::size_t v = 0; v < vertical.size(); ++v) candela[6 * vertical.size() + v] = candela[v];
  return IesProfile::parse(iesText(vertical, horizontal, candela), "asymmetric.ies");
}

TEST(IesProfile, IsotropicFileHasTheIntegralOfASphereAndUnitWeights) {
  const IesProfile p =
      IesProfile::parse(iesText({0, 90, 180}, {0}, {100, 100, 100}, "TILT=NONE", "1", "2.5"), "iso.ies");
  EXPECT_NEAR(p.integral(), 4.0 * kPi * 250.0, 1e-9 * p.integral());
  EXPECT_DOUBLE_EQ(p.intensity({0.3, -0.2, 0.9}), 250.0);
  EXPECT_EQ(p.keywords().at("TEST"), "unit test");
  EXPECT_EQ(p.keywords().at("MANUFAC"), "Duplex\nsecond line");
  EXPECT_EQ(p.tilt(), IesProfile::Tilt::None);
  EXPECT_EQ(p.lumensPerLamp(), -1.0);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    const double u1 = u(rng), u2 = u(rng);
    const auto s = p.sample(u1, u2);
    EXPECT_NEAR(glm::dot(s.direction_lf, s.direction_lf), 1.0, 1e-12);
    EXPECT_NEAR(s.weight, 1.0, 1e-9);
    EXPECT_NEAR(p.pdf(s.direction_lf), 1.0 / (4.0 * kPi), 1e-12);
  }
}

TEST(IesProfile, ExactIntegralAgreesWithQuadratureOfIntensity) {
  const IesProfile p = asymmetricProfile();
  const double q = quadrature(p, [](const glm::dvec3&) { return 1.0; });
  EXPECT_NEAR(p.integral(), q, 2e-4 * q);
  // A downlight (vertical 0-90): nothing above the horizon, and the integral only counts below.
  const IesProfile down = IesProfile::parse(iesText({0, 45, 90}, {0}, {300, 200, 100}), "down.ies");
  EXPECT_EQ(down.intensity({0, 0, 1}), 0.0);
  EXPECT_EQ(down.intensity({1, 0, 0.2}), 0.0);
  EXPECT_DOUBLE_EQ(down.intensity({0, 0, -1}), 300.0);
  const double qd = quadrature(down, [](const glm::dvec3&) { return 1.0; });
  EXPECT_NEAR(down.integral(), qd, 2e-3 * qd);
}

TEST(IesProfile, TableValuesAndSymmetriesAreHonoured) {
  const std::vector<double> vertical{0, 45, 90, 135, 180};
  // Quadrant (0-90), three planes with distinct values.
  std::vector<double> quad;
  for (int h = 0; h < 3; ++h)
    for (int v = 0; v < 5; ++v) quad.push_back(10.0 * h + v + 1);
  const IesProfile q = IesProfile::parse(iesText(vertical, {0, 45, 90}, quad), "quad.ies");
  const double g = 50 * kPi / 180;
  for (const double deg : {0.0, 20.0, 45.0, 70.0, 90.0}) {
    const double phi = deg * kPi / 180;
    const double i = q.intensityAt(g, phi);
    EXPECT_NEAR(q.intensityAt(g, kPi - phi), i, 1e-9) << deg;
    EXPECT_NEAR(q.intensityAt(g, kPi + phi), i, 1e-9) << deg;
    EXPECT_NEAR(q.intensityAt(g, -phi), i, 1e-9) << deg;
  }
  // Tabulated points are reproduced exactly; between them the interpolation is linear.
  EXPECT_DOUBLE_EQ(q.intensityAt(kPi / 4, kPi / 4), 12.0);
  EXPECT_DOUBLE_EQ(q.intensityAt(kPi / 2, kPi / 2), 23.0);
  EXPECT_NEAR(q.intensityAt(kPi / 4, kPi / 8), 7.0, 1e-9);  // halfway between 2 and 12
  // Bilateral 0-180: I(phi) = I(-phi); bilateral 90-270: I(phi) = I(180 - phi).
  std::vector<double> three;
  for (int h = 0; h < 3; ++h)
    for (int v = 0; v < 5; ++v) three.push_back(7.0 * h + 2 * v + 1);
  const IesProfile b = IesProfile::parse(iesText(vertical, {0, 90, 180}, three), "bilateral.ies");
  const IesProfile c = IesProfile::parse(iesText(vertical, {90, 180, 270}, three), "bilateral90.ies");
  for (const double deg : {10.0, 80.0, 100.0, 170.0}) {
    const double phi = deg * kPi / 180;
    EXPECT_NEAR(b.intensityAt(g, -phi), b.intensityAt(g, phi), 1e-9) << deg;
    EXPECT_NEAR(c.intensityAt(g, kPi - phi), c.intensityAt(g, phi), 1e-9) << deg;
  }
  EXPECT_DOUBLE_EQ(c.intensityAt(kPi / 4, 1.5 * kPi), 7.0 * 2 + 3);  // the 270 plane as given
  EXPECT_DOUBLE_EQ(c.intensityAt(kPi / 4, 0.0), 7.0 + 3);            // 0 mirrors the 180 plane
  EXPECT_EQ(b.horizontalAngles().front(), 0.0);
  EXPECT_EQ(b.horizontalAngles().back(), 360.0);
}

TEST(IesProfile, SamplingIsUnbiasedAgainstQuadrature) {
  const IesProfile p = asymmetricProfile();
  // The share of the flux in a tilted cone and in the upper hemisphere.
  const glm::dvec3 axis = glm::normalize(glm::dvec3(0.4, -0.3, -0.8));
  const auto in_cone = [&](const glm::dvec3& d) { return glm::dot(glm::normalize(d), axis) > 0.8 ? 1.0 : 0.0; };
  const auto upper = [](const glm::dvec3& d) { return d.z > 0.0 ? 1.0 : 0.0; };
  for (const auto& f :
       {std::function<double(const glm::dvec3&)>(in_cone), std::function<double(const glm::dvec3&)>(upper)}) {
    const double exact = quadrature(p, f) / p.integral();
    std::mt19937_64 rng(42);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const int n = 200000;
    double sum = 0.0, sum2 = 0.0;
    for (int i = 0; i < n; ++i) {
      const double u1 = u(rng), u2 = u(rng);
      const auto s = p.sample(u1, u2);
      // The weight is the ratio the class promises, for every sample.
      ASSERT_NEAR(s.weight, p.intensity(s.direction_lf) / (p.pdf(s.direction_lf) * p.integral()),
                  1e-9 * (1 + s.weight));
      const double x = s.weight * f(s.direction_lf);
      sum += x;
      sum2 += x * x;
    }
    const double mean = sum / n;
    const double se = std::sqrt(std::max(0.0, sum2 / n - mean * mean) / n);
    EXPECT_NEAR(mean, exact, 4.0 * se + 1e-4) << "exact " << exact << " standard error " << se;
  }
}

TEST(IesProfile, OlderLayoutsCommasAndTiltDataAreRead) {
  // LM-63-1986: free text header, no keywords; comma separators; TILT=INCLUDE data skipped.
  const std::string text =
      "Some luminaire, old format\nmeasured 1985\nTILT=INCLUDE\n1\n3\n0,45,90\n1.0,0.9,0.8\n"
      "1,1000,1,3,1,1,1,0.5,0.5,0\n1,1,60\n0,90,180\n0\n50,40,30\n";
  const IesProfile p = IesProfile::parse(text, "old.ies");
  EXPECT_EQ(p.tilt(), IesProfile::Tilt::Include);
  EXPECT_EQ(p.lumensPerLamp(), 1000.0);
  EXPECT_DOUBLE_EQ(p.intensityAt(0.0, 1.0), 50.0);
  EXPECT_DOUBLE_EQ(p.intensityAt(kPi / 4, 2.0), 45.0);
  const IesProfile f = IesProfile::parse(iesText({0, 90}, {0}, {1, 1}, "TILT=lamp.tlt"), "tiltfile.ies");
  EXPECT_EQ(f.tilt(), IesProfile::Tilt::File);
}

TEST(IesProfile, MalformedFilesGiveErrorsNamingFileAndProblem) {
  const std::vector<double> v{0, 90, 180};
  struct Case {
    std::string text;
    std::string expect;
  };
  const std::vector<Case> cases{
      {"IESNA:LM-63-2002\n[TEST] x\n1 -1 1 3 1 1 2 0 0 0\n", "no TILT= line"},
      {iesText(v, {0}, {1, 2, 3}).substr(0, iesText(v, {0}, {1, 2, 3}).size() - 4), "ends before a candela value"},
      {iesText(v, {0}, {1, 2, 3}) + "4\n", "unexpected data after the candela table"},
      {iesText(v, {0}, {1, -2, 3}), "is negative"},
      {iesText({0, 90, 80}, {0}, {1, 2, 3}), "vertical angles must increase"},
      {iesText({0, 90, 190}, {0}, {1, 2, 3}), "outside [0, 180]"},
      {iesText(v, {0, 45}, {1, 2, 3, 1, 2, 3}), "no known symmetry"},
      {iesText(v, {0}, {1, 2, 3}, "TILT=NONE", "2"), "type B is not supported"},
      {iesText(v, {0}, {0, 0, 0}), "emits nothing"},
      {iesText(v, {0}, {1, 2, 3}, "TILT=NONE", "1", "0"), "multiplier must be > 0"},
      {iesText({0}, {0}, {1}), "number of vertical angles must be a whole number >= 2"},
      {iesText(v, {0}, {1, 2, 3}, "TILT"), "malformed TILT line"},
      {"TILT=NONE\n1 -1 1 3 1 1 2 0 0 x\n", "'x' is not a number"},
      {"TILT=NONE\n1 -1 1 3.5 1 1 2 0 0 0\n", "whole number"},
      {"TILT=INCLUDE\n4\n", "geometry must be 1, 2 or 3"},
  };
  for (const Case& c : cases) {
    try {
      (void)IesProfile::parse(c.text, "bad.ies");
      ADD_FAILURE() << "accepted a file that should fail with '" << c.expect << "':\n" << c.text;
    } catch (const FileError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind("bad.ies: ", 0), 0u) << what;
      EXPECT_NE(what.find(c.expect), std::string::npos) << "expected '" << c.expect << "' in: " << what;
    }
  }
  // Line numbers point at the bad value.
  try {
    (void)IesProfile::parse("IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 100\n0 90 180\n0\n1 oops 3\n",
                            "l.ies");
    ADD_FAILURE() << "accepted a non-number";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("line 7"), std::string::npos) << e.what();
  }
  const auto missing = std::filesystem::temp_directory_path() / "duplex_no_such_file.ies";
  try {
    (void)IesProfile::load(missing);
    ADD_FAILURE() << "loaded a missing file";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(missing.string()), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)IesProfile::fromTable({0, 90}, {0}, {1, 2, 3}, "table"), InvalidArgument);
  EXPECT_THROW((void)IesProfile::fromTable({0, 90}, {0}, {1, std::nan("")}, "table"), InvalidArgument);
}

TEST(IesProfile, LoadsFromAFile) {
  const auto path = std::filesystem::temp_directory_path() / "duplex_ies_test.ies";
  {
    std::ofstream out(path);
    out << iesText({0, 90, 180}, {0, 90}, {4, 4, 4, 4, 4, 4});
  }
  const IesProfile p = IesProfile::load(path);
  std::filesystem::remove(path);
  EXPECT_NEAR(p.integral(), 16.0 * kPi, 1e-9);
  EXPECT_EQ(p.source(), path.string());
}

}  // namespace
}  // namespace duplex
