// ConvexRegion: the triangle test against the separating-axis test of a triangle and a box
// (Akenine-Moller), also through transformed regions (the object-space view of a world region),
// and the box tests against their corners.

#include "TestSupport.h"

#include "duplex/accel/ConvexRegion.h"
#include "duplex/accel/Error.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <array>
#include <cmath>
#include <limits>
#include <random>

namespace duplex::test {
namespace {

/// The six planes of the box [lo, hi] (outward normals).
std::vector<glm::dvec4> boxPlanes(const glm::dvec3& lo, const glm::dvec3& hi) {
  return {{1, 0, 0, hi.x}, {-1, 0, 0, -lo.x}, {0, 1, 0, hi.y}, {0, -1, 0, -lo.y}, {0, 0, 1, hi.z}, {0, 0, -1, -lo.z}};
}

/// Separating-axis test of a non-degenerate triangle against the box [lo, hi]: the 3 box axes,
/// the triangle's normal and the 9 cross products of edges and axes.
bool satOverlap(const glm::dvec3& lo, const glm::dvec3& hi, const std::array<glm::dvec3, 3>& tri) {
  const glm::dvec3 c = 0.5 * (lo + hi), h = 0.5 * (hi - lo);
  std::array<glm::dvec3, 3> v{tri[0] - c, tri[1] - c, tri[2] - c};
  const auto separated = [&](const glm::dvec3& axis) {
    if (glm::dot(axis, axis) < 1e-30) return false;  // parallel edges: no axis
    double mn = std::numeric_limits<double>::infinity(), mx = -mn;
    for (const glm::dvec3& p : v) {
      mn = std::min(mn, glm::dot(p, axis));
      mx = std::max(mx, glm::dot(p, axis));
    }
    const double r = h.x * std::abs(axis.x) + h.y * std::abs(axis.y) + h.z * std::abs(axis.z);
    return mn > r || mx < -r;
  };
  const glm::dvec3 axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (const glm::dvec3& a : axes)
    if (separated(a)) return false;
  if (separated(glm::cross(v[1] - v[0], v[2] - v[0]))) return false;
  for (int e = 0; e < 3; ++e)
    for (const glm::dvec3& a : axes)
      if (separated(glm::cross(v[(e + 1) % 3] - v[e], a))) return false;
  return true;
}

TEST(ConvexRegion, TriangleTestAgreesWithTheSeparatingAxisTest) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-2.0, 2.0), s(0.1, 1.5);
  int met = 0, missed = 0;
  for (int k = 0; k < 20000; ++k) {
    const glm::dvec3 lo = 0.5 * draw3<glm::dvec3>(u, rng);
    const glm::dvec3 hi = lo + draw3<glm::dvec3>(s, rng);
    const std::array<glm::dvec3, 3> tri{draw3<glm::dvec3>(u, rng), draw3<glm::dvec3>(u, rng),
                                        draw3<glm::dvec3>(u, rng)};
    const ConvexRegion region(boxPlanes(lo, hi));
    const bool want = satOverlap(lo, hi, tri);
    ASSERT_EQ(region.meetsTriangle(tri[0], tri[1], tri[2]), want) << "case " << k;
    (want ? met : missed) += 1;
  }
  EXPECT_GT(met, 2000);  // both outcomes well represented
  EXPECT_GT(missed, 2000);
}

TEST(ConvexRegion, TransformedRegionsSeeTheSameTrianglesAndPoints) {
  // A world box region seen from object space through a random affine map (rotation, uneven
  // scale, mirror, shear): an object triangle meets the transformed region iff its world image
  // meets the box.
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 5000; ++k) {
    glm::dmat3 m;
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) m[c][r] = u(rng) + (c == r ? 1.5 : 0.0);
    const Affine world_from_object{m, draw3<glm::dvec3>(u, rng) * 3.0};
    const glm::dvec3 lo(-0.6, -0.4, -0.8), hi(0.7, 0.5, 0.3);
    const ConvexRegion world(boxPlanes(lo, hi));
    const ConvexRegion object = world.transformed(world_from_object);
    const Affine object_from_world = world_from_object.inverse();
    std::array<glm::dvec3, 3> tri_os, tri_ws;
    for (int i = 0; i < 3; ++i) {
      tri_ws[i] = draw3<glm::dvec3>(u, rng) * 1.5;
      tri_os[i] = object_from_world.point(tri_ws[i]);
    }
    ASSERT_EQ(object.meetsTriangle(tri_os[0], tri_os[1], tri_os[2]), satOverlap(lo, hi, tri_ws)) << "case " << k;
    ASSERT_EQ(object.contains(tri_os[0]), world.contains(tri_ws[0])) << "case " << k;
  }
}

