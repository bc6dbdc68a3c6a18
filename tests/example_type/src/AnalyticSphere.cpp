#include "duplex/example/AnalyticSphere.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

namespace duplex::example {

AnalyticSphere::AnalyticSphere(std::string name, double radius) : Object(std::move(name)), radius_(radius) {
  if (!(std::isfinite(radius) && radius > 0.0))
    throw InvalidArgument("analytic sphere '" + this->name() + "': radius must be finite and > 0");
}

Box AnalyticSphere::bounds() const {
  // Rounded outward: the float box must hold every point of the sphere.
  const float r = std::nextafter(static_cast<float>(radius_), std::numeric_limits<float>::infinity());
  return Box{glm::vec3(-r), glm::vec3(r)};
}

bool AnalyticSphere::crossings(const Ray& ray_os, double& t0, double& t1) const {
  const glm::dvec3 o(ray_os.origin), d(ray_os.dir);
  const double a = glm::dot(d, d);
  const double b = glm::dot(o, d);
  const double c = glm::dot(o, o) - radius_ * radius_;
  const double disc = b * b - a * c;
  if (!(disc >= 0.0) || !(a > 0.0)) return false;
  // The root of larger magnitude first, the other from the product of the roots: no cancellation.
  const double q = -(b + std::copysign(std::sqrt(disc), b));
  if (q == 0.0) {  // the origin lies on the sphere and the ray is tangent to it
    t0 = t1 = 0.0;
    return true;
  }
  t0 = q / a;
  t1 = c / q;
  if (t0 > t1) std::swap(t0, t1);
  return true;
}

Hit AnalyticSphere::hitAt(const Ray& ray_os, double t) const {
  const glm::dvec3 p = glm::dvec3(ray_os.origin) + t * glm::dvec3(ray_os.dir);
  Hit hit;
  hit.t = static_cast<float>(t);
  const double phi = std::atan2(p.y, p.x);
  hit.u = static_cast<float>((phi < 0.0 ? phi + 2.0 * std::numbers::pi : phi) / (2.0 * std::numbers::pi));
  hit.v = static_cast<float>(std::acos(std::clamp(p.z / radius_, -1.0, 1.0)) / std::numbers::pi);
  hit.prim_id = 0;
  hit.ng = glm::vec3(p);
  return hit;
}

bool AnalyticSphere::intersect(const Ray& ray_os, Hit& hit, QueryContext&) const {
  double t[2];
  if (!crossings(ray_os, t[0], t[1])) return false;
  for (const double ti : t)
    if (ti >= ray_os.tnear && ti <= ray_os.tfar && static_cast<float>(ti) < hit.t) {
      const Hit found = hitAt(ray_os, ti);
      hit.t = found.t;
      hit.u = found.u;
      hit.v = found.v;
      hit.prim_id = found.prim_id;
      hit.ng = found.ng;
      return true;
    }
  return false;
}

bool AnalyticSphere::occluded(const Ray& ray_os, QueryContext&) const {
  double t0, t1;
  if (!crossings(ray_os, t0, t1)) return false;
  return (t0 >= ray_os.tnear && t0 <= ray_os.tfar) || (t1 >= ray_os.tnear && t1 <= ray_os.tfar);
}

void AnalyticSphere::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext&) const {
  double t0, t1;
  if (!crossings(ray_os, t0, t1)) return;
  if (t0 >= ray_os.tnear && t0 <= ray_os.tfar) hits.push_back(hitAt(ray_os, t0));
  if (t1 != t0 && t1 >= ray_os.tnear && t1 <= ray_os.tfar) hits.push_back(hitAt(ray_os, t1));
}

void registerAnalyticSphereType(ObjectTypeRegistry& registry) {
  const auto read = [](const nlohmann::json& spec, const ObjectSpecContext& ctx) -> ObjectSpecResult {
    const std::string& p = ctx.pointer;
    if (!spec.is_object()) ctx.fail(p, "expected an object");
    ctx.onlyKeys(spec, p, {"radius"});
    const double radius = spec.contains("radius") ? ctx.positiveNumber(spec["radius"], p + "/radius") : 1.0;
    // Nothing to build: the object is made now rather than deferred to ObjectLibrary::buildAll.
    return std::shared_ptr<const Object>(std::make_shared<const AnalyticSphere>(ctx.object_name, radius));
  };
  registry.add({std::string(AnalyticSphere::kTypeName), read, /*in_scene_json_v1=*/false, /*accepts_structure=*/false});
}

}  // namespace duplex::example
