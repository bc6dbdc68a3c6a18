/// \file SceneGraph.cpp
/// Layout: a flat node table addressed by NodeId (ids are sequential and never reused; the record
/// of a node removed by a commit, or added by a rolled-back batch, is released and its slot taken
/// by a later node: a dead id costs 4 bytes, `SlotTable`), children as intrusive doubly linked sibling lists (O(1) add,
/// remove and re-parent), and one hash index (parent, name) -> node for path lookup and name collisions.
///
/// A batch keeps three lists, so that no edit and no commit scans the whole graph:
/// - the undo log (one record per edit, replayed backwards by rollback());
/// - dirty roots: nodes whose world transform or effective visibility must be recomputed with
///   their subtree (added, moved, re-parented, shown/hidden);
/// - touched instances, each with its committed (visible, object, mask) recorded when the instance
///   is first touched in the batch; the committed world transform stays in the node until commit()
///   overwrites it, which is where "moved" is decided.
/// commit() recomputes the subtrees of the outermost dirty roots, then compares each touched
/// instance with its record: O(edited subtrees + touched instances + depth per dirty root).

#include "duplex/scenegraph/SceneGraph.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/accel/TopLevelMemory.h"
#include "duplex/scenegraph/SceneMemory.h"
#include "SlotTable.h"

#include <algorithm>
#include <exception>
#include <functional>
#include <unordered_map>
#include <utility>

namespace duplex {

namespace {

constexpr std::uint32_t kNotTouched = 0xFFFFFFFFu;

// Node::flags bits.
constexpr std::uint8_t kAlive = 1;       // exists (pending state: cleared by remove() at once)
constexpr std::uint8_t kVisible = 2;     // the node's own flag (pending state)
constexpr std::uint8_t kEffVisible = 4;  // it and all ancestors visible, as of the last commit
constexpr std::uint8_t kDirty = 8;       // listed in dirty_roots

/// One node. Instances, groups and transform nodes share the record (groups keep an identity local).
struct Node {
  Affine local;  ///< parent_from_local (pending state)
  Affine world;  ///< world_from_local as of the last commit
  std::string name;
  NodeId parent = kInvalidNode;
  NodeId first_child = kInvalidNode;
  NodeId last_child = kInvalidNode;
  NodeId prev_sibling = kInvalidNode;
  NodeId next_sibling = kInvalidNode;
  ObjectId object = kInvalidObject;     ///< instances (pending state)
  std::uint32_t mask = 0xFFFFFFFFu;     ///< instances (pending state)
  std::uint32_t touched = kNotTouched;  ///< index in Impl::touched while the instance is in the batch
  NodeKind kind = NodeKind::Group;
  std::uint8_t flags = 0;
};

/// The committed state of an instance, recorded when the batch first touches it.
struct Touched {
  NodeId id;
  ObjectId object;
  std::uint32_t mask;
  bool was_visible;
  bool moved;  ///< set by commit() when the recomputed world transform differs
};

enum class UndoKind : std::uint8_t { Added, Removed, Reparented, Renamed, Transform, Object, Visible, Mask, Replaced };

/// One edit, with what rollback() needs to restore the state before it. Old transforms and names
/// go to their own stacks (Impl::undo_locals, undo_names), popped in the same reverse order, so that
/// a record stays 20 bytes.
struct Undo {
  UndoKind kind;
  NodeId node;
  NodeId parent = kInvalidNode;  ///< Removed, Reparented: old parent
  NodeId prev = kInvalidNode;    ///< Removed, Reparented: old previous sibling (kInvalidNode: first)
  std::uint32_t value = 0;       ///< Object, Mask, Visible: old value
};

const char* kindName(NodeKind k) {
  switch (k) {
    case NodeKind::Group: return "group";
    case NodeKind::Transform: return "transform";
    case NodeKind::Instance: return "instance";
  }
  return "node";
}

/// Room for one more element, growing geometrically (reserve(size() + 1) would copy every time).
template <class V>
void reserveOneMore(V& v) {
  if (v.size() == v.capacity()) v.reserve(2 * v.size() + 16);
}

bool sameAffine(const Affine& a, const Affine& b) {
  for (int c = 0; c < 3; ++c)
    if (a.linear[c] != b.linear[c]) return false;
  return a.translation == b.translation;
}

/// Builds `object` now (deferred objects) so that a failed build rejects the edit. `who()` names
/// the node in the message (built only on failure: edits are on the update path).
template <class Who>
void requireObject(const ObjectLibrary& library, const char* call, const Who& who, ObjectId object) {
  try {
    (void)library.get(object);
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(std::string("SceneGraph::") + call + ": " + who() + ": " + e.what());
  }
}

/// What add*() was asked for.
struct NewNode {
  NodeKind kind;
  Affine local;
  std::string name;
  ObjectId object = kInvalidObject;
  std::uint32_t mask = 0xFFFFFFFFu;
};

}  // namespace

struct SceneGraph::Impl {
  SlotTable<Node> nodes;
  /// (parent, name) hash -> child; collisions resolved by comparing the node's parent and name.
  /// Holds exactly the alive nodes except the root.
  std::unordered_multimap<std::uint64_t, NodeId> name_index;
  std::vector<Undo> undo;
  std::vector<Affine> undo_locals;      // Transform records' old locals, in edit order
  std::vector<std::string> undo_names;  // Renamed records' old names, in edit order
  // Pending object replacements in edit order (one per Replaced record; a later one of the same
  // object wins; removeObject() nulls the replacement and keeps the record).
  std::vector<std::pair<ObjectId, std::shared_ptr<const Object>>> replaced;
  std::vector<NodeId> dirty_roots;
  std::vector<Touched> touched;
  std::vector<NodeId> stack;  // scratch for subtree walks (edits and commit only)
  std::vector<std::pair<ObserverId, Observer>> observers;
  ObserverId next_observer = 1;
  std::uint64_t commits = 0;
  std::uint64_t revision = 0;  // commits that applied edits (changed something or not)
  std::size_t alive = 0;

