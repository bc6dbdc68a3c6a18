#include "duplex/objects/MeshTypes.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace duplex {

using nlohmann::json;

namespace {

// The scene load reads each mesh file once, in parallel with the others, before any build.
constexpr std::string_view kMeshFileKind = "mesh";

std::shared_ptr<const TriangleMesh> readMeshFile(const std::filesystem::path& file, SceneLoadCache& cache) {
  MeshLoadReport report;
  auto mesh = std::make_shared<const TriangleMesh>(loadMesh(file, &report));
  cache.addCount("complex_edge_warnings", report.complex_edge_warnings);
  return mesh;
}

// A mesh object over `mesh`, from the prepared structure when the entry names one.
std::shared_ptr<const Object> meshObjectFor(std::shared_ptr<const TriangleMesh> mesh, const ObjectSpecContext& ctx) {
  if (!ctx.structure) return std::make_shared<const MeshObject>(std::move(mesh), ctx.build);
  std::shared_ptr<const MeshObject> object;
  try {
    object = loadMeshObject(*ctx.structure, std::move(mesh));
  } catch (const FileError& e) {
    ctx.fail(ctx.entry_pointer + "/structure", e.what());
  }
  ++ctx.cache->structures_loaded;
  return object;
}

ObjectSpecResult readMesh(const json& spec, const ObjectSpecContext& ctx) {
  const std::string& p = ctx.pointer;
  if (!spec.is_object()) ctx.fail(p, "expected an object");
  if (spec.contains("file")) {
    // scene-json-v1: "file" wins over inline arrays; the own format refuses both at once.
    ctx.onlyKeys(spec, p, {"file"});
    const std::filesystem::path file = ctx.resolve(ctx.string(spec["file"], p + "/file"));
    ctx.cache->requestFile<TriangleMesh>(kMeshFileKind, file, readMeshFile);
    // Entries naming the same file (and the same structure) share one object.
    std::string share_key = "mesh:" + SceneLoadCache::fileKey(file).string();
    if (ctx.structure) share_key += "|structure:" + SceneLoadCache::fileKey(*ctx.structure).string();
    return ObjectLibrary::Factory([ctx, file, share_key] {
      return ctx.cache->shared(share_key,
                               [&] { return meshObjectFor(ctx.cache->file<TriangleMesh>(kMeshFileKind, file), ctx); });
    });
  }
  if (!spec.contains("positions") && !spec.contains("indices"))
    ctx.fail(p, "expected \"file\" or \"positions\" and \"indices\"");
  ctx.onlyKeys(spec, p, {"positions", "indices"});
  const json& pos = ctx.member(spec, p, "positions");
  const json& idx = ctx.member(spec, p, "indices");
  if (!pos.is_array()) ctx.fail(p + "/positions", "expected an array");
  if (!idx.is_array()) ctx.fail(p + "/indices", "expected an array");
  std::vector<float> positions;
  positions.reserve(pos.size());
  for (std::size_t k = 0; k < pos.size(); ++k) {
    const std::string pp = p + "/positions/" + std::to_string(k);
    const float v = static_cast<float>(ctx.number(pos[k], pp));
    // Positions are stored as float: a finite double beyond float range would become an infinite
    // vertex and silently a degenerate triangle.
    if (!std::isfinite(v)) ctx.fail(pp, "outside float range");
    positions.push_back(v);
  }
  std::vector<std::uint32_t> indices;
  indices.reserve(idx.size());
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const std::string ip = p + "/indices/" + std::to_string(k);
    const double d = ctx.number(idx[k], ip);
    if (d < 0.0 || d > 4294967295.0 || d != std::floor(d)) ctx.fail(ip, "expected a vertex index (integer >= 0)");
    indices.push_back(static_cast<std::uint32_t>(d));
  }
  // The mesh is validated in the factory, in parallel with the other objects' builds.
  return ObjectLibrary::Factory([ctx, positions = std::move(positions), indices = std::move(indices)] {
    return meshObjectFor(
        std::make_shared<const TriangleMesh>(TriangleMesh::fromArrays(positions, indices, ctx.object_name)), ctx);
  });
}

}  // namespace

void registerMeshTypes(ObjectTypeRegistry& registry) {
  registry.add({std::string(MeshObject::kTypeName), readMesh, /*in_scene_json_v1=*/true, /*accepts_structure=*/true});
}

}  // namespace duplex
