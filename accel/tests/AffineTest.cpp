// Affine transforms: the scene-json-v1 row-major layout, round trip, inverse, composition,
// transformed boxes (contain every transformed corner, and are tight), rays (direction not
// renormalised), singularity.

#include "TestSupport.h"

#include "duplex/accel/Affine.h"
#include "duplex/accel/Box.h"
#include "duplex/accel/Ray.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <sstream>

namespace duplex::test {
namespace {

constexpr double kNaNd = std::numeric_limits<double>::quiet_NaN();
constexpr double kInfd = std::numeric_limits<double>::infinity();

/// Random well-conditioned transforms: rotation * scale (some mirrored) + translation.
std::vector<Affine> randomTransforms(int count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0), s(0.2, 5.0);
  std::vector<Affine> out;
  for (int i = 0; i < count; ++i) {
    glm::dvec3 scale = draw3<glm::dvec3>(s, rng);
    if (i % 3 == 1) scale.z = -scale.z;
    out.push_back(Affine::fromRowMajor3x4(rotationScaleTranslation(draw3<glm::dvec3>(u, rng) + 1e-3, 4.0 * u(rng),
                                                                   scale, draw3<glm::dvec3>(u, rng) * 100.0)));
  }
  return out;
}

double maxAbsDiff(const glm::dvec3& a, const glm::dvec3& b) {
  const glm::dvec3 d = glm::abs(a - b);
  return std::max({d.x, d.y, d.z});
}

TEST(Affine, RowMajorLayoutAndRoundTrip) {
  const std::array<double, 12> m = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  const Affine a = Affine::fromRowMajor3x4(m);
  // x' = [r00 r01 r02] . x + t0 etc.
  EXPECT_EQ(a.point(glm::dvec3(1, 0, 0)), glm::dvec3(1 + 4, 5 + 8, 9 + 12));
  EXPECT_EQ(a.point(glm::dvec3(0, 1, 0)), glm::dvec3(2 + 4, 6 + 8, 10 + 12));
  EXPECT_EQ(a.point(glm::dvec3(0, 0, 1)), glm::dvec3(3 + 4, 7 + 8, 11 + 12));
  EXPECT_EQ(a.vector(glm::dvec3(1, 1, 1)), glm::dvec3(6, 18, 30));  // no translation
  EXPECT_EQ(a.translation, glm::dvec3(4, 8, 12));
  EXPECT_EQ(a.toRowMajor3x4(), m);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1e6, 1e6);
  for (int i = 0; i < 100; ++i) {
    std::array<double, 12> r{};
    for (double& x : r) x = u(rng);
    EXPECT_EQ(Affine::fromRowMajor3x4(r).toRowMajor3x4(), r);
  }
  EXPECT_EQ(Affine::identity().toRowMajor3x4(), (std::array<double, 12>{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}));
}

TEST(Affine, InverseAndComposition) {
  const auto transforms = randomTransforms(50, 2);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    const Affine& a = transforms[i];
    const Affine& b = transforms[(i + 1) % transforms.size()];
    ASSERT_FALSE(a.isSingular()) << a;
    const Affine inv = a.inverse();
    const Affine id = a * inv;
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) EXPECT_NEAR(id.linear[c][r], c == r ? 1.0 : 0.0, 1e-12) << a;
    EXPECT_LT(maxAbsDiff(id.translation, glm::dvec3(0.0)), 1e-10) << a;
    for (int k = 0; k < 10; ++k) {
      const glm::dvec3 p = draw3<glm::dvec3>(u, rng);
      EXPECT_LT(maxAbsDiff(inv.point(a.point(p)), p), 1e-10) << a;
      EXPECT_LT(maxAbsDiff((a * b).point(p), a.point(b.point(p))), 1e-9) << a << " * " << b;
      EXPECT_LT(maxAbsDiff((a * b).vector(p), a.vector(b.vector(p))), 1e-9);
    }
  }
}

