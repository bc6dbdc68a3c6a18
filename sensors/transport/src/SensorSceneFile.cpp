// SensorScene::load: the scene file's "lights", "sensors" and per-object "material" keys
// (docs/sensors.md). The graph itself is read by loadSceneDocument with the sensor type registered.

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/sensors/SensorScene.h"
#include "duplex/sensors/SensorTypes.h"

#include <glm/matrix.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
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

// A non-empty array of numbers (per-band values).
std::vector<double> numbers(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  if (!v.is_array() || v.empty()) ctx.fail(p, "expected a non-empty array of numbers (one per band)");
  std::vector<double> out;
  for (std::size_t k = 0; k < v.size(); ++k) out.push_back(ctx.number(v[k], at(p, k)));
  return out;
}

// Per-band values given by band name ({"red": 0.9, ...}): every band of `bands` once, in band order.
std::vector<double> namedBandValues(const json& x, const std::string& p, const ObjectSpecContext& ctx,
                                    const std::vector<std::string>& bands) {
  std::vector<double> values(bands.size(), 0.0);
  std::vector<bool> given(bands.size(), false);
  for (const auto& [name, value] : x.items()) {
    const auto it = std::find(bands.begin(), bands.end(), name);
    if (it == bands.end())
      ctx.fail(p, "unknown band \"" + name + "\" (the scene's \"bands\" are " +
                      (bands.empty() ? std::string("none") : "\"" + bands.front() + "\", ...") + ")");
    const auto k = static_cast<std::size_t>(it - bands.begin());
    values[k] = ctx.number(value, at(p, name));
    given[k] = true;
  }
  for (std::size_t k = 0; k < bands.size(); ++k)
    if (!given[k]) ctx.fail(p, "no value for band \"" + bands[k] + "\"");
  return values;
}

