/// \file SceneGraphTest.cpp
/// SceneGraph against a brute-force model: seeded random edit batches (valid and rejected edits,
/// commits and rollbacks); after every edit the pending graph equals the model, after every commit
/// world transforms and visibility equal a from-scratch recomputation and the ChangeSet lists exactly
/// the instances that changed. Plus rejected edits, instances sharing one object, paths and names,
/// observers.

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"

#include "MeshChecks.h"
#include "TestSupport.h"

#include <gtest/gtest.h>

#include <malloc.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

// AddressSanitizer as clang says it (GCC defines __SANITIZE_ADDRESS__).
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define DUPLEX_CLANG_ASAN 1
#endif
#endif
#ifndef DUPLEX_CLANG_ASAN
#define DUPLEX_CLANG_ASAN 0
#endif

namespace duplex {
namespace {

using test::expectErrorNaming;
using test::tinyMeshObject;

bool sameAffine(const Affine& a, const Affine& b) { return a.linear == b.linear && a.translation == b.translation; }

/// A library with three built objects, one deferred object that builds and one that never does.
struct Library {
  std::shared_ptr<ObjectLibrary> lib = std::make_shared<ObjectLibrary>();
  ObjectId failing = kInvalidObject;
  Library() {
    (void)lib->add("o0", tinyMeshObject("o0"));
    (void)lib->add("o1", tinyMeshObject("o1"));
    (void)lib->add("o2", tinyMeshObject("o2"));
    (void)lib->addDeferred("lazy", "mesh", [] { return tinyMeshObject("lazy"); });
    failing =
        lib->addDeferred("broken", "mesh", []() -> std::shared_ptr<const Object> { throw std::runtime_error("no"); });
  }
};

Affine translation(double x, double y, double z) {
  Affine a;
  a.translation = {x, y, z};
  return a;
}

// ---------------------------------------------------------------------------------------------
// The model: the pending graph as plain maps; everything derived is recomputed from scratch.

struct MNode {
  NodeKind kind = NodeKind::Group;
  NodeId parent = kInvalidNode;
  std::string name;
  Affine local;
  bool visible = true;
  ObjectId object = kInvalidObject;
  std::uint32_t mask = 0xFFFFFFFFu;
  std::vector<NodeId> children;
};

struct Committed {
  bool visible;
  Affine world;
  ObjectId object;
  std::uint32_t mask;
};

const char* kindName(NodeKind k) {
  return k == NodeKind::Group ? "group" : k == NodeKind::Transform ? "transform" : "instance";
}

struct Model {
  std::map<NodeId, MNode> nodes{{kRootNode, MNode{}}};
  NodeId next_id = 1;

  [[nodiscard]] bool has(NodeId id) const { return nodes.count(id) != 0; }
  [[nodiscard]] bool isParent(NodeId id) const { return has(id) && nodes.at(id).kind != NodeKind::Instance; }
  [[nodiscard]] bool nameFree(NodeId parent, const std::string& name, NodeId self) const {
    for (const NodeId c : nodes.at(parent).children)
      if (c != self && nodes.at(c).name == name) return false;
    return true;
  }
  /// The name a node gets, or nullopt when it is invalid there.
  [[nodiscard]] std::optional<std::string> finalName(NodeId parent, NodeId self, NodeKind kind,
                                                     std::string name) const {
    if (name.empty()) name = kindName(kind) + std::to_string(self);
    if (name.find('/') != std::string::npos || !nameFree(parent, name, self)) return std::nullopt;
    return name;
  }
  [[nodiscard]] bool isAncestorOrSelf(NodeId a, NodeId n) const {
    for (; n != kInvalidNode; n = nodes.at(n).parent)
      if (n == a) return true;
    return false;
  }
  void detach(NodeId id) {
    auto& siblings = nodes.at(nodes.at(id).parent).children;
    siblings.erase(std::find(siblings.begin(), siblings.end(), id));
  }
  void eraseSubtree(NodeId id) {
    const std::vector<NodeId> children = nodes.at(id).children;
    for (const NodeId c : children) eraseSubtree(c);
    nodes.erase(id);
  }
  [[nodiscard]] std::string path(NodeId id) const {
    if (id == kRootNode) return "/";
    std::string p;
    for (NodeId n = id; n != kRootNode; n = nodes.at(n).parent) p = "/" + nodes.at(n).name + p;
    return p;
  }
  /// From scratch: world = local(root child) * ... * local(instance), groups contributing nothing,
  /// folded from the root down as the graph does; visible = every node on the path visible.
  [[nodiscard]] std::map<NodeId, Committed> evaluate() const {
    std::map<NodeId, Committed> out;
    for (const auto& [id, n] : nodes) {
      if (n.kind != NodeKind::Instance) continue;
      std::vector<NodeId> chain;
      for (NodeId a = id; a != kInvalidNode; a = nodes.at(a).parent) chain.push_back(a);
      Affine world;
      bool visible = true;
      for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
        const MNode& a = nodes.at(*it);
        if (a.kind != NodeKind::Group) world = world * a.local;
        visible = visible && a.visible;
      }
      out[id] = {visible, world, n.object, n.mask};
    }
    return out;
  }
};

/// The ChangeSet a commit must produce, from the committed states before and after.
ChangeSet expectedChanges(const std::map<NodeId, Committed>& before, const std::map<NodeId, Committed>& after) {
  ChangeSet cs;
  std::vector<NodeId> ids;
  for (const auto& [id, c] : before) ids.push_back(id);
  for (const auto& [id, c] : after) ids.push_back(id);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  for (const NodeId id : ids) {
    const auto b = before.find(id);
    const auto a = after.find(id);
    const bool was = b != before.end() && b->second.visible;
    const bool now = a != after.end() && a->second.visible;
    if (was != now) {
      (now ? cs.appeared : cs.disappeared).push_back(id);
    } else if (now) {
      if (!sameAffine(b->second.world, a->second.world)) cs.moved.push_back(id);
      if (b->second.object != a->second.object) cs.object_changed.push_back(id);
      if (b->second.mask != a->second.mask) cs.mask_changed.push_back(id);
    }
  }
  return cs;
}

bool sameChanges(const ChangeSet& a, const ChangeSet& b) {
  return a.appeared == b.appeared && a.disappeared == b.disappeared && a.moved == b.moved &&
         a.object_changed == b.object_changed && a.mask_changed == b.mask_changed;
}

/// Pending state of the graph equals the model: every node's fields, children order, paths, and
/// nothing else exists.
void expectPendingEquals(const SceneGraph& g, const Model& m, const std::string& where) {
  SCOPED_TRACE(where);
  ASSERT_EQ(g.nodeCount(), m.nodes.size());
  std::vector<NodeId> instances;
  for (const auto& [id, n] : m.nodes) {
    ASSERT_TRUE(g.contains(id)) << "node " << id;
    const NodeInfo info = g.node(id);
    EXPECT_EQ(info.kind, n.kind) << "node " << id;
    EXPECT_EQ(info.parent, n.parent) << "node " << id;
    EXPECT_EQ(info.name, n.name) << "node " << id;
    EXPECT_TRUE(sameAffine(info.local, n.local)) << "node " << id;
    EXPECT_EQ(info.visible, n.visible) << "node " << id;
    EXPECT_EQ(g.children(id), n.children) << "node " << id;
    if (n.kind == NodeKind::Instance) {
      EXPECT_EQ(info.object, n.object) << "node " << id;
      EXPECT_EQ(info.mask, n.mask) << "node " << id;
      instances.push_back(id);
    }
    const std::string p = m.path(id);
    EXPECT_EQ(g.path(id), p);
    EXPECT_EQ(g.find(p), std::optional<NodeId>(id)) << p;
  }
  EXPECT_EQ(g.instances(), instances);
  for (NodeId id = 0; id < m.next_id + 3; ++id) EXPECT_EQ(g.contains(id), m.has(id)) << "node " << id;
}

/// Committed state of the graph equals the model's from-scratch evaluation.
void expectCommittedEquals(const SceneGraph& g, const std::map<NodeId, Committed>& eval) {
  std::vector<NodeId> visible;
  for (const auto& [id, c] : eval) {
    EXPECT_TRUE(sameAffine(g.worldTransform(id), c.world))
        << "instance " << id << ": " << g.worldTransform(id) << " vs " << c.world;
    EXPECT_EQ(g.isVisibleInstance(id), c.visible) << "instance " << id;
    if (c.visible) visible.push_back(id);
  }
  EXPECT_EQ(g.visibleInstances(), visible);
}

// ---------------------------------------------------------------------------------------------
// Random edits.

class RandomEdits {
 public:
  RandomEdits(SceneGraph& g, Model& m, const Library& lib, std::uint64_t seed) : g_(g), m_(m), lib_(lib), rng_(seed) {}