  // ---- lookups ----
  [[nodiscard]] bool contains(NodeId id) const { return nodes.has(id) && (nodes[id].flags & kAlive) != 0; }

  [[nodiscard]] std::string path(NodeId id) const {
    if (id == kRootNode) return "/";
    std::vector<NodeId> ids;
    for (NodeId n = id; n != kRootNode && n != kInvalidNode; n = nodes[n].parent) ids.push_back(n);
    std::string p;
    for (auto it = ids.rbegin(); it != ids.rend(); ++it) p.append("/").append(nodes[*it].name);
    return p;
  }

  /// "node 12 ('/a/b')" for messages.
  [[nodiscard]] std::string describe(NodeId id) const {
    return std::string(kindName(nodes[id].kind)) + " node " + std::to_string(id) + " ('" + path(id) + "')";
  }

  /// The alive node, or InvalidArgument naming the call and the id.
  const Node& live(NodeId id, const char* call) const {
    if (!contains(id))
      throw InvalidArgument(std::string("SceneGraph::") + call + ": unknown node id " + std::to_string(id));
    return nodes[id];
  }

  static std::uint64_t key(NodeId parent, std::string_view name) {
    return std::hash<std::string_view>{}(name) ^ (std::uint64_t{parent} * 0x9E3779B97F4A7C15ull);
  }

  /// The alive child of `parent` named `name`, or kInvalidNode.
  [[nodiscard]] NodeId child(NodeId parent, std::string_view name) const {
    const auto [b, e] = name_index.equal_range(key(parent, name));
    for (auto it = b; it != e; ++it) {
      const Node& n = nodes[it->second];
      if (n.parent == parent && n.name == name) return it->second;
    }
    return kInvalidNode;
  }

  void indexInsert(NodeId id) { name_index.emplace(key(nodes[id].parent, nodes[id].name), id); }
  void indexErase(NodeId id) {
    const auto [b, e] = name_index.equal_range(key(nodes[id].parent, nodes[id].name));
    for (auto it = b; it != e; ++it)
      if (it->second == id) {
        name_index.erase(it);
        return;
      }
  }

  // ---- sibling lists ----
  /// Inserts `id` into `parent`'s children after `prev` (at the front when prev is kInvalidNode).
  void link(NodeId id, NodeId parent, NodeId prev) {
    Node& n = nodes[id];
    Node& p = nodes[parent];
    n.parent = parent;
    n.prev_sibling = prev;
    n.next_sibling = prev == kInvalidNode ? p.first_child : nodes[prev].next_sibling;
    if (prev == kInvalidNode) p.first_child = id;
    else nodes[prev].next_sibling = id;
    if (n.next_sibling == kInvalidNode) p.last_child = id;
    else nodes[n.next_sibling].prev_sibling = id;
  }
  void unlink(NodeId id) {
    Node& n = nodes[id];
    Node& p = nodes[n.parent];
    if (n.prev_sibling == kInvalidNode) p.first_child = n.next_sibling;
    else nodes[n.prev_sibling].next_sibling = n.next_sibling;
    if (n.next_sibling == kInvalidNode) p.last_child = n.prev_sibling;
    else nodes[n.next_sibling].prev_sibling = n.prev_sibling;
    n.prev_sibling = n.next_sibling = kInvalidNode;
  }

  /// Calls f(id) for `root` and every node below it (pre-order).
  template <class F>
  void forEachInSubtree(NodeId root, F&& f) {
    stack.clear();
    stack.push_back(root);
    while (!stack.empty()) {
      const NodeId id = stack.back();
      stack.pop_back();
      f(id);
      for (NodeId c = nodes[id].first_child; c != kInvalidNode; c = nodes[c].next_sibling) stack.push_back(c);
    }
  }

