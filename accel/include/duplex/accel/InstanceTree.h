#pragma once
/// \file InstanceTree.h
/// One incremental kd-tree (BSP) over the world boxes of object instances: the building block of
/// the top level (TopLevel composes two, one for the instances that block or attenuate rays and
/// one for the non-blocking ones). Built with the same builder and traversed with the same code as
/// the bottom level, and updated incrementally when instances move, appear or disappear.
///
/// Lifecycle (after Embree's edit -> commit -> trace): set() / remove() record edits; commit()
/// applies them to the tree; queries see the state of the last commit. Queries are const and may
/// run from any number of threads at once, each with its own QueryContext, but not while
/// set() / remove() / commit() / build() run (the caller serialises them).

#include "duplex/accel/Affine.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/Object.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <glm/vec4.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace duplex {

namespace toplevel_detail {
struct WorldRay;   // the world ray in float and double (src/InstanceTreeState.h)
struct LeafVisit;  // a leaf reached by routing a box (src/InstanceTreeState.h)
struct Prepared;   // a validated instance edit (src/InstanceTreeState.h)
}  // namespace toplevel_detail

/// One instance as the top level sees it.
struct InstanceDesc {
  std::shared_ptr<const Object> object;  ///< the object, shared with other instances; not null
  Affine world_from_object;              ///< maps the object's space to world space; finite and not singular
  std::uint32_t id = 0;                  ///< the caller's id, reported in Hit::instance_id; unique
  std::uint32_t mask = 0xFFFFFFFFu;      ///< user bits; a query sees the instance when (mask & query mask) != 0
};

/// How commit() brings the tree up to date.
enum class TopLevelUpdate : std::uint8_t {
  /// Re-insert only the edited instances into the leaves their old and new boxes touch; rebuild a
  /// subtree when its leaves overflow, and the whole tree when its SAH cost drifts above the cost
  /// of a fresh build by more than TopLevelConfig::rebuild_ratio.
  Incremental,
  /// Rebuild the whole tree on every commit that changed something (the paper's method; the
  /// baseline of the update benchmark).
  FullRebuild,
};

/// The top level's build defaults. A reference in a leaf costs a box test (the three slabs in one
/// vector operation) and, when its box is met, a visit (ray transform, bottom-level set-up and
/// traversal), which leaves visiting nearest box first often skip; an inner node step costs a
/// dependent load and a branch that mispredicts on about half the steps of incoherent rays. So the
/// intersection cost is 0.3 node steps and empty-space cuts get no bonus: shallower trees with
/// leaves of a few instances. Higher costs make deeper trees whose node steps mispredict, lower
/// ones test and visit more instances per ray (the sweep: docs/design/two-level.md, "Costs").
inline KdBuildConfig topLevelBuildDefaults() {
  KdBuildConfig c;
  c.intersection_cost = 0.3f;
  c.empty_bonus = 0.0f;
  return c;
}

/// The crossing level's build defaults (TopLevelConfig::crossing_build), tuned for small flat
/// non-blocking instances (light sensors). Its leaves are tested 16, 8
/// or 4 boxes at a time from a leaf-ordered copy of the boxes (no instance record is read unless a box
/// is met), which costs far less than a node step, and a small sensor gains little from an
/// empty-space cut, which costs every ray passing near it a node step. So: intersection cost 0.05
/// and no empty bonus, a shallow tree with leaves of several sensors (the benchmark's many small
/// sensors query about twice as fast as with the top-level defaults; docs/design/sensors.md, "Speed").
inline KdBuildConfig crossingLevelBuildDefaults() {
  KdBuildConfig c;
  c.intersection_cost = 0.05f;
  c.empty_bonus = 0.0f;
  return c;
}

