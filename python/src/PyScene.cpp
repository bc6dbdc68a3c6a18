#include "PyScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/MemoryLimit.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/objects/MeshLoader.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/objects/MeshTypes.h>
#include <duplex/objects/VolumeObject.h>
#include <duplex/sensors/SensorTypes.h>

#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <new>
#include <sstream>

namespace duplex::python {

namespace {

// Exclusive access for an edit, with the GIL released while waiting (see the file comment).
template <class F>
auto exclusive(WriterPreferringMutex& mutex, F&& f) {
  py::gil_scoped_release nogil;
  std::unique_lock lock(mutex);
  return f();
}

template <class F>
auto shared(WriterPreferringMutex& mutex, F&& f) {
  py::gil_scoped_release nogil;
  std::shared_lock lock(mutex);
  return f();
}

py::array_t<double> vec3(const glm::dvec3& v) {
  py::array_t<double> a(3);
  double* p = a.mutable_data();
  p[0] = v.x;
  p[1] = v.y;
  p[2] = v.z;
  return a;
}

py::array_t<double> matrix3x4(const Affine& t) {
  py::array_t<double> a(std::vector<py::ssize_t>{3, 4});
  const std::array<double, 12> rows = t.toRowMajor3x4();
  std::copy(rows.begin(), rows.end(), a.mutable_data());
  return a;
}

py::array_t<std::uint32_t> nodeArray(const std::vector<NodeId>& nodes) {
  py::array_t<std::uint32_t> a(static_cast<py::ssize_t>(nodes.size()));
  std::copy(nodes.begin(), nodes.end(), a.mutable_data());
  return a;
}

// Rays of the generators in the Python layout [ox, oy, oz, dx, dy, dz, tnear, tfar].
py::array pythonRays(const std::vector<Ray>& rays, std::vector<py::ssize_t> shape) {
  py::array_t<float> out(withAxis(std::move(shape), 8));
  float* p = out.mutable_data();
  for (const Ray& r : rays) {
    *p++ = r.origin.x;
    *p++ = r.origin.y;
    *p++ = r.origin.z;
    *p++ = r.dir.x;
    *p++ = r.dir.y;
    *p++ = r.dir.z;
    *p++ = r.tnear;
    *p++ = r.tfar;
  }
  return out;
}

VolumeKind volumeKind(const std::optional<std::string>& kind) {
  if (!kind || *kind == "auto") return VolumeKind::Auto;
  if (*kind == "levelset" || *kind == "level_set") return VolumeKind::LevelSet;
  if (*kind == "fog") return VolumeKind::Fog;
  throw InvalidArgument("kind: expected None, \"auto\", \"levelset\" or \"fog\", got \"" + *kind + "\"");
}

// Vertex positions from a float32 or float64 (N, 3) array, rounded to float32 (object space).
std::vector<glm::vec3> positionsFrom(const py::object& obj) {
  const FloatRows rows = floatRows(obj, {3}, "positions");
  if (rows.shape.size() != 1) throw InvalidArgument("positions: expected a (N, 3) array");
  std::vector<glm::vec3> out(rows.rows);
  for (std::size_t i = 0; i < rows.rows; ++i)
    out[i] = {static_cast<float>(rows.at(i, 0)), static_cast<float>(rows.at(i, 1)), static_cast<float>(rows.at(i, 2))};
  return out;
}

std::vector<TriangleMesh::Triangle> trianglesFrom(const py::object& obj, std::size_t vertex_count) {
  const py::array a = asArray(obj, "triangles");
  if (a.dtype().kind() != 'i' && a.dtype().kind() != 'u')
    throw InvalidArgument("triangles: dtype " + py::str(a.dtype()).cast<std::string>() +
                          " is not an integer type (expected vertex indices)");
  const std::vector<py::ssize_t> lead = leadingShape(a, {3}, "triangles");
  if (lead.size() != 1) throw InvalidArgument("triangles: expected a (M, 3) array");
  const auto idx = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(a);
  const std::int64_t* p = idx.data();
  std::vector<TriangleMesh::Triangle> out(static_cast<std::size_t>(lead[0]));
  for (std::size_t t = 0; t < out.size(); ++t) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::int64_t v = p[3 * t + k];
      if (v < 0 || static_cast<std::uint64_t>(v) >= vertex_count)
        throw InvalidArgument("triangles: triangle " + std::to_string(t) + " has vertex index " + std::to_string(v) +
                              ", outside [0, " + std::to_string(vertex_count) + ")");
      out[t][k] = static_cast<std::uint32_t>(v);
    }
  }
  return out;
}

}  // namespace