  int rejected = 0;
  int applied = 0;

  /// One random edit, applied to both; the graph must throw exactly when the model refuses it.
  void step() {
    const int op = uniform(0, 99);
    if (op < 8) addGroup();
    else if (op < 16) addTransform();
    else if (op < 38) addInstance();
    else if (op < 41 || (op < 50 && m_.nodes.size() > 200)) remove();
    else if (op < 52) reparent();
    else if (op < 66) setTransform();
    else if (op < 74) setObject();
    else if (op < 84) setVisible();
    else if (op < 91) setMask();
    else rename();
  }

 private:
  int uniform(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
  double real(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }

  /// Mostly an existing node; sometimes an id that does not exist (removed, rolled back, never made).
  NodeId anyNode() {
    if (uniform(0, 29) == 0)
      return uniform(0, 1) ? m_.next_id + 5 : static_cast<NodeId>(uniform(0, static_cast<int>(m_.next_id)));
    auto it = m_.nodes.begin();
    std::advance(it, uniform(0, static_cast<int>(m_.nodes.size()) - 1));
    return it->first;
  }
  /// A node of the wanted kind when there is one (parents: groups and transforms).
  NodeId pick(bool want_instance) {
    for (int tries = 0; tries < 8; ++tries) {
      const NodeId id = anyNode();
      if (!m_.has(id) || (m_.nodes.at(id).kind == NodeKind::Instance) == want_instance) return id;
    }
    return anyNode();
  }
  std::string anyName() {
    static const char* const kNames[] = {"", "", "", "", "", "a", "b", "c", "wheel", "door", "lamp", "x/y"};
    return kNames[uniform(0, 11)];
  }
  /// Valid (rotation, scale, translation), or singular, or non-finite.
  std::pair<Affine, bool> anyTransform() {
    Affine a;
    const double ax = real(0, 6.3), ay = real(0, 6.3);
    const glm::dmat3 rx(1, 0, 0, 0, std::cos(ax), std::sin(ax), 0, -std::sin(ax), std::cos(ax));
    const glm::dmat3 ry(std::cos(ay), 0, -std::sin(ay), 0, 1, 0, std::sin(ay), 0, std::cos(ay));
    a.linear = rx * ry * glm::dmat3(real(0.5, 2.0));
    a.translation = {real(-10, 10), real(-10, 10), real(-10, 10)};
    switch (uniform(0, 19)) {
      case 0: a.linear[uniform(0, 2)] = glm::dvec3(0.0); return {a, false};  // singular
      case 1: a.linear[2] = a.linear[0] * 2.0; return {a, false};            // singular, non-zero
      case 2: a.translation[uniform(0, 2)] = std::numeric_limits<double>::quiet_NaN(); return {a, false};
      case 3: a.linear[1][1] = std::numeric_limits<double>::infinity(); return {a, false};
      default: return {a, true};
    }
  }
  ObjectId anyObject() {
    switch (uniform(0, 9)) {
      case 0: return lib_.failing;
      case 1: return 77;  // unknown
      case 2: return 3;   // deferred, builds
      default: return static_cast<ObjectId>(uniform(0, 2));
    }
  }

  template <class F>
  void expectOutcome(bool valid, F&& f, const char* what) {
    if (valid) {
      ASSERT_NO_THROW(f()) << what;
      ++applied;
    } else {
      EXPECT_THROW(f(), InvalidArgument) << what;
      ++rejected;
    }
  }

  void add(NodeKind kind) {
    const NodeId parent = pick(false);
    const std::string name = anyName();
    // Named variables, not a structured binding: the lambda below captures them (clang 14 cannot
    // capture bindings).
    const std::pair<Affine, bool> transform =
        kind == NodeKind::Group ? std::pair{Affine::identity(), true} : anyTransform();
    const Affine& local = transform.first;
    const bool local_ok = transform.second;
    const ObjectId object = kind == NodeKind::Instance ? anyObject() : kInvalidObject;
    const std::uint32_t mask = static_cast<std::uint32_t>(uniform(0, 15));
    std::optional<std::string> final_name;
    if (m_.isParent(parent)) final_name = m_.finalName(parent, m_.next_id, kind, name);
    const bool object_ok = kind != NodeKind::Instance || object < lib_.failing;
    const bool valid = final_name && local_ok && object_ok;
    NodeId got = kInvalidNode;
    expectOutcome(
        valid,
        [&] {
          got = kind == NodeKind::Group       ? g_.addGroup(parent, name)
                : kind == NodeKind::Transform ? g_.addTransform(parent, local, name)
                                              : g_.addInstance(parent, object, local, name, mask);
        },
        "add");
    if (!valid) return;
    ASSERT_EQ(got, m_.next_id);
    MNode n;
    n.kind = kind;
    n.parent = parent;
    n.name = *final_name;
    n.local = local;
    if (kind == NodeKind::Instance) {
      n.object = object;
      n.mask = mask;
    }
    m_.nodes[got] = n;
    m_.nodes.at(parent).children.push_back(got);
    ++m_.next_id;
  }
  void addGroup() { add(NodeKind::Group); }
  void addTransform() { add(NodeKind::Transform); }
  void addInstance() { add(NodeKind::Instance); }

  void remove() {
    const NodeId id = uniform(0, 30) == 0 ? kRootNode : anyNode();
    const bool valid = m_.has(id) && id != kRootNode;
    expectOutcome(
        valid, [&] { g_.remove(id); }, "remove");
    if (!valid) return;
    m_.detach(id);
    m_.eraseSubtree(id);
  }

  void reparent() {
    const NodeId id = uniform(0, 30) == 0 ? kRootNode : anyNode();
    NodeId parent = pick(false);
    // Often aim below the node itself: a cycle that must be refused.
    if (m_.has(id) && uniform(0, 3) == 0) {
      NodeId d = id;
      while (!m_.nodes.at(d).children.empty() && uniform(0, 2) != 0) d = m_.nodes.at(d).children.front();
      parent = d;
    }
    const bool valid = m_.has(id) && id != kRootNode && m_.isParent(parent) && !m_.isAncestorOrSelf(id, parent) &&
                       m_.nameFree(parent, m_.nodes.at(id).name, id);
    expectOutcome(
        valid, [&] { g_.reparent(id, parent); }, "reparent");
    if (!valid) return;
    m_.detach(id);
    m_.nodes.at(id).parent = parent;
    m_.nodes.at(parent).children.push_back(id);
  }

  void rename() {
    const NodeId id = uniform(0, 30) == 0 ? kRootNode : anyNode();
    const std::string name = anyName();
    std::optional<std::string> final_name;
    if (m_.has(id) && id != kRootNode)
      final_name = m_.finalName(m_.nodes.at(id).parent, id, m_.nodes.at(id).kind, name);
    expectOutcome(
        final_name.has_value(), [&] { g_.rename(id, name); }, "rename");
    if (final_name) m_.nodes.at(id).name = *final_name;
  }

  void setTransform() {
    const NodeId id = pick(uniform(0, 1) == 0);
    const std::pair<Affine, bool> transform = anyTransform();
    const Affine& local = transform.first;
    const bool valid = m_.has(id) && m_.nodes.at(id).kind != NodeKind::Group && transform.second;
    expectOutcome(
        valid, [&] { g_.setTransform(id, local); }, "setTransform");
    if (valid) m_.nodes.at(id).local = local;
  }

  void setObject() {
    const NodeId id = pick(true);
    const ObjectId object = anyObject();
    const bool valid = m_.has(id) && m_.nodes.at(id).kind == NodeKind::Instance && object < lib_.failing;
    expectOutcome(
        valid, [&] { g_.setObject(id, object); }, "setObject");
    if (valid) m_.nodes.at(id).object = object;
  }

  void setVisible() {
    const NodeId id = anyNode();
    const bool visible = uniform(0, 2) != 0;
    expectOutcome(
        m_.has(id), [&] { g_.setVisible(id, visible); }, "setVisible");
    if (m_.has(id)) m_.nodes.at(id).visible = visible;
  }

  void setMask() {
    const NodeId id = pick(true);
    const auto mask = static_cast<std::uint32_t>(uniform(0, 3));
    const bool valid = m_.has(id) && m_.nodes.at(id).kind == NodeKind::Instance;
    expectOutcome(
        valid, [&] { g_.setMask(id, mask); }, "setMask");
    if (valid) m_.nodes.at(id).mask = mask;
  }

  SceneGraph& g_;
  Model& m_;
  const Library& lib_;
  std::mt19937_64 rng_;
};

class SceneGraphRandom : public ::testing::TestWithParam<std::uint64_t> {};

TEST_P(SceneGraphRandom, MatchesBruteForceAfterEveryCommit) {
  const Library lib;
  SceneGraph g(lib.lib);
  Model model;
  Model committed_model = model;
  std::map<NodeId, Committed> committed = model.evaluate();
  std::vector<ChangeSet> observed;
  (void)g.subscribe([&observed](const ChangeSet& cs) { observed.push_back(cs); });

  RandomEdits edits(g, model, lib, GetParam());
  std::mt19937_64 rng(GetParam() * 7 + 1);
  int edits_done = 0, commits = 0, rollbacks = 0, nonempty = 0;
  std::size_t max_nodes = 0;
  while (edits_done < 2500) {
    const int batch = std::uniform_int_distribution<int>(1, 14)(rng);
    for (int i = 0; i < batch; ++i, ++edits_done) {
      edits.step();
      if (::testing::Test::HasFatalFailure()) return;
      expectPendingEquals(g, model, "after edit " + std::to_string(edits_done));
      if (::testing::Test::HasFailure()) return;
    }
    max_nodes = std::max(max_nodes, model.nodes.size());
    if (std::uniform_int_distribution<int>(0, 9)(rng) == 0) {
      // Rollback: the graph returns to the last commit (ids are not reused).
      g.rollback();
      ++rollbacks;
      const NodeId next = model.next_id;
      model = committed_model;
      model.next_id = next;
      EXPECT_FALSE(g.hasPendingEdits());
      expectPendingEquals(g, model, "after rollback at edit " + std::to_string(edits_done));
      expectCommittedEquals(g, committed);
      if (::testing::Test::HasFailure()) return;
      continue;
    }
    const std::uint64_t count_before = g.commitCount();
    const std::size_t observed_before = observed.size();
    const ChangeSet cs = g.commit();
    ++commits;
    const auto now = model.evaluate();
    const ChangeSet expected = expectedChanges(committed, now);
    EXPECT_TRUE(sameChanges(cs, expected)) << "edit " << edits_done << "\n got " << cs << "\nwant " << expected;
    EXPECT_FALSE(g.hasPendingEdits());
    if (expected.empty()) {
      EXPECT_EQ(g.commitCount(), count_before);
      EXPECT_EQ(observed.size(), observed_before);
    } else {
      ++nonempty;
      EXPECT_EQ(g.commitCount(), count_before + 1);
      EXPECT_EQ(cs.commit, count_before + 1);
      ASSERT_EQ(observed.size(), observed_before + 1);
      EXPECT_TRUE(sameChanges(observed.back(), cs));
      EXPECT_EQ(observed.back().commit, cs.commit);
    }
    expectCommittedEquals(g, now);
    if (::testing::Test::HasFailure()) return;
    committed = now;
    committed_model = model;
  }
  // The run exercised what it claims to (both outcomes of each kind of edit, real changes).
  EXPECT_GT(edits.applied, 1500);
  EXPECT_GT(edits.rejected, 200);
  EXPECT_GT(nonempty, 60);
  EXPECT_GT(rollbacks, 10);
  EXPECT_GT(max_nodes, 40u);
  RecordProperty("commits", commits);
}

INSTANTIATE_TEST_SUITE_P(Seeds, SceneGraphRandom, ::testing::Values(1u, 2u, 3u, 20240611u));

// ---------------------------------------------------------------------------------------------

/// Everything a caller can observe, for before/after comparisons.
struct Snapshot {
  std::vector<std::string> lines;
  bool pending = false;
  std::size_t count = 0;
  std::uint64_t commits = 0;
  bool operator==(const Snapshot&) const = default;
};

Snapshot snapshot(const SceneGraph& g, NodeId max_id) {
  Snapshot s;
  s.pending = g.hasPendingEdits();
  s.count = g.nodeCount();
  s.commits = g.commitCount();
  for (NodeId id = 0; id <= max_id; ++id) {
    if (!g.contains(id)) {
      s.lines.push_back(std::to_string(id) + " absent");
      continue;
    }
    const NodeInfo n = g.node(id);
    std::ostringstream os;
    os << id << ' ' << static_cast<int>(n.kind) << ' ' << n.parent << ' ' << n.name << ' ' << n.local << ' '
       << n.visible << ' ' << n.object << ' ' << n.mask << ' ' << g.path(id) << " world " << g.worldTransform(id) << ' '
       << g.isVisibleInstance(id) << " children";
    for (const NodeId c : g.children(id)) os << ' ' << c;
    s.lines.push_back(os.str());
  }
  return s;
}

/// A small scene, committed, then a few pending edits. Deterministic: two calls give equal graphs.
struct Scene {
  Library lib;
  SceneGraph g{lib.lib};
  NodeId car = 0, body = 0, wheel0 = 0, wheel1 = 0, lamp = 0, hidden = 0, ghost = 0;
  Scene() {
    car = g.addTransform(kRootNode, translation(1, 0, 0), "car");
    body = g.addInstance(car, 0, Affine::identity(), "body");
    const NodeId axle = g.addGroup(car, "axle");
    wheel0 = g.addInstance(axle, 1, translation(0, 0, 1), "wheel0");
    wheel1 = g.addInstance(axle, 1, translation(0, 0, -1), "wheel1");
    hidden = g.addGroup(kRootNode, "hidden");
    ghost = g.addInstance(hidden, 2, Affine::identity(), "ghost");
    g.setVisible(hidden, false);
    (void)g.commit();
    // Pending: move the car, add a lamp, hide a wheel, re-mask the body.
    g.setTransform(car, translation(2, 0, 0));
    lamp = g.addInstance(car, 2, translation(0, 1, 0), "lamp");
    g.setVisible(wheel1, false);
    g.setMask(body, 2);
  }
};

TEST(SceneGraph, RejectedEditsLeaveEverythingUnchanged) {
  Scene s;
  Scene twin;
  SceneGraph& g = s.g;
  const NodeId max_id = s.lamp + 3;
  const Snapshot before = snapshot(g, max_id);
  ASSERT_EQ(before, snapshot(twin.g, max_id));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Affine singular;
  singular.linear[1] = glm::dvec3(0.0);
  Affine nan_local = translation(nan, 0, 0);

  const std::vector<std::pair<const char*, std::function<void()>>> bad = {
      {"cycle", [&] { g.reparent(s.car, s.car); }},
      {"cycle below", [&] { g.reparent(s.car, g.node(s.wheel0).parent); }},
      {"reparent root", [&] { g.reparent(kRootNode, s.hidden); }},
      {"parent is instance", [&] { g.reparent(s.lamp, s.body); }},
      {"name taken under new parent",
       [&] {
         (void)g.addInstance(s.hidden, 0, Affine::identity(), "lamp");
         g.reparent(s.lamp, s.hidden);
       }},
      {"unknown node", [&] { g.setTransform(999, translation(1, 1, 1)); }},
      {"unknown parent", [&] { (void)g.addGroup(999, "g"); }},
      {"NaN transform", [&] { g.setTransform(s.car, nan_local); }},
      {"singular transform", [&] { g.setTransform(s.wheel0, singular); }},
      {"NaN new instance", [&] { (void)g.addInstance(s.car, 0, nan_local, "n"); }},
      {"singular new instance", [&] { (void)g.addInstance(s.car, 0, singular, "n"); }},
      {"unknown object, new instance", [&] { (void)g.addInstance(s.car, 42, Affine::identity(), "n"); }},
      {"singular new transform", [&] { (void)g.addTransform(s.car, singular, "n"); }},
      {"transform of a group", [&] { g.setTransform(s.hidden, translation(1, 0, 0)); }},
      {"instance under instance", [&] { (void)g.addInstance(s.body, 0); }},
      {"bad name", [&] { g.rename(s.body, "a/b"); }},
      {"sibling name", [&] { g.rename(s.body, "axle"); }},
      {"new sibling name", [&] { (void)g.addGroup(s.car, "body"); }},
      {"rename root", [&] { g.rename(kRootNode, "r"); }},
      {"remove root", [&] { g.remove(kRootNode); }},
      {"unknown object", [&] { g.setObject(s.body, 42); }},
      {"failing object", [&] { g.setObject(s.body, s.lib.failing); }},
      {"failing new instance", [&] { (void)g.addInstance(s.car, s.lib.failing); }},
      {"object of a group", [&] { g.setObject(s.car, 0); }},
      {"mask of a group", [&] { g.setMask(s.car, 1); }},
      {"removed node", [&] { g.setVisible(999, false); }},
  };
  for (const auto& [what, edit] : bad) {
    SCOPED_TRACE(what);
    const Snapshot pre = snapshot(g, max_id + 2);
    if (std::string(what) == "name taken under new parent") {
      // Two steps: the first is a valid add (done on the twin as well), the second must be refused.
      EXPECT_THROW(edit(), InvalidArgument);
      (void)twin.g.addInstance(twin.hidden, 0, Affine::identity(), "lamp");
      continue;
    }
    EXPECT_THROW(edit(), InvalidArgument);
    EXPECT_EQ(snapshot(g, max_id + 2), pre);
  }
  // And the commit of the batch equals the twin's, which never saw a rejected edit.
  EXPECT_EQ(snapshot(g, max_id + 2), snapshot(twin.g, max_id + 2));
  const ChangeSet a = g.commit();
  const ChangeSet b = twin.g.commit();
  EXPECT_TRUE(sameChanges(a, b)) << a << " vs " << b;
  EXPECT_EQ(a.commit, b.commit);
  EXPECT_EQ(snapshot(g, max_id + 2), snapshot(twin.g, max_id + 2));
  // The batch did what it said.
  EXPECT_EQ(a.moved, (std::vector<NodeId>{s.body, s.wheel0}));
  EXPECT_EQ(a.appeared, std::vector<NodeId>{s.lamp});
  EXPECT_EQ(a.disappeared, std::vector<NodeId>{s.wheel1});
  EXPECT_EQ(a.mask_changed, std::vector<NodeId>{s.body});
  EXPECT_TRUE(a.object_changed.empty());
}

// Two instances of one library object: each is its own node, the object (and its bottom-level
// structure) is shared, rejected instances change nothing, and the world bounds are those of the
// placed objects.
TEST(SceneGraph, InstancesShareTheirObjectAndRejectedOnesChangeNothing) {
  auto lib = std::make_shared<ObjectLibrary>();
  const auto sphere = test::buildChecked(test::icosphere(1));  // unit sphere: x in [-1, 1]
  const ObjectId object = lib->add("sphere", sphere);
  EXPECT_EQ(object, 0u);
  SceneGraph g(lib);
  const NodeId plain = g.addInstance(kRootNode, object);
  // Object (x, y, z) -> world (2x + 5, 2y, 2z).
  const NodeId scaled = g.addInstance(kRootNode, object, Affine::fromRowMajor3x4({2, 0, 0, 5, 0, 2, 0, 0, 0, 0, 2, 0}));
  EXPECT_NE(plain, scaled);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW((void)g.addInstance(kRootNode, object + 1), InvalidArgument);  // unknown object
  EXPECT_THROW((void)g.addInstance(kRootNode, object, Affine::fromRowMajor3x4({nan, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0})),
               InvalidArgument);
  EXPECT_THROW((void)g.addInstance(kRootNode, object, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0})),
               InvalidArgument);  // singular
  EXPECT_EQ(g.instances(), (std::vector<NodeId>{plain, scaled})) << "a rejected instance changed the graph";
  (void)g.commit();
  EXPECT_EQ(g.library().get(g.node(plain).object).get(), sphere.get());
  EXPECT_EQ(g.library().get(g.node(scaled).object).get(), sphere.get());
  EXPECT_TRUE(sameAffine(g.worldTransform(plain), Affine::identity()));
  EXPECT_EQ(g.worldTransform(scaled).translation, glm::dvec3(5, 0, 0));
  const SceneTracer tracer(g);
  const Box wb = tracer.bounds();
  EXPECT_TRUE(wb.contains(glm::vec3(7.0f, 0.0f, 0.0f)) && wb.contains(glm::vec3(-1.0f, 0.0f, 0.0f))) << wb;
  EXPECT_LE(wb.hi.x, 7.001f);
  EXPECT_GE(wb.lo.x, -1.001f);
}

