#include "duplex/objects/VolumeTypes.h"

#include "duplex/objects/VolumeObject.h"

#include <nlohmann/json.hpp>

#include <string>

namespace duplex {

using nlohmann::json;

namespace {

// Read by the factory; entries with the same file, grid and kind share one object.
ObjectSpecResult readVolume(const json& spec, const ObjectSpecContext& ctx) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  ctx.onlyKeys(spec, p, {"file", "grid", "kind"});
  const std::filesystem::path file = ctx.resolve(ctx.string(ctx.member(spec, p, "file"), p + "/file"));
  VolumeLoadOptions options;
  if (spec.contains("grid")) {
    options.grid = ctx.string(spec["grid"], p + "/grid");
    if (options.grid.empty()) ctx.fail(p + "/grid", "expected a non-empty grid name");
  }
  if (spec.contains("kind")) {
    const std::string kind = ctx.string(spec["kind"], p + "/kind");
    if (kind == "fog") options.kind = VolumeKind::Fog;
    else if (kind == "levelset") options.kind = VolumeKind::LevelSet;
    else ctx.fail(p + "/kind", "expected \"fog\" or \"levelset\", got \"" + kind + "\"");
  }
  options.name = ctx.object_name;
  const std::string share_key = "volume:" + SceneLoadCache::fileKey(file).string() + "|grid:" + options.grid +
                                "|kind:" + std::string(toString(options.kind));
  return ObjectLibrary::Factory([ctx, file, options, share_key] {
    return ctx.cache->shared(share_key,
                             [&] { return std::shared_ptr<const Object>(VolumeObject::load(file, options)); });
  });
}
}  // namespace

void registerVolumeTypes(ObjectTypeRegistry& registry) {
  registry.add(
      {std::string(VolumeObject::kTypeName), readVolume, /*in_scene_json_v1=*/true, /*accepts_structure=*/false});
}

}  // namespace duplex
