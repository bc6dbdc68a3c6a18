#pragma once
/// \file ConvexRegion.h
/// A convex region bounded by planes (a picking frustum, a selection box): the geometric part of
/// rectangle selection and tolerance picking, in whatever space its planes are given.

#include "duplex/accel/Affine.h"
#include "duplex/accel/Box.h"

#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include <span>
#include <vector>

namespace duplex {

/// The points x with dot(n_i, x) <= d_i for every plane i, each plane stored as
/// glm::dvec4(n.x, n.y, n.z, d) (normal pointing out of the region, any non-zero length). No
/// plane: all of space. Closed: points on a plane belong to the region. Tests are in double.
class ConvexRegion {
 public:
  /// All of space.
  ConvexRegion() = default;
  /// The region of `planes`. Throws InvalidArgument for a non-finite or zero normal or a non-finite
  /// offset (a NaN plane would never exclude anything).
  explicit ConvexRegion(std::span<const glm::dvec4> planes);

  /// The planes, as given (or as transformed()).
  [[nodiscard]] const std::vector<glm::dvec4>& planes() const { return planes_; }
  /// The same region seen from an instance's object space: the object-space points whose image
  /// under `world_from_object` lies in this (world-space) region. Exact up to rounding for any
  /// invertible affine map (planes transform by the transpose of the linear part).
  [[nodiscard]] ConvexRegion transformed(const Affine& world_from_object) const;

  /// Whether point `p` lies in the region.
  [[nodiscard]] bool contains(const glm::dvec3& p) const;
  /// Whether some plane has all of box `b` outside: then the box and the region are disjoint (an
  /// empty box is always excluded). Conservative: a box near a corner of the region may be
  /// disjoint from it and still not excluded.
  [[nodiscard]] bool excludes(const Box& b) const;
  /// Whether all of the (non-empty) box `b` lies in the region.
  [[nodiscard]] bool containsBox(const Box& b) const;
  /// Whether triangle (a, b, c) shares a point with the region: exact up to rounding (the triangle
  /// is clipped by every plane; something left means they meet). Degenerate triangles are
  /// segments or points and are tested as such.
  [[nodiscard]] bool meetsTriangle(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) const;

 private:
  std::vector<glm::dvec4> planes_;
};

}  // namespace duplex