TEST(SceneGraph, WorldTransformsFollowGroupsAndReparenting) {
  Library lib;
  SceneGraph g(lib.lib);
  const NodeId t = g.addTransform(kRootNode, translation(10, 0, 0), "t");
  const NodeId grp = g.addGroup(t, "g");
  const NodeId i = g.addInstance(grp, 0, translation(0, 1, 0), "i");
  EXPECT_FALSE(g.isVisibleInstance(i));  // not committed yet
  ChangeSet cs = g.commit();
  EXPECT_EQ(cs.commit, 1u);
  EXPECT_EQ(cs.appeared, std::vector<NodeId>{i});
  EXPECT_EQ(g.worldTransform(i).translation, glm::dvec3(10, 1, 0));
  // Moving the transform node moves the instance below it.
  g.setTransform(t, translation(20, 0, 0));
  EXPECT_EQ(g.worldTransform(i).translation, glm::dvec3(10, 1, 0));  // pending until commit
  cs = g.commit();
  EXPECT_EQ(cs.moved, std::vector<NodeId>{i});
  EXPECT_EQ(g.worldTransform(i).translation, glm::dvec3(20, 1, 0));
  // Re-parenting keeps the local transform.
  g.reparent(grp, kRootNode);
  cs = g.commit();
  EXPECT_EQ(cs.moved, std::vector<NodeId>{i});
  EXPECT_EQ(g.worldTransform(i).translation, glm::dvec3(0, 1, 0));
  // Setting the same transform again is an edit but no change.
  g.setTransform(i, translation(0, 1, 0));
  EXPECT_TRUE(g.hasPendingEdits());
  cs = g.commit();
  EXPECT_TRUE(cs.empty());
  EXPECT_EQ(cs.commit, 3u);
  EXPECT_EQ(g.commitCount(), 3u);
  // Added and removed in one batch: nowhere.
  const NodeId j = g.addInstance(grp, 1);
  g.remove(j);
  EXPECT_TRUE(g.commit().empty());
  EXPECT_FALSE(g.contains(j));
  // Moved and given another object: in both lists.
  g.setTransform(i, translation(5, 5, 5));
  g.setObject(i, 3);  // deferred: built now
  EXPECT_TRUE(lib.lib->isBuilt(3));
  cs = g.commit();
  EXPECT_EQ(cs.moved, std::vector<NodeId>{i});
  EXPECT_EQ(cs.object_changed, std::vector<NodeId>{i});
  // Removing a group removes its instances.
  g.remove(grp);
  cs = g.commit();
  EXPECT_EQ(cs.disappeared, std::vector<NodeId>{i});
  EXPECT_FALSE(g.contains(i));
  EXPECT_TRUE(g.visibleInstances().empty());
  EXPECT_EQ(g.nodeCount(), 2u);
}

