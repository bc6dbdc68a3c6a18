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

}  // namespace duplex