Light readLight(const json& v, const std::string& p, const ObjectSpecContext& ctx, const SceneGraph& graph,
                const std::vector<std::string>& bands) {
  if (!v.is_object()) ctx.fail(p, "expected a light (an object with \"type\")");
  Light l;
  if (v.contains("node")) {  // attached to a node: the geometry below is in its local space
    const std::string path = ctx.string(v["node"], at(p, "node"));
    const std::optional<NodeId> node = graph.find(path);
    if (!node || *node == kRootNode)
      ctx.fail(at(p, "node"), "no node \"" + path + "\" in the scene (a path such as \"/lamp\")");
    l.node = *node;
  }
  l.name = v.contains("name") ? ctx.string(v["name"], at(p, "name")) : p.substr(1);
  const std::string type = ctx.string(ctx.member(v, p, "type"), at(p, "type"));
  // Watts or lumens, never both; an "ies" light with neither takes its lumens from its file. Area
  // lights may give their luminance (cd/m^2) or luminous exitance (lm/m^2) and directional lights
  // their illuminance across the beam (lx) instead: lumens follow from their size below.
  const char* photometric_amount = nullptr;
  for (const char* key : {"luminance", "exitance", "illuminance"})
    if (v.contains(key)) {
      if (photometric_amount || v.contains("power") || v.contains("lumens"))
        ctx.fail(p, std::string("a light has one of \"power\" (W), \"lumens\" (lm), \"luminance\" (cd/m^2, area), "
                                "\"exitance\" (lm/m^2, area) or \"illuminance\" (lx, directional); \"") +
                        key + "\" is not the only one");
      photometric_amount = key;
    }
  if (photometric_amount) {
    const bool fits = type == "area" || type == "disk" || type == "polygon" || type == "mesh"
                          ? std::string_view(photometric_amount) != "illuminance"
                          : type == "directional" && std::string_view(photometric_amount) == "illuminance";
    if (!fits)
      ctx.fail(at(p, photometric_amount),
               std::string("\"") + photometric_amount + "\" is not a key of a \"" + type +
                   "\" light (luminance and exitance: area, disk, polygon and mesh lights; illuminance: directional)");
  }
  if (v.contains("power") && v.contains("lumens"))
    ctx.fail(p, "a light has \"power\" (W) or \"lumens\" (lm), not both");
  if (photometric_amount) {
    // Set from the light's size once it is read.
  } else if (v.contains("lumens")) {
    l.lumens = ctx.number(v["lumens"], at(p, "lumens"));
    if (!(l.lumens > 0.0)) ctx.fail(at(p, "lumens"), "lumens must be > 0 lm (got " + std::to_string(l.lumens) + ")");
  } else if (v.contains("power") || type != "ies") {
    const double power = ctx.number(ctx.member(v, p, "power"), at(p, "power"));
    if (!(power > 0.0)) ctx.fail(at(p, "power"), "power must be > 0 W (got " + std::to_string(power) + ")");
    l.power_w = power;
  }
  if (type == "point") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "lumens", "spectrum", "node", "position"});
    l.type = LightType::Point;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
  } else if (type == "spot") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "lumens", "spectrum", "node", "position", "direction", "half_angle"});
    l.type = LightType::Spot;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
    l.direction = direction(ctx.member(v, p, "direction"), at(p, "direction"), ctx);
    const double deg = ctx.number(ctx.member(v, p, "half_angle"), at(p, "half_angle"));
    if (!(deg > 0.0 && deg <= 180.0)) ctx.fail(at(p, "half_angle"), "expected a half-angle in (0, 180] degrees");
    l.cone_angle = deg * std::numbers::pi / 180.0;
  } else if (type == "directional") {
    ctx.onlyKeys(
        v, p,
        {"type", "name", "power", "lumens", "illuminance", "spectrum", "node", "position", "direction", "radius"});
    l.type = LightType::Directional;
    l.position = vec3(ctx.member(v, p, "position"), at(p, "position"), ctx);
    l.direction = direction(ctx.member(v, p, "direction"), at(p, "direction"), ctx);
    l.radius = ctx.positiveNumber(ctx.member(v, p, "radius"), at(p, "radius"));
    // Illuminance E (lx) on a plane across the beam: E pi r^2 lumens.
    if (photometric_amount)
      l.lumens = ctx.positiveNumber(v["illuminance"], at(p, "illuminance")) * std::numbers::pi * l.radius * l.radius;
  } else if (type == "area" || type == "disk" || type == "polygon" || type == "mesh") {
    ctx.onlyKeys(v, p,
                 {"type", "name", "power", "lumens", "luminance", "exitance", "spectrum", "node",
                  type == "disk"      ? "radius"
                  : type == "polygon" ? "vertices"
                  : type == "mesh"    ? "object"
                                      : "size",
                  "transform", "two_sided"});
    l.type = LightType::Area;
    l.disk = type == "disk";
    if (type == "mesh") {
      // The triangles of a mesh object of the scene (instanced or not), in its object space,
      // placed by "transform"; each emits from its front face.
      const std::string q = at(p, "object");
      const std::string object = ctx.string(ctx.member(v, p, "object"), q);
      const std::optional<ObjectId> id = graph.library().find(object);
      if (!id) ctx.fail(q, "no object \"" + object + "\" in the scene");
      std::shared_ptr<const MeshObject> mesh;
      try {
        mesh = std::dynamic_pointer_cast<const MeshObject>(graph.library().get(*id));
      } catch (const Error& e) {
        ctx.fail(q, e.what());
      }
      if (!mesh) ctx.fail(q, "object \"" + object + "\" is not a triangle mesh");
      std::vector<std::array<glm::dvec3, 3>> tris(mesh->mesh().triangleCount());
      for (std::size_t t = 0; t < tris.size(); ++t) {
        const std::array<glm::vec3, 3> f = mesh->mesh().vertices(t);
        tris[t] = {glm::dvec3(f[0]), glm::dvec3(f[1]), glm::dvec3(f[2])};
      }
      try {
        l.setTriangles(std::move(tris));
      } catch (const InvalidArgument& e) {
        ctx.fail(q, e.what());
      }
    } else if (type == "polygon") {
      // [[x, y], ...]: the polygon in the light's z = 0 plane, placed by "transform".
      const std::string q = at(p, "vertices");
      const json& list = ctx.member(v, p, "vertices");
      if (!list.is_array()) ctx.fail(q, "expected an array of [x, y] vertices");
      std::vector<glm::dvec2> vertices;
      for (std::size_t k = 0; k < list.size(); ++k) {
        if (!list[k].is_array() || list[k].size() != 2) ctx.fail(at(q, k), "expected [x, y]");
        vertices.emplace_back(ctx.number(list[k][0], at(at(q, k), 0)), ctx.number(list[k][1], at(at(q, k), 1)));
      }
      try {
        l.setPolygon(std::move(vertices));
      } catch (const InvalidArgument& e) {
        ctx.fail(q, e.what());
      }
    } else if (l.disk) {
      l.width = l.height = 2.0 * ctx.positiveNumber(ctx.member(v, p, "radius"), at(p, "radius"));
    } else {
      const auto size = ctx.positiveSizes(ctx.member(v, p, "size"), at(p, "size"), 2);
      l.width = size[0];
      l.height = size[1];
    }
    if (v.contains("transform")) l.world_from_light = transform12(v["transform"], at(p, "transform"), ctx);
    if (v.contains("two_sided")) {
      if (!v["two_sided"].is_boolean()) ctx.fail(at(p, "two_sided"), "expected true or false");
      l.two_sided = v["two_sided"].get<bool>();
    }
    if (photometric_amount) {
      // Per emitting face: a Lambertian face of luminance L has exitance M = pi L, and emits M A
      // (A: the rectangle's area as its transform places it).
      const glm::dmat3& m = l.world_from_light.linear;
      const double area =
          !l.triangles.empty() ? [&] {  // the triangles as the transform places them
            double sum = 0.0;
            for (const auto& t : l.triangles) sum += 0.5 * glm::length(glm::cross(m * (t[1] - t[0]), m * (t[2] - t[0])));
            return sum;
          }()
          : l.polygon.empty() ? glm::length(glm::cross(m * glm::dvec3(l.width, 0, 0), m * glm::dvec3(0, l.height, 0))) *
                                  (l.disk ? std::numbers::pi / 4.0 : 1.0)  // the inscribed disk's share
                            : glm::length(glm::cross(m * glm::dvec3(1, 0, 0), m * glm::dvec3(0, 1, 0))) * l.localArea();
      const double faces = l.two_sided ? 2.0 : 1.0;
      const double value = ctx.positiveNumber(v[photometric_amount], at(p, photometric_amount));
      l.lumens =
          (std::string_view(photometric_amount) == "luminance" ? std::numbers::pi * value : value) * area * faces;
    }
  } else if (type == "ies") {
    ctx.onlyKeys(v, p, {"type", "name", "power", "lumens", "spectrum", "node", "file", "position", "transform"});
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
    // Neither watts nor lumens: the file's candela values (multiplier applied) are the intensity,
    // so the light emits their integral.
    if (!v.contains("power") && !v.contains("lumens")) l.lumens = l.profile->integral();
  } else {
    ctx.fail(at(p, "type"), "unknown light type \"" + type +
                                "\" (expected \"point\", \"spot\", \"directional\", \"area\", \"disk\", \"polygon\", "
                                "\"mesh\", \"ies\" or \"sky\")");
  }
  if (v.contains("spectrum"))
    l.spectrum = v["spectrum"].is_object() ? namedBandValues(v["spectrum"], at(p, "spectrum"), ctx, bands)
                                           : numbers(v["spectrum"], at(p, "spectrum"), ctx);
  try {
    l.validate();
  } catch (const InvalidArgument& e) {
    ctx.fail(p, e.what());
  }
  return l;
}

