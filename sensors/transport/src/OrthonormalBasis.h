#pragma once
// Private to sensors/transport/src: an orthonormal basis completing a unit vector, for sampling directions.

#include <glm/vec3.hpp>

#include <cmath>

namespace duplex::detail {

/// (t, b) such that (t, b, n) is a right-handed orthonormal basis, for unit n (Duff et al. 2017,
/// "Building an orthonormal basis, revisited"): branch-free, continuous except at one sign flip.
inline void orthonormalBasis(const glm::dvec3& n, glm::dvec3& t, glm::dvec3& b) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z);
  const double c = n.x * n.y * a;
  t = glm::dvec3(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
  b = glm::dvec3(c, sign + n.y * n.y * a, -n.y);
}

}  // namespace duplex::detail
