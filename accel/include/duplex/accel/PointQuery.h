#pragma once
/// \file PointQuery.h
/// Closest-point queries: what an object is asked (the world point and its instance's transform)
/// and the answer it improves. Distances are measured in world space, so that instances scaled
/// unevenly still report the truly nearest point.

#include "duplex/accel/Affine.h"
#include "duplex/accel/Box.h"
#include "duplex/accel/Hit.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <glm/vec2.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex {

/// The nearest point found so far (world space, double precision).
struct ClosestPoint {
  /// World-space distance from the query point; starts at the query's maximum distance.
  double distance = std::numeric_limits<double>::infinity();
  glm::dvec3 point_ws{0.0};   ///< the point on the surface, world space
  glm::dvec3 normal_ws{0.0};  ///< unit geometric normal there (meshes: the triangle's), world space
  /// Meshes: the point's barycentric coordinates (u, v) on its triangle (a, b, c) in the mesh's
  /// vertex order, point = (1 - u - v) a + u b + v c; 0 for other objects.
  glm::dvec2 uv{0.0};
  std::uint32_t prim_id = kInvalidId;      ///< primitive of the object (a triangle); kInvalidId: none found
  std::uint32_t instance_id = kInvalidId;  ///< set by scene queries (objects leave it)

  /// Whether a point was found (within the maximum distance).
  [[nodiscard]] bool valid() const { return prim_id != kInvalidId; }
};

/// A closest-point query as an object receives it for one instance.
struct PointQuery {
  glm::dvec3 point_ws{0.0};  ///< the query point, world space
  Affine world_from_object;  ///< the instance's transform
  glm::dvec3 point_os{0.0};  ///< the query point in object space
  /// Per object axis, the largest object-space offset a world-space offset of length 1 can have
  /// (the norms of the rows of object_from_world's linear part): every point within world distance
  /// d of point_ws lies in the object-space box point_os +- d * reach_os.
  glm::dvec3 reach_os{1.0};
  /// An upper bound of the spectral norm of object_from_world's linear part: a world distance d
  /// is at most d * stretch_os in object space, so an object-space distance e means a world
  /// distance of at least e / stretch_os.
  double stretch_os = 1.0;
  /// Whether world_from_object is a similarity (a rotation, possibly with a reflection, times one
  /// scale, and a translation; identity included): then world distances are object-space distances
  /// times scale_ws, and an object may search in object space.
  bool similarity = false;
  /// For a similarity, the world length of a unit object-space length.
  double scale_ws = 1.0;
  /// For a similarity, +1 or -1: the sign of det(world_from_object), which flips a triangle's
  /// normal (the cross product of its edges) when the transform reflects.
  double orientation = 1.0;

  /// The query for `point_ws` and an instance with these transforms.
  static PointQuery make(const glm::dvec3& point_ws, const Affine& world_from_object, const Affine& object_from_world) {
    PointQuery q;
    q.point_ws = point_ws;
    q.world_from_object = world_from_object;
    q.point_os = object_from_world.point(point_ws);
    const glm::dmat3& m = object_from_world.linear;  // column-major: row i is (m[0][i], m[1][i], m[2][i])
    for (int i = 0; i < 3; ++i) {
      const double r = std::sqrt(m[0][i] * m[0][i] + m[1][i] * m[1][i] + m[2][i] * m[2][i]);
      q.reach_os[i] = r * (1.0 + 1e-12) + 1e-300;  // rounding of the norm must not shrink the box
    }
    // The largest eigenvalue of m^T m is at most its largest absolute row sum (Gershgorin; exact
    // for rotations and axis-aligned scales).
    const glm::dmat3 g = glm::transpose(m) * m;
    double row_max = 0.0;
    for (int i = 0; i < 3; ++i) row_max = std::max(row_max, std::abs(g[0][i]) + std::abs(g[1][i]) + std::abs(g[2][i]));
    q.stretch_os = std::sqrt(row_max) * (1.0 + 1e-12) + 1e-300;
    // A similarity's columns are orthogonal and of one length: w^T w = s^2 I. The tolerance (far
    // below float rounding of the vertices) lets rotations computed in double count as one.
    const glm::dmat3& w = world_from_object.linear;
    const glm::dmat3 ww = glm::transpose(w) * w;
    const double s2 = ww[0][0];
    bool similar = s2 > 0.0 && std::isfinite(s2);
    for (int i = 0; i < 3 && similar; ++i)
      for (int j = 0; j < 3; ++j)
        if (std::abs(ww[i][j] - (i == j ? s2 : 0.0)) > 1e-13 * s2) similar = false;
    if (similar) {
      q.similarity = true;
      q.scale_ws = std::sqrt(s2);
      q.orientation = glm::determinant(w) < 0.0 ? -1.0 : 1.0;
    }
    return q;
  }