// A "sky" entry: the sky light and, with "sun", the sun as a directional light named
// "<name>/sun" (docs/sensors.md, "Skies and the sun").
std::vector<Light> readSky(const json& v, const std::string& p, const ObjectSpecContext& ctx,
                           const std::vector<std::string>& bands) {
  ctx.onlyKeys(v, p,
               {"type", "name", "model", "cie_type", "zenith_luminance", "horizontal_illuminance", "zenith_radiance",
                "horizontal_irradiance", "sun", "centre", "radius", "spectrum"});
  Light sky;
  sky.type = LightType::Sky;
  sky.name = v.contains("name") ? ctx.string(v["name"], at(p, "name")) : p.substr(1);
  sky.position = vec3(ctx.member(v, p, "centre"), at(p, "centre"), ctx);
  sky.radius = ctx.positiveNumber(ctx.member(v, p, "radius"), at(p, "radius"));
  // The sun's position: altitude above the horizon, azimuth from north (+y) towards east (+x).
  std::optional<glm::dvec3> sun_dir;
  const json* sun = v.contains("sun") ? &v["sun"] : nullptr;
  const std::string ps = at(p, "sun");
  if (sun) {
    if (!sun->is_object()) ctx.fail(ps, "expected {\"altitude\": deg, \"azimuth\": deg, ...}");
    ctx.onlyKeys(*sun, ps, {"altitude", "azimuth", "normal_illuminance", "normal_irradiance"});
    const double alt = ctx.number(ctx.member(*sun, ps, "altitude"), at(ps, "altitude"));
    const double az = ctx.number(ctx.member(*sun, ps, "azimuth"), at(ps, "azimuth"));
    if (!(alt >= 0.0 && alt <= 90.0)) ctx.fail(at(ps, "altitude"), "expected an altitude in [0, 90] degrees");
    const double h = alt * std::numbers::pi / 180.0, a = az * std::numbers::pi / 180.0;
    sun_dir = glm::dvec3(std::cos(h) * std::sin(a), std::cos(h) * std::cos(a), std::sin(h));
  }
  const std::string model = v.contains("model") ? ctx.string(v["model"], at(p, "model")) : "overcast";
  if (v.contains("cie_type") != (model == "cie"))
    ctx.fail(p, "\"cie_type\" (1-15) goes with \"model\": \"cie\" and only with it");
  try {
    if (model == "overcast") {
      sky.sky = std::make_shared<const CieSky>(CieSky::overcast());
    } else if (model == "uniform") {
      sky.sky = std::make_shared<const CieSky>(CieSky::general(5, {0.0, 0.0, 1.0}));
    } else if (model == "clear" || model == "cie") {
      int type = 12;
      if (model == "cie") {
        const double t = ctx.number(v["cie_type"], at(p, "cie_type"));
        if (!(t >= 1.0 && t <= 15.0 && t == std::floor(t))) ctx.fail(at(p, "cie_type"), "expected a type 1-15");
        type = static_cast<int>(t);
      }
      // Types 1, 3 and 5 have no indicatrix (c = 0, e = 0): no sun needed.
      const bool needs_sun = type != 1 && type != 3 && type != 5;
      if (needs_sun && !sun_dir) ctx.fail(p, "this sky's luminance follows the sun: give \"sun\" with its position");
      sky.sky = std::make_shared<const CieSky>(CieSky::general(type, sun_dir.value_or(glm::dvec3(0.0, 0.0, 1.0))));
    } else {
      ctx.fail(at(p, "model"),
               "unknown sky \"" + model + "\" (expected \"overcast\", \"clear\", \"uniform\" or \"cie\")");
    }
  } catch (const InvalidArgument& e) {
    ctx.fail(p, e.what());
  }
  // Its level: zenith luminance (cd/m^2) or horizontal illuminance (lx), or their radiometric
  // counterparts; the sky emits L_z * radianceIntegral * pi r^2 into the sphere.
  const char* level = nullptr;
  for (const char* key : {"zenith_luminance", "horizontal_illuminance", "zenith_radiance", "horizontal_irradiance"})
    if (v.contains(key)) {
      if (level)
        ctx.fail(p, std::string("a sky has one of \"zenith_luminance\", \"horizontal_illuminance\", "
                                "\"zenith_radiance\" or \"horizontal_irradiance\"; \"") +
                        key + "\" is not the only one");
      level = key;
    }
  if (!level)
    ctx.fail(p,
             "a sky needs its level: \"zenith_luminance\" (cd/m^2) or \"horizontal_illuminance\" (lx), "
             "or \"zenith_radiance\" (W/(m^2 sr)) or \"horizontal_irradiance\" (W/m^2)");
  const std::string_view lv(level);
  const double value = ctx.positiveNumber(v[level], at(p, level));
  const double zenith = lv.starts_with("horizontal") ? value / sky.sky->horizontalIntegral() : value;
  const double power = zenith * sky.sky->radianceIntegral() * std::numbers::pi * sky.radius * sky.radius;
  const bool photometric = lv == "zenith_luminance" || lv == "horizontal_illuminance";
  if (photometric) sky.lumens = power;
  else sky.power_w = power;
  if (v.contains("spectrum"))
    sky.spectrum = v["spectrum"].is_object() ? namedBandValues(v["spectrum"], at(p, "spectrum"), ctx, bands)
                                             : numbers(v["spectrum"], at(p, "spectrum"), ctx);
  std::vector<Light> out{sky};
  // The sun: a directional light of the direct normal illuminance across its beam, covering the
  // same sphere from one radius upstream.
  if (sun && (sun->contains("normal_illuminance") || sun->contains("normal_irradiance"))) {
    if (sun->contains("normal_illuminance") && sun->contains("normal_irradiance"))
      ctx.fail(ps, "the sun has \"normal_illuminance\" (lx) or \"normal_irradiance\" (W/m^2), not both");
    const bool lx = sun->contains("normal_illuminance");
    const char* key = lx ? "normal_illuminance" : "normal_irradiance";
    Light s;
    s.type = LightType::Directional;
    s.name = sky.name + "/sun";
    s.direction = -*sun_dir;
    s.position = sky.position + sky.radius * *sun_dir;
    s.radius = sky.radius;
    const double e = ctx.positiveNumber((*sun)[key], at(ps, key)) * std::numbers::pi * s.radius * s.radius;
    if (lx) s.lumens = e;
    else s.power_w = e;
    s.spectrum = sky.spectrum;
    out.push_back(s);
  }
  for (const Light& l : out) try {
      l.validate();
    } catch (const InvalidArgument& e) {
      ctx.fail(p, e.what());
    }
  return out;
}