  // ---- batch bookkeeping ----
  void touch(NodeId id) {
    Node& n = nodes[id];
    if (n.touched != kNotTouched) return;
    n.touched = static_cast<std::uint32_t>(touched.size());
    touched.push_back({id, n.object, n.mask, (n.flags & kEffVisible) != 0, false});
  }
  void markDirty(NodeId id) {
    if (nodes[id].flags & kDirty) return;
    nodes[id].flags |= kDirty;
    dirty_roots.push_back(id);
  }
  /// Ends the batch's bookkeeping (after commit or rollback).
  void clearBatch() {
    for (const Touched& t : touched) nodes[t.id].touched = kNotTouched;
    for (const NodeId r : dirty_roots) nodes[r].flags &= static_cast<std::uint8_t>(~kDirty);
    touched.clear();
    dirty_roots.clear();
    undo.clear();
    undo_locals.clear();
    undo_names.clear();
    replaced.clear();
  }

  /// The latest pending replacement of `object`, or null.
  [[nodiscard]] std::shared_ptr<const Object> pendingReplacement(ObjectId object) const {
    for (auto it = replaced.rbegin(); it != replaced.rend(); ++it)
      if (it->first == object) return it->second;
    return nullptr;
  }

  // ---- validation (before any mutation) ----
  /// The name a node gets: `name`, or "<kind><id>" when empty. Throws when it contains '/' or a
  /// sibling other than `self` already has it.
  std::string checkName(const char* call, NodeId parent, NodeId self, NodeKind kind, std::string name) const {
    if (name.empty()) name = kindName(kind) + std::to_string(self);
    if (name.find('/') != std::string::npos)
      throw InvalidArgument(std::string("SceneGraph::") + call + ": name '" + name + "' of node " +
                            std::to_string(self) + " contains '/'");
    const NodeId other = child(parent, name);
    if (other != kInvalidNode && other != self)
      throw InvalidArgument(std::string("SceneGraph::") + call + ": name '" + name + "' is already used under '" +
                            path(parent) + "' (by node " + std::to_string(other) + ")");
    return name;
  }
  void checkParent(const char* call, NodeId parent) const {
    if (live(parent, call).kind == NodeKind::Instance)
      throw InvalidArgument(std::string("SceneGraph::") + call + ": parent " + describe(parent) +
                            " is an instance; parents must be groups or transform nodes");
  }
  template <class Who>
  static void checkTransform(const char* call, const Who& who, const Affine& local) {
    if (!local.isFinite())
      throw InvalidArgument(std::string("SceneGraph::") + call + ": " + who() + ": transform is not finite");
    if (local.isSingular())
      throw InvalidArgument(std::string("SceneGraph::") + call + ": " + who() + ": transform is singular");
  }