PendingPolicy pendingPolicy(const std::string& name) {
  if (name == "commit") return PendingPolicy::Commit;
  if (name == "raise") return PendingPolicy::Raise;
  if (name == "snapshot") return PendingPolicy::Snapshot;
  throw InvalidArgument("pending: expected \"commit\", \"raise\" or \"snapshot\", got \"" + name + "\"");
}

PyScene::PyScene(PendingPolicy pending)
    : graph_(std::make_unique<SceneGraph>()), tracer_(std::make_unique<SceneTracer>(*graph_)), pending_(pending) {}

PyScene::PyScene(SceneDocument doc, PendingPolicy pending)
    : graph_(std::move(doc.graph)), pending_(pending), format_(doc.format), file_(doc.file.string()) {
  {
    py::gil_scoped_release nogil;
    tracer_ = std::make_unique<SceneTracer>(*graph_);
  }
  for (const NodeId node : doc.instances) noteInstance(node);
  committed_instances_ = instances_.size();
}

PyScene::~PyScene() = default;

std::unique_ptr<PyScene> PyScene::load(const std::filesystem::path& path, const std::string& structure,
                                       PendingPolicy pending) {
  SceneDocumentOptions options;
  options.structure = structure;
  std::optional<SceneDocument> doc;
  {
    py::gil_scoped_release nogil;
    try {
      doc.emplace(loadSceneDocument(path, sensorTypeRegistry(), options));
    } catch (const Error&) {
      throw;  // names the file
    } catch (const std::bad_alloc&) {
      throw;
    } catch (const std::exception& e) {  // e.g. the JSON library's out_of_range for 1e999
      throw FileError(path.string() + ": " + e.what());
    }
  }
  return std::unique_ptr<PyScene>(new PyScene(std::move(*doc), pending));
}

std::string PyScene::pending() const {
  switch (pending_) {
    case PendingPolicy::Commit: return "commit";
    case PendingPolicy::Raise: return "raise";
    case PendingPolicy::Snapshot: return "snapshot";
  }
  return "commit";
}

std::vector<std::string> PyScene::pendingEdits() const {
  std::shared_lock lock(mutex_);
  std::vector<std::string> out = pending_log_;
  if (pending_count_ > out.size()) out.push_back("... " + std::to_string(pending_count_ - out.size()) + " more");
  return out;
}

void PyScene::noteEdit(std::string call) {
  // Called under the exclusive lock, after the edit succeeded.
  constexpr std::size_t kShown = 8;
  if (pending_log_.size() < kShown) pending_log_.push_back(std::move(call));
  ++pending_count_;
}

