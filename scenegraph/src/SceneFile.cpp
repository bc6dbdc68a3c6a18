#include "duplex/scenegraph/SceneFile.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_for.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace duplex {

namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

/// Error reporting with the file and the JSON pointer of the offending value.
struct Context {
  std::filesystem::path file;
  [[noreturn]] void fail(const std::string& pointer, const std::string& problem) const {
    throw FileError(file.string() + ": " + (pointer.empty() ? "/" : pointer) + ": " + problem);
  }
  const json& member(const json& obj, const std::string& pointer, const char* key) const {
    if (!obj.is_object()) fail(pointer, "expected an object");
    const auto it = obj.find(key);
    if (it == obj.end()) fail(pointer, std::string("missing key \"") + key + "\"");
    return *it;
  }
  double number(const json& v, const std::string& pointer) const {
    if (!v.is_number()) fail(pointer, "expected a number");
    const double d = v.get<double>();
    if (!std::isfinite(d)) fail(pointer, "number is not finite");
    return d;
  }
  const json& array(const json& v, const std::string& pointer) const {
    if (!v.is_array()) fail(pointer, "expected an array");
    return v;
  }
  std::string string(const json& v, const std::string& pointer) const {
    if (!v.is_string()) fail(pointer, "expected a string");
    return v.get<std::string>();
  }
};

// An object as read from the file, before meshes are loaded and built.
struct PendingObject {
  std::string name;
  std::string pointer;
  std::filesystem::path file;  // empty for inline meshes
  std::vector<float> positions;
  std::vector<std::uint32_t> indices;
};

}  // namespace