  /// A lower bound of the world distance from point_ws to any point of object-space box `b`.
  [[nodiscard]] double lowerBound(const Box& b) const { return std::sqrt(distanceSquared(b, point_os)) / stretch_os; }

  /// Whether the object-space box `b` may hold a point closer than world distance `d`
  /// (conservative: the box must meet the object-space box of the world ball and lie nearer than
  /// d by lowerBound; always true for an infinite d and a non-empty box).
  [[nodiscard]] bool mayReach(const Box& b, double d) const {
    if (b.empty()) return false;
    if (!(d < std::numeric_limits<double>::infinity())) return true;
    for (int i = 0; i < 3; ++i) {
      const double r = d * reach_os[i];
      if (double{b.lo[i]} > point_os[i] + r || double{b.hi[i]} < point_os[i] - r) return false;
    }
    return lowerBound(b) < d;
  }
};

/// The point of triangle (a, b, c) nearest to p (all in one space; glm::dvec3 for the library's
/// double-precision queries, glm::vec3 where float suffices): the Voronoi-region walk of
/// Ericson's "Real-Time Collision Detection" (5.1.5). Degenerate triangles give a point of their
/// segment or vertex.
template <class Vec>
Vec closestPointOnTriangle(const Vec& p, const Vec& a, const Vec& b, const Vec& c) {
  using T = typename Vec::value_type;
  const T zero(0);
  const Vec ab = b - a, ac = c - a, ap = p - a;
  const T d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= zero && d2 <= zero) return a;
  const Vec bp = p - b;
  const T d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= zero && d4 <= d3) return b;
  const T vc = d1 * d4 - d3 * d2;
  if (vc <= zero && d1 >= zero && d3 <= zero) {
    const T den = d1 - d3;
    return den > zero ? a + (d1 / den) * ab : a;
  }
  const Vec cp = p - c;
  const T d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= zero && d5 <= d6) return c;
  const T vb = d5 * d2 - d1 * d6;
  if (vb <= zero && d2 >= zero && d6 <= zero) {
    const T den = d2 - d6;
    return den > zero ? a + (d2 / den) * ac : a;
  }
  const T va = d3 * d6 - d5 * d4;
  if (va <= zero && (d4 - d3) >= zero && (d5 - d6) >= zero) {
    const T den = (d4 - d3) + (d5 - d6);
    return den > zero ? b + ((d4 - d3) / den) * (c - b) : b;
  }
  const T sum = va + vb + vc;
  if (!(sum > zero)) return a;  // degenerate: every region test above failed by rounding
  return a + (vb / sum) * ab + (vc / sum) * ac;
}

/// The barycentric coordinates (u, v) of p on triangle (a, b, c): p = (1 - u - v) a + u b + v c
/// for p in the triangle's plane (else those of its projection); (0, 0) for a degenerate triangle.
inline glm::dvec2 barycentricUv(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 e1 = b - a, e2 = c - a, w = p - a;
  const double d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
  const double w1 = glm::dot(w, e1), w2 = glm::dot(w, e2);
  const double det = d11 * d22 - d12 * d12;
  if (!(det != 0.0)) return glm::dvec2(0.0);
  return {(d22 * w1 - d12 * w2) / det, (d11 * w2 - d12 * w1) / det};
}

}  // namespace duplex