TEST(Affine, TransformedBoxContainsEveryCornerAndIsTight) {
  const auto transforms = randomTransforms(60, 4);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-10.0f, 10.0f), e(0.0f, 5.0f);
  for (std::size_t i = 0; i < transforms.size(); ++i) {
    const Affine& a = transforms[i];
    glm::vec3 lo = draw3(u, rng);
    glm::vec3 hi = lo + draw3(e, rng);
    if (i % 5 == 0) hi.z = lo.z;  // some flat boxes
    const Box box(lo, hi);
    const Box out = a.apply(box);
    ASSERT_FALSE(out.empty());
    glm::dvec3 cmin(std::numeric_limits<double>::infinity()), cmax(-std::numeric_limits<double>::infinity());
    for (int c = 0; c < 8; ++c) {
      const glm::dvec3 corner(c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z);
      const glm::dvec3 p = a.point(corner);
      cmin = glm::min(cmin, p);
      cmax = glm::max(cmax, p);
      for (int k = 0; k < 3; ++k) {
        EXPECT_LE(double(out.lo[k]), p[k]) << a << " box " << box << " corner " << c;
        EXPECT_GE(double(out.hi[k]), p[k]) << a << " box " << box << " corner " << c;
      }
    }
    // Tight: the exact bounds of an affine image are the corners' bounds; allow float rounding.
    for (int k = 0; k < 3; ++k) {
      const double slack = 4.0 * std::numeric_limits<float>::epsilon() * (std::abs(cmin[k]) + std::abs(cmax[k]) + 1.0);
      EXPECT_GE(double(out.lo[k]), cmin[k] - slack) << a << " " << box;
      EXPECT_LE(double(out.hi[k]), cmax[k] + slack) << a << " " << box;
    }
  }
  EXPECT_TRUE(Affine::identity().apply(Box()).empty());
  EXPECT_TRUE(transforms[0].apply(Box()).empty());
}

TEST(Affine, RayDirectionIsNotRenormalised) {
  const auto transforms = randomTransforms(30, 6);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-3.0f, 3.0f);
  for (const Affine& a : transforms) {
    Ray r;
    r.origin = draw3(u, rng);
    r.dir = draw3(u, rng);
    r.tnear = 0.25f;
    r.tfar = 7.5f;
    const Ray w = a.apply(r);
    EXPECT_EQ(w.tnear, r.tnear);
    EXPECT_EQ(w.tfar, r.tfar);
    // The point at t maps to the transformed ray's point at the same t.
    for (const double t : {0.0, 1.0, 2.5}) {
      const glm::dvec3 expected = a.point(glm::dvec3(r.origin) + t * glm::dvec3(r.dir));
      const glm::dvec3 got = glm::dvec3(w.origin) + t * glm::dvec3(w.dir);
      EXPECT_LT(maxAbsDiff(got, expected), 1e-5 * (1.0 + glm::length(expected))) << a << " " << r;
    }
    EXPECT_NEAR(glm::length(glm::dvec3(w.dir)), glm::length(a.vector(glm::dvec3(r.dir))),
                1e-6 * glm::length(a.vector(glm::dvec3(r.dir))));
  }
}

TEST(Affine, SingularityAndFiniteness) {
  EXPECT_FALSE(Affine::identity().isSingular());
  EXPECT_TRUE(Affine::identity().isFinite());
  const auto fromRows = [](std::array<double, 12> m) { return Affine::fromRowMajor3x4(m); };
  // Scale invariance: tiny or huge but well-shaped transforms are fine.
  EXPECT_FALSE(fromRows({1e-8, 0, 0, 0, 0, 1e-8, 0, 0, 0, 0, 1e-8, 0}).isSingular());
  EXPECT_FALSE(fromRows({1e8, 0, 0, 0, 0, 1e8, 0, 0, 0, 0, 1e8, 5}).isSingular());
  EXPECT_FALSE(fromRows({1e3, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1e-3, 0}).isSingular());
  EXPECT_FALSE(fromRows({-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}).isSingular());  // mirror
  // Singular: zero, flat, rank 2, nearly parallel columns.
  EXPECT_TRUE(fromRows({0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}).isSingular());
  EXPECT_TRUE(fromRows({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0}).isSingular());
  EXPECT_TRUE(fromRows({1, 2, 3, 0, 2, 4, 6, 0, 1, 0, 1, 0}).isSingular());
  EXPECT_TRUE(fromRows({1, 1, 0, 0, 0, 1e-14, 0, 0, 0, 0, 1, 0}).isSingular());
  // Non-finite entries are reported as such, and count as singular.
  for (const double bad : {kNaNd, kInfd, -kInfd}) {
    for (int k = 0; k < 12; ++k) {
      std::array<double, 12> m = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
      m[k] = bad;
      EXPECT_FALSE(fromRows(m).isFinite()) << "entry " << k;
      EXPECT_TRUE(fromRows(m).isSingular()) << "entry " << k;
    }
  }
}

TEST(Affine, PrintsRowMajorNumbers) {
  std::ostringstream os;
  os << Affine::fromRowMajor3x4({1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12});
  const std::string s = os.str();
  for (const char* n : {"1", "4", "8", "12"}) EXPECT_NE(s.find(n), std::string::npos) << s;
  EXPECT_LT(s.find('4'), s.find('8')) << s;  // row-major order
}

}  // namespace
}  // namespace duplex::test
