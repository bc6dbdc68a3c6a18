// Exact bounds of a triangle clipped to a box (the mesh type's perfect splits): every point of the
// triangle inside the box is kept, a split equals clipping each half, and the bounds are tight.

#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Box.h"
#include "duplex/objects/TriangleClip.h"

#include <gtest/gtest.h>
#include <glm/vec3.hpp>

#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace duplex::test {
namespace {

/// A box of half-size 0.01-0.06 around the centroid of triangle `t`, or (every fourth `i`)
/// anywhere in [0, 1]^3.
Box boxNearTriangle(const std::array<glm::vec3, 3>& t, std::size_t i, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::vec3 centre = i % 4 == 0 ? draw3(u, rng) : (t[0] + t[1] + t[2]) / 3.0f;
  const glm::vec3 half = 0.01f + 0.05f * draw3(u, rng);
  return Box(centre - half, centre + half);
}

/// Sample `s` of triangle `t` in double: the corners (s < 3), edge points (s < 6), then any point.
glm::dvec3 trianglePoint(const std::array<glm::vec3, 3>& t, int s, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double a = u(rng), b = u(rng);
  if (s < 3) {
    a = s == 1 ? 1.0 : 0.0;
    b = s == 2 ? 1.0 : 0.0;
  }
  if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
  if (s >= 3 && s < 6) b = 0.0;
  return (1.0 - a - b) * glm::dvec3(t[0]) + a * glm::dvec3(t[1]) + b * glm::dvec3(t[2]);
}

/// False when `p` lies in `box` but outside `clipped` (allowing the 1e-16 relative rounding of the
/// sample itself).
bool keptIfInside(const glm::dvec3& p, const Box& box, const Box& clipped) {
  bool in_box = true, in_clip = !clipped.empty();
  for (int k = 0; k < 3; ++k) {
    const double slack = 1e-12 * (1.0 + std::abs(p[k]));
    in_box = in_box && p[k] >= box.lo[k] && p[k] <= box.hi[k];
    in_clip = in_clip && p[k] >= clipped.lo[k] - slack && p[k] <= clipped.hi[k] + slack;
  }
  return !in_box || in_clip;
}

TEST(TriangleClip, ContainsEveryPointOfTheTriangleInsideTheBox) {
  std::mt19937_64 rng(77);
  const auto tris = randomTriangles(400, 78);
  std::size_t nonempty = 0;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const auto& t = tris[i];
    const Box box = boxNearTriangle(t, i, rng);
    const Box clipped = clipTriangleToBox(t[0], t[1], t[2], box);
    if (!clipped.empty()) {
      ++nonempty;
      EXPECT_TRUE(box.contains(clipped.lo) && box.contains(clipped.hi)) << clipped << " not inside " << box;
    }
    // Points of the triangle in the box must be in the result.
    for (int s = 0; s < 300; ++s) {
      ASSERT_TRUE(keptIfInside(trianglePoint(t, s, rng), box, clipped))
          << "triangle " << i << " point inside " << box << " outside clipped " << clipped;
    }
  }
  EXPECT_GT(nonempty, 250u);
}

TEST(TriangleClip, SplitEqualsClippingEachHalf) {
  // splitTriangleInBox clips once and cuts the polygon; each side must hold every sampled point of
  // the triangle in that half box, stay inside the half, and match clipTriangleToBox on the half up
  // to rounding of the crossings (they are computed in another order).
  std::mt19937_64 rng(79);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto tris = randomTriangles(400, 80);
  std::size_t both = 0;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const auto& t = tris[i];
    const Box box = boxNearTriangle(t, i, rng);
    const int axis = static_cast<int>(i % 3);
    // Planes through the box, on a vertex now and then.
    const float pos =
        i % 5 == 0 ? t[0][axis] : box.lo[axis] + static_cast<float>(u(rng)) * (box.hi[axis] - box.lo[axis]);
    Box parts[2];
    splitTriangleInBox(t[0], t[1], t[2], box, axis, pos, parts[0], parts[1]);
    Box halves[2] = {box, box};
    halves[0].hi[axis] = std::min(box.hi[axis], pos);
    halves[1].lo[axis] = std::max(box.lo[axis], pos);
    both += !parts[0].empty() && !parts[1].empty();
    for (int side = 0; side < 2; ++side) {
      const Box& part = parts[side];
      const Box reference = clipTriangleToBox(t[0], t[1], t[2], halves[side]);
      if (!part.empty()) {
        EXPECT_TRUE(halves[side].contains(part.lo) && halves[side].contains(part.hi))
            << part << " not inside " << halves[side];
      }
      EXPECT_EQ(part.empty(), reference.empty()) << "triangle " << i << " side " << side;
      if (!part.empty() && !reference.empty())
        for (int k = 0; k < 3; ++k) {
          const float tol = 1e-5f * (1.0f + std::abs(reference.lo[k]) + std::abs(reference.hi[k]));
          EXPECT_NEAR(part.lo[k], reference.lo[k], tol) << "triangle " << i << " side " << side;
          EXPECT_NEAR(part.hi[k], reference.hi[k], tol) << "triangle " << i << " side " << side;
        }
      for (int s = 0; s < 300; ++s) {
        ASSERT_TRUE(keptIfInside(trianglePoint(t, s, rng), halves[side], part))
            << "triangle " << i << " side " << side << " point inside " << halves[side] << " outside " << part;
      }
    }
  }
  EXPECT_GT(both, 100u);
}

