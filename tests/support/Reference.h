#pragma once
/// \file Reference.h
/// The brute-force reference of the differential tests: every triangle against every ray, in
/// double precision, written independently of the library's watertight test (plane distance first,
/// then the signs of three Pluecker products / signed volumes; edges and vertices count as inside).

#include "duplex/accel/Affine.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/TriangleMesh.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <span>
#include <vector>

namespace duplex::test {

/// A triangle in the query's space, in double, with what the reference needs precomputed.
struct RefTriangle {
  glm::dvec3 a, b, c;
  glm::dvec3 n;        // cross(b - a, c - a)
  double plane = 0.0;  // dot(n, a)
  std::uint32_t prim = kInvalidId;
  std::uint32_t instance = kInvalidId;
};

inline RefTriangle makeRefTriangle(const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c, std::uint32_t prim,
                                   std::uint32_t instance) {
  RefTriangle t{a, b, c, glm::cross(b - a, c - a), 0.0, prim, instance};
  t.plane = glm::dot(t.n, a);
  return t;
}

/// The valid triangles of `mesh`, mapped by `world_from_object` in double.
inline std::vector<RefTriangle> refTriangles(const TriangleMesh& mesh, const Affine& world_from_object = Affine(),
                                             std::uint32_t instance = kInvalidId) {
  std::vector<RefTriangle> out;
  out.reserve(mesh.triangleCount());
  for (std::size_t i = 0; i < mesh.triangleCount(); ++i) {
    if (!mesh.isValid(i)) continue;
    const auto v = mesh.vertices(i);
    out.push_back(makeRefTriangle(world_from_object.point(glm::dvec3(v[0])), world_from_object.point(glm::dvec3(v[1])),
                                  world_from_object.point(glm::dvec3(v[2])), static_cast<std::uint32_t>(i), instance));
  }
  return out;
}

struct RefHit {
  double t = std::numeric_limits<double>::infinity();
  std::uint32_t prim = kInvalidId;
  std::uint32_t instance = kInvalidId;
  [[nodiscard]] bool valid() const { return prim != kInvalidId; }
};

/// Whether the reference answers this ray at all: finite origin/direction, non-zero direction,
/// tnear <= tfar (mirrors the documented Ray contract, written out independently).
inline bool refQueryable(const Ray& r) {
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(r.origin[k]) || !std::isfinite(r.dir[k])) return false;
  if (r.dir.x == 0.0f && r.dir.y == 0.0f && r.dir.z == 0.0f) return false;
  return r.tnear <= r.tfar;
}

/// Hit distance of the line o + t d with `tri`, or NaN when the line misses it (or is parallel to
/// its plane). Two-sided; points on edges and vertices count as hits.
inline double refIntersect(const glm::dvec3& o, const glm::dvec3& d, const RefTriangle& tri) {
  const double denom = glm::dot(d, tri.n);
  if (denom == 0.0) return std::numeric_limits<double>::quiet_NaN();
  const double t = (tri.plane - glm::dot(tri.n, o)) / denom;
  // Signed volumes of the ray line with the three edges: same sign (or zero) means inside.
  const glm::dvec3 A = tri.a - o, B = tri.b - o, C = tri.c - o;
  const double s0 = glm::dot(d, glm::cross(B, C));
  const double s1 = glm::dot(d, glm::cross(C, A));
  const double s2 = glm::dot(d, glm::cross(A, B));
  const bool inside = (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0);
  return inside ? t : std::numeric_limits<double>::quiet_NaN();
}

/// The triangles of a reference with a bounding sphere per triangle, so that a ray tests only the
/// few triangles whose sphere it passes (conservative cull: the sphere radius is padded).
/// Makes `tri` the closest hit when the ray meets it with t in [tnear, tfar] before best.t.
inline void refConsider(const glm::dvec3& o, const glm::dvec3& d, double tnear, double tfar, const RefTriangle& tri,
                        RefHit& best) {
  const double denom = glm::dot(d, tri.n);
  if (denom == 0.0) return;
  const double t = (tri.plane - glm::dot(tri.n, o)) / denom;
  if (!(t >= tnear && t <= tfar && t < best.t)) return;
  if (std::isnan(refIntersect(o, d, tri))) return;
  best.t = t;
  best.prim = tri.prim;
  best.instance = tri.instance;
}