TEST(SceneGraph, ACommitWhoseWorldTransformDegeneratesThrowsAndCommitsNothing) {
  // Each scale is a valid transform on its own (determinant 1e-180 or 1e180); in their product
  // (scale 1e-120 or 1e120 per axis) the determinant underflows to 0 or overflows to inf.
  for (const double s : {1e-60, 1e60}) {
    Library lib;
    SceneGraph g(lib.lib);
    const Affine scale = Affine::fromRowMajor3x4({s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0});
    const NodeId t = g.addTransform(kRootNode, Affine::identity(), "t");
    const NodeId i = g.addInstance(t, 0, Affine::identity(), "i");
    (void)g.commit();
    int calls = 0;
    (void)g.subscribe([&calls](const ChangeSet&) { ++calls; });
    g.setTransform(t, scale);
    g.setTransform(i, scale);
    try {
      (void)g.commit();
      ADD_FAILURE() << "a degenerate world transform was committed (scale " << s << ")";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find("/t/i"), std::string::npos) << e.what();
    }
    EXPECT_EQ(calls, 0) << "observers saw a failed commit";
    EXPECT_TRUE(sameAffine(g.worldTransform(i), Affine::identity())) << "the failed commit changed a world transform";
    EXPECT_TRUE(g.hasPendingEdits());
    g.rollback();
    EXPECT_TRUE(g.commit().empty());
    // A valid edit after the rollback commits normally.
    g.setTransform(t, translation(1, 2, 3));
    EXPECT_EQ(g.commit().moved, std::vector<NodeId>{i});
    EXPECT_EQ(g.worldTransform(i).translation, glm::dvec3(1, 2, 3));
  }
}

