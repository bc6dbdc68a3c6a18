#include "duplex/sensors/SensorTypes.h"

#include "duplex/objects/BuiltinTypes.h"

#include "duplex/accel/Error.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <vector>

namespace duplex {

using nlohmann::json;

namespace {

std::uint32_t binCount(const json& v, const std::string& p, const ObjectSpecContext& ctx) {
  const double d = ctx.number(v, p);
  if (d < 1.0 || d > 65536.0 || d != std::floor(d)) ctx.fail(p, "expected a bin count (integer in [1, 65536])");
  return static_cast<std::uint32_t>(d);
}

}  // namespace

SensorSpec readSensorSpec(const json& spec, const ObjectSpecContext& ctx,
                          std::initializer_list<std::string_view> extra_keys, bool allow_far_field) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  if (ctx.strict) {
    for (const auto& [key, value] : spec.items()) {
      bool known = key == "shape" || key == "size" || key == "radius" || key == "bins" || key == "two_sided" ||
                   key == "angular_bins";
      for (const std::string_view k : extra_keys) known = known || key == k;
      if (!known) ctx.fail(p + "/" + key, "unknown key \"" + key + "\"");
    }
  }
  SensorSpec s;
  if (spec.contains("shape")) {
    const std::string shape = ctx.string(spec["shape"], p + "/shape");
    if (shape == "rectangle") s.shape = SensorShape::Rectangle;
    else if (shape == "disk") s.shape = SensorShape::Disk;
    else if (shape == "sphere") s.shape = SensorShape::Sphere;
    else if (shape == "farfield" && allow_far_field) s.shape = SensorShape::FarField;
    else if (shape == "farfield")
      ctx.fail(p + "/shape",
               "a \"farfield\" sensor is not an object of the scene: list it in the top-level \"sensors\"");
    else
      ctx.fail(p + "/shape", std::string("expected \"rectangle\", \"disk\", \"sphere\"") +
                                 (allow_far_field ? " or \"farfield\"" : "") + ", got \"" + shape + "\"");
  }
  if (s.shape == SensorShape::FarField) {
    // Directions only: no size, sides or angular bins; "bins" [n_c, n_gamma] (n_gamma >= 2:
    // the grid includes gamma 0 and 180).
    for (const char* key : {"size", "radius", "two_sided", "angular_bins"})
      if (spec.contains(key)) ctx.fail(p + "/" + key, std::string("a far-field sensor takes no \"") + key + "\"");
    const json& b = ctx.member(spec, p, "bins");
    if (!b.is_array() || b.size() != 2) ctx.fail(p + "/bins", "expected [n_c, n_gamma] (C-planes, vertical angles)");
    s.nx = binCount(b[0], p + "/bins/0", ctx);
    s.ny = binCount(b[1], p + "/bins/1", ctx);
    if (s.ny < 2) ctx.fail(p + "/bins/1", "a far-field sensor needs at least 2 vertical angles (0 and 180 degrees)");
    if (static_cast<std::uint64_t>(s.nx) * s.ny > (1u << 26)) ctx.fail(p + "/bins", "more than 2^26 bins");
    return s;
  }
  // Disks and spheres take their radius (the convention of lights and shapes) or, as before, their
  // diameter as "size"; never both.
  if (spec.contains("radius")) {
    if (s.shape == SensorShape::Rectangle)
      ctx.fail(p + "/radius", "a rectangle has no radius: give \"size\" [w, h] (or \"shape\": \"disk\")");
    if (spec.contains("size")) ctx.fail(p + "/radius", "give \"radius\" or \"size\" (the diameter), not both");
    s.width = s.height = 2.0 * ctx.positiveNumber(spec["radius"], p + "/radius");
  } else {
    const std::vector<double> size = ctx.positiveSizes(ctx.member(spec, p, "size"), p + "/size", 2);
    s.width = size[0];
    s.height = size[1];
  }
  if (s.shape != SensorShape::Rectangle && s.width != s.height)
    ctx.fail(p + "/size", std::string("a ") + (s.shape == SensorShape::Disk ? "disk" : "sphere") +
                              " has one diameter: a number or [d, d]");
  if (spec.contains("bins")) {
    const json& b = spec["bins"];
    if (b.is_number()) {
      s.nx = s.ny = binCount(b, p + "/bins", ctx);
    } else {
      if (!b.is_array() || b.size() != 2) ctx.fail(p + "/bins", "expected [nx, ny] (two integers >= 1)");
      s.nx = binCount(b[0], p + "/bins/0", ctx);
      s.ny = binCount(b[1], p + "/bins/1", ctx);
    }
  }
  if (static_cast<std::uint64_t>(s.nx) * s.ny > (1u << 26)) ctx.fail(p + "/bins", "more than 2^26 bins");
  if (spec.contains("two_sided")) {
    if (!spec["two_sided"].is_boolean()) ctx.fail(p + "/two_sided", "expected true or false");
    s.two_sided = spec["two_sided"].get<bool>();
  }
  if (spec.contains("angular_bins")) {  // n_theta, or [n_theta, n_phi]
    const json& a = spec["angular_bins"];
    if (a.is_number()) {
      s.theta_bins = binCount(a, p + "/angular_bins", ctx);
    } else {
      if (!a.is_array() || a.size() != 2)
        ctx.fail(p + "/angular_bins", "expected n_theta or [n_theta, n_phi] (integers >= 1)");
      s.theta_bins = binCount(a[0], p + "/angular_bins/0", ctx);
      s.phi_bins = binCount(a[1], p + "/angular_bins/1", ctx);
    }
    if (static_cast<std::uint64_t>(s.theta_bins) * s.phi_bins > (1u << 20))
      ctx.fail(p + "/angular_bins", "more than 2^20 angular bins");
    if (s.shape == SensorShape::Sphere)
      ctx.fail(p + "/angular_bins", "a sphere takes no angular bins (its bins are directions)");
  }
  return s;
}

void registerSensorTypes(ObjectTypeRegistry& registry) {
  registry.add({std::string(SensorObject::kTypeName),
                [](const json& spec, const ObjectSpecContext& ctx) -> ObjectSpecResult {
                  const SensorSpec s = readSensorSpec(spec, ctx);
                  return std::shared_ptr<const Object>(std::make_shared<const SensorObject>(ctx.object_name, s));
                },
                /*in_scene_json_v1=*/false, /*accepts_structure=*/false});
}

const ObjectTypeRegistry& sensorTypeRegistry() {
  static const ObjectTypeRegistry registry = [] {
    ObjectTypeRegistry r = builtinObjectTypes();
    registerSensorTypes(r);
    return r;
  }();
  return registry;
}

}  // namespace duplex
