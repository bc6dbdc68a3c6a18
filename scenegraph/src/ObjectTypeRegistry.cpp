#include "duplex/scenegraph/ObjectTypeRegistry.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"
#include "duplex/objects/ProceduralMesh.h"
#include "duplex/objects/VolumeObject.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <cmath>

namespace duplex {

using nlohmann::json;

// ---- SceneLoadCache ----

SceneLoadCache::MeshEntry& SceneLoadCache::meshEntry(const std::filesystem::path& file) {
  // One entry per file however it is spelt ("a/../b.obj", "./b.obj"); read under the first spelling.
  std::error_code ec;
  std::filesystem::path key = std::filesystem::weakly_canonical(file, ec);
  if (ec) key = file;
  std::lock_guard lock(mutex_);
  auto& slot = meshes_[key];
  if (!slot) {
    slot = std::make_unique<MeshEntry>();
    slot->file = file;
  }
  return *slot;
}

void SceneLoadCache::requestMesh(const std::filesystem::path& file) { (void)meshEntry(file); }

std::shared_ptr<const TriangleMesh> SceneLoadCache::mesh(const std::filesystem::path& file) {
  MeshEntry& e = meshEntry(file);
  // OpenMesh's reader runs no TBB work, so waiting in call_once cannot block a nested task.
  std::call_once(e.once, [&] {
    try {
      MeshLoadReport report;
      e.mesh = std::make_shared<const TriangleMesh>(loadMesh(e.file, &report));
      e.complex_edge_warnings = report.complex_edge_warnings;
    } catch (const std::exception& ex) {
      e.error = ex.what();
    }
  });
  if (!e.mesh) throw FileError(e.error);
  return e.mesh;
}

void SceneLoadCache::readRequested() {
  std::vector<std::filesystem::path> files;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [file, entry] : meshes_) files.push_back(file);
  }
  tbb::parallel_for(std::size_t{0}, files.size(), [&](std::size_t i) {
    try {
      (void)mesh(files[i]);
    } catch (const std::exception&) {
      // kept in the entry; thrown to the object that needs the mesh
    }
  });
}

std::shared_ptr<const Object> SceneLoadCache::shared(const std::string& key,
                                                     const std::function<std::shared_ptr<const Object>()>& build) {
  SharedEntry* e;
  {
    std::lock_guard lock(mutex_);
    auto& slot = shared_[key];
    if (!slot) slot = std::make_unique<SharedEntry>();
    e = slot.get();
  }
  std::lock_guard lock(e->mutex);
  // Isolated: while this thread waits inside the build's parallel work it must not pick up another
  // object's task that waits for this same mutex.
  if (!e->object) tbb::this_task_arena::isolate([&] { e->object = build(); });
  return e->object;
}

std::size_t SceneLoadCache::meshFiles() const {
  std::lock_guard lock(mutex_);
  return meshes_.size();
}

std::size_t SceneLoadCache::complexEdgeWarnings() const {
  std::lock_guard lock(mutex_);
  std::size_t n = 0;
  for (const auto& [file, entry] : meshes_) n += entry->complex_edge_warnings;
  return n;
}

// ---- ObjectSpecContext ----

void ObjectSpecContext::fail(const std::string& pointer, const std::string& problem) const {
  throw FileError(scene_file.string() + ": " + (pointer.empty() ? "/" : pointer) + ": " + problem);
}

std::filesystem::path ObjectSpecContext::resolve(const std::string& path) const {
  const std::filesystem::path p(path);
  return p.is_relative() ? scene_file.parent_path() / p : p;
}

const json& ObjectSpecContext::member(const json& obj, const std::string& at, const char* key) const {
  if (!obj.is_object()) fail(at, "expected an object");
  const auto it = obj.find(key);
  if (it == obj.end()) fail(at, std::string("missing key \"") + key + "\"");
  return *it;
}

double ObjectSpecContext::number(const json& v, const std::string& at) const {
  if (!v.is_number()) fail(at, "expected a number");
  const double d = v.get<double>();
  if (!std::isfinite(d)) fail(at, "number is not finite");
  return d;
}

double ObjectSpecContext::positiveNumber(const json& v, const std::string& at) const {
  const double d = number(v, at);
  if (!(d > 0.0)) fail(at, "expected a number > 0");
  return d;
}