// `bands`: the scene's band names, which per-band values may use as keys ({"red": 0.9, ...}).
Material readMaterial(const json& v, const std::string& p, const ObjectSpecContext& ctx,
                      const std::vector<std::string>& bands) {
  if (!v.is_object()) ctx.fail(p, "expected a material (an object with \"type\")");
  return Material::read(MaterialReader(v, p, ctx, bands));
}

}  // namespace

MaterialReader::MaterialReader(const json& v, std::string pointer, const ObjectSpecContext& ctx,
                               const std::vector<std::string>& bands)
    : v_(&v), pointer_(std::move(pointer)), ctx_(&ctx), bands_(&bands) {}

void MaterialReader::onlyKeys(std::initializer_list<std::string_view> allowed) const {
  ctx_->onlyKeys(*v_, pointer_, allowed);
}

bool MaterialReader::has(const char* key) const { return v_->contains(key); }

double MaterialReader::number(const char* key) const {
  return ctx_->number(ctx_->member(*v_, pointer_, key), at(pointer_, key));
}

double MaterialReader::positiveNumber(const char* key) const {
  return ctx_->positiveNumber(ctx_->member(*v_, pointer_, key), at(pointer_, key));
}

std::string MaterialReader::string(const char* key) const {
  return ctx_->string(ctx_->member(*v_, pointer_, key), at(pointer_, key));
}