TEST(SceneGraph, PathsAndNames) {
  Library lib;
  SceneGraph g(lib.lib);
  EXPECT_EQ(g.path(kRootNode), "/");
  EXPECT_EQ(g.find("/"), kRootNode);
  const NodeId car = g.addGroup(kRootNode, "car");
  const NodeId wheel = g.addInstance(car, 0, Affine::identity(), "wheel");
  const NodeId unnamed = g.addInstance(car, 0);
  EXPECT_EQ(g.node(unnamed).name, "instance" + std::to_string(unnamed));
  EXPECT_EQ(g.node(g.addGroup(kRootNode)).name.substr(0, 5), "group");
  EXPECT_EQ(g.path(wheel), "/car/wheel");
  EXPECT_EQ(g.pathIds(wheel), (std::vector<NodeId>{car, wheel}));
  EXPECT_TRUE(g.pathIds(kRootNode).empty());
  EXPECT_EQ(g.find("/car/wheel"), wheel);
  EXPECT_EQ(g.find("/car"), car);
  for (const char* bad : {"", "car", "/car/", "//car", "/car//wheel", "/car/wheel/x", "/wheel", "/car/Wheel"})
    EXPECT_EQ(g.find(bad), std::nullopt) << bad;
  // Siblings must differ; cousins may share a name.
  expectErrorNaming<InvalidArgument>([&] { (void)g.addInstance(car, 0, Affine::identity(), "wheel"); }, "wheel");
  const NodeId other = g.addGroup(kRootNode, "other");
  const NodeId wheel2 = g.addInstance(other, 0, Affine::identity(), "wheel");
  EXPECT_EQ(g.find("/other/wheel"), wheel2);
  expectErrorNaming<InvalidArgument>([&] { g.reparent(wheel2, car); }, "wheel");
  expectErrorNaming<InvalidArgument>([&] { g.rename(wheel2, "x/y"); }, "x/y");
  // Rename: the old path is gone, the new one found; renaming to its own name is fine.
  g.rename(wheel, "front");
  EXPECT_EQ(g.find("/car/wheel"), std::nullopt);
  EXPECT_EQ(g.find("/car/front"), wheel);
  g.rename(wheel, "front");
  g.reparent(wheel2, car);
  EXPECT_EQ(g.find("/car/wheel"), wheel2);
  EXPECT_EQ(g.path(wheel2), "/car/wheel");
  // Rollback (nothing committed yet) forgets all of it, and ids are not handed out again.
  g.rollback();
  EXPECT_EQ(g.nodeCount(), 1u);
  EXPECT_EQ(g.find("/car"), std::nullopt);
  EXPECT_FALSE(g.contains(car));
  const NodeId fresh = g.addGroup(kRootNode, "car");
  EXPECT_GT(fresh, wheel2);
  EXPECT_EQ(g.find("/car"), fresh);
  // Renames after a commit roll back to the committed name.
  (void)g.commit();
  g.rename(fresh, "truck");
  g.rollback();
  EXPECT_EQ(g.path(fresh), "/car");
  EXPECT_EQ(g.find("/truck"), std::nullopt);
  // Errors name the node by path.
  expectErrorNaming<InvalidArgument>([&] { g.setTransform(fresh, Affine::identity()); }, "/car");
  expectErrorNaming<InvalidArgument>([&] { (void)g.path(12345); }, "12345");
}