TEST(TriangleClip, SplitOfATriangleInsideTheBoxIsTightAndContainsItsPart) {
  // A triangle inside the box is cut from its float corners with the edge crossings rounded
  // outward (two thirds of the splits of a mesh build). Against the exact part on each side
  // (corners and crossings in long double): the bounds must contain it and be at most one float
  // step looser, at coordinates from 1e-3 to 1e3 of either sign, with planes through a vertex and
  // at zero next to a -0 corner.
  std::mt19937_64 rng(81);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::size_t crossings = 0;
  for (int i = 0; i < 3000; ++i) {
    const double scale = std::pow(10.0, -3 + i % 7);
    std::array<glm::vec3, 3> t;
    for (auto& v : t)
      for (int k = 0; k < 3; ++k) v[k] = static_cast<float>((u(rng) - 0.3) * scale);
    const int axis = i % 3;
    float pos = static_cast<float>((u(rng) - 0.3) * scale);
    if (i % 5 == 0) pos = t[1][axis];
    if (i % 7 == 0) t[0][axis] = -0.0f, pos = 0.0f;
    Box box;
    for (const auto& v : t) box.extend(v);
    box.lo -= glm::vec3(0.25f * static_cast<float>(scale));
    box.hi += glm::vec3(0.25f * static_cast<float>(scale));
    if (!(pos > box.lo[axis] && pos < box.hi[axis])) continue;
    Box parts[2];
    splitTriangleInBox(t[0], t[1], t[2], box, axis, pos, parts[0], parts[1]);
    // The exact parts: corners on each closed side, and the crossings of the edges.
    using L = long double;
    L lo[2][3], hi[2][3];
    bool any[2] = {false, false};
    auto extend = [&](int side, const L* p) {
      for (int k = 0; k < 3; ++k) {
        lo[side][k] = any[side] ? std::min(lo[side][k], p[k]) : p[k];
        hi[side][k] = any[side] ? std::max(hi[side][k], p[k]) : p[k];
      }
      any[side] = true;
    };
    for (int e = 0; e < 3; ++e) {
      const glm::vec3& a = t[static_cast<std::size_t>(e)];
      const glm::vec3& b = t[static_cast<std::size_t>((e + 1) % 3)];
      const L da = static_cast<L>(a[axis]) - pos, db = static_cast<L>(b[axis]) - pos;
      const L pa[3] = {a.x, a.y, a.z};
      if (da <= 0) extend(0, pa);
      if (da >= 0) extend(1, pa);
      if ((da < 0 && db > 0) || (da > 0 && db < 0)) {
        ++crossings;
        L x[3];
        for (int k = 0; k < 3; ++k) x[k] = static_cast<L>(a[k]) + da / (da - db) * (static_cast<L>(b[k]) - a[k]);
        x[axis] = pos;
        extend(0, x);
        extend(1, x);
      }
    }
    for (int side = 0; side < 2; ++side) {
      ASSERT_EQ(parts[side].empty(), !any[side]) << "triangle " << i << " side " << side;
      if (!any[side]) continue;
      for (int k = 0; k < 3; ++k) {
        const float part_lo = parts[side].lo[k], part_hi = parts[side].hi[k];
        EXPECT_LE(static_cast<L>(part_lo), lo[side][k]) << "triangle " << i << " side " << side << " axis " << k;
        EXPECT_GE(static_cast<L>(part_hi), hi[side][k]) << "triangle " << i << " side " << side << " axis " << k;
        EXPECT_GT(static_cast<L>(std::nextafter(part_lo, std::numeric_limits<float>::infinity())), lo[side][k])
            << "loose lower bound: triangle " << i << " side " << side << " axis " << k;
        EXPECT_LT(static_cast<L>(std::nextafter(part_hi, -std::numeric_limits<float>::infinity())), hi[side][k])
            << "loose upper bound: triangle " << i << " side " << side << " axis " << k;
      }
    }
  }
  EXPECT_GT(crossings, 2000u);
}

TEST(TriangleClip, ExactCases) {
  const glm::vec3 a(0.0f), b(1.0f, 0.0f, 0.0f), c(0.0f, 1.0f, 0.0f);
  // Entirely inside: the triangle's bounds.
  EXPECT_EQ(clipTriangleToBox(a, b, c, Box(glm::vec3(-1.0f), glm::vec3(2.0f))), Box(a, glm::vec3(1.0f, 1.0f, 0.0f)));
  // Disjoint: empty.
  EXPECT_TRUE(clipTriangleToBox(a, b, c, Box(glm::vec3(0.6f, 0.6f, -1.0f), glm::vec3(1.0f, 1.0f, 1.0f))).empty());
  EXPECT_TRUE(clipTriangleToBox(a, b, c, Box(glm::vec3(0.0f, 0.0f, 0.5f), glm::vec3(1.0f))).empty());
  // Half space x <= 0.5: bounds [0, 0.5] x [0, 1] x [0, 0].
  const Box half = clipTriangleToBox(a, b, c, Box(glm::vec3(-1.0f), glm::vec3(0.5f, 2.0f, 2.0f)));
  EXPECT_EQ(half, Box(a, glm::vec3(0.5f, 1.0f, 0.0f)));
  // Corner box around the hypotenuse midpoint: [0.25, 0.75]^2 clipped by x + y <= 1.
  const Box corner = clipTriangleToBox(a, b, c, Box(glm::vec3(0.25f, 0.25f, -1.0f), glm::vec3(0.75f, 0.75f, 1.0f)));
  EXPECT_EQ(corner, Box(glm::vec3(0.25f, 0.25f, 0.0f), glm::vec3(0.75f, 0.75f, 0.0f)));
  // Empty box in, empty box out.
  EXPECT_TRUE(clipTriangleToBox(a, b, c, Box()).empty());
}

}  // namespace
}  // namespace duplex::test
