#include "duplex/objects/MeshTypes.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <cstdint>
#include <sstream>
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
  cache.addCount("repeated_corner_faces", report.repeated_corner_faces);
  return mesh;
}

// A "deform" edit's file: a mesh of the same triangles as `current`; its positions.
std::vector<glm::vec3> readDeformTarget(const std::filesystem::path& file, const Object& current) {
  const auto* object = dynamic_cast<const MeshObject*>(&current);
  if (!object) throw FileError(file.string() + ": object '" + current.name() + "' is not a mesh");
  const TriangleMesh target = loadMesh(file);
  const TriangleMesh& now = object->mesh();
  std::ostringstream why;
  if (target.positions().size() != now.positions().size() || target.triangleCount() != now.triangleCount()) {
    why << target.positions().size() << " vertices and " << target.triangleCount() << " triangles, expected "
        << now.positions().size() << " and " << now.triangleCount();
  } else {
    for (std::size_t t = 0; t < now.triangleCount() && why.tellp() == 0; ++t)
      if (target.triangles()[t] != now.triangles()[t]) why << "triangle " << t << " has other vertices";
  }
  if (why.tellp() != 0)
    throw FileError(file.string() + ": not the topology of mesh '" + current.name() + "' (" + why.str() + ")");
  return target.positions();
}

MeshBuildConfig parseChoice(std::string_view name, std::string_view params, const KdBuildConfig& kd) {
  MeshBuildConfig config;
  config.kd = kd;
  config.structure = parseMeshStructure(name);
  if (config.structure == MeshStructure::KdTree) {
    if (!params.empty())
      throw InvalidArgument("the kd-tree takes no parameters (\"kdtree:" + std::string(params) + "\")");
  } else if (!params.empty()) {
    config.bvh = BvhBuildConfig::parse(params);
  }
  return config;
}

// The structure an entry builds: its choice, the load's default, or the BVH.
MeshBuildConfig buildConfigOf(const ObjectSpecContext& ctx) {
  if (ctx.structure_name.empty()) return parseChoice("bvh", "", ctx.build);
  try {
    return parseChoice(ctx.structure_name, ctx.structure_params, ctx.build);
  } catch (const InvalidArgument& e) {
    const bool is_default = ctx.structure_pointer == ctx.entry_pointer;
    std::string choice = ctx.structure_name + (ctx.structure_params.empty() ? "" : ":" + ctx.structure_params);
    ctx.fail(ctx.structure_pointer,
             (is_default ? "default structure \"" : "structure \"") + choice + "\": " + e.what());
  }
}

// A mesh object over `mesh`, from the prepared structure when the entry names one, else built.
std::shared_ptr<const Object> meshObjectFor(std::shared_ptr<const TriangleMesh> mesh, const ObjectSpecContext& ctx,
                                            const MeshBuildConfig& config) {
  if (!ctx.structure) return std::make_shared<const MeshObject>(std::move(mesh), config);
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
  const MeshBuildConfig config = buildConfigOf(ctx);
  if (spec.contains("file")) {
    // scene-json-v1: "file" wins over inline arrays; the own format refuses both at once.
    ctx.onlyKeys(spec, p, {"file"});
    const std::filesystem::path file = ctx.resolve(ctx.string(spec["file"], p + "/file"));
    ctx.cache->requestFile<TriangleMesh>(kMeshFileKind, file, readMeshFile);
    // Entries naming the same file and the same structure (prepared file, or structure and build
    // parameters) share one object.
    std::string share_key = "mesh:" + SceneLoadCache::fileKey(file).string();
    if (ctx.structure) {
      share_key += "|structure:" + SceneLoadCache::fileKey(*ctx.structure).string();
    } else if (config.structure == MeshStructure::KdTree) {
      std::ostringstream kd;
      kd << config.kd;
      share_key += "|kdtree:" + kd.str();
    } else {
      share_key += "|" + toString(config);
    }
    return ObjectLibrary::Factory([ctx, file, share_key, config] {
      return ctx.cache->shared(
          share_key, [&] { return meshObjectFor(ctx.cache->file<TriangleMesh>(kMeshFileKind, file), ctx, config); });
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
  return ObjectLibrary::Factory([ctx, config, positions = std::move(positions), indices = std::move(indices)] {
    return meshObjectFor(
        std::make_shared<const TriangleMesh>(TriangleMesh::fromArrays(positions, indices, ctx.object_name)), ctx,
        config);
  });
}

}  // namespace

MeshBuildConfig parseMeshStructureChoice(std::string_view text, const KdBuildConfig& kd) {
  const std::size_t colon = text.find(':');
  if (colon == std::string_view::npos) return parseChoice(text, "", kd);
  return parseChoice(text.substr(0, colon), text.substr(colon + 1), kd);
}

std::string toString(const MeshBuildConfig& config) {
  if (config.structure == MeshStructure::KdTree) return "kdtree";
  return "bvh:" + config.bvh.toString();
}

void registerMeshTypes(ObjectTypeRegistry& registry) {
  registry.add({std::string(MeshObject::kTypeName), readMesh, /*in_scene_json_v1=*/true, /*accepts_structure=*/true,
                /*structure_names=*/{"bvh", "kdtree"}, readDeformTarget});
}

}  // namespace duplex