TEST(SceneGraph, ObserversAreCalledOncePerCommitThatChangedSomething) {
  Library lib;
  SceneGraph g(lib.lib);
  std::vector<ChangeSet> a, b;
  const auto ida = g.subscribe([&a](const ChangeSet& cs) { a.push_back(cs); });
  const auto idb = g.subscribe([&b](const ChangeSet& cs) { b.push_back(cs); });
  EXPECT_NE(ida, idb);
  EXPECT_TRUE(g.commit().empty());  // nothing pending
  EXPECT_TRUE(a.empty());
  const NodeId i = g.addInstance(kRootNode, 0);
  const ChangeSet first = g.commit();
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(a[0].appeared, std::vector<NodeId>{i});
  EXPECT_EQ(a[0].commit, 1u);
  EXPECT_EQ(first.commit, 1u);
  // Edits without effect on instances: no call, no commit number.
  g.rename(i, "named");
  (void)g.addGroup(kRootNode, "empty");
  g.setMask(i, 0xFFFFFFFFu);
  EXPECT_TRUE(g.commit().empty());
  EXPECT_EQ(a.size(), 1u);
  EXPECT_EQ(g.commitCount(), 1u);
  // Unsubscribed: no more calls; the other still gets its one.
  g.unsubscribe(ida);
  g.setVisible(i, false);
  const ChangeSet third = g.commit();
  EXPECT_EQ(third.commit, 2u);
  EXPECT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b[1].disappeared, std::vector<NodeId>{i});
  // A throwing observer does not undo the commit and does not stop the others.
  std::vector<ChangeSet> c;
  (void)g.subscribe([](const ChangeSet&) { throw std::runtime_error("observer failed"); });
  (void)g.subscribe([&c](const ChangeSet& cs) { c.push_back(cs); });
  g.setVisible(i, true);
  EXPECT_THROW((void)g.commit(), std::runtime_error);
  EXPECT_FALSE(g.hasPendingEdits());
  EXPECT_EQ(g.commitCount(), 3u);
  EXPECT_TRUE(g.isVisibleInstance(i));
  EXPECT_EQ(b.size(), 3u);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].appeared, std::vector<NodeId>{i});
}