  // ---- edits and commit (defined below) ----
  NodeId add(const ObjectLibrary& library, const char* call, NodeId parent, NewNode nn);
  void undoOne(const Undo& u);
  /// Recomputes world transforms and effective visibility of `root`'s subtree from its parent's.
  void checkWorlds(NodeId root) const;
  void propagate(NodeId root);
  ChangeSet collectChanges(ObjectLibrary& library);
};

SceneGraph::SceneGraph(std::shared_ptr<ObjectLibrary> library)
    : library_(library ? std::move(library) : std::make_shared<ObjectLibrary>()), impl_(std::make_unique<Impl>()) {
  Node root;
  root.flags = kAlive | kVisible | kEffVisible;
  (void)impl_->nodes.push(std::move(root));  // kRootNode
  impl_->alive = 1;
}

SceneGraph::~SceneGraph() = default;

// ---- edits ----

NodeId SceneGraph::Impl::add(const ObjectLibrary& library, const char* call, NodeId parent, NewNode nn) {
  checkParent(call, parent);
  if (nodes.idCount() >= kInvalidNode)
    throw InvalidArgument(std::string("SceneGraph::") + call + ": node ids exhausted");
  const auto id = static_cast<NodeId>(nodes.idCount());
  std::string name = checkName(call, parent, id, nn.kind, std::move(nn.name));
  const auto who = [&] {
    return "new " + std::string(kindName(nn.kind)) + " '" + name + "' under '" + path(parent) + "'";
  };
  if (nn.kind != NodeKind::Group) checkTransform(call, who, nn.local);
  if (nn.kind == NodeKind::Instance) requireObject(library, call, who, nn.object);
  // Valid. Reserve first (geometrically) so that the bookkeeping below cannot fail half-way.
  reserveOneMore(undo);
  reserveOneMore(dirty_roots);
  reserveOneMore(touched);
  nodes.reserveOneMore();
  Node n;
  n.local = nn.local;
  n.name = std::move(name);
  n.kind = nn.kind;
  n.object = nn.object;
  n.mask = nn.mask;
  n.parent = parent;               // the name index key; link() below sets it again
  n.flags = kAlive | kVisible;     // not kEffVisible: it was not visible at the last commit
  (void)nodes.push(std::move(n));  // == id
  try {
    indexInsert(id);
  } catch (...) {
    nodes.popLast();
    throw;
  }
  link(id, parent, nodes[parent].last_child);
  ++alive;
  undo.push_back({UndoKind::Added, id});
  markDirty(id);
  if (nn.kind == NodeKind::Instance) touch(id);
  return id;
}

NodeId SceneGraph::addGroup(NodeId parent, std::string name) {
  return impl_->add(*library_, "addGroup", parent, {NodeKind::Group, Affine::identity(), std::move(name)});
}

NodeId SceneGraph::addTransform(NodeId parent, const Affine& local, std::string name) {
  return impl_->add(*library_, "addTransform", parent, {NodeKind::Transform, local, std::move(name)});
}

NodeId SceneGraph::addInstance(NodeId parent, ObjectId object, const Affine& local, std::string name,
                               std::uint32_t mask) {
  return impl_->add(*library_, "addInstance", parent, {NodeKind::Instance, local, std::move(name), object, mask});
}

void SceneGraph::remove(NodeId node) {
  Impl& m = *impl_;
  m.live(node, "remove");
  if (node == kRootNode) throw InvalidArgument("SceneGraph::remove: the root cannot be removed");
  m.undo.push_back({UndoKind::Removed, node, m.nodes[node].parent, m.nodes[node].prev_sibling});
  m.unlink(node);
  // The whole subtree leaves the graph: its instances are compared at commit (they disappear if
  // they were visible); the name index forgets every node of it.
  m.forEachInSubtree(node, [&m](NodeId id) {
    Node& n = m.nodes[id];
    m.indexErase(id);
    n.flags &= static_cast<std::uint8_t>(~kAlive);
    --m.alive;
    if (n.kind == NodeKind::Instance) m.touch(id);
  });
}

void SceneGraph::reparent(NodeId node, NodeId new_parent) {
  Impl& m = *impl_;
  m.live(node, "reparent");
  if (node == kRootNode) throw InvalidArgument("SceneGraph::reparent: the root cannot be re-parented");
  m.checkParent("reparent", new_parent);
  for (NodeId a = new_parent; a != kInvalidNode; a = m.nodes[a].parent)
    if (a == node)
      throw InvalidArgument("SceneGraph::reparent: moving " + m.describe(node) + " under " + m.describe(new_parent) +
                            " would make a cycle");
  Node& n = m.nodes[node];
  if (const NodeId other = m.child(new_parent, n.name); other != kInvalidNode && other != node)
    throw InvalidArgument("SceneGraph::reparent: " + m.describe(node) + ": name '" + n.name +
                          "' is already used under '" + m.path(new_parent) + "' (by node " + std::to_string(other) +
                          ")");
  m.undo.push_back({UndoKind::Reparented, node, n.parent, n.prev_sibling});
  m.indexErase(node);
  m.unlink(node);
  m.link(node, new_parent, m.nodes[new_parent].last_child);
  m.indexInsert(node);
  m.markDirty(node);
}

void SceneGraph::rename(NodeId node, std::string name) {
  Impl& m = *impl_;
  const Node& n = m.live(node, "rename");
  if (node == kRootNode) throw InvalidArgument("SceneGraph::rename: the root has no name");
  name = m.checkName("rename", n.parent, node, n.kind, std::move(name));
  m.undo_names.push_back(n.name);
  m.undo.push_back({UndoKind::Renamed, node});
  m.indexErase(node);
  m.nodes[node].name = std::move(name);
  m.indexInsert(node);
}

void SceneGraph::setTransform(NodeId node, const Affine& local) {
  Impl& m = *impl_;
  const Node& n = m.live(node, "setTransform");
  if (n.kind == NodeKind::Group)
    throw InvalidArgument("SceneGraph::setTransform: " + m.describe(node) +
                          " is a group; only transform and instance nodes have one");
  Impl::checkTransform(
      "setTransform", [&] { return m.describe(node); }, local);
  m.undo_locals.push_back(n.local);
  m.undo.push_back({UndoKind::Transform, node});
  m.nodes[node].local = local;
  m.markDirty(node);
}

void SceneGraph::setObject(NodeId instance, ObjectId object) {
  Impl& m = *impl_;
  const Node& n = m.live(instance, "setObject");
  if (n.kind != NodeKind::Instance)
    throw InvalidArgument("SceneGraph::setObject: " + m.describe(instance) + " is not an instance");
  requireObject(
      *library_, "setObject", [&] { return m.describe(instance); }, object);
  m.undo.push_back({UndoKind::Object, instance, kInvalidNode, kInvalidNode, n.object});
  m.touch(instance);
  m.nodes[instance].object = object;
}

void SceneGraph::setVisible(NodeId node, bool visible) {
  Impl& m = *impl_;
  const Node& n = m.live(node, "setVisible");
  m.undo.push_back({UndoKind::Visible, node, kInvalidNode, kInvalidNode, (n.flags & kVisible) ? 1u : 0u});
  Node& w = m.nodes[node];
  w.flags = visible ? (w.flags | kVisible) : (w.flags & static_cast<std::uint8_t>(~kVisible));
  m.markDirty(node);
}

void SceneGraph::setMask(NodeId instance, std::uint32_t mask) {
  Impl& m = *impl_;
  const Node& n = m.live(instance, "setMask");
  if (n.kind != NodeKind::Instance)
    throw InvalidArgument("SceneGraph::setMask: " + m.describe(instance) + " is not an instance");
  m.undo.push_back({UndoKind::Mask, instance, kInvalidNode, kInvalidNode, n.mask});
  m.touch(instance);
  m.nodes[instance].mask = mask;
}

// ---- object edits ----

void SceneGraph::replaceObject(ObjectId object, std::shared_ptr<const Object> replacement) {
  Impl& m = *impl_;
  if (!library_->contains(object))
    throw InvalidArgument("SceneGraph::replaceObject: unknown or removed object id " + std::to_string(object));
  if (!replacement)
    throw InvalidArgument("SceneGraph::replaceObject: null replacement for object '" + library_->name(object) + "'");
  reserveOneMore(m.replaced);
  reserveOneMore(m.undo);
  m.replaced.emplace_back(object, std::move(replacement));
  m.undo.push_back({UndoKind::Replaced, kRootNode, kInvalidNode, kInvalidNode, object});
}

std::shared_ptr<const Object> SceneGraph::pendingObject(ObjectId object) const {
  if (auto pending = impl_->pendingReplacement(object)) return pending;
  return library_->get(object);
}

void SceneGraph::deformObject(ObjectId object, std::span<const glm::vec3> positions_os) {
  if (!library_->contains(object))
    throw InvalidArgument("SceneGraph::deformObject: unknown or removed object id " + std::to_string(object));
  std::shared_ptr<const Object> next;
  try {
    next = pendingObject(object)->deformed(positions_os);
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("SceneGraph::deformObject: object '" + library_->name(object) + "': " + e.what());
  }
  replaceObject(object, std::move(next));
}

void SceneGraph::removeObject(ObjectId object) {
  Impl& m = *impl_;
  if (!library_->contains(object))
    throw InvalidArgument("SceneGraph::removeObject: unknown or removed object id " + std::to_string(object));
  // Users: instances that refer to it now, and instances of the batch whose committed object it is.
  std::vector<NodeId> users;
  m.nodes.forEach([&](NodeId id, const Node& n) {
    if (n.kind == NodeKind::Instance && (n.flags & kAlive) && n.object == object) users.push_back(id);
  });
  for (const Touched& t : m.touched)
    if (t.object == object && std::find(users.begin(), users.end(), t.id) == users.end()) users.push_back(t.id);
  if (!users.empty()) {
    std::sort(users.begin(), users.end());
    std::string list;
    for (std::size_t i = 0; i < users.size() && i < 5; ++i) list += (i ? ", " : "") + m.path(users[i]);
    if (users.size() > 5) list += ", ...";
    throw InvalidArgument("SceneGraph::removeObject: object '" + library_->name(object) + "' is used by " +
                          std::to_string(users.size()) + " instance" + (users.size() == 1 ? "" : "s") + " (" + list +
                          "), committed or pending; remove them or give them another object first");
  }
  library_->remove(object);
  for (auto& r : m.replaced)
    if (r.first == object) r.second.reset();
}

// ---- commit and rollback ----

bool SceneGraph::hasPendingEdits() const { return !impl_->undo.empty(); }

void SceneGraph::Impl::propagate(NodeId root) {
  stack.clear();
  stack.push_back(root);
  while (!stack.empty()) {
    const NodeId id = stack.back();
    stack.pop_back();
    Node& n = nodes[id];
    // world_from_local = world_from_parent * parent_from_local (groups: the parent's).
    bool eff = (n.flags & kVisible) != 0;
    Affine world = n.local;
    if (n.parent != kInvalidNode) {
      const Node& p = nodes[n.parent];
      world = n.kind == NodeKind::Group ? p.world : p.world * n.local;
      eff = eff && (p.flags & kEffVisible) != 0;
    }
    if (n.kind == NodeKind::Instance) {
      touch(id);  // records the committed visibility before it is overwritten below
      if (!sameAffine(world, n.world)) touched[n.touched].moved = true;
    }
    n.world = world;
    n.flags = eff ? (n.flags | kEffVisible) : (n.flags & static_cast<std::uint8_t>(~kEffVisible));
    for (NodeId c = n.first_child; c != kInvalidNode; c = nodes[c].next_sibling) stack.push_back(c);
  }
}

void SceneGraph::Impl::checkWorlds(NodeId root) const {
  // The same walk as propagate(), writing nothing: each local transform was checked on its own, but
  // a product of valid transforms can still overflow to inf or lose its determinant to underflow
  // (scales of 1e-200 twice), which the tracer could not invert.
  std::vector<std::pair<NodeId, Affine>> todo;  // (node, world_from_parent)
  const NodeId parent = nodes[root].parent;
  todo.emplace_back(root, parent == kInvalidNode ? Affine::identity() : nodes[parent].world);
  while (!todo.empty()) {
    const auto [id, world_from_parent] = todo.back();
    todo.pop_back();
    const Node& n = nodes[id];
    const Affine world = n.kind == NodeKind::Group ? world_from_parent : world_from_parent * n.local;
    if (n.kind != NodeKind::Group && world.isSingular())
      throw InvalidArgument("SceneGraph::commit: the world transform of " + describe(id) + " is " +
                            (world.isFinite() ? "singular" : "not finite") +
                            " (a product of the transforms on its path); nothing was committed, the edits are still "
                            "pending (fix them or rollback())");
    for (NodeId c = n.first_child; c != kInvalidNode; c = nodes[c].next_sibling) todo.emplace_back(c, world);
  }
}

ChangeSet SceneGraph::Impl::collectChanges(ObjectLibrary& library) {
  // Recompute below the outermost dirty roots only (a root with a dirty ancestor is covered by it).
  std::vector<NodeId> roots;
  for (const NodeId r : dirty_roots) {
    if (!(nodes[r].flags & kAlive)) continue;
    bool covered = false;
    for (NodeId a = nodes[r].parent; a != kInvalidNode && !covered; a = nodes[a].parent)
      covered = (nodes[a].flags & kDirty) != 0;
    if (!covered) roots.push_back(r);
  }
  // Validate every new world transform first, so that a commit that throws changes nothing.
  for (const NodeId r : roots) checkWorlds(r);
  // The replacements that take effect (the latest per object), checked before anything changes.
  std::vector<std::pair<ObjectId, std::shared_ptr<const Object>>> replacements;
  for (auto it = replaced.rbegin(); it != replaced.rend(); ++it) {
    if (!it->second) continue;  // its object was removed
    bool later = false;
    for (const auto& r : replacements) later = later || r.first == it->first;
    if (later) continue;
    if (!library.contains(it->first))
      throw InvalidArgument("SceneGraph::commit: object id " + std::to_string(it->first) +
                            " was removed from the library while its replacement was pending; nothing was committed");
    replacements.emplace_back(it->first, it->second);
  }
  std::sort(replacements.begin(), replacements.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  auto isReplaced = [&replacements](ObjectId id) {
    return std::binary_search(replacements.begin(), replacements.end(),
                              std::make_pair(id, std::shared_ptr<const Object>()),
                              [](const auto& a, const auto& b) { return a.first < b.first; });
  };
  if (!replacements.empty()) {
    // Every instance of a replaced object takes part in the comparison below (it changes object).
    nodes.forEach([&](NodeId id, const Node& n) {
      if (n.kind == NodeKind::Instance && (n.flags & kAlive) && isReplaced(n.object)) touch(id);
    });
    for (auto& [id, object] : replacements) library.replace(id, std::move(object));
  }
  for (const NodeId r : roots) propagate(r);
  // Compare every touched instance with its committed state.
  ChangeSet cs;
  for (const Touched& t : touched) {
    Node& n = nodes[t.id];
    if (!(n.flags & kAlive)) n.flags &= static_cast<std::uint8_t>(~kEffVisible);
    const bool now = (n.flags & kEffVisible) != 0;
    if (t.was_visible != now) {
      (now ? cs.appeared : cs.disappeared).push_back(t.id);
    } else if (now) {
      if (t.moved) cs.moved.push_back(t.id);
      if (t.object != n.object || isReplaced(n.object)) cs.object_changed.push_back(t.id);
      if (t.mask != n.mask) cs.mask_changed.push_back(t.id);
    }
  }
  for (auto* list : {&cs.appeared, &cs.disappeared, &cs.moved, &cs.object_changed, &cs.mask_changed})
    std::sort(list->begin(), list->end());
  for (const auto& r : replacements) cs.objects_changed.push_back(r.first);
  // The nodes removed in this batch are gone for good now: release their records (their ids stay
  // dead). After clearBatch(), which still reads the touched records.
  std::vector<NodeId> dead;
  for (const Undo& u : undo)
    if (u.kind == UndoKind::Removed) forEachInSubtree(u.node, [&dead](NodeId id) { dead.push_back(id); });
  clearBatch();
  for (const NodeId id : dead) nodes.releaseId(id);
  return cs;
}

ChangeSet SceneGraph::commit() {
  Impl& m = *impl_;
  ChangeSet cs;
  if (m.undo.empty()) {
    cs.commit = m.commits;
    return cs;
  }
  cs = m.collectChanges(*library_);
  ++m.revision;
  if (cs.empty()) {
    cs.commit = m.commits;
    return cs;
  }
  cs.commit = ++m.commits;
  logger()->debug(
      "scene graph commit {}: {} appeared, {} disappeared, {} moved, {} object changed, {} mask changed, {} objects "
      "replaced",
      cs.commit, cs.appeared.size(), cs.disappeared.size(), cs.moved.size(), cs.object_changed.size(),
      cs.mask_changed.size(), cs.objects_changed.size());
  // Observers run on a copy of the list, so that one may subscribe or unsubscribe while called.
  const auto observers = m.observers;
  std::exception_ptr first_failure;
  for (const auto& [id, observer] : observers) {
    try {
      observer(cs);
    } catch (...) {
      if (!first_failure) first_failure = std::current_exception();
    }
  }
  if (first_failure) std::rethrow_exception(first_failure);
  return cs;
}

void SceneGraph::Impl::undoOne(const Undo& u) {
  if (u.kind == UndoKind::Replaced) {  // records pair with `replaced` in edit order
    replaced.pop_back();
    return;
  }
  Node& n = nodes[u.node];
  switch (u.kind) {
    case UndoKind::Added:
      indexErase(u.node);
      unlink(u.node);
      n.flags &= static_cast<std::uint8_t>(~kAlive);
      --alive;
      break;
    case UndoKind::Removed:
      link(u.node, u.parent, u.prev);
      forEachInSubtree(u.node, [this](NodeId id) {
        nodes[id].flags |= kAlive;
        ++alive;
        indexInsert(id);
      });
      break;
    case UndoKind::Reparented:
      indexErase(u.node);
      unlink(u.node);
      link(u.node, u.parent, u.prev);
      indexInsert(u.node);
      break;
    case UndoKind::Renamed:
      indexErase(u.node);
      n.name = std::move(undo_names.back());
      undo_names.pop_back();
      indexInsert(u.node);
      break;
    case UndoKind::Transform:
      n.local = undo_locals.back();
      undo_locals.pop_back();
      break;
    case UndoKind::Object: n.object = u.value; break;
    case UndoKind::Mask: n.mask = u.value; break;
    case UndoKind::Visible:
      n.flags = u.value ? (n.flags | kVisible) : (n.flags & static_cast<std::uint8_t>(~kVisible));
      break;
    case UndoKind::Replaced: break;  // handled above
  }
}

void SceneGraph::rollback() {
  Impl& m = *impl_;
  // Edits only changed pending state (world transforms and committed visibility are written by
  // commit() alone), so undoing them in reverse order restores the committed graph exactly,
  // children order included.
  // Nodes added in the batch are gone for good: their records are released (ids not reused).
  std::vector<NodeId> dead;
  dead.reserve(m.undo.size());
  for (auto it = m.undo.rbegin(); it != m.undo.rend(); ++it) {
    m.undoOne(*it);
    if (it->kind == UndoKind::Added) dead.push_back(it->node);
  }
  m.clearBatch();
  for (const NodeId id : dead) m.nodes.releaseId(id);
}

// ---- observers ----

SceneGraph::ObserverId SceneGraph::subscribe(Observer observer) {
  if (!observer) throw InvalidArgument("SceneGraph::subscribe: empty observer");
  const ObserverId id = impl_->next_observer++;
  impl_->observers.emplace_back(id, std::move(observer));
  return id;
}

void SceneGraph::unsubscribe(ObserverId id) {
  auto& obs = impl_->observers;
  obs.erase(std::remove_if(obs.begin(), obs.end(), [id](const auto& o) { return o.first == id; }), obs.end());
}

// ---- queries ----

bool SceneGraph::contains(NodeId id) const { return impl_->contains(id); }

NodeInfo SceneGraph::node(NodeId id) const {
  const Node& n = impl_->live(id, "node");
  NodeInfo info;
  info.id = id;
  info.kind = n.kind;
  info.parent = n.parent;
  info.name = n.name;
  info.local = n.local;
  info.visible = (n.flags & kVisible) != 0;
  info.object = n.object;
  info.mask = n.mask;
  return info;
}

std::vector<NodeId> SceneGraph::children(NodeId id) const {
  const Impl& m = *impl_;
  std::vector<NodeId> out;
  for (NodeId c = m.live(id, "children").first_child; c != kInvalidNode; c = m.nodes[c].next_sibling) out.push_back(c);
  return out;
}

std::string SceneGraph::path(NodeId id) const {
  impl_->live(id, "path");
  return impl_->path(id);
}

std::vector<NodeId> SceneGraph::pathIds(NodeId id) const {
  const Impl& m = *impl_;
  m.live(id, "pathIds");
  std::vector<NodeId> ids;
  for (NodeId n = id; n != kRootNode; n = m.nodes[n].parent) ids.push_back(n);
  std::reverse(ids.begin(), ids.end());
  return ids;
}

std::vector<NodeId> SceneGraph::committedPathIds(NodeId id) const {
  const Impl& m = *impl_;
  if (id == kRootNode) return {};
  // The batch's undo log names every node added, removed or re-parented since the last commit (a
  // removed node keeps its record until the commit); a node's first Removed or Reparented record
  // holds its parent as of the last commit. Linear in the batch per level: picks are rare, batches
  // short, and the common case (no pending edits) is the plain walk.
  const auto addedSince = [&m](NodeId n) {
    return std::any_of(m.undo.begin(), m.undo.end(),
                       [n](const Undo& u) { return u.kind == UndoKind::Added && u.node == n; });
  };
  if (!m.nodes.has(id) || addedSince(id))
    throw InvalidArgument("SceneGraph::committedPathIds: node id " + std::to_string(id) +
                          " did not exist at the last commit");
  const auto committedParent = [&m](NodeId n) {
    for (const Undo& u : m.undo)
      if (u.node == n && (u.kind == UndoKind::Removed || u.kind == UndoKind::Reparented)) return u.parent;
    return m.nodes[n].parent;
  };
  std::vector<NodeId> ids;
  for (NodeId n = id; n != kRootNode; n = committedParent(n)) ids.push_back(n);
  std::reverse(ids.begin(), ids.end());
  return ids;
}

std::optional<NodeId> SceneGraph::find(std::string_view path) const {
  // One hash look-up per path component.
  if (path.empty() || path.front() != '/') return std::nullopt;
  NodeId at = kRootNode;
  std::string_view rest = path.substr(1);
  while (!rest.empty()) {
    const std::size_t slash = rest.find('/');
    const std::string_view component = rest.substr(0, slash);
    if (component.empty()) return std::nullopt;
    at = impl_->child(at, component);
    if (at == kInvalidNode) return std::nullopt;
    if (slash == std::string_view::npos) break;
    rest = rest.substr(slash + 1);
    if (rest.empty()) return std::nullopt;  // trailing '/'
  }
  return at;
}

const Affine& SceneGraph::worldTransform(NodeId id) const { return impl_->live(id, "worldTransform").world; }

bool SceneGraph::isVisibleInstance(NodeId id) const {
  return (impl_->live(id, "isVisibleInstance").flags & kEffVisible) != 0;
}

Box SceneGraph::worldBounds(std::span<const NodeId> instances) const {
  Box bounds;
  for (const NodeId node : instances)
    if (contains(node) && isVisibleInstance(node))
      bounds.extend(worldTransform(node).apply(library().get(this->node(node).object)->bounds()));
  return bounds;
}

namespace {
/// Instance nodes with `flag` set, by id (a scan of the node table: a query, not on the update path).
std::vector<NodeId> instancesWith(const SlotTable<Node>& nodes, std::uint8_t flag) {
  std::vector<NodeId> out;
  nodes.forEach([&](NodeId id, const Node& n) {
    if (n.kind == NodeKind::Instance && (n.flags & flag)) out.push_back(id);
  });
  std::sort(out.begin(), out.end());
  return out;
}
}  // namespace

std::vector<NodeId> SceneGraph::instances() const { return instancesWith(impl_->nodes, kAlive); }

// Committed visibility: an instance removed since the last commit is listed until the next one.
std::vector<NodeId> SceneGraph::visibleInstances() const { return instancesWith(impl_->nodes, kEffVisible); }

std::size_t SceneGraph::nodeCount() const { return impl_->alive; }
std::size_t SceneGraph::nodeSlots() const { return impl_->nodes.slotCount(); }
std::uint64_t SceneGraph::commitCount() const { return impl_->commits; }

std::uint64_t SceneGraph::revision() const { return impl_->revision; }

std::size_t SceneGraph::bytesPerInstance() {
  // The node record, plus one entry of the (parent, name) index: a hash node (next pointer, key,
  // id) and its share of the bucket array at load factor 1. Not counted: names longer than the
  // std::string small-buffer (15 chars; default names like "instance20967" fit) and the batch's
  // transient lists (undo log, touched records), which are empty between commits.
  // The slot table's two id maps (id -> slot, slot -> id) add 4 bytes each.
  constexpr std::size_t index_entry = sizeof(void*) + sizeof(std::pair<const std::uint64_t, NodeId>) + sizeof(void*);
  return sizeof(Node) + index_entry + 2 * sizeof(std::uint32_t);
}

std::uint64_t sceneBytesPerInstance() {
  // An unordered_multimap<uint64_t, NodeId> node (next pointer, pair, cached hash) and its bucket.
  constexpr std::uint64_t kNameIndexEntry = 2 * sizeof(void*) + sizeof(std::pair<std::uint64_t, NodeId>) + 8;
  return sizeof(Node) + 2 * sizeof(std::uint32_t) + kNameIndexEntry + sizeof(Undo) + sizeof(Touched) + sizeof(NodeId) +
         topLevelBytesPerInstance();
}

}  // namespace duplex
