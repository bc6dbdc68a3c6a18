#include "duplex/accel/Affine.h"

#include <glm/matrix.hpp>

#include <cmath>

namespace duplex {

Affine Affine::fromRowMajor3x4(const std::array<double, 12>& m) {
  Affine a;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) a.linear[c][r] = m[r * 4 + c];  // GLM is column-major
    a.translation[r] = m[r * 4 + 3];
  }
  return a;
}

std::array<double, 12> Affine::toRowMajor3x4() const {
  std::array<double, 12> m{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[r * 4 + c] = linear[c][r];
    m[r * 4 + 3] = translation[r];
  }
  return m;
}

bool Affine::isFinite() const {
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r)
      if (!std::isfinite(linear[c][r])) return false;
  return std::isfinite(translation.x) && std::isfinite(translation.y) && std::isfinite(translation.z);
}

bool Affine::isSingular() const {
  if (!isFinite()) return true;
  // Compare the determinant with the product of the column lengths (Hadamard's bound), so the
  // test is scale invariant: a tiny but well-shaped transform is not singular.
  const double bound = glm::length(linear[0]) * glm::length(linear[1]) * glm::length(linear[2]);
  return !(bound > 0.0) || std::abs(glm::determinant(linear)) <= 1e-12 * bound;
}

Affine Affine::inverse() const {
  Affine inv;
  inv.linear = glm::inverse(linear);
  inv.translation = -(inv.linear * translation);
  return inv;
}

Box Affine::apply(const Box& b) const {
  if (b.empty()) return b;
  const glm::dvec3 c = point(0.5 * (glm::dvec3(b.lo) + glm::dvec3(b.hi)));
  const glm::dvec3 h = 0.5 * (glm::dvec3(b.hi) - glm::dvec3(b.lo));
  glm::dvec3 e(0.0);
  for (int col = 0; col < 3; ++col) e += glm::abs(linear[col]) * h[col];
  glm::vec3 lo, hi;
  for (int k = 0; k < 3; ++k) {
    // Round outward so the float box still contains the exact (double) one.
    lo[k] = std::nextafter(static_cast<float>(c[k] - e[k]), -INFINITY);
    hi[k] = std::nextafter(static_cast<float>(c[k] + e[k]), INFINITY);
  }
  return {lo, hi};
}

Ray Affine::apply(const Ray& r) const {
  Ray out = r;
  out.origin = glm::vec3(point(glm::dvec3(r.origin)));
  out.dir = glm::vec3(vector(glm::dvec3(r.dir)));
  return out;
}

std::ostream& operator<<(std::ostream& os, const Affine& a) {
  const auto m = a.toRowMajor3x4();
  os << "Affine[";
  for (int i = 0; i < 12; ++i) os << m[i] << (i == 11 ? "]" : (i % 4 == 3 ? "; " : ", "));
  return os;
}

}  // namespace duplex