TEST(SceneGraph, ChangeSetPrintsEveryList) {
  ChangeSet cs;
  cs.commit = 4;
  cs.appeared = {1, 2};
  cs.mask_changed = {7};
  std::ostringstream os;
  os << cs;
  EXPECT_EQ(os.str(),
            "ChangeSet{commit=4, appeared=[1,2], disappeared=[], moved=[], object_changed=[], mask_changed=[7]}");
}

TEST(SceneGraph, MovingOneInstanceOfManyTouchesOnlyIt) {
  Library lib;
  SceneGraph g(lib.lib);
  std::vector<NodeId> ids;
  for (int k = 0; k < 100; ++k) {
    const NodeId grp = g.addTransform(kRootNode, translation(k, 0, 0));
    for (int j = 0; j < 210; ++j) ids.push_back(g.addInstance(grp, static_cast<ObjectId>(j % 3), translation(0, j, 0)));
  }
  EXPECT_EQ(g.commit().appeared.size(), ids.size());
  const NodeId one = ids[12345];
  g.setTransform(one, translation(0, 0, 1));
  const ChangeSet cs = g.commit();
  EXPECT_EQ(cs.moved, std::vector<NodeId>{one});
  EXPECT_TRUE(cs.appeared.empty() && cs.disappeared.empty());
  // A group moves all of its instances, and only those.
  const NodeId grp = g.node(one).parent;
  g.setTransform(grp, translation(-1, 0, 0));
  const ChangeSet moved = g.commit();
  EXPECT_EQ(moved.moved, g.children(grp));
  EXPECT_EQ(moved.moved.size(), 210u);
  EXPECT_GT(SceneGraph::bytesPerInstance(), 2 * sizeof(Affine));
}