void PyScene::beforeQuery() const {
  if (pending_ != PendingPolicy::Snapshot) {
    bool pending = false;
    {
      py::gil_scoped_release nogil;
      std::shared_lock lock(mutex_);
      pending = graph_->hasPendingEdits();
    }
    if (pending && pending_ == PendingPolicy::Raise) {
      std::string calls;
      for (const std::string& c : pendingEdits()) calls += (calls.empty() ? "" : ", ") + c;
      throw InvalidArgument("the scene has edits that no commit() applied yet (" + calls +
                            "); call commit() before querying (Scene(pending=\"commit\") does it for you)");
    }
    if (pending) {
      exclusive(mutex_, [&] {
        // Another thread may have committed between the two locks.
        if (graph_->hasPendingEdits()) graph_->commit();
        committed_instances_ = instances_.size();
        pending_log_.clear();
        pending_count_ = 0;
      });
    }
  }
  if (!warned_no_instances_) {
    bool empty = false;
    {
      std::shared_lock lock(mutex_);
      empty = graph_->library().count() > 0 && instances_.empty();
    }
    if (empty) {
      warned_no_instances_ = true;
      if (PyErr_WarnEx(PyExc_UserWarning,
                       "duplex.Scene: the library has objects but the scene has no instance of them, so every "
                       "query misses; place them with add_instance(object_id)",
                       1) != 0)
        throw py::error_already_set();
    }
  }
}

void PyScene::noteInstance(NodeId node) {
  if (node >= id_of_node_.size()) id_of_node_.resize(std::size_t{node} + 1, kInvalidId);
  id_of_node_[node] = static_cast<std::uint32_t>(instances_.size());
  instances_.push_back(node);
}

std::string PyScene::uniqueName(const std::string& base) const {
  const ObjectLibrary& library = graph_->library();
  if (!base.empty() && !library.find(base)) return base;
  const std::string stem = base.empty() ? "object" : base;
  for (std::size_t k = library.size();; ++k) {
    std::string name = stem;
    name += '#';
    name += std::to_string(k);
    if (!library.find(name)) return name;
  }
}

py::array_t<std::uint32_t> PyScene::instanceIds(const std::vector<NodeId>& nodes) const {
  std::vector<std::uint32_t> ids;
  ids.reserve(nodes.size());
  for (const NodeId n : nodes) ids.push_back(idOf(n));
  std::sort(ids.begin(), ids.end());
  py::array_t<std::uint32_t> a(static_cast<py::ssize_t>(ids.size()));
  std::copy(ids.begin(), ids.end(), a.mutable_data());
  return a;
}

// ---- objects ----

ObjectId PyScene::addMeshObject(TriangleMesh mesh, const std::optional<std::string>& name, const std::string& base,
                                const std::string& structure) {
  const MeshBuildConfig config = parseMeshStructureChoice(structure.empty() ? "bvh" : structure);
  py::gil_scoped_release nogil;
  auto object = std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(std::move(mesh)), config);
  std::unique_lock lock(mutex_);
  return graph_->library().add(name && !name->empty() ? *name : uniqueName(base), std::move(object));
}

ObjectId PyScene::addMesh(const PositionsArray& positions, const TrianglesArray& triangles,
                          const std::optional<std::string>& name, const std::string& structure, int nthreads) {
  std::vector<glm::vec3> p = positionsFrom(positions);
  std::vector<TriangleMesh::Triangle> t = trianglesFrom(triangles, p.size());
  const std::string mesh_name = name && !name->empty() ? *name : "mesh";
  if (nthreads < 0) throw InvalidArgument("nthreads must be >= 0 (0: all hardware threads)");
  ObjectId id = 0;
  // The build runs in an arena of nthreads workers; the GIL is released inside addMeshObject.
  withThreads(nthreads, [&] {
    id = addMeshObject(TriangleMesh::fromTriangles(std::move(p), std::move(t), mesh_name), name, "mesh", structure);
  });
  return id;
}

ObjectId PyScene::loadMesh(const std::filesystem::path& path, const std::optional<std::string>& name,
                           const std::string& structure) {
  TriangleMesh mesh = [&] {
    py::gil_scoped_release nogil;
    return duplex::loadMesh(path);
  }();
  return addMeshObject(std::move(mesh), name, path.stem().string(), structure);
}