std::string ObjectSpecContext::string(const json& v, const std::string& at) const {
  if (!v.is_string()) fail(at, "expected a string");
  return v.get<std::string>();
}

std::vector<double> ObjectSpecContext::positiveSizes(const json& v, const std::string& at, std::size_t n) const {
  if (v.is_number()) return std::vector<double>(n, positiveNumber(v, at));
  if (!v.is_array() || v.size() != n) fail(at, "expected a number or an array of " + std::to_string(n) + " numbers");
  std::vector<double> out;
  for (std::size_t k = 0; k < n; ++k) out.push_back(positiveNumber(v[k], at + "/" + std::to_string(k)));
  return out;
}

void ObjectSpecContext::onlyKeys(const json& obj, const std::string& at,
                                 std::initializer_list<std::string_view> allowed) const {
  if (!strict || !obj.is_object()) return;
  for (const auto& [key, value] : obj.items()) {
    bool known = false;
    for (const std::string_view a : allowed) known = known || key == a;
    if (!known) fail(at + "/" + key, "unknown key \"" + key + "\"");
  }
}

// ---- built-in types ----

namespace {

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
    ctx.cache->requestMesh(file);
    // Entries naming the same file (and the same structure) share one object.
    std::error_code ec;
    auto key = std::filesystem::weakly_canonical(file, ec);
    if (ec) key = file;
    std::string share_key = "mesh:" + key.string();
    if (ctx.structure) share_key += "|structure:" + std::filesystem::weakly_canonical(*ctx.structure, ec).string();
    return ObjectLibrary::Factory([ctx, file, share_key] {
      return ctx.cache->shared(share_key, [&] { return meshObjectFor(ctx.cache->mesh(file), ctx); });
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

// An OpenVDB volume: {"file": PATH.vdb, "grid": G?, "kind": "fog" | "levelset"?} (also a
// scene-json-v1 type). Read by the factory; entries with the same file, grid and kind share one object.
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
  std::error_code ec;
  auto key = std::filesystem::weakly_canonical(file, ec);
  if (ec) key = file;
  const std::string share_key =
      "volume:" + key.string() + "|grid:" + options.grid + "|kind:" + std::string(toString(options.kind));
  return ObjectLibrary::Factory([ctx, file, options, share_key] {
    return ctx.cache->shared(share_key,
                             [&] { return std::shared_ptr<const Object>(VolumeObject::load(file, options)); });
  });
}
}  // namespace

// ---- ObjectTypeRegistry ----

const ObjectTypeRegistry& ObjectTypeRegistry::builtin() {
  static const ObjectTypeRegistry registry = [] {
    ObjectTypeRegistry r;
    r.add({std::string(MeshObject::kTypeName), readMesh, /*in_scene_json_v1=*/true, /*accepts_structure=*/true});
    r.add({"sphere", readSphere, false, false});
    r.add({"box", readBox, false, false});
    r.add({"plane", readPlane, false, false});
    r.add({std::string(VolumeObject::kTypeName), readVolume, /*in_scene_json_v1=*/true, /*accepts_structure=*/false});
    return r;
  }();
  return registry;
}

void ObjectTypeRegistry::add(ObjectTypeInfo info) {
  if (info.name.empty()) throw InvalidArgument("ObjectTypeRegistry::add: empty type name");
  if (info.name == "name" || info.name == "structure")
    throw InvalidArgument("ObjectTypeRegistry::add: '" + info.name +
                          "' is a key of every object entry, not a type name");
  if (!info.reader) throw InvalidArgument("ObjectTypeRegistry::add: type '" + info.name + "' has no reader");
  if (find(info.name)) throw InvalidArgument("ObjectTypeRegistry::add: type '" + info.name + "' is already registered");
  types_.push_back(std::move(info));
}

const ObjectTypeInfo* ObjectTypeRegistry::find(std::string_view name) const {
  for (const auto& t : types_)
    if (t.name == name) return &t;
  return nullptr;
}

std::vector<std::string> ObjectTypeRegistry::names() const {
  std::vector<std::string> out;
  for (const auto& t : types_) out.push_back(t.name);
  return out;
}

}  // namespace duplex
