#pragma once
/// \file Affine.h
/// Affine transforms in double precision. The name of a transform says which way it maps:
/// `world_from_object` maps object-space points to world space, so compositions read right to left.

#include "duplex/accel/Box.h"
#include "duplex/accel/Ray.h"

#include <glm/mat3x3.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <ostream>

namespace duplex {

/// x' = linear * x + translation, in double so that objects far from the origin keep their
/// precision; rays are converted to float only after the transform.
struct Affine {
  glm::dmat3 linear{1.0};       ///< column-major (GLM convention)
  glm::dvec3 translation{0.0};  ///< added after the linear part

  /// The identity transform.
  static Affine identity() { return {}; }
  /// From 12 numbers, row-major 3x4 [r00 r01 r02 t0  r10 r11 r12 t1  r20 r21 r22 t2] (the
  /// scene-json-v1 layout). Takes the numbers as they are: callers that need a valid transform
  /// check isFinite() and !isSingular() (the scene graph and the top level do).
  static Affine fromRowMajor3x4(const std::array<double, 12>& m);
  /// The 12 numbers in the row-major 3x4 layout of fromRowMajor3x4().
  [[nodiscard]] std::array<double, 12> toRowMajor3x4() const;

  /// Maps point `p` (linear part and translation).
  [[nodiscard]] glm::dvec3 point(const glm::dvec3& p) const { return linear * p + translation; }
  /// Maps vector `v` (linear part only: directions and offsets).
  [[nodiscard]] glm::dvec3 vector(const glm::dvec3& v) const { return linear * v; }
  /// Whether all 12 entries are finite.
  [[nodiscard]] bool isFinite() const;
  /// |det(linear)| relative to the scale of the matrix is tiny: not invertible in practice.
  [[nodiscard]] bool isSingular() const;
  /// Inverse; precondition: !isSingular() (a singular matrix gives infinite or NaN entries, no
  /// exception).
  [[nodiscard]] Affine inverse() const;
  /// Bounds of the transformed box (exact for affine maps: the box of the 8 mapped corners, computed
  /// with the centre/half-extent form and rounded outward to float).
  [[nodiscard]] Box apply(const Box& b) const;
  /// Transform a ray; the direction is not renormalised, so t keeps its meaning.
  [[nodiscard]] Ray apply(const Ray& r) const;

  /// Composition: `a * b` applies `b` first, then `a`.
  friend Affine operator*(const Affine& a, const Affine& b) {
    return {a.linear * b.linear, a.linear * b.translation + a.translation};
  }
};

/// Writes the 12 row-major numbers, for logs and test messages.
std::ostream& operator<<(std::ostream& os, const Affine& a);

}  // namespace duplex