ObjectId PyScene::loadVolume(const std::filesystem::path& path, const std::optional<std::string>& grid,
                             const std::optional<std::string>& kind, const std::optional<std::string>& name) {
  VolumeLoadOptions options;
  options.grid = grid.value_or("");
  options.kind = volumeKind(kind);
  options.name = name.value_or("");
  py::gil_scoped_release nogil;
  std::shared_ptr<const Object> object = VolumeObject::load(path, options);
  std::unique_lock lock(mutex_);
  return graph_->library().add(name && !name->empty() ? *name : uniqueName(object->name()), std::move(object));
}

void PyScene::deformObject(ObjectId object, const PositionsArray& positions) {
  const std::vector<glm::vec3> p = positionsFrom(positions);
  exclusive(mutex_, [&] {
    graph_->deformObject(object, p);
    noteEdit("deform_object(object=" + std::to_string(object) + ")");
  });
}

void PyScene::removeObject(ObjectId object) {
  exclusive(mutex_, [&] {
    graph_->removeObject(object);
    noteEdit("remove_object(object=" + std::to_string(object) + ")");
  });
}

std::size_t PyScene::objectCount() const {
  std::shared_lock lock(mutex_);
  return graph_->library().count();
}

std::optional<ObjectId> PyScene::findObject(const std::string& name) const {
  std::shared_lock lock(mutex_);
  return graph_->library().find(name);
}

// ---- nodes ----

NodeId PyScene::addGroup(const std::optional<NodeId>& parent, const TransformArray& transform,
                         const std::optional<std::string>& name) {
  const bool has_transform = !transform.is_none();
  const Affine local = transformFrom(transform, "transform");
  return exclusive(mutex_, [&] {
    const NodeId p = parent.value_or(kRootNode);
    const NodeId node =
        has_transform ? graph_->addTransform(p, local, name.value_or("")) : graph_->addGroup(p, name.value_or(""));
    noteEdit("add_group() -> node " + std::to_string(node));
    return node;
  });
}

NodeId PyScene::addInstance(ObjectId object, const TransformArray& transform, const std::optional<NodeId>& parent,
                            const std::optional<std::string>& name, std::uint32_t mask) {
  const Affine local = transformFrom(transform, "transform");
  return exclusive(mutex_, [&] {
    const NodeId node = graph_->addInstance(parent.value_or(kRootNode), object, local, name.value_or(""), mask);
    noteInstance(node);
    noteEdit("add_instance(obj=" + std::to_string(object) + ") -> node " + std::to_string(node));
    return node;
  });
}

void PyScene::setTransform(NodeId node, const TransformArray& transform) {
  const Affine local = transformFrom(transform, "T");
  exclusive(mutex_, [&] {
    graph_->setTransform(node, local);
    noteEdit("set_transform(node=" + std::to_string(node) + ")");
  });
}

void PyScene::setVisible(NodeId node, bool visible) {
  exclusive(mutex_, [&] {
    graph_->setVisible(node, visible);
    noteEdit("set_visible(node=" + std::to_string(node) + ")");
  });
}

void PyScene::setMask(NodeId node, std::uint32_t mask) {
  exclusive(mutex_, [&] {
    graph_->setMask(node, mask);
    noteEdit("set_mask(node=" + std::to_string(node) + ")");
  });
}

void PyScene::remove(NodeId node) {
  exclusive(mutex_, [&] {
    graph_->remove(node);
    noteEdit("remove(node=" + std::to_string(node) + ")");
  });
}

py::dict PyScene::commit() {
  const ChangeSet c = exclusive(mutex_, [&] {
    ChangeSet changes = graph_->commit();
    committed_instances_ = instances_.size();
    pending_log_.clear();
    pending_count_ = 0;
    return changes;
  });
  py::dict d;
  d["appeared"] = instanceIds(c.appeared);
  d["disappeared"] = instanceIds(c.disappeared);
  d["moved"] = instanceIds(c.moved);
  d["object_changed"] = instanceIds(c.object_changed);
  d["mask_changed"] = instanceIds(c.mask_changed);
  d["objects_changed"] = nodeArray(c.objects_changed);
  d["commit"] = c.commit;
  return d;
}

