#pragma once
/// \file PyScene.h
/// duplex.Scene: an object library, a scene graph and its tracer in one Python object, with the
/// instance numbering of the tool's hit files.
///
/// Instance ids: instances are numbered in the order they entered the scene (a loaded file's
/// instances first, in the order of SceneDocument::instances: for scene-json-v1 the position in
/// "instances"; then each add_instance()). Removed instances keep their number (never hit). Hits,
/// commits, selections and closest points report instance ids; edits take node ids (what
/// add_group() and add_instance() return, instance_node() gives).
///
/// Threading: every query releases the GIL and holds a shared lock; edits and commits hold the
/// lock exclusively, also with the GIL released, and a waiting edit keeps new queries out
/// (WriterPreferringMutex), so that it never waits for ever. Whoever holds the lock without the
/// GIL never asks for the GIL before releasing it, which rules out a deadlock between the two.
///
/// Pending edits: what a query does when edits wait for a commit is the scene's PendingPolicy
/// (commit them first, raise naming them, or answer from the last commit); see docs/python.md.

#include "Arrays.h"

#include <duplex/accel/WriterPreferringMutex.h>
#include <duplex/objects/TriangleMesh.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <vector>

namespace duplex::python {

/// What a query does when the scene has edits that no commit applied yet.
enum class PendingPolicy {
  Commit,    ///< commit them first (the forgiving default for a single-threaded script)
  Raise,     ///< raise ValueError naming the pending edits
  Snapshot,  ///< answer from the last commit (edits from one thread while others query)
};

/// "commit", "raise" or "snapshot"; InvalidArgument naming the value otherwise.
PendingPolicy pendingPolicy(const std::string& name);

/// The scene behind duplex.Scene (see the file comment).
class PyScene {
 public:
  /// An empty scene.
  explicit PyScene(PendingPolicy pending = PendingPolicy::Commit);
  /// A scene file (scene-json-v1 or duplex-scene-v1, sensors included), built with all threads.
  static std::unique_ptr<PyScene> load(const std::filesystem::path& path, const std::string& structure,
                                       PendingPolicy pending = PendingPolicy::Commit);
  ~PyScene();

  // ---- objects (library ids) ----
  ObjectId addMesh(const PositionsArray& positions, const TrianglesArray& triangles,
                   const std::optional<std::string>& name, const std::string& structure, int nthreads = 0);
  ObjectId loadMesh(const std::filesystem::path& path, const std::optional<std::string>& name,
                    const std::string& structure);
  ObjectId loadVolume(const std::filesystem::path& path, const std::optional<std::string>& grid,
                      const std::optional<std::string>& kind, const std::optional<std::string>& name);
  void deformObject(ObjectId object, const PositionsArray& positions);
  void removeObject(ObjectId object);
  [[nodiscard]] std::size_t objectCount() const;
  [[nodiscard]] std::optional<ObjectId> findObject(const std::string& name) const;

  // ---- nodes (node ids) ----
  NodeId addGroup(const std::optional<NodeId>& parent, const TransformArray& transform,
                  const std::optional<std::string>& name);
  NodeId addInstance(ObjectId object, const TransformArray& transform, const std::optional<NodeId>& parent,
                     const std::optional<std::string>& name, std::uint32_t mask);
  void setTransform(NodeId node, const TransformArray& transform);
  void setVisible(NodeId node, bool visible);
  void setMask(NodeId node, std::uint32_t mask);
  void remove(NodeId node);
  py::dict commit();
  void rollback();

  // ---- queries (world space) ----
  py::dict castRays(const RaysArray& rays, int nthreads, std::uint32_t mask) const;
  py::array testOcclusions(const RaysArray& rays, int nthreads, std::uint32_t mask) const;
  py::dict listIntersections(const RaysArray& rays, int nthreads, std::uint32_t mask) const;
  py::dict computeClosestPoints(const PointsArray& points, const DistanceLimit& max_distance, int nthreads,
                                std::uint32_t mask) const;
  py::dict pick(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x, double y,
                std::uint32_t mask) const;
  py::dict pickElement(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x, double y,
                       const PickOptions& options) const;
  py::array selectRectangle(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, double x0,
                            double y0, double x1, double y1, std::uint32_t mask, RegionMode mode) const;
  /// Rays in the Python layout [ox, oy, oz, dx, dy, dz, tnear, tfar], shaped (height, width, 8).
  py::array primaryRays(std::uint32_t width, std::uint32_t height) const;
  /// Rays in the Python layout, shaped (count, 8).
  py::array randomRays(std::size_t count, std::uint64_t seed) const;

  // ---- introspection ----
  [[nodiscard]] py::array instances() const;
  [[nodiscard]] std::uint32_t instanceId(NodeId node) const;
  [[nodiscard]] NodeId instanceNode(std::uint32_t id) const;
  [[nodiscard]] std::optional<NodeId> find(const std::string& path) const;
  [[nodiscard]] std::string path(NodeId node) const;
  [[nodiscard]] py::dict node(NodeId node) const;
  [[nodiscard]] py::object bounds() const;
  [[nodiscard]] std::string format() const { return format_; }
  [[nodiscard]] std::string file() const { return file_; }
  [[nodiscard]] std::string pending() const;
  /// The edits made since the last commit, as calls ("set_transform(node=3)", ...).
  [[nodiscard]] std::vector<std::string> pendingEdits() const;

 private:
  PyScene(SceneDocument doc, PendingPolicy pending);

  // Run by every query with the GIL held, before it releases it: applies the PendingPolicy and
  // warns once when the library has objects but the scene no instance (every ray would miss).
  void beforeQuery() const;
  // Notes an edit for the messages of PendingPolicy::Raise (kept short: the first few calls).
  void noteEdit(std::string call);

  [[nodiscard]] std::uint32_t idOf(std::uint32_t node) const {
    return node < id_of_node_.size() ? id_of_node_[node] : kInvalidId;
  }
  void noteInstance(NodeId node);
  [[nodiscard]] std::string uniqueName(const std::string& base) const;
  [[nodiscard]] py::array_t<std::uint32_t> instanceIds(const std::vector<NodeId>& nodes) const;
  // Builds `mesh` and adds it under `name`, or a free name made from `base`.
  ObjectId addMeshObject(TriangleMesh mesh, const std::optional<std::string>& name, const std::string& base,
                         const std::string& structure);

  mutable WriterPreferringMutex mutex_;
  std::unique_ptr<SceneGraph> graph_;
  std::unique_ptr<SceneTracer> tracer_;
  std::vector<NodeId> instances_;          // instance id -> node
  std::vector<std::uint32_t> id_of_node_;  // node -> instance id (kInvalidId for other nodes)
  // instances_.size() at the last commit (rollback); mutable: a query may commit (PendingPolicy).
  mutable std::size_t committed_instances_ = 0;
  PendingPolicy pending_ = PendingPolicy::Commit;
  mutable std::vector<std::string> pending_log_;  // edits since the last commit (the first few)
  mutable std::size_t pending_count_ = 0;         // all of them
  mutable bool warned_no_instances_ = false;
  std::string format_;
  std::string file_;
};

}  // namespace duplex::python