TEST(ConvexRegion, DegenerateTrianglesAreTestedAsSegmentsAndPoints) {
  const ConvexRegion region(boxPlanes(glm::dvec3(0.0), glm::dvec3(1.0)));
  const glm::dvec3 a(-1.0, 0.5, 0.5), b(2.0, 0.5, 0.5);  // crosses the box
  EXPECT_TRUE(region.meetsTriangle(a, b, b));
  EXPECT_TRUE(region.meetsTriangle(a, a + 0.5 * (b - a), b));  // collinear
  const glm::dvec3 c(-1.0, 1.5, 0.5), d(2.0, 1.5, 0.5);        // passes above it
  EXPECT_FALSE(region.meetsTriangle(c, d, d));
  EXPECT_TRUE(region.meetsTriangle(glm::dvec3(0.5), glm::dvec3(0.5), glm::dvec3(0.5)));
  EXPECT_FALSE(region.meetsTriangle(glm::dvec3(1.5), glm::dvec3(1.5), glm::dvec3(1.5)));
  // Closed: a triangle touching a face counts.
  EXPECT_TRUE(region.meetsTriangle(glm::dvec3(1.0, 0.2, 0.2), glm::dvec3(2.0, 0.2, 0.2), glm::dvec3(2.0, 0.8, 0.8)));
}

TEST(ConvexRegion, BoxTestsAgreeWithTheCorners) {
  // A tilted slab region: excludes() must never drop a box with a corner inside, and
  // containsBox() holds exactly when all eight corners are inside.
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> u(-2.0, 2.0), s(0.01, 1.0);
  const std::vector<glm::dvec4> planes{{1, 1, 0, 1.0}, {-1, -1, 0, 1.0}, {0, 0.3, 1, 0.8}, {0, 0, -1, 1.2}};
  const ConvexRegion region(planes);
  int inside = 0, excluded = 0;
  for (int k = 0; k < 20000; ++k) {
    const glm::vec3 lo = draw3(u, rng);
    const Box b(lo, lo + draw3(s, rng));
    int corners_in = 0;
    for (int c = 0; c < 8; ++c)
      corners_in +=
          region.contains(glm::dvec3(c & 1 ? b.hi.x : b.lo.x, c & 2 ? b.hi.y : b.lo.y, c & 4 ? b.hi.z : b.lo.z));
    ASSERT_EQ(region.containsBox(b), corners_in == 8) << b;
    if (corners_in > 0) {
      ASSERT_FALSE(region.excludes(b)) << b;
    }
    inside += corners_in == 8;
    excluded += region.excludes(b);
  }
  EXPECT_GT(inside, 100);
  EXPECT_GT(excluded, 1000);
  EXPECT_TRUE(region.excludes(Box{}));
  EXPECT_FALSE(region.containsBox(Box{}));
  EXPECT_TRUE(ConvexRegion().containsBox(Box(glm::vec3(-1e30f), glm::vec3(1e30f))));  // no plane: all space
}

TEST(ConvexRegion, RefusesPlanesThatWouldSelectEverything) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const glm::dvec4& bad : {glm::dvec4(nan, 0, 0, 1), glm::dvec4(0, 0, 0, 1), glm::dvec4(1, 0, 0, INFINITY)}) {
    const std::vector<glm::dvec4> planes{{1, 0, 0, 1}, bad};
    EXPECT_THROW((void)ConvexRegion(planes), InvalidArgument);
  }
}

}  // namespace
}  // namespace duplex::test
