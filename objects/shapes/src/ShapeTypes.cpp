#include "duplex/objects/ShapeTypes.h"

#include "duplex/objects/MeshObject.h"
#include "duplex/objects/ProceduralMesh.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <string>
#include <vector>

namespace duplex {

using nlohmann::json;

namespace {

// A procedural shape: parameters are read now, the mesh is generated and built by the factory.
template <class Generate>
ObjectSpecResult deferredShape(const ObjectSpecContext& ctx, Generate generate) {
  return ObjectLibrary::Factory([ctx, generate] {
    return std::shared_ptr<const Object>(
        std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(generate(ctx.object_name)), ctx.build));
  });
}

ObjectSpecResult readSphere(const json& spec, const ObjectSpecContext& ctx) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  ctx.onlyKeys(spec, p, {"radius", "subdivisions"});
  const double radius = spec.contains("radius") ? ctx.positiveNumber(spec["radius"], p + "/radius") : 1.0;
  int subdivisions = 3;
  if (spec.contains("subdivisions")) {
    const double s = ctx.number(spec["subdivisions"], p + "/subdivisions");
    if (s < 0 || s > kMaxSphereSubdivisions || s != std::floor(s))
      ctx.fail(p + "/subdivisions", "expected an integer in [0, " + std::to_string(kMaxSphereSubdivisions) + "]");
    subdivisions = static_cast<int>(s);
  }
  return deferredShape(
      ctx, [radius, subdivisions](const std::string& name) { return makeSphere(radius, subdivisions, name); });
}

ObjectSpecResult readBox(const json& spec, const ObjectSpecContext& ctx) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  ctx.onlyKeys(spec, p, {"size"});
  const auto s = spec.contains("size") ? ctx.positiveSizes(spec["size"], p + "/size", 3) : std::vector<double>(3, 1.0);
  const glm::dvec3 size(s[0], s[1], s[2]);
  return deferredShape(ctx, [size](const std::string& name) { return makeBox(size, name); });
}

ObjectSpecResult readPlane(const json& spec, const ObjectSpecContext& ctx) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  ctx.onlyKeys(spec, p, {"size"});
  const auto s = spec.contains("size") ? ctx.positiveSizes(spec["size"], p + "/size", 2) : std::vector<double>(2, 1.0);
  const glm::dvec2 size(s[0], s[1]);
  return deferredShape(ctx, [size](const std::string& name) { return makePlane(size, name); });
}

}  // namespace

void registerShapeTypes(ObjectTypeRegistry& registry) {
  registry.add({"sphere", readSphere, /*in_scene_json_v1=*/false, /*accepts_structure=*/false});
  registry.add({"box", readBox, false, false});
  registry.add({"plane", readPlane, false, false});
}

}  // namespace duplex