class RefScene {
 public:
  RefScene() = default;
  explicit RefScene(std::vector<RefTriangle> tris) : tris_(std::move(tris)) {
    spheres_.reserve(tris_.size());
    for (const RefTriangle& t : tris_) {
      const glm::dvec3 c = (t.a + t.b + t.c) / 3.0;
      const double r =
          std::sqrt(std::max({glm::dot(t.a - c, t.a - c), glm::dot(t.b - c, t.b - c), glm::dot(t.c - c, t.c - c)}));
      spheres_.push_back({c.x, c.y, c.z, r * (1.0 + 1e-9)});
      magnitude_ = std::max({magnitude_, std::abs(c.x), std::abs(c.y), std::abs(c.z), r});
    }
  }
  [[nodiscard]] std::span<const RefTriangle> triangles() const { return tris_; }
  [[nodiscard]] std::size_t size() const { return tris_.size(); }

  /// Closest hit with t in [ray.tnear, ray.tfar], or a miss.
  [[nodiscard]] RefHit closestHit(const Ray& ray) const {
    RefHit best;
    if (!refQueryable(ray)) return best;
    const glm::dvec3 o(ray.origin), d(ray.dir);
    const double inv_dd = 1.0 / glm::dot(d, d);
    const double tnear = ray.tnear, tfar = ray.tfar;
    const std::size_t n = spheres_.size();
    // The cull compares the distance from each sphere centre to the ray's line (the perpendicular
    // computed explicitly, so rounding stays relative to the coordinates, not their squares) with
    // the radius padded far beyond that rounding.
    const double pad = 1e-10 * (magnitude_ + std::max({std::abs(o.x), std::abs(o.y), std::abs(o.z)}));
    for (std::size_t i = 0; i < n; ++i) {
      const Sphere& s = spheres_[i];
      const double wx = s.x - o.x, wy = s.y - o.y, wz = s.z - o.z;
      const double k = (wx * d.x + wy * d.y + wz * d.z) * inv_dd;
      const double px = wx - k * d.x, py = wy - k * d.y, pz = wz - k * d.z;
      const double r = s.r + pad;
      if (px * px + py * py + pz * pz > r * r) continue;
      const RefTriangle& tri = tris_[i];
      refConsider(o, d, tnear, tfar, tri, best);
    }
    return best;
  }

 private:
  struct Sphere {
    double x, y, z, r;
  };
  std::vector<RefTriangle> tris_;
  std::vector<Sphere> spheres_;
  double magnitude_ = 0.0;
};

/// Closest hit with t in [ray.tnear, ray.tfar], or a miss (plain loop, no culling).
inline RefHit refClosestHit(std::span<const RefTriangle> tris, const Ray& ray) {
  RefHit best;
  if (!refQueryable(ray)) return best;
  const glm::dvec3 o(ray.origin), d(ray.dir);
  const double tnear = ray.tnear, tfar = ray.tfar;
  for (const RefTriangle& tri : tris) {
    refConsider(o, d, tnear, tfar, tri, best);
  }
  return best;
}

inline RefHit refClosestHit(const RefScene& scene, const Ray& ray) { return scene.closestHit(ray); }

/// Whether anything is hit with t in [tnear, tfar].
inline bool refAnyHit(const RefScene& scene, const Ray& ray) { return scene.closestHit(ray).valid(); }

/// Tolerances of a comparison against the reference.
struct HitTolerance {
  double tie_rel = 1e-5;   ///< different primitives are accepted when t agrees this closely (relative)
  double same_rel = 1e-4;  ///< same primitive: t agreement (float test vs double reference)
  double abs_scale = 0.0;  ///< absolute floor, in world units (divided by |dir| to get t units)
};

/// Compares a library hit with the reference hit of the same ray. `check_instance` also compares
/// instance ids (two-level queries).
inline ::testing::AssertionResult hitMatches(const Hit& hit, const RefHit& ref, const Ray& ray, const HitTolerance& tol,
                                             bool check_instance) {
  const double dir_len = glm::length(glm::dvec3(ray.dir));
  const double floor = dir_len > 0.0 ? tol.abs_scale / dir_len : 0.0;
  if (!hit.valid() && !ref.valid()) return ::testing::AssertionSuccess();
  if (hit.valid() != ref.valid())
    return ::testing::AssertionFailure() << ray << ": library " << hit << " but reference "
                                         << (ref.valid() ? "hits" : "misses") << " (ref t=" << ref.t
                                         << ", prim=" << ref.prim << ", inst=" << ref.instance << ")";
  const bool same = hit.prim_id == ref.prim && (!check_instance || hit.instance_id == ref.instance);
  const double err = std::abs(double(hit.t) - ref.t);
  const double allowed = (same ? tol.same_rel : tol.tie_rel) * std::abs(ref.t) + floor;
  if (err <= allowed) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << ray << ": library " << hit << " vs reference t=" << ref.t
                                       << " prim=" << ref.prim << " inst=" << ref.instance << " (|dt|=" << err << " > "
                                       << allowed << (same ? ", same primitive)" : ", different primitive)");
}

