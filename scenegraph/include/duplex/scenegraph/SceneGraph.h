#pragma once
/// \file SceneGraph.h
/// The hierarchical scene: groups, transform nodes and object instances, edited in batches and
/// committed at once; observers (the tracer) learn per commit which instances changed.
///
/// Lifecycle: edits (add*, remove, reparent, set*) are validated when called and take effect in
/// the graph at once (getters show them), but world transforms, visibility and observers are
/// brought up to date only by commit(), which turns the pending batch into one ChangeSet. An edit
/// that throws changes nothing. rollback() undoes every edit since the last commit.
///
/// Threading: one thread edits and commits. Observers run inside commit(), on that thread. Const
/// getters may run concurrently with each other but not with edits.
///
/// Spaces: a node's `local` transform maps its own space to its parent's space (parent_from_local);
/// an instance's world transform is the product of the local transforms from the root down to and
/// including the instance (world_from_object), all in double precision.

#include "duplex/accel/Affine.h"
#include "duplex/scenegraph/ChangeSet.h"
#include "duplex/scenegraph/NodeId.h"
#include "duplex/scenegraph/ObjectLibrary.h"

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace duplex {

/// What a scene-graph node is.
enum class NodeKind : std::uint8_t {
  Group,      ///< children only, no transform of its own
  Transform,  ///< children under a local transform
  Instance    ///< an instance of a library object (a leaf)
};

/// A read-only view of one node (as of the edits made so far; world transforms as of the last commit).
struct NodeInfo {
  NodeId id = kInvalidNode;          ///< the node's id
  NodeKind kind = NodeKind::Group;   ///< group, transform node or instance
  NodeId parent = kInvalidNode;      ///< kInvalidNode for the root
  std::string_view name;             ///< valid until the next edit of the graph
  Affine local;                      ///< parent_from_local (identity for groups)
  bool visible = true;               ///< the node's own flag; hidden if it or an ancestor is hidden
  ObjectId object = kInvalidObject;  ///< instances only
  std::uint32_t mask = 0xFFFFFFFFu;  ///< instances only
};

/// The hierarchical scene of groups, transform nodes and instances (see the file comment for the lifecycle, threading
/// and spaces).
class SceneGraph {
 public:
  /// Called by commit() with the batch's ChangeSet.
  using Observer = std::function<void(const ChangeSet&)>;
  /// Handle of a subscription, for unsubscribe().
  using ObserverId = std::uint64_t;

  /// An empty graph (just the root group, named "") over `library` (a new one when null).
  explicit SceneGraph(std::shared_ptr<ObjectLibrary> library = nullptr);
  SceneGraph(const SceneGraph&) = delete;
  SceneGraph& operator=(const SceneGraph&) = delete;

  /// The library whose objects the instances refer to.
  [[nodiscard]] ObjectLibrary& library() { return *library_; }
  /// The library whose objects the instances refer to.
  [[nodiscard]] const ObjectLibrary& library() const { return *library_; }
  /// The library as shared with other graphs or loaders.
  [[nodiscard]] const std::shared_ptr<ObjectLibrary>& sharedLibrary() const { return library_; }

  // ---- edits (pending until commit) ----
  // Names: non-empty, without '/', unique among the parent's children; an empty name is replaced
  // by "<kind><id>" (e.g. "instance17"). Parents must be groups or transform nodes.
  // Transforms must be finite and non-singular. Every error throws InvalidArgument naming the node
  // (by path or id) and the problem, and changes nothing.

  /// Adds a group under `parent`: no transform of its own, its children are placed in `parent`'s space.
  NodeId addGroup(NodeId parent, std::string name = {});
  /// Adds a transform node under `parent` with parent_from_local transform `local`.
  NodeId addTransform(NodeId parent, const Affine& local, std::string name = {});
  /// Instance of library object `object` with its own local transform. The object is built now if it
  /// was deferred (a failed build rejects the edit).
  NodeId addInstance(NodeId parent, ObjectId object, const Affine& local = Affine::identity(), std::string name = {},
                     std::uint32_t mask = 0xFFFFFFFFu);
  /// Removes `node` and its whole subtree (not the root).
  void remove(NodeId node);
  /// Moves `node` (with its subtree) under `new_parent`, keeping its local transform (so its world
  /// transform changes with the new parent's). Rejects cycles and the root.
  void reparent(NodeId node, NodeId new_parent);
  /// Renames `node` (not the root) under the name rules above.
  void rename(NodeId node, std::string name);
  /// Transform and instance nodes only.
  void setTransform(NodeId node, const Affine& local);
  /// Instances only; builds the object if deferred.
  void setObject(NodeId instance, ObjectId object);
  /// Hides or shows a node and (effectively) its subtree.
  void setVisible(NodeId node, bool visible);
  /// Instances only.
  void setMask(NodeId instance, std::uint32_t mask);

  // ---- object edits (pending until commit, like node edits) ----
  /// Replaces library object `object` with `replacement` (a new mesh, another topology, another
  /// type) at the next commit: the library then holds `replacement` under the same id and name,
  /// every visible instance of it in this graph is listed in object_changed, and the object in
  /// objects_changed. A later replacement of the same object in the batch wins; rollback() drops
  /// them. Other graphs sharing the library see the new object only where their own edits touch its
  /// instances. Throws for an unknown or removed id or a null replacement.
  void replaceObject(ObjectId object, std::shared_ptr<const Object> replacement);
  /// replaceObject(object, current->deformed(positions_os)), where `current` is the object as this
  /// batch leaves it (its pending replacement, if any, so that steps of a deformation chain their
  /// refits). positions_os: object space, Object::deformableVertexCount() of them. The new object
  /// is computed now; an error (wrong count, non-finite positions, a type that cannot be deformed)
  /// throws naming the object and changes nothing.
  void deformObject(ObjectId object, std::span<const glm::vec3> positions_os);
  /// The object as this batch leaves it: a pending replacement, or the library's.
  [[nodiscard]] std::shared_ptr<const Object> pendingObject(ObjectId object) const;
  /// Removes library object `object` now (ObjectLibrary::remove), when no instance of this graph
  /// refers to it, neither as committed nor as pending; its pending replacement is dropped. Not an
  /// edit: rollback() does not bring it back. Throws InvalidArgument naming up to five of the
  /// instances that use it (or an unknown or removed id); nothing changes then.
  /// Cost: one pass over the node table.
  void removeObject(ObjectId object);

  /// Whether there are edits since the last commit.
  [[nodiscard]] bool hasPendingEdits() const;
  /// Brings world transforms up to date (only below edited nodes), builds the ChangeSet of the batch,
  /// calls every observer with it (in subscription order) and returns it. With no pending edits,
  /// returns an empty ChangeSet without calling observers; a batch whose net effect on instances is
  /// nil (renames, a transform set to its old value) does the same. An empty ChangeSet carries the
  /// number of the last commit that changed something. An observer that throws does not undo the
  /// commit; the exception propagates after the remaining observers ran.
  /// Throws InvalidArgument, naming the node, when a new world transform (a product of valid local
  /// transforms) overflows or becomes singular; nothing is committed then and the edits stay
  /// pending, to be fixed or rolled back.
  /// Cost: O(edits + nodes below the edited ones + depth per edited node); no scan of the graph,
  /// except one pass over the node table when the batch replaced objects (to find their instances).
  ChangeSet commit();
  /// Undoes every edit since the last commit (children order included). Ids handed out by rolled-back
  /// additions are not reused.
  void rollback();

  // ---- observers ----
  /// `observer` is called on every commit that changed something.
  ObserverId subscribe(Observer observer);
  /// Ends subscription `id` (no effect for an unknown id).
  void unsubscribe(ObserverId id);

  // ---- queries (edits so far; world transforms and visibility as of the last commit) ----
  /// Whether node `id` exists (edits so far).
  [[nodiscard]] bool contains(NodeId id) const;
  /// Throws InvalidArgument for an unknown id.
  [[nodiscard]] NodeInfo node(NodeId id) const;
  /// Children of `id` in insertion order; throws InvalidArgument for an unknown id.
  [[nodiscard]] std::vector<NodeId> children(NodeId id) const;
  /// "/a/b/c" from the root's children down; the root is "/".
  [[nodiscard]] std::string path(NodeId id) const;
  /// Node ids from the root's child down to `id` (the root excluded).
  [[nodiscard]] std::vector<NodeId> pathIds(NodeId id) const;
  /// pathIds as of the last commit, ignoring the pending batch (nodes removed or re-parented since
  /// keep their committed place): what observers and the tracer's hits refer to. Throws
  /// InvalidArgument for a node that did not exist at the last commit (unknown, or added since).
  /// Cost: depth x (1 + pending edits).
  [[nodiscard]] std::vector<NodeId> committedPathIds(NodeId id) const;
  /// The node at `path` ("/" is the root), or nullopt (also for a malformed path: no leading '/', an
  /// empty component, a trailing '/'). One hash look-up per component.
  [[nodiscard]] std::optional<NodeId> find(std::string_view path) const;
  /// world_from_object of an instance (or world_from_local of any node) as of the last commit
  /// (identity for a node added since).
  [[nodiscard]] const Affine& worldTransform(NodeId id) const;
  /// Whether an instance is visible (itself and all ancestors) as of the last commit.
  [[nodiscard]] bool isVisibleInstance(NodeId id) const;
  /// World box (world units) of those of `instances` that are in the graph and visible as of the
  /// last commit: each one's object bounds through its world transform. Empty when there are none.
  /// Nodes that are not instances of this graph any more (removed) are skipped.
  [[nodiscard]] Box worldBounds(std::span<const NodeId> instances) const;
  /// Every instance node that exists (committed or not), sorted by id.
  [[nodiscard]] std::vector<NodeId> instances() const;
  /// Visible instances as of the last commit, sorted by id (an instance removed since is listed
  /// until the next commit). Scans the node table.
  [[nodiscard]] std::vector<NodeId> visibleInstances() const;
  /// Nodes that exist (edits so far), the root included.
  [[nodiscard]] std::size_t nodeCount() const;
  /// Commits that changed something (the number the last such ChangeSet carries).
  [[nodiscard]] std::uint64_t commitCount() const;
  /// Commits that applied edits, also those whose net effect on instances is nil (a transform node
  /// without instances below it moved, a rename): for layers that read more of the graph than its
  /// instances (lights placed at nodes, node names), which must notice such commits too.
  [[nodiscard]] std::uint64_t revision() const;

  /// Bytes the graph holds per instance node (documented in the README): the node record (local and
  /// committed world transform, links, object, mask, flags, name in the small-string buffer) plus its
  /// entry in the (parent, name) index. Names longer than 15 characters and the pending batch's
  /// transient lists are not counted. A removed node's record is freed by the commit that removes
  /// it (by rollback() for a node added in the batch) and its slot taken by a later node; its id is
  /// never reused and costs 4 bytes for the graph's lifetime.
  [[nodiscard]] static std::size_t bytesPerInstance();
  /// Node records the graph holds: alive nodes, nodes removed in the pending batch, and freed
  /// slots awaiting reuse (at most the largest number of nodes alive at once since creation, plus
  /// a pending batch's removals).
  [[nodiscard]] std::size_t nodeSlots() const;

 private:
  struct Impl;
  std::shared_ptr<ObjectLibrary> library_;
  std::unique_ptr<Impl> impl_;

 public:
  ~SceneGraph();
};

}  // namespace duplex
