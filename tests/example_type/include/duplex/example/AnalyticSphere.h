#pragma once
/// \file AnalyticSphere.h
/// A worked example of an object type outside the library (docs/object-types.md): a sphere
/// intersected exactly, in closed form, instead of as a triangle mesh. The tests register it
/// (registerAnalyticSphereType) the way an application registers its own types.

#include "duplex/accel/Object.h"
#include "duplex/scenegraph/ObjectTypeRegistry.h"

#include <string>
#include <string_view>
#include <vector>

namespace duplex::example {

/// The sphere of `radius` around the object-space origin (scene units). Immutable; queries are
/// thread-safe and keep no state in the QueryContext.
class AnalyticSphere final : public Object {
 public:
  static constexpr std::string_view kTypeName = "analytic_sphere";

  /// Throws InvalidArgument naming the object when `radius` is not finite and > 0.
  AnalyticSphere(std::string name, double radius);

  [[nodiscard]] std::string_view typeName() const override { return kTypeName; }
  /// The cube [-radius, radius]^3, rounded outward to float (object space).
  [[nodiscard]] Box bounds() const override;
  /// Closest crossing of the sphere with t in [tnear, hit.t) (object space): t, u = longitude / 2 pi
  /// in [0, 1], v = colatitude / pi in [0, 1], prim_id 0, ng the outward normal times the radius.
  bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const override;
  [[nodiscard]] bool occluded(const Ray& ray_os, QueryContext& ctx) const override;
  /// Both crossings within [tnear, tfar] (one where the ray only touches the sphere).
  void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const override;
  [[nodiscard]] std::size_t memoryBytes() const override { return sizeof(*this); }
  /// "analytic_spheres": 1.
  [[nodiscard]] std::vector<ObjectFigure> figures() const override { return {{"analytic_spheres", 1}}; }

  [[nodiscard]] double radius() const { return radius_; }

 private:
  /// The ray's parameters t0 <= t1 where it meets the sphere (in double); false when it misses.
  bool crossings(const Ray& ray_os, double& t0, double& t1) const;
  /// The hit record of the crossing at `t`.
  [[nodiscard]] Hit hitAt(const Ray& ray_os, double t) const;

  double radius_;
};

/// Adds "analytic_sphere" (`{"radius": r}`, r > 0, default 1; own scene format only) to `registry`.
/// Throws InvalidArgument when the name is taken.
void registerAnalyticSphereType(ObjectTypeRegistry& registry);

}  // namespace duplex::example