/// Absolute t tolerance of a reference hit at `t` (see HitTolerance).
inline double tSlack(double t, const Ray& ray, const HitTolerance& tol) {
  const double dir_len = glm::length(glm::dvec3(ray.dir));
  return tol.tie_rel * std::abs(t) + (dir_len > 0.0 ? tol.abs_scale / dir_len : 0.0);
}

/// hitMatches, except that a reference hit lying within rounding distance of tnear or tfar may be
/// missed by the library (whether t = tnear + rounding counts is not decidable in float); the
/// library must then agree with the reference on the rest of the interval.
inline ::testing::AssertionResult agreesWithReference(const Hit& hit, const Ray& ray, const RefScene& ref,
                                                      const HitTolerance& tol, bool check_instance) {
  const RefHit expected = ref.closestHit(ray);
  auto match = hitMatches(hit, expected, ray, tol, check_instance);
  if (match || !expected.valid()) return match;
  const double slack = tSlack(expected.t, ray, tol);
  if (expected.t - double(ray.tnear) <= slack) {
    Ray later = ray;
    later.tnear = std::nextafter(static_cast<float>(expected.t + slack), std::numeric_limits<float>::infinity());
    if (later.tnear <= later.tfar && hitMatches(hit, ref.closestHit(later), later, tol, check_instance))
      return ::testing::AssertionSuccess();
  }
  if (double(ray.tfar) - expected.t <= slack && !hit.valid()) return ::testing::AssertionSuccess();
  return match;
}

/// occluded() against "the reference has a hit in [tnear, tfar]", with the same boundary rule.
inline ::testing::AssertionResult occlusionAgrees(bool occluded, const Ray& ray, const RefScene& ref,
                                                  const HitTolerance& tol) {
  const RefHit expected = ref.closestHit(ray);
  if (occluded == expected.valid()) return ::testing::AssertionSuccess();
  if (expected.valid()) {
    // Reported clear: fine only if every hit in the interval is within rounding of an end.
    const double slack = tSlack(expected.t, ray, tol);
    if (expected.t - double(ray.tnear) <= slack) {
      Ray later = ray;
      later.tnear = std::nextafter(static_cast<float>(expected.t + slack), std::numeric_limits<float>::infinity());
      const RefHit next = later.tnear <= later.tfar ? ref.closestHit(later) : RefHit{};
      if (!next.valid() || double(ray.tfar) - next.t <= tSlack(next.t, ray, tol)) return ::testing::AssertionSuccess();
    } else if (double(ray.tfar) - expected.t <= slack) {
      return ::testing::AssertionSuccess();
    }
  } else {
    // Reported occluded: fine only if a hit lies just outside the interval.
    Ray wide = ray;
    const double t_lo = double(ray.tnear), t_hi = double(ray.tfar);
    wide.tnear = static_cast<float>(t_lo - tSlack(t_lo, ray, tol));
    if (std::isfinite(t_hi)) wide.tfar = static_cast<float>(t_hi + tSlack(t_hi, ray, tol));
    if (ref.closestHit(wide).valid()) return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure() << ray << ": occluded() = " << occluded << " but the reference "
                                       << (expected.valid() ? "hits" : "misses") << " (t=" << expected.t
                                       << ", prim=" << expected.prim << ")";
}

/// Signed volume of a closed mesh (positive for outward winding).
inline double signedVolume(const TriangleMesh& mesh) {
  double v = 0.0;
  for (std::size_t i = 0; i < mesh.triangleCount(); ++i) {
    if (!mesh.isValid(i)) continue;
    const auto p = mesh.vertices(i);
    v += glm::dot(glm::dvec3(p[0]), glm::cross(glm::dvec3(p[1]), glm::dvec3(p[2]))) / 6.0;
  }
  return v;
}

}  // namespace duplex::test