void PyScene::rollback() {
  exclusive(mutex_, [&] {
    graph_->rollback();
    pending_log_.clear();
    pending_count_ = 0;
    for (std::size_t i = committed_instances_; i < instances_.size(); ++i) id_of_node_[instances_[i]] = kInvalidId;
    instances_.resize(committed_instances_);
  });
}

// ---- queries ----

py::dict PyScene::castRays(const RaysArray& rays, int nthreads, std::uint32_t mask) const {
  beforeQuery();
  const FloatRows rows = floatRows(rays, {6, 8}, "rays");
  auto t_hit = newArray<float>(rows.shape);
  auto inst = newArray<std::uint32_t>(rows.shape);
  auto prim = newArray<std::uint32_t>(rows.shape);
  auto uvs = newArray<float>(withAxis(rows.shape, 2));
  auto normals = newArray<float>(withAxis(rows.shape, 3));
  float* t = t_hit.mutable_data();
  std::uint32_t* ip = inst.mutable_data();
  std::uint32_t* pp = prim.mutable_data();
  float* uv = uvs.mutable_data();
  float* ng = normals.mutable_data();
  // Streamed block by block: the rays are read from the array and the hits scattered into the
  // result arrays by the worker threads, with no whole-batch copy of either.
  shared(mutex_, [&] {
    withThreads(nthreads, [&] {
      tracer_->intersectBlocks(
          rows.rows, [&](std::size_t first, std::span<Ray> block) { readRays(rows, first, block); },
          [&](std::size_t first, std::span<const Hit> hits) {
            // Misses come back as Hit{} (t = +inf, ids invalid, u = v = 0, ng = 0), so one
            // branch-free pass serves hits and misses alike.
            float* __restrict tt = t + first;
            std::uint32_t* __restrict ii = ip + first;
            std::uint32_t* __restrict pi = pp + first;
            float* __restrict uu = uv + 2 * first;
            float* __restrict nn = ng + 3 * first;
            for (std::size_t k = 0; k < hits.size(); ++k) {
              const Hit& h = hits[k];
              tt[k] = h.t;
              ii[k] = idOf(h.instance_id);
              pi[k] = h.prim_id;
              uu[2 * k] = h.u;
              uu[2 * k + 1] = h.v;
              const float len2 = h.ng.x * h.ng.x + h.ng.y * h.ng.y + h.ng.z * h.ng.z;
              const float scale = len2 > 0.0f ? 1.0f / std::sqrt(len2) : 0.0f;
              nn[3 * k] = h.ng.x * scale;
              nn[3 * k + 1] = h.ng.y * scale;
              nn[3 * k + 2] = h.ng.z * scale;
            }
          },
          mask);
    });
  });
  py::dict d;
  d["t_hit"] = t_hit;
  d["instance_ids"] = inst;
  d["primitive_ids"] = prim;
  d["primitive_uvs"] = uvs;
  d["primitive_normals"] = normals;
  return d;
}

py::array PyScene::testOcclusions(const RaysArray& rays, int nthreads, std::uint32_t mask) const {
  beforeQuery();
  const FloatRows rows = floatRows(rays, {6, 8}, "rays");
  auto out = newArray<bool>(rows.shape);
  // NumPy's bool is one byte holding 0 or 1, as the batch query writes it.
  static_assert(sizeof(bool) == sizeof(std::uint8_t));
  auto* blocked = reinterpret_cast<std::uint8_t*>(out.mutable_data());
  shared(mutex_, [&] {
    withThreads(nthreads, [&] {
      tracer_->occludedBlocks(
          rows.rows, [&](std::size_t first, std::span<Ray> block) { readRays(rows, first, block); },
          [&](std::size_t first, std::span<const std::uint8_t> flags) {
            std::copy(flags.begin(), flags.end(), blocked + first);
          },
          mask);
    });
  });
  return out;
}

