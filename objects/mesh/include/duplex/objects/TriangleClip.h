#pragma once
/// \file TriangleClip.h
/// Exact bounds of a triangle clipped to a box (for "perfect split" kd-tree builds).

#include "duplex/accel/Box.h"

#include <glm/vec3.hpp>

namespace duplex {

/// Bounds of the part of triangle (a, b, c) inside `box`, all in one space. Clipping runs in
/// double (Sutherland-Hodgman against the six planes); the result is rounded outward to float and
/// limited to `box`, so it contains every float point of the triangle inside the box. Empty when
/// the triangle misses the box.
[[nodiscard]] Box clipTriangleToBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box);

/// The triangle clipped to `box`, then cut by the plane at `pos` on `axis` (0 = x, 1 = y, 2 = z):
/// `lower` bounds its part on the closed side below the plane, `upper` the part above, each as
/// clipTriangleToBox would give for the box's two halves (rounded outward, limited to the half),
/// from one clip instead of two. Either is empty when the triangle has no point on that side.
void splitTriangleInBox(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, const Box& box, int axis, float pos,
                        Box& lower, Box& upper);

}  // namespace duplex