Scene loadScene(const std::filesystem::path& path, const SceneLoadOptions& options, SceneLoadReport* report) {
  const auto t_load = Clock::now();
  const Context ctx{path};
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path.string() + ": cannot open scene file");
  std::stringstream text;
  text << in.rdbuf();
  json doc;
  try {
    doc = json::parse(text.str());
  } catch (const json::exception& e) {
    // parse_error, and out_of_range for numbers such as 1e999
    throw FileError(path.string() + ": not valid JSON (" + e.what() + ")");
  }
  if (!doc.is_object()) ctx.fail("", "expected a JSON object at the top level");
  const std::string format = ctx.string(ctx.member(doc, "", "format"), "/format");
  if (format != "scene-json-v1")
    ctx.fail("/format", "unknown format \"" + format + "\" (this version reads \"scene-json-v1\")");

  // Objects.
  std::vector<PendingObject> pending;
  const json& objects = ctx.array(ctx.member(doc, "", "objects"), "/objects");
  for (std::size_t i = 0; i < objects.size(); ++i) {
    const std::string p = "/objects/" + std::to_string(i);
    PendingObject po;
    po.pointer = p;
    po.name = ctx.string(ctx.member(objects[i], p, "name"), p + "/name");
    const json& mesh = ctx.member(objects[i], p, "mesh");
    if (!mesh.is_object()) ctx.fail(p + "/mesh", "expected an object");
    if (mesh.contains("file")) {
      std::filesystem::path f = ctx.string(mesh["file"], p + "/mesh/file");
      po.file = f.is_relative() ? path.parent_path() / f : f;
    } else if (mesh.contains("positions") || mesh.contains("indices")) {
      const json& pos = ctx.array(ctx.member(mesh, p + "/mesh", "positions"), p + "/mesh/positions");
      const json& idx = ctx.array(ctx.member(mesh, p + "/mesh", "indices"), p + "/mesh/indices");
      po.positions.reserve(pos.size());
      for (std::size_t k = 0; k < pos.size(); ++k)
        po.positions.push_back(static_cast<float>(ctx.number(pos[k], p + "/mesh/positions/" + std::to_string(k))));
      po.indices.reserve(idx.size());
      for (std::size_t k = 0; k < idx.size(); ++k) {
        const std::string ip = p + "/mesh/indices/" + std::to_string(k);
        const double d = ctx.number(idx[k], ip);
        if (d < 0.0 || d > 4294967295.0 || d != std::floor(d)) ctx.fail(ip, "expected a vertex index (integer >= 0)");
        po.indices.push_back(static_cast<std::uint32_t>(d));
      }
    } else {
      ctx.fail(p + "/mesh", "expected \"file\" or \"positions\" and \"indices\"");
    }
    pending.push_back(std::move(po));
  }

  // Read mesh files (each distinct file once) and inline meshes, in parallel.
  std::map<std::filesystem::path, std::size_t> file_slot;
  std::vector<std::filesystem::path> files;
  std::vector<std::size_t> slot_of(pending.size());
  for (std::size_t i = 0; i < pending.size(); ++i) {
    if (pending[i].file.empty()) {
      slot_of[i] = files.size();
      files.emplace_back();
      continue;
    }
    std::error_code ec;
    auto key = std::filesystem::weakly_canonical(pending[i].file, ec);
    if (ec) key = pending[i].file;
    auto [it, inserted] = file_slot.emplace(key, files.size());
    if (inserted) files.push_back(pending[i].file);
    slot_of[i] = it->second;
  }
  std::vector<std::shared_ptr<const TriangleMesh>> meshes(files.size());
  std::vector<MeshLoadReport> reports(files.size());
  std::vector<std::string> errors(files.size());
  std::vector<std::size_t> owner(files.size());
  for (std::size_t i = 0; i < pending.size(); ++i) owner[slot_of[i]] = i;
  tbb::parallel_for(std::size_t(0), files.size(), [&](std::size_t s) {
    const PendingObject& po = pending[owner[s]];
    try {
      if (po.file.empty())
        meshes[s] = std::make_shared<const TriangleMesh>(TriangleMesh::fromArrays(po.positions, po.indices, po.name));
      else
        meshes[s] = std::make_shared<const TriangleMesh>(loadMesh(po.file, &reports[s]));
    } catch (const std::exception& e) {
      errors[s] = e.what();
    }
  });
  for (std::size_t s = 0; s < files.size(); ++s)
    if (!errors[s].empty()) ctx.fail(pending[owner[s]].pointer + "/mesh", errors[s]);
  const double load_ms = msSince(t_load);

  // Bottom-level structures, one per distinct mesh.
  const auto t_build = Clock::now();
  std::vector<std::shared_ptr<const Object>> built(files.size());
  tbb::parallel_for(std::size_t(0), files.size(),
                    [&](std::size_t s) { built[s] = std::make_shared<const MeshObject>(meshes[s], options.build); });
  const double build_ms = msSince(t_build);

  Scene scene;
  for (std::size_t i = 0; i < pending.size(); ++i) {
    try {
      scene.addObject(pending[i].name, built[slot_of[i]]);
    } catch (const InvalidArgument& e) {
      ctx.fail(pending[i].pointer + "/name", e.what());
    }
  }

  const json& instances = ctx.array(ctx.member(doc, "", "instances"), "/instances");
  for (std::size_t i = 0; i < instances.size(); ++i) {
    const std::string p = "/instances/" + std::to_string(i);
    const std::string object_name = ctx.string(ctx.member(instances[i], p, "object"), p + "/object");
    const auto object = scene.findObject(object_name);
    if (!object) ctx.fail(p + "/object", "no object named \"" + object_name + "\"");
    const json& m = ctx.array(ctx.member(instances[i], p, "transform"), p + "/transform");
    if (m.size() != 12) ctx.fail(p + "/transform", "expected 12 numbers (row-major 3x4), got " + std::to_string(m.size()));
    std::array<double, 12> values{};
    for (std::size_t k = 0; k < 12; ++k) values[k] = ctx.number(m[k], p + "/transform/" + std::to_string(k));
    try {
      scene.addInstance(*object, Affine::fromRowMajor3x4(values));
    } catch (const InvalidArgument& e) {
      ctx.fail(p + "/transform", e.what());
    }
  }

  if (report) {
    report->load_ms = load_ms;
    report->build_ms = build_ms;
    report->triangles = report->degenerate_triangles = report->complex_edge_warnings = 0;
    for (std::size_t s = 0; s < files.size(); ++s) {
      report->triangles += meshes[s]->triangleCount();
      report->degenerate_triangles += meshes[s]->degenerateCount();
      report->complex_edge_warnings += reports[s].complex_edge_warnings;
    }
  }
  return scene;
}

}  // namespace duplex