/// Parameters of the top level (both of its trees) and of how commit() updates them.
struct TopLevelConfig {
  KdBuildConfig build = topLevelBuildDefaults();  ///< for full and subtree builds
  /// The same for the crossing level (non-blocking instances, see TopLevel); build() with an explicit configuration
  /// sets `build` only.
  KdBuildConfig crossing_build = crossingLevelBuildDefaults();
  /// The crossing query walks a uniform grid over the crossing level's boxes instead of its
  /// kd-tree when the level holds many instances (at least 256, each spanning few cells) and the ray's
  /// rounding is small against the grid's margin; same crossings either way (docs/design/sensors.md,
  /// "The crossing query"). false: always the kd-tree (for comparisons).
  bool crossing_grid = true;
  /// Closest-hit, any-hit and packet queries of the blocking instances walk an 8-wide form derived
  /// from the kd-tree after every build and commit (tight boxes tested 8 at a time; a commit
  /// derives again only what its edits' paths cross): fewer steps and mispredictions per ray than
  /// the kd-tree's node steps, for a little more memory and commit time (docs/design/two-level.md, "The
  /// wide form"). false: the kd-tree itself (for comparisons). Same hits either way. Unlike the
  /// other fields, a change through setConfig() takes effect at once.
  bool wide_traversal = true;
  TopLevelUpdate update = TopLevelUpdate::Incremental;  ///< how commit() brings the trees up to date
  /// Full rebuild when (current SAH cost) > rebuild_ratio * (SAH cost after the last full build,
  /// scaled to the current instance count).
  double rebuild_ratio = 1.05;
  /// A leaf that grows past this many references is rebuilt as a subtree.
  std::uint32_t leaf_split_size = 8;
  /// Below this many instances every commit rebuilds the whole tree (it costs microseconds).
  std::size_t min_incremental_instances = 16;
  /// A commit that edits more than this fraction of the instances rebuilds the whole tree: cheaper
  /// than as many re-insertions, and a better tree.
  double max_incremental_fraction = 0.125;
};

class TopLevel;

/// An incremental kd-tree over instance world boxes (see the file comment). Every query is in world
/// space; t is in units of the world ray's direction.
class InstanceTree {
 public:
  /// Which instances the tree holds. A crossing tree (non-blocking instances) builds with
  /// TopLevelConfig::crossing_build and keeps, after every build and commit, a leaf-ordered copy of
  /// its boxes, the planes of its flat instances and a uniform grid, for the crossing query.
  enum class Kind : std::uint8_t {
    Blocking,  ///< instances that block or attenuate rays (surfaces and media)
    Crossing   ///< non-blocking instances (sensors): the crossing level
  };

  InstanceTree() = default;
  /// `config` is not validated here (TopLevel validates it).
  explicit InstanceTree(const TopLevelConfig& config, Kind kind = Kind::Blocking);
  InstanceTree(const InstanceTree&) = delete;
  InstanceTree& operator=(const InstanceTree&) = delete;
  /// Moves the instances and the tree.
  InstanceTree(InstanceTree&&) noexcept = default;
  /// Moves the instances and the tree.
  InstanceTree& operator=(InstanceTree&&) noexcept = default;

  /// The configuration; config().build is the one this tree builds with.
  [[nodiscard]] const TopLevelConfig& config() const { return config_; }
  /// Takes effect at the next build or commit.
  void setConfig(const TopLevelConfig& config);

  /// Replaces everything by `instances` and builds a fresh tree with `build` (kept for later
  /// commits). Throws InvalidArgument as TopLevel::build does; the tree is then unchanged.
  void build(std::span<const InstanceDesc> instances, const KdBuildConfig& build);
  /// Records an insertion or a change; validated at once (throws InvalidArgument, records nothing).
  void set(const InstanceDesc& instance);
  /// Records the removal of `id` (the caller checks contains() first).
  void remove(std::uint32_t id);
  /// Whether `id` is present (after the edits recorded so far).
  [[nodiscard]] bool contains(std::uint32_t id) const;
  /// Applies the recorded edits; on failure as TopLevel::commit.
  void commit();
  /// Rebuilds the whole tree over the committed instances now (pending edits stay pending).
  void rebuild();

