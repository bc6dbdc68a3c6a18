// SensorScene::load: the scene file's "lights", "sensors" and per-object "material" keys
// (docs/sensors.md). The graph itself is read by loadSceneDocument with the sensor type registered.

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorScene.h"
#include "duplex/sensors/SensorTypes.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <numbers>

namespace duplex {

using nlohmann::json;

namespace {

std::string at(const std::string& p, std::string_view key) { return p + "/" + std::string(key); }
std::string at(const std::string& p, std::size_t i) { return p + "/" + std::to_string(i); }

glm::dvec3 vec3(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  if (!v.is_array() || v.size() != 3) ctx.fail(p, "expected an array of 3 numbers");
  return {ctx.number(v[0], at(p, 0)), ctx.number(v[1], at(p, 1)), ctx.number(v[2], at(p, 2))};
}

Affine transform12(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  if (!v.is_array() || v.size() != 12) ctx.fail(p, "expected 12 numbers (row-major 3x4)");
  std::array<double, 12> m{};
  for (std::size_t k = 0; k < 12; ++k) m[k] = ctx.number(v[k], at(p, k));
  const Affine a = Affine::fromRowMajor3x4(m);
  if (a.isSingular()) ctx.fail(p, "singular transform");
  return a;
}

glm::dvec3 direction(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  const glm::dvec3 d = vec3(v, p, ctx);
  if (d == glm::dvec3(0.0)) ctx.fail(p, "direction must be a non-zero vector");
  return d;
}

Light readLight(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  if (!v.is_object()) ctx.fail(p, "expected a light (an object with \"type\")");
  Light l;
  l.name = v.contains("name") ? ctx.string(v["name"], at(p, "name")) : p.substr(1);
  const std::string type = ctx.string(ctx.member(v, p, "type"), at(p, "type"));
  const double power = ctx.number(ctx.member(v, p, "power"), at(p, "power"));
  if (!(power > 0.0)) ctx.fail(at(p, "power"), "power must be > 0 W (got " + std::to_string(power) + ")");
  l.power_w = power;
  if (type == "point") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "position"});
    l.type = LightType::Point;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
  } else if (type == "spot") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "position", "direction", "half_angle"});
    l.type = LightType::Spot;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
    l.direction = direction(ctx.member(v, p, "direction"), at(p, "direction"), ctx);
    const double deg = ctx.number(ctx.member(v, p, "half_angle"), at(p, "half_angle"));
    if (!(deg > 0.0 && deg <= 180.0)) ctx.fail(at(p, "half_angle"), "expected a half-angle in (0, 180] degrees");
    l.cone_angle = deg * std::numbers::pi / 180.0;
  } else if (type == "directional") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "position", "direction", "radius"});
    l.type = LightType::Directional;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
    l.direction = direction(ctx.member(v, p, "direction"), at(p, "direction"), ctx);
    l.radius = ctx.positiveNumber(ctx.member(v, p, "radius"), at(p, "radius"));
  } else if (type == "area") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "size", "transform", "two_sided"});
    l.type = LightType::Area;
    const auto size = ctx.positiveSizes(ctx.member(v, p, "size"), at(p, "size"), 2);
    l.width = size[0];
    l.height = size[1];
    if (v.contains("transform")) l.world_from_light = transform12(v["transform"], at(p, "transform"), ctx);
    if (v.contains("two_sided")) {
      if (!v["two_sided"].is_boolean()) ctx.fail(at(p, "two_sided"), "expected true or false");
      l.two_sided = v["two_sided"].get<bool>();
    }
  } else if (type == "ies") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "file", "position", "transform"});
    l.type = LightType::Goniometric;
    if (v.contains("position") == v.contains("transform"))
      ctx.fail(p, "an \"ies\" light has either \"position\" or \"transform\" (rotation and translation)");
    if (v.contains("transform")) {
      l.world_from_light = transform12(v["transform"], at(p, "transform"), ctx);
      l.position = l.world_from_light.translation;
    } else {
      l.position = vec3(v["position"], at(p, "position"), ctx);
    }
    const std::filesystem::path file = ctx.resolve(ctx.string(ctx.member(v, p, "file"), at(p, "file")));
    try {
      l.profile = std::make_shared<const IesProfile>(IesProfile::load(file));
    } catch (const Error& e) {
      ctx.fail(at(p, "file"), e.what());
    }
  } else {
    ctx.fail(at(p, "type"), "unknown light type \"" + type + "\" (expected \"point\", \"spot\", \"directional\", \"area\" or \"ies\")");
  }
  try {
    l.validate();
  } catch (const InvalidArgument& e) {
    ctx.fail(p, e.what());
  }
  return l;
}