BandValue MaterialReader::perBand(const char* key, double hi) const {
  const json& x = ctx_->member(*v_, pointer_, key);
  const std::string p = at(pointer_, key);
  const std::vector<double> values =
      x.is_object() ? namedBandValues(x, p, *ctx_, *bands_)
                    : (x.is_array() ? numbers(x, p, *ctx_) : std::vector<double>{ctx_->number(x, p)});
  double sum = 0.0;
  for (std::size_t k = 0; k < values.size(); ++k) {
    if (!(values[k] >= 0.0 && values[k] <= hi))
      ctx_->fail(x.is_array()    ? at(p, k)
                 : x.is_object() ? at(p, (*bands_)[k])
                                 : p,
                 std::string("expected ") + (key[0] == 'a' ? "an " : "a ") + key +
                     (hi == 1.0 ? " in [0, 1]" : " >= 0 (finite)"));
    sum += values[k];
  }
  // The mean, for messages; per-band values are one per band of the scene.
  const double mean = sum / static_cast<double>(values.size());
  if (!x.is_array() && !x.is_object()) return BandValue(mean);
  if (values.size() != std::max<std::size_t>(1, bands_->size()))
    ctx_->fail(p, std::to_string(values.size()) + " per-band values, the scene has " +
                      (bands_->empty() ? std::string("no \"bands\"") : std::to_string(bands_->size()) + " bands"));
  return BandValue(mean, values);
}

MaterialReader MaterialReader::child(const char* key) const {
  const json& x = ctx_->member(*v_, pointer_, key);
  if (!x.is_object()) ctx_->fail(at(pointer_, key), std::string("expected an object (\"") + key + "\")");
  return MaterialReader(x, at(pointer_, key), *ctx_, *bands_);
}

void MaterialReader::fail(std::string_view key, const std::string& problem) const {
  ctx_->fail(key.empty() ? pointer_ : at(pointer_, key), problem);
}