py::dict PyScene::listIntersections(const RaysArray& rays, int nthreads, std::uint32_t mask) const {
  beforeQuery();
  const FloatRows rows = floatRows(rays, {6, 8}, "rays");
  std::vector<Hit> hits;
  std::vector<std::size_t> offsets;
  shared(mutex_, [&] {
    withThreads(nthreads, [&] {
      const std::vector<Ray> world_rays = raysFromRows(rows);
      tracer_->intersectAll(world_rays, hits, offsets, mask);
    });
  });
  const auto n = static_cast<py::ssize_t>(hits.size());
  py::array_t<std::int64_t> splits(static_cast<py::ssize_t>(offsets.size()));
  py::array_t<std::int64_t> ray_ids(n);
  py::array_t<float> t_hit(n);
  py::array_t<std::uint32_t> inst(n), prim(n);
  py::array_t<float> uvs(std::vector<py::ssize_t>{n, 2});
  std::int64_t* sp = splits.mutable_data();
  std::int64_t* rp = ray_ids.mutable_data();
  float* tp = t_hit.mutable_data();
  std::uint32_t* ip = inst.mutable_data();
  std::uint32_t* pp = prim.mutable_data();
  float* uv = uvs.mutable_data();
  {
    py::gil_scoped_release nogil;
    for (std::size_t r = 0; r < offsets.size(); ++r) sp[r] = static_cast<std::int64_t>(offsets[r]);
    for (std::size_t r = 0; r + 1 < offsets.size(); ++r)
      for (std::size_t k = offsets[r]; k < offsets[r + 1]; ++k) rp[k] = static_cast<std::int64_t>(r);
    for (std::size_t k = 0; k < hits.size(); ++k) {
      tp[k] = hits[k].t;
      ip[k] = idOf(hits[k].instance_id);
      pp[k] = hits[k].prim_id;
      uv[2 * k] = hits[k].u;
      uv[2 * k + 1] = hits[k].v;
    }
  }
  py::dict d;
  d["ray_splits"] = splits;
  d["ray_ids"] = ray_ids;
  d["t_hit"] = t_hit;
  d["instance_ids"] = inst;
  d["primitive_ids"] = prim;
  d["primitive_uvs"] = uvs;
  return d;
}

py::dict PyScene::computeClosestPoints(const PointsArray& points, const DistanceLimit& max_distance, int nthreads,
                                       std::uint32_t mask) const {
  const FloatRows rows = floatRows(points, {3}, "points");
  beforeQuery();
  // max_distance: None (no limit), a number, or an array that broadcasts to the points' shape.
  py::module_ np = py::module_::import("numpy");
  py::object limit = max_distance.is_none() ? py::object(py::float_(INFINITY)) : py::object(max_distance);
  py::array_t<double, py::array::c_style | py::array::forcecast> limits;
  try {
    limits = np.attr("ascontiguousarray")(
        np.attr("broadcast_to")(np.attr("asarray")(limit, "float64"), py::tuple(py::cast(rows.shape))));
  } catch (const py::error_already_set& e) {
    throw InvalidArgument(std::string("max_distance: does not broadcast to the points' shape (") + e.what() + ")");
  }
  const double* lp = limits.data();
  auto out_points = newArray<double>(withAxis(rows.shape, 3));
  auto distances = newArray<double>(rows.shape);
  auto inst = newArray<std::uint32_t>(rows.shape);
  auto prim = newArray<std::uint32_t>(rows.shape);
  auto normals = newArray<double>(withAxis(rows.shape, 3));
  auto uvs = newArray<double>(withAxis(rows.shape, 2));
  double* op = out_points.mutable_data();
  double* dp = distances.mutable_data();
  std::uint32_t* ip = inst.mutable_data();
  std::uint32_t* pp = prim.mutable_data();
  double* np_ = normals.mutable_data();
  double* up = uvs.mutable_data();
  shared(mutex_, [&] {
    withThreads(nthreads, [&] {
      std::vector<ClosestPointRequest> requests(rows.rows);
      for (std::size_t i = 0; i < rows.rows; ++i) requests[i] = {{rows.at(i, 0), rows.at(i, 1), rows.at(i, 2)}, lp[i]};
      std::vector<ClosestPoint> found(rows.rows);
      tracer_->closestPoints(requests, found, mask);
      for (std::size_t i = 0; i < rows.rows; ++i) {
        const ClosestPoint& c = found[i];
        const bool ok = c.valid();
        for (int k = 0; k < 3; ++k) {
          op[3 * i + k] = ok ? c.point_ws[k] : 0.0;
          np_[3 * i + k] = ok ? c.normal_ws[k] : 0.0;
        }
        for (int k = 0; k < 2; ++k) up[2 * i + k] = ok ? c.uv[k] : 0.0;
        dp[i] = ok ? c.distance : INFINITY;
        ip[i] = ok ? idOf(c.instance_id) : kInvalidId;
        pp[i] = ok ? c.prim_id : kInvalidId;
      }
    });
  });
  py::dict d;
  d["points"] = out_points;
  d["distances"] = distances;
  d["instance_ids"] = inst;
  d["primitive_ids"] = prim;
  d["primitive_normals"] = normals;
  d["primitive_uvs"] = uvs;
  return d;
}