  /// Closest hit among Surface instances whose mask meets `mask` (see TopLevel::intersect).
  [[nodiscard]] Hit intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// The same for a double-precision world ray (object-space rays computed in double).
  [[nodiscard]] Hit intersect(const RayD& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Whether a Surface instance whose mask meets `mask` is hit within [tnear, tfar].
  [[nodiscard]] bool occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Closest hits of up to kMaxPacketRays world rays traced together (see TopLevel::intersectPacket):
  /// hits[i] is exactly intersect(rays_ws[i], ctx, mask). Returns the lanes that hit.
  std::uint32_t intersectPacket(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Bit i set when occluded(rays_ws[i], ctx, mask) (see TopLevel::occludedPacket).
  [[nodiscard]] std::uint32_t occludedPacket(std::span<const Ray> rays_ws, QueryContext& ctx,
                                             std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Every hit within [tnear, tfar] of this tree's instances whose mask meets `mask`, of any role,
  /// sorted by t (ties by instance id, then primitive id); world-space t and ng.
  void intersectAll(const Ray& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                    std::uint32_t mask = 0xFFFFFFFFu) const;
  /// The same for a double-precision world ray (object-space rays computed in double).
  void intersectAll(const RayD& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                    std::uint32_t mask = 0xFFFFFFFFu) const;
  /// See TopLevel::transmittance (this tree's instances only). InstanceTreeTransmittance.cpp.
  [[nodiscard]] float transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;

  /// Improves `best` (world space, see TopLevel::closestPoint) with the Surface instances whose mask
  /// meets `mask`; best.instance_id is set to the instance of a better point. InstanceTreeClosest.cpp.
  void closestPoint(const glm::dvec3& point_ws, ClosestPoint& best, QueryContext& ctx,
                    std::uint32_t mask = 0xFFFFFFFFu) const;

  /// object_from_world of instance `id` (last commit); nullptr for an id this tree does not hold.
  [[nodiscard]] const Affine* findObjectFromWorld(std::uint32_t id) const;
  /// World box of instance `id` (last commit); nullptr for an id this tree does not hold.
  [[nodiscard]] const Box* findBounds(std::uint32_t id) const;
  /// The id of the instance that tree().prim_indices entry `slot` refers to; kInvalidId for a free slot.
  [[nodiscard]] std::uint32_t idAt(std::uint32_t slot) const;
  /// Instances of the last commit.
  [[nodiscard]] std::size_t size() const { return live_count_; }
  /// The tree of the last commit, over slots (idAt() maps them to ids); world space.
  [[nodiscard]] const KdTree& tree() const { return tree_; }

 private:
  friend class TopLevel;  // the crossing query and the statistics read both trees' records
  struct State;           // instance records, id map, pending edits, leaf bookkeeping (InstanceTreeState.h)
  struct CommitPass;      // what one commit's steps share (InstanceTree.cpp)
  void ensureState();
  void collectAll(const toplevel_detail::WorldRay& w, std::vector<Hit>& hits, QueryContext& ctx,
                  std::uint32_t mask) const;
  // Region queries (InstanceTreeRegion.cpp): the slots whose mask meets `mask` and whose world box
  // the region does not exclude, sorted.
  [[nodiscard]] std::vector<std::uint32_t> slotsInRegion(const ConvexRegion& region, std::uint32_t mask) const;
  void appendInRegion(const ConvexRegion& region, std::uint32_t mask, RegionMode mode,
                      std::vector<std::uint32_t>& out) const;
  void appendTrianglesInRegion(const ConvexRegion& region, std::uint32_t mask,
                               std::vector<InstanceTriangle>& out) const;
  void fullRebuild();
  void install(KdTree&& tree);
  void refreshTraversalForms();
  void commitEdits();
  void applyRemoval(CommitPass& pass, std::uint32_t id);
  void applySet(CommitPass& pass, std::uint32_t id, toplevel_detail::Prepared&& edit);
  void removeFromLeaf(CommitPass& pass, const toplevel_detail::LeafVisit& v, std::uint32_t slot);
  void appendToLeaf(CommitPass& pass, const toplevel_detail::LeafVisit& v, std::uint32_t slot);
  void growRoot(const Box& box);
  [[nodiscard]] bool onRootFace(const Box& box) const;
  void finishIncrementalCommit(CommitPass& pass);
  void shrinkRootIfDue(bool periodic);
  void compact();
  Hit intersectImpl(const Ray& ray_f, const RayD* ray_d, QueryContext& ctx, std::uint32_t mask) const;
  // The packet queries (InstanceTreePacket.cpp).
  struct PacketState;
  template <bool AnyHit>
  std::uint32_t packetQuery(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                            std::uint32_t mask) const;
  template <bool AnyHit>
  std::uint32_t packetWalk(PacketState& p, std::uint32_t lanes, std::uint32_t octant, QueryContext& ctx,
                           std::uint32_t mask) const;
  /// Every hit of this tree and, when given, of `also` (the top level's other tree): one query.
  void intersectAllImpl(const Ray& ray_f, const RayD* ray_d, std::vector<Hit>& hits, QueryContext& ctx,
                        std::uint32_t mask, const InstanceTree* also = nullptr) const;
  TopLevelConfig config_;
  Kind kind_ = Kind::Blocking;
  KdTree tree_;
  std::size_t live_count_ = 0;
  std::shared_ptr<State> state_;
};

}  // namespace duplex