Material readMaterial(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  if (!v.is_object()) ctx.fail(p, "expected a material (an object with \"type\")");
  Material m;
  const std::string type = ctx.string(ctx.member(v, p, "type"), at(p, "type"));
  auto reflectance = [&] {
    const double r = ctx.number(ctx.member(v, p, "reflectance"), at(p, "reflectance"));
    if (!(r >= 0.0 && r <= 1.0)) ctx.fail(at(p, "reflectance"), "expected a reflectance in [0, 1]");
    return r;
  };
  if (type == "absorber") {
    ctx.onlyKeys(v, p, {"type"});
  } else if (type == "lambertian") {
    ctx.onlyKeys(v, p, {"type", "reflectance"});
    m.type = MaterialType::Lambertian;
    m.reflectance = reflectance();
  } else if (type == "mirror") {
    ctx.onlyKeys(v, p, {"type", "reflectance"});
    m.type = MaterialType::Mirror;
    m.reflectance = v.contains("reflectance") ? reflectance() : 1.0;
  } else if (type == "dielectric") {
    ctx.onlyKeys(v, p, {"type", "ior"});
    m.type = MaterialType::Dielectric;
    m.ior = ctx.positiveNumber(ctx.member(v, p, "ior"), at(p, "ior"));
  } else {
    ctx.fail(at(p, "type"), "unknown material \"" + type + "\" (expected \"absorber\", \"lambertian\", \"mirror\" or \"dielectric\")");
  }
  return m;
}

}  // namespace

SensorScene SensorScene::load(const std::filesystem::path& path, const SceneDocumentOptions& options) {
  SceneDocumentOptions o = options;
  if (!o.registry) o.registry = &sensorTypeRegistry();
  auto doc = std::make_unique<SceneDocument>(loadSceneDocument(path, o));
  const json& root = *doc->parsed;
  ObjectSpecContext ctx;
  ctx.scene_file = path;
  ctx.strict = doc->format != "scene-json-v1";
  ctx.cache = std::make_shared<SceneLoadCache>();
  SceneGraph& graph = *doc->graph;

  // Materials by object (file order = library order of the "objects" entries).
  std::vector<Material> materials(graph.library().size());
  const json& objects = root["objects"];
  for (std::size_t i = 0; i < objects.size() && i < doc->objects.size(); ++i)
    if (objects[i].contains("material"))
      materials[doc->objects[i]] = readMaterial(objects[i]["material"], at(at("/objects", i), "material"), ctx);

  std::vector<Light> lights;
  if (root.contains("lights")) {
    const json& list = root["lights"];
    if (!list.is_array()) ctx.fail("/lights", "expected an array of lights");
    for (std::size_t i = 0; i < list.size(); ++i) lights.push_back(readLight(list[i], at("/lights", i), ctx));
  }

  if (root.contains("sensors")) {
    const json& list = root["sensors"];
    if (!list.is_array()) ctx.fail("/sensors", "expected an array of sensors");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string p = at("/sensors", i);
      const json& e = list[i];
      ObjectSpecContext sctx = ctx;
      sctx.pointer = p;
      const SensorSpec spec = readSensorSpec(e, sctx, {"name", "transform"});
      const std::string name = ctx.string(ctx.member(e, p, "name"), at(p, "name"));
      if (name.empty()) ctx.fail(at(p, "name"), "expected a non-empty sensor name");
      const Affine world = e.contains("transform") ? transform12(e["transform"], at(p, "transform"), ctx) : Affine::identity();
      try {
        const ObjectId id = graph.library().add("sensors/" + name, std::make_shared<const SensorObject>(name, spec));
        (void)graph.addInstance(kRootNode, id, world, name);
      } catch (const InvalidArgument& ex) {
        ctx.fail(p, ex.what());
      }
    }
    (void)graph.commit();
  }
  try {
    SensorScene scene(graph, std::move(lights), std::move(materials));
    scene.doc_ = std::move(doc);  // the graph lives in the document (a stable address)
    return scene;
  } catch (const InvalidArgument& ex) {
    ctx.fail("/sensors", ex.what());
  }
}

}  // namespace duplex
