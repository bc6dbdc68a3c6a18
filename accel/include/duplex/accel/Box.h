#pragma once
/// \file Box.h
/// Axis-aligned box in float; the space is that of whatever it bounds.

#include <glm/common.hpp>
#include <glm/vec3.hpp>

#include <cmath>
#include <limits>
#include <ostream>

namespace duplex {

/// Axis-aligned bounding box [lo, hi]. A default-constructed box is empty (lo > hi) so that
/// extending it by anything gives that thing's bounds.
struct Box {
  glm::vec3 lo{std::numeric_limits<float>::infinity()};   ///< lower corner
  glm::vec3 hi{-std::numeric_limits<float>::infinity()};  ///< upper corner

  Box() = default;
  /// The box [lo_, hi_], taken as given (empty when some lo_ > hi_).
  Box(const glm::vec3& lo_, const glm::vec3& hi_) : lo(lo_), hi(hi_) {}

  /// Whether the box holds no point (some lo > hi, or a NaN bound).
  [[nodiscard]] bool empty() const { return !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z); }
  /// Whether all six bounds are finite (false for the default empty box, whose bounds are +-inf).
  [[nodiscard]] bool finite() const {
    return std::isfinite(lo.x) && std::isfinite(lo.y) && std::isfinite(lo.z) && std::isfinite(hi.x) &&
           std::isfinite(hi.y) && std::isfinite(hi.z);
  }
  /// Grows the box to contain point `p`.
  void extend(const glm::vec3& p) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  /// Grows the box to contain box `b` (no change for an empty `b`).
  void extend(const Box& b) {
    lo = glm::min(lo, b.lo);
    hi = glm::max(hi, b.hi);
  }
  /// hi - lo per axis (negative for an empty box).
  [[nodiscard]] glm::vec3 extent() const { return hi - lo; }
  /// Midpoint of lo and hi.
  [[nodiscard]] glm::vec3 center() const { return 0.5f * (lo + hi); }
  /// Surface area; 0 for an empty or degenerate box.
  [[nodiscard]] float area() const {
    if (empty()) return 0.0f;
    const glm::vec3 e = hi - lo;
    return 2.0f * (e.x * e.y + e.y * e.z + e.z * e.x);
  }
  /// Index of the longest axis (ties resolved x, y, z).
  [[nodiscard]] int longestAxis() const {
    const glm::vec3 e = extent();
    return (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
  }
  /// Whether point `p` lies in the closed box.
  [[nodiscard]] bool contains(const glm::vec3& p) const {
    return p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z;
  }
  /// Whether the closed boxes share a point (touching counts).
  [[nodiscard]] bool overlaps(const Box& b) const {
    return lo.x <= b.hi.x && b.lo.x <= hi.x && lo.y <= b.hi.y && b.lo.y <= hi.y && lo.z <= b.hi.z && b.lo.z <= hi.z;
  }
  /// Equal bounds, compared exactly.
  bool operator==(const Box&) const = default;
};

/// Intersection of two boxes; empty when they are disjoint.
[[nodiscard]] inline Box intersection(const Box& a, const Box& b) {
  return Box(glm::max(a.lo, b.lo), glm::min(a.hi, b.hi));
}

/// Squared distance from point `p` to the closed box `b` (0 inside), in double, in the box's space.
[[nodiscard]] inline double distanceSquared(const Box& b, const glm::dvec3& p) {
  double s = 0.0;
  for (int a = 0; a < 3; ++a) {
    const double lo = b.lo[a], hi = b.hi[a];
    const double e = p[a] < lo ? lo - p[a] : (p[a] > hi ? p[a] - hi : 0.0);
    s += e * e;
  }
  return s;
}

/// Writes both corners, for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Box& b) {
  return os << "Box{(" << b.lo.x << ", " << b.lo.y << ", " << b.lo.z << ") - (" << b.hi.x << ", " << b.hi.y << ", "
            << b.hi.z << ")}";
}

}  // namespace duplex
