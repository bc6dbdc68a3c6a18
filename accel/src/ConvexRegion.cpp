#include "duplex/accel/ConvexRegion.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <cmath>

namespace duplex {

namespace {

double signedDistance(const glm::dvec4& plane, const glm::dvec3& p) {
  return plane.x * p.x + plane.y * p.y + plane.z * p.z - plane.w;
}

}  // namespace

ConvexRegion::ConvexRegion(std::span<const glm::dvec4> planes) : planes_(planes.begin(), planes.end()) {
  for (const glm::dvec4& p : planes_)
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || !std::isfinite(p.w) ||
        !(p.x != 0.0 || p.y != 0.0 || p.z != 0.0))
      throw InvalidArgument("convex region: a plane has a non-finite or zero normal, or a non-finite offset");
}

ConvexRegion ConvexRegion::transformed(const Affine& world_from_object) const {
  // dot(n, L x + t) <= d  <=>  dot(L^T n, x) <= d - dot(n, t).
  ConvexRegion r;
  r.planes_.reserve(planes_.size());
  const glm::dmat3 lt = glm::transpose(world_from_object.linear);
  for (const glm::dvec4& p : planes_) {
    const glm::dvec3 n(p.x, p.y, p.z);
    r.planes_.emplace_back(lt * n, p.w - glm::dot(n, world_from_object.translation));
  }
  return r;
}

bool ConvexRegion::contains(const glm::dvec3& p) const {
  for (const glm::dvec4& plane : planes_)
    if (signedDistance(plane, p) > 0.0) return false;
  return true;
}

bool ConvexRegion::excludes(const Box& b) const {
  if (b.empty()) return true;
  // The box is outside a plane when even its corner furthest against the normal is outside.
  for (const glm::dvec4& p : planes_) {
    const glm::dvec3 corner(p.x >= 0 ? b.lo.x : b.hi.x, p.y >= 0 ? b.lo.y : b.hi.y, p.z >= 0 ? b.lo.z : b.hi.z);
    if (signedDistance(p, corner) > 0.0) return true;
  }
  return false;
}

bool ConvexRegion::containsBox(const Box& b) const {
  if (b.empty()) return false;
  // Inside every plane when the corner furthest along the normal is.
  for (const glm::dvec4& p : planes_) {
    const glm::dvec3 corner(p.x >= 0 ? b.hi.x : b.lo.x, p.y >= 0 ? b.hi.y : b.lo.y, p.z >= 0 ? b.hi.z : b.lo.z);
    if (signedDistance(p, corner) > 0.0) return false;
  }
  return true;
}

bool ConvexRegion::meetsTriangle(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) const {
  // The common cases first: a plane with all three corners outside, or every corner inside.
  bool all_inside = true;
  for (const glm::dvec4& p : planes_) {
    const double da = signedDistance(p, a), db = signedDistance(p, b), dc = signedDistance(p, c);
    if (da > 0.0 && db > 0.0 && dc > 0.0) return false;
    all_inside = all_inside && da <= 0.0 && db <= 0.0 && dc <= 0.0;
  }
  if (all_inside) return true;
  // Sutherland-Hodgman: in exact arithmetic each plane adds at most one vertex to the convex
  // polygon; the buffers hold twice that (a picking frustum's five planes fit on the stack).
  constexpr std::size_t kStack = 16;
  const std::size_t capacity = std::max<std::size_t>(kStack, 2 * (3 + planes_.size()));
  glm::dvec3 stack_a[kStack], stack_b[kStack];
  std::vector<glm::dvec3> heap_a, heap_b;
  glm::dvec3* poly = stack_a;
  glm::dvec3* next = stack_b;
  if (capacity > kStack) {
    heap_a.resize(capacity);
    heap_b.resize(capacity);
    poly = heap_a.data();
    next = heap_b.data();
  }
  poly[0] = a;
  poly[1] = b;
  poly[2] = c;
  std::size_t n = 3;
  for (const glm::dvec4& p : planes_) {
    std::size_t m = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const glm::dvec3& u = poly[i];
      const glm::dvec3& v = poly[i + 1 == n ? 0 : i + 1];
      const double du = signedDistance(p, u), dv = signedDistance(p, v);
      // Rounding can make a sliver's polygon change sides more often than a convex one can: when
      // the buffer would overflow, call it a meeting (the callers' tests stay conservative).
      if (m + 2 > capacity) return true;
      if (du <= 0.0) next[m++] = u;
      if ((du < 0.0 && dv > 0.0) || (du > 0.0 && dv < 0.0)) next[m++] = u + (du / (du - dv)) * (v - u);
    }
    if (m == 0) return false;
    std::swap(poly, next);
    n = m;
  }
  return true;
}

}  // namespace duplex