SensorScene SensorScene::load(const std::filesystem::path& path, const SceneDocumentOptions& options,
                              const ObjectTypeRegistry& registry) {
  auto doc = std::make_unique<SceneDocument>(loadSceneDocument(path, registry, options));
  const json& root = *doc->parsed;
  ObjectSpecContext ctx;
  ctx.scene_file = path;
  ctx.strict = doc->format != "scene-json-v1";
  ctx.cache = std::make_shared<SceneLoadCache>();
  SceneGraph& graph = *doc->graph;

  std::vector<std::string> bands;
  std::vector<std::array<double, 2>> band_nm;
  if (root.contains("bands")) {
    const json& list = root["bands"];
    if (!list.is_array() || list.empty()) ctx.fail("/bands", "expected a non-empty array of band names");
    if (list.size() > 256) ctx.fail("/bands", std::to_string(list.size()) + " bands, at most 256");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string p = at("/bands", i);
      // A name, or {"name": N, "nm": [lo, hi]}: wavelengths for every band or for none.
      if (list[i].is_object()) {
        ctx.onlyKeys(list[i], p, {"name", "nm"});
        bands.push_back(ctx.string(ctx.member(list[i], p, "name"), at(p, "name")));
        const json& nm = ctx.member(list[i], p, "nm");
        if (!nm.is_array() || nm.size() != 2) ctx.fail(at(p, "nm"), "expected [lo, hi] in nm");
        const double lo = ctx.number(nm[0], at(at(p, "nm"), 0)), hi = ctx.number(nm[1], at(at(p, "nm"), 1));
        if (!(lo > 0.0 && lo < hi)) ctx.fail(at(p, "nm"), "expected wavelengths 0 < lo < hi in nm");
        band_nm.push_back({lo, hi});
      } else {
        bands.push_back(ctx.string(list[i], p));
      }
      if (band_nm.size() != (band_nm.empty() ? 0 : i + 1))
        ctx.fail(p, "either every band has wavelengths (\"nm\") or none");
      for (std::size_t j = 0; j < i; ++j)
        if (bands[j] == bands[i] || bands[i].empty())
          ctx.fail(at("/bands", i), "band names must be non-empty and distinct");
    }
  }
  // Materials by object (file order = library order of the "objects" entries).
  std::vector<Material> materials(graph.library().size());
  const json& objects = root["objects"];
  for (std::size_t i = 0; i < objects.size() && i < doc->objects.size(); ++i)
    if (objects[i].contains("material"))
      materials[doc->objects[i]] = readMaterial(objects[i]["material"], at(at("/objects", i), "material"), ctx, bands);

  // Objects declared by "add_object" edits may carry a material too (applied once they are instanced).
  if (root.contains("edits"))
    for (const SceneEdit& e : doc->edits)
      if (e.kind == SceneEditKind::AddObject && e.object < materials.size()) {
        const json& entry = root["edits"][std::stoul(e.pointer.substr(std::string("/edits/").size()))]["add_object"];
        if (entry.is_object() && entry.contains("material"))
          materials[e.object] =
              readMaterial(entry["material"], at(at(e.pointer, "add_object"), "material"), ctx, bands);
      }

  // Instances' own materials: scene-json-v1 "instances" entries, duplex-scene-v1 instance nodes
  // (doc->instances lists them depth first in file order, as the walk below meets them).
  std::vector<std::pair<NodeId, Material>> instance_materials;
  std::size_t instance_index = 0;
  auto instanceMaterial = [&](const json& entry, const std::string& p) {
    if (instance_index >= doc->instances.size()) return;
    const NodeId node = doc->instances[instance_index++];
    if (entry.is_object() && entry.contains("material"))
      instance_materials.emplace_back(node, readMaterial(entry["material"], at(p, "material"), ctx, bands));
  };
  if (doc->format == "scene-json-v1") {
    if (root.contains("instances") && root["instances"].is_array())
      for (std::size_t i = 0; i < root["instances"].size(); ++i)
        instanceMaterial(root["instances"][i], at("/instances", i));
  } else if (root.contains("nodes") && root["nodes"].is_array()) {
    auto walk = [&](auto&& self, const json& list, const std::string& p) -> void {
      for (std::size_t i = 0; i < list.size(); ++i) {
        const json& n = list[i];
        if (!n.is_object()) continue;
        if (n.contains("instance")) instanceMaterial(n, at(p, i));
        else if (n.contains("children") && n["children"].is_array())
          self(self, n["children"], at(at(p, i), "children"));
      }
    };
    walk(walk, root["nodes"], "/nodes");
  }

  auto bandCount = [&](const std::vector<double>& values, const std::string& p) {
    if (!values.empty() && values.size() != std::max<std::size_t>(1, bands.size()))
      ctx.fail(p, std::to_string(values.size()) + " per-band values, the scene has " +
                      (bands.empty() ? std::string("no \"bands\"") : std::to_string(bands.size()) + " bands"));
  };
  std::vector<Light> lights;
  if (root.contains("lights")) {
    const json& list = root["lights"];
    if (!list.is_array()) ctx.fail("/lights", "expected an array of lights");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const json& e = list[i];
      if (e.is_object() && e.contains("type") && e["type"] == "sky") {
        for (Light& l : readSky(e, at("/lights", i), ctx, bands)) lights.push_back(std::move(l));
      } else {
        lights.push_back(readLight(e, at("/lights", i), ctx, graph, bands));
      }
      bandCount(lights.back().spectrum, at(at("/lights", i), "spectrum"));
    }
  }

  std::vector<FarFieldSensor> far_field;
  if (root.contains("sensors")) {
    const json& list = root["sensors"];
    if (!list.is_array()) ctx.fail("/sensors", "expected an array of sensors");
    std::uint64_t bins_so_far = 0;  // of the sensors before this one
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string p = at("/sensors", i);
      const json& e = list[i];
      ObjectSpecContext sctx = ctx;
      sctx.pointer = p;
      const SensorSpec spec = readSensorSpec(e, sctx, {"name", "transform"}, /*allow_far_field=*/true);
      const std::string name = ctx.string(ctx.member(e, p, "name"), at(p, "name"));
      if (name.empty()) ctx.fail(at(p, "name"), "expected a non-empty sensor name");
      // Every sensor object keeps its bins' areas: their sum over the list so far against the
      // memory limit (each object checks its own too).
      bins_so_far += std::uint64_t{spec.nx} * spec.ny;
      std::ostringstream what;
      what << path.string() << ": " << p << ": sensor '" << name << "' (" << spec.nx << " x " << spec.ny << " bins";
      if (i > 0) what << "; " << bins_so_far << " bins with the sensors listed before it";
      what << ")";
      requireMemory(arrayBytes(bins_so_far, sizeof(double)), what.str());
      const Affine world =
          e.contains("transform") ? transform12(e["transform"], at(p, "transform"), ctx) : Affine::identity();
      if (spec.shape == SensorShape::FarField) {  // not in the graph: it records the rays leaving the scene
        if (!SensorScene::isSimilarity(world.linear) || !(std::abs(glm::determinant(world.linear) - 1.0) < 1e-9) ||
            world.translation != glm::dvec3(0.0))
          ctx.fail(at(p, "transform"), "a far-field sensor's transform must be a rotation (no translation, no scale)");
        for (const FarFieldSensor& f : far_field)
          if (f.name == name) ctx.fail(at(p, "name"), "two sensors named '" + name + "'");
        far_field.push_back({name, std::make_shared<const SensorObject>(name, spec), world});
        continue;
      }
      if (spec.shape == SensorShape::Sphere && !SensorScene::isSimilarity(world.linear))
        ctx.fail(at(p, "transform"), "a sphere sensor's transform must be a rotation with uniform scale");
      try {
        const ObjectId id = graph.library().add("sensors/" + name, std::make_shared<const SensorObject>(name, spec));
        (void)graph.addInstance(kRootNode, id, world, name);
      } catch (const InvalidArgument& ex) {
        ctx.fail(p, ex.what());
      }
    }
    (void)graph.commit();
  }
  // Illuminance meters: {"name", "points": [[x, y, z], ...], "normal": [x, y, z] (all points) or
  // "normals": [[x, y, z], ...] (one per point)}, world space.
  std::vector<PointMeter> meters;
  if (root.contains("meters")) {
    const json& list = root["meters"];
    if (!list.is_array()) ctx.fail("/meters", "expected an array of meters");
    for (std::size_t i = 0; i < list.size(); ++i) {
      const std::string p = at("/meters", i);
      const json& e = list[i];
      if (!e.is_object()) ctx.fail(p, "expected an object");
      ctx.onlyKeys(e, p, {"name", "points", "normal", "normals", "half_angle", "camera"});
      PointMeter m;
      m.name = ctx.string(ctx.member(e, p, "name"), at(p, "name"));
      if (e.contains("camera")) {
        // A pinhole camera: {"eye", "target", "up" (default +z), "fov" (vertical, degrees), "pixels": [w, h]}.
        if (e.contains("points") || e.contains("normal") || e.contains("normals") || e.contains("half_angle"))
          ctx.fail(p, "a camera meter has \"camera\" and no \"points\", \"normal(s)\" or \"half_angle\"");
        const std::string q = at(p, "camera");
        const json& c = e["camera"];
        if (!c.is_object()) ctx.fail(q, "expected {\"eye\", \"target\", \"up\", \"fov\", \"pixels\"}");
        ctx.onlyKeys(c, q, {"eye", "target", "up", "fov", "pixels"});
        const glm::dvec3 eye = vec3(ctx.member(c, q, "eye"), at(q, "eye"), ctx);
        const glm::dvec3 target = vec3(ctx.member(c, q, "target"), at(q, "target"), ctx);
        const glm::dvec3 up = c.contains("up") ? direction(c["up"], at(q, "up"), ctx) : glm::dvec3(0, 0, 1);
        const double fov = ctx.number(ctx.member(c, q, "fov"), at(q, "fov"));
        const json& px = ctx.member(c, q, "pixels");
        if (!px.is_array() || px.size() != 2 || !px[0].is_number_unsigned() || !px[1].is_number_unsigned() ||
            px[0].get<std::uint64_t>() == 0 || px[1].get<std::uint64_t>() == 0 ||
            px[0].get<std::uint64_t>() * px[1].get<std::uint64_t>() > (std::uint64_t{1} << 24))
          ctx.fail(at(q, "pixels"), "expected [width, height], positive integers, at most 2^24 pixels");
        requireMemory(arrayBytes(px[0].get<std::uint64_t>() * px[1].get<std::uint64_t>(), 3 * sizeof(glm::dvec3)),
                      path.string() + ": " + q + ": camera pixels");
        try {
          m = pinholeMeter(m.name, eye, target, up, fov * std::numbers::pi / 180.0,
                           static_cast<std::uint32_t>(px[0].get<std::uint64_t>()),
                           static_cast<std::uint32_t>(px[1].get<std::uint64_t>()));
        } catch (const InvalidArgument& ex) {
          ctx.fail(q, ex.what());
        }
        meters.push_back(std::move(m));
        continue;
      }
      const json& pts = ctx.member(e, p, "points");
      if (!pts.is_array() || pts.empty()) ctx.fail(at(p, "points"), "expected a non-empty array of [x, y, z]");
      requireMemory(arrayBytes(pts.size(), 2 * sizeof(glm::dvec3)), path.string() + ": " + p + ": meter points");
      for (std::size_t k = 0; k < pts.size(); ++k) m.points.push_back(vec3(pts[k], at(at(p, "points"), k), ctx));
      if (e.contains("normal") == e.contains("normals"))
        ctx.fail(p, "expected \"normal\" (one for all points) or \"normals\" (one per point)");
      if (e.contains("normal")) {
        m.normals.assign(m.points.size(), direction(e["normal"], at(p, "normal"), ctx));
      } else {
        const json& ns = e["normals"];
        if (!ns.is_array() || ns.size() != pts.size())
          ctx.fail(at(p, "normals"), "expected one [x, y, z] per point (" + std::to_string(pts.size()) + ")");
        for (std::size_t k = 0; k < ns.size(); ++k) m.normals.push_back(direction(ns[k], at(at(p, "normals"), k), ctx));
      }
      if (e.contains("half_angle")) {  // a luminance meter: the cone about each normal, degrees
        const double deg = ctx.number(e["half_angle"], at(p, "half_angle"));
        if (!(deg > 0.0 && deg <= 90.0)) ctx.fail(at(p, "half_angle"), "expected a half-angle in (0, 90] degrees");
        m.half_angle = deg * std::numbers::pi / 180.0;
      }
      meters.push_back(std::move(m));
    }
  }
  try {
    SensorScene scene(graph, std::move(lights), std::move(materials), std::move(bands), std::move(far_field),
                      std::move(band_nm), std::move(instance_materials));
    scene.setMeters(std::move(meters));
    scene.doc_ = std::move(doc);  // the graph lives in the document (a stable address)
    return scene;
  } catch (const InvalidArgument& ex) {
    ctx.fail("", ex.what());  // names the object, light or sensor
  }
}

}  // namespace duplex