py::dict PyScene::pick(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x, double y,
                       std::uint32_t mask) const {
  beforeQuery();
  struct Found {
    std::vector<SceneHit> hits;
    std::string path;
  };
  const Found found = shared(mutex_, [&] {
    Found f;
    f.hits = tracer_->pick(camera, x, y, width, height, PickMode::Nearest, mask);
    if (!f.hits.empty()) f.path = graph_->path(f.hits.front().instance);
    return f;
  });
  py::dict d;
  const bool hit = !found.hits.empty();
  const SceneHit h = hit ? found.hits.front() : SceneHit{};
  const glm::dvec3 nan(std::nan(""));
  d["hit"] = hit;
  d["t"] = h.hit.t;
  d["instance_id"] = hit ? idOf(h.instance) : kInvalidId;
  d["node"] = hit ? h.instance : kInvalidNode;
  d["node_path"] = nodeArray(h.path);
  d["path"] = found.path;
  d["primitive_id"] = h.hit.prim_id;
  d["uv"] = py::make_tuple(h.hit.u, h.hit.v);
  d["point"] = vec3(hit ? h.position_ws : nan);
  d["normal"] = vec3(hit ? h.normal_ws : nan);
  return d;
}

py::dict PyScene::pickElement(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x,
                              double y, const PickOptions& options) const {
  beforeQuery();
  struct Found {
    ElementPick pick;
    std::string path;
  };
  const Found found = shared(mutex_, [&] {
    Found f;
    f.pick = tracer_->pickElement(camera, x, y, width, height, options);
    if (f.pick.valid()) f.path = graph_->path(f.pick.instance);
    return f;
  });
  const ElementPick& e = found.pick;
  static constexpr const char* kKinds[] = {"none", "vertex", "edge", "face"};
  py::dict d;
  d["kind"] = kKinds[static_cast<int>(e.kind)];
  d["instance_id"] = e.valid() ? idOf(e.instance) : kInvalidId;
  d["node"] = e.instance;
  d["node_path"] = nodeArray(e.path);
  d["path"] = found.path;
  d["primitive_id"] = e.prim_id;
  d["vertex"] = e.vertex;
  d["edge"] = py::make_tuple(e.edge[0], e.edge[1]);
  d["point"] = vec3(e.valid() ? e.point_ws : glm::dvec3(std::nan("")));
  d["distance_px"] = e.distance_px;
  d["depth"] = e.depth;
  return d;
}

py::array PyScene::selectRectangle(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x0,
                                   double y0, double x1, double y1, std::uint32_t mask, RegionMode mode) const {
  beforeQuery();
  const std::vector<NodeId> nodes =
      shared(mutex_, [&] { return tracer_->selectRectangle(camera, x0, y0, x1, y1, width, height, mask, mode); });
  return instanceIds(nodes);
}