// The documented bytes per instance (SceneGraph + TopLevel records) against what adding 20,000
// instances to a scene with a tracer really allocates (glibc's count of bytes in use): at least
// the figure (it is not overstated) and at most twice it plus the top-level tree's references and
// nodes (vectors grow by doubling, so up to half of a vector's capacity may be unused).
TEST(SceneGraph, BytesPerInstanceAccountsForWhatAnInstanceAllocates) {
#if defined(__SANITIZE_ADDRESS__) || DUPLEX_CLANG_ASAN
  GTEST_SKIP() << "AddressSanitizer's allocator is not glibc's: mallinfo2() does not count it (the Release build runs "
                  "this test)";
#endif
  Library lib;
  SceneGraph g(lib.lib);
  SceneTracer tracer(g);
  const auto add = [&](int first, int count) {
    for (int i = first; i < first + count; ++i) {
      char name[16];
      std::snprintf(name, sizeof name, "i%06d", i);  // fits std::string's small buffer, as counted
      (void)g.addInstance(kRootNode, static_cast<ObjectId>(i % 3), translation(i % 100, i / 100 % 100, i / 10000),
                          name);
    }
    (void)g.commit();
  };
  // Bytes in use: the arena's and the chunks glibc maps on their own (large vectors: the top level's
  // per-slot arrays pass the mmap threshold).
  const auto in_use = [] {
    const struct mallinfo2 m = ::mallinfo2();
    return m.uordblks + m.hblkhd;
  };
  add(0, 1000);
  const std::size_t before = in_use();
  const int n = 20000;
  add(1000, n);
  const double measured = double(in_use() - before) / n;
  const double documented = double(SceneGraph::bytesPerInstance() + TopLevel::bytesPerInstance());
  const TopLevelStats st = tracer.stats();
  const double tree =
      (4.0 * double(st.tree.references) + 8.0 * double(st.tree.nodes) + double(st.wide_bytes)) / double(st.instances);
  EXPECT_GE(measured, 0.95 * documented) << "graph " << SceneGraph::bytesPerInstance() << " + top level "
                                         << TopLevel::bytesPerInstance() << " bytes documented";
  EXPECT_LE(measured, 2.0 * (documented + tree)) << "graph " << SceneGraph::bytesPerInstance() << " + top level "
                                                 << TopLevel::bytesPerInstance() << " + tree " << tree;
  std::printf("bytes per instance: %.0f allocated, %.0f documented (graph %zu, top level %zu) + tree %.1f\n", measured,
              documented, SceneGraph::bytesPerInstance(), TopLevel::bytesPerInstance(), tree);
}

TEST(SceneGraph, ALongSessionOfAddsAndRemovesReusesNodeRecords) {
  // A CAD session: parts come and go for a long time. Ids keep growing (a caller may still hold a
  // removed one), but the node records of removed nodes are reused, so the table does not grow.
  Library lib;
  SceneGraph g(lib.lib);
  const NodeId grp = g.addTransform(kRootNode, translation(1, 2, 3), "parts");
  std::vector<NodeId> parts;
  for (int k = 0; k < 50; ++k) parts.push_back(g.addInstance(grp, static_cast<ObjectId>(k % 3), translation(k, 0, 0)));
  (void)g.commit();
  const std::size_t base_slots = g.nodeSlots();
  EXPECT_EQ(base_slots, 52u);  // root, group, 50 instances
  std::mt19937_64 rng(7);
  std::vector<NodeId> gone;
  NodeId last_id = 0;
  for (int cycle = 0; cycle < 2000; ++cycle) {
    // Five new parts, hidden or masked now and then (a reused record must not keep old flags).
    std::vector<NodeId> added;
    for (int j = 0; j < 5; ++j) {
      const NodeId id = g.addInstance(grp, static_cast<ObjectId>(j % 3), translation(cycle, j, 0), {}, 1u + j);
      ASSERT_GT(id, last_id);
      last_id = id;
      added.push_back(id);
    }
    if (cycle % 7 == 0) {
      g.rollback();  // their records are released, their ids stay dead
      for (const NodeId id : added) ASSERT_FALSE(g.contains(id));
      continue;
    }
    const ChangeSet cs = g.commit();
    ASSERT_EQ(cs.appeared, added);
    for (std::size_t j = 0; j < added.size(); ++j) {
      const NodeInfo info = g.node(added[j]);
      ASSERT_EQ(info.mask, 1u + j);
      ASSERT_TRUE(info.visible);
      ASSERT_TRUE(g.isVisibleInstance(added[j]));
      ASSERT_EQ(g.worldTransform(added[j]).translation, glm::dvec3(1 + cycle, 2 + double(j), 3));
      ASSERT_EQ(g.find(g.path(added[j])), std::optional<NodeId>(added[j]));
    }
    parts.insert(parts.end(), added.begin(), added.end());
    // Five random parts leave.
    std::vector<NodeId> removed;
    for (int j = 0; j < 5; ++j) {
      const std::size_t pick = std::uniform_int_distribution<std::size_t>(0, parts.size() - 1)(rng);
      removed.push_back(parts[pick]);
      g.remove(parts[pick]);
      parts.erase(parts.begin() + static_cast<std::ptrdiff_t>(pick));
    }
    std::sort(removed.begin(), removed.end());
    ASSERT_EQ(g.commit().disappeared, removed);
    gone.insert(gone.end(), removed.begin(), removed.end());
    ASSERT_LE(g.nodeSlots(), base_slots + 5) << "cycle " << cycle;
  }
  EXPECT_GT(last_id, 10000u);
  EXPECT_EQ(g.nodeCount(), 52u);
  EXPECT_EQ(g.nodeSlots(), base_slots + 5);
  std::sort(parts.begin(), parts.end());
  EXPECT_EQ(g.instances(), parts);
  EXPECT_EQ(g.visibleInstances(), parts);
  // Dead ids stay dead: not contained, rejected by name, never reused by a new node.
  for (const NodeId id : gone) ASSERT_FALSE(g.contains(id));
  expectErrorNaming<InvalidArgument>([&] { (void)g.node(gone.front()); },
                                     "unknown node id " + std::to_string(gone.front()));
  expectErrorNaming<InvalidArgument>([&] { g.setTransform(gone.back(), translation(0, 0, 0)); },
                                     "unknown node id " + std::to_string(gone.back()));
  EXPECT_GT(g.addGroup(kRootNode), last_id);
}

}  // namespace
}  // namespace duplex