py::array PyScene::primaryRays(std::uint32_t width, std::uint32_t height) const {
  const std::vector<Ray> rays = shared(mutex_, [&] {
    const Box bounds = graph_->worldBounds(instances_);
    if (bounds.empty())
      throw InvalidArgument("primary_rays: the scene has no visible instances, so no bounds to aim the camera at");
    std::ostringstream what;
    what << "primary_rays(" << width << ", " << height << ")";
    requireMemory(arrayBytes(std::uint64_t{width} * height, 2 * sizeof(Ray)), what.str());  // the rays and the array
    return duplex::primaryRays(bounds, width, height);
  });
  return pythonRays(rays, {static_cast<py::ssize_t>(height), static_cast<py::ssize_t>(width)});
}

py::array PyScene::randomRays(std::size_t count, std::uint64_t seed) const {
  const std::vector<Ray> rays = shared(mutex_, [&] {
    const Box bounds = graph_->worldBounds(instances_);
    if (bounds.empty())
      throw InvalidArgument("random_rays: the scene has no visible instances, so no bounds to start rays in");
    std::ostringstream what;
    what << "random_rays(" << count << ")";
    requireMemory(arrayBytes(count, 2 * sizeof(Ray)), what.str());  // the rays and the array
    return duplex::randomRays(bounds, count, seed);
  });
  return pythonRays(rays, {static_cast<py::ssize_t>(count)});
}

// ---- introspection ----

py::array PyScene::instances() const {
  std::shared_lock lock(mutex_);
  return nodeArray(instances_);
}

std::uint32_t PyScene::instanceId(NodeId node) const {
  std::shared_lock lock(mutex_);
  const std::uint32_t id = idOf(node);
  if (id == kInvalidId) throw InvalidArgument("instance_id: node " + std::to_string(node) + " is not an instance");
  return id;
}

NodeId PyScene::instanceNode(std::uint32_t id) const {
  std::shared_lock lock(mutex_);
  if (id >= instances_.size())
    throw InvalidArgument("instance_node: no instance " + std::to_string(id) + " (the scene has " +
                          std::to_string(instances_.size()) + ")");
  return instances_[id];
}

std::optional<NodeId> PyScene::find(const std::string& path) const {
  std::shared_lock lock(mutex_);
  return graph_->find(path);
}

std::string PyScene::path(NodeId node) const {
  std::shared_lock lock(mutex_);
  return graph_->path(node);
}

py::dict PyScene::node(NodeId node) const {
  std::shared_lock lock(mutex_);
  const NodeInfo info = graph_->node(node);
  static constexpr const char* kKinds[] = {"group", "transform", "instance"};
  py::dict d;
  d["id"] = info.id;
  d["kind"] = kKinds[static_cast<int>(info.kind)];
  d["parent"] = info.parent == kInvalidNode ? py::object(py::none()) : py::object(py::int_(info.parent));
  d["name"] = std::string(info.name);
  d["path"] = graph_->path(node);
  d["transform"] = matrix3x4(info.local);
  d["visible"] = info.visible;
  d["children"] = nodeArray(graph_->children(node));
  if (info.kind == NodeKind::Instance) {
    d["object"] = info.object;
    d["mask"] = info.mask;
    d["instance_id"] = idOf(node);
    d["world_transform"] = matrix3x4(graph_->worldTransform(node));
  }
  return d;
}

py::object PyScene::bounds() const {
  const Box b = [&] {
    std::shared_lock lock(mutex_);
    return graph_->worldBounds(instances_);
  }();
  if (b.empty()) return py::none();
  py::array_t<double> a(std::vector<py::ssize_t>{2, 3});
  double* p = a.mutable_data();
  for (int k = 0; k < 3; ++k) {
    p[k] = b.lo[k];
    p[3 + k] = b.hi[k];
  }
  return a;
}

}  // namespace duplex::python
