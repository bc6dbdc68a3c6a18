#pragma once
/// \file TopLevel.h
/// The top level of the two-level structure: a kd-tree (BSP) over the world boxes of object
/// instances, built with the same builder and traversed with the same code as the bottom level,
/// and updated incrementally when instances move, appear or disappear.
///
/// Non-blocking instances (ObjectRole::Crossing: objects that record the rays crossing them, such as
/// light sensors) live in a second tree of their own, the crossing level, kept by the same rules
/// (both are InstanceTrees): closest-hit, occlusion and transmittance queries never traverse it, so
/// rendering costs the same with 10,000 of them in the scene as without; intersectAll,
/// instancesInRegion and the crossing query traverse both. An instance whose object changes role
/// moves between the two on commit.
///
/// Lifecycle (after Embree's edit -> commit -> trace): set() / remove() record edits; commit()
/// applies them to the tree; queries see the state of the last commit. Queries are const and may
/// run from any number of threads at once, each with its own QueryContext, but not while
/// set() / remove() / commit() / build() run (the caller serialises them; SceneTracer does).

#include "duplex/accel/Affine.h"
#include "duplex/accel/InstanceTree.h"
#include "duplex/accel/Crossing.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/Object.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <glm/mat3x3.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace duplex {

/// Figures of the current tree and of the last commit (for tests and the benchmark).
struct TopLevelStats {
  std::size_t instances = 0;           ///< blocking and medium instances of the last commit
  KdTreeStats tree;                    ///< figures of the tree over those instances
  double sah_cost = 0.0;               ///< current
  double fresh_sah_cost = 0.0;         ///< the estimate of a fresh build's cost it is compared with
  std::uint64_t commits = 0;           ///< commits that applied edits (the blocking and medium tree)
  std::uint64_t full_rebuilds = 0;     ///< whole-tree builds: build(), rebuild() and commits that rebuilt
  std::uint64_t subtree_rebuilds = 0;  ///< subtrees rebuilt by commits (overflowing leaves, refinement)
  std::size_t last_commit_edits = 0;   ///< instances set or removed by the last commit
  /// Nodes of tree().nodes that no traversal reaches: subtrees that a local rebuild replaced,
  /// dropped when the tree is compacted (InstanceTreeRefine.cpp).
  std::size_t garbage_nodes = 0;
  bool last_commit_full_rebuild = false;  ///< whether the last commit or build built the whole tree
  /// The wide traversal form (TopLevelConfig::wide_traversal): its nodes reachable from its root
  /// (0 when the kd-tree is walked instead), nodes that replaced parts left behind until the next
  /// full derivation, and the bytes it holds (nodes and what it keeps per kd node for refreshes).
  std::size_t wide_nodes = 0;
  std::size_t wide_garbage_nodes = 0;  ///< see wide_nodes
  std::size_t wide_bytes = 0;          ///< see wide_nodes
  /// The crossing level (non-blocking instances, see TopLevel): its instances and figures.
  /// `instances` and `tree` above count the other instances only.
  std::size_t crossing_instances = 0;
  KdTreeStats crossing_tree;  ///< figures of the crossing level's tree
  /// The uniform grid the crossing query walks over the crossing level (TopLevelConfig::crossing_grid):
  /// its cells and entries (instances times the cells each is listed in); 0 when it walks the tree.
  std::size_t crossing_grid_cells = 0;
  std::size_t crossing_grid_entries = 0;  ///< entries of that grid (see above)
  /// Crossing-level boxes per vector test: 16 (AVX-512F), 8 (AVX2) or 4 (SSE2), the widest the CPU runs,
  /// capped by the environment variable DUPLEX_ISA ("sse2", "avx2") when the level was last
  /// committed; 1 on other CPUs or without non-blocking instances.
  std::uint32_t crossing_box_lanes = 1;
};

/// The top level over object instances: a tree of the blocking and medium instances and the crossing level of the
/// non-blocking ones (see the file comment). Queries take world-space rays; t is in units of the world ray's direction.
class TopLevel {
 public:
  TopLevel() = default;
  /// Throws InvalidArgument for a configuration out of range (non-positive costs, empty_bonus
  /// outside [0, 1), negative max_depth, rebuild_ratio below 1, ...).
  explicit TopLevel(const TopLevelConfig& config);
  // Not copyable: the copy would share the instance records. Movable.
  TopLevel(const TopLevel&) = delete;
  TopLevel& operator=(const TopLevel&) = delete;
  /// Moves the instances and both trees.
  TopLevel(TopLevel&&) noexcept = default;
  /// Moves the instances and both trees.
  TopLevel& operator=(TopLevel&&) noexcept = default;

  /// The configuration of both trees (config().build is the one the blocking tree builds with).
  [[nodiscard]] const TopLevelConfig& config() const { return blocking_.config(); }
  /// Takes effect at the next build or commit; validated as in the constructor.
  void setConfig(const TopLevelConfig& config);

  /// Replaces everything by `instances` and builds a fresh tree. Throws InvalidArgument for a null
  /// object, a duplicate id, or a non-finite or singular transform (naming the instance id and its
  /// object); the top level is then unchanged.
  void build(std::span<const InstanceDesc> instances);
  /// Same with `config` as the build configuration (kept for later commits).
  void build(std::span<const InstanceDesc> instances, const KdBuildConfig& config);

  /// Records an insertion (new id) or a change (known id: transform, object or mask). Validated
  /// at once: throws InvalidArgument as build() does, and nothing is recorded.
  void set(const InstanceDesc& instance);
  /// Records the removal of `id`; throws InvalidArgument for an id that is not present (after the
  /// edits recorded so far).
  void remove(std::uint32_t id);
  /// Whether `id` is present (after the edits recorded so far).
  [[nodiscard]] bool contains(std::uint32_t id) const;
  /// Applies the recorded edits. Cheap when nothing was recorded. If it throws (out of memory),
  /// the edits are applied to the instance records and the tree is rebuilt from them, or, when
  /// even that fails, queries miss until the next commit rebuilds it.
  void commit();
  /// Rebuilds the whole tree over the committed instances now (pending edits stay pending).
  void rebuild();

  /// Closest blocking hit of a world-space ray among instances whose mask meets `mask`; t in units
  /// of the world ray's direction (comparable across instances), hit.ng the world-space geometric
  /// normal cross(v1 - v0, v2 - v0) (unnormalised, winding kept under mirroring),
  /// hit.instance_id the instance's id. A miss has hit.valid() false.
  [[nodiscard]] Hit intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// The same for a double-precision world ray: the transform into object space is done in double
  /// from the double origin and direction (picking far from the origin).
  [[nodiscard]] Hit intersect(const RayD& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Whether any blocking instance whose mask meets `mask` is hit within [tnear, tfar].
  [[nodiscard]] bool occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Closest hits of a batch of world rays traced one by one: hits[i] is intersect(rays_ws[i], ctx,
  /// mask) bit for bit, world space as intersect(); the per-call work (the kernel for the CPU, the
  /// tree's state) is done once per batch. Throws InvalidArgument when `hits` is shorter than
  /// `rays_ws`.
  void intersectBatch(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                      std::uint32_t mask = 0xFFFFFFFFu) const;
  /// occluded[i] = 1 when occluded(rays_ws[i], ctx, mask), else 0, the rays traced one by one as
  /// intersectBatch's. Throws InvalidArgument when `occluded` is shorter than `rays_ws`.
  void occludedBatch(std::span<const Ray> rays_ws, std::span<std::uint8_t> occluded, QueryContext& ctx,
                     std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Closest hits of up to kMaxPacketRays world rays (world space, t in units of each ray's
  /// direction) traced together: the rays of each octant go through the kd-tree as one packet, and
  /// each instance they reach answers the sub-packet of rays that reach it, transformed to object
  /// space (Object::intersectPacket). hits[i] is bit for bit intersect(rays_ws[i], ctx, mask) (a
  /// miss: Hit{}); returns the lanes that hit. Coherent rays (neighbouring pixels, rays towards one
  /// light) trace fastest; the rays of an octant holding at most three, and every ray of a packet
  /// spread over more than four octants (random directions), go the single-ray way. Throws
  /// InvalidArgument for more than kMaxPacketRays rays or fewer hits than rays.
  std::uint32_t intersectPacket(std::span<const Ray> rays_ws, std::span<Hit> hits, QueryContext& ctx,
                                std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Bit i set when occluded(rays_ws[i], ctx, mask), the rays traced as intersectPacket's. Throws
  /// InvalidArgument for more than kMaxPacketRays rays.
  [[nodiscard]] std::uint32_t occludedPacket(std::span<const Ray> rays_ws, QueryContext& ctx,
                                             std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Every hit within [tnear, tfar] of instances whose mask meets `mask`, of any role (sensor
  /// crossings included), sorted by t (ties by instance id, then primitive id); world-space t and ng.
  void intersectAll(const Ray& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                    std::uint32_t mask = 0xFFFFFFFFu) const;
  /// The same for a double-precision world ray (object-space rays computed in double).
  void intersectAll(const RayD& ray_ws, std::vector<Hit>& hits, QueryContext& ctx,
                    std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Fraction of light that passes along [tnear, tfar] of a world-space ray, in [0, 1]: 0 when a
  /// blocking instance (role Surface) is hit within the segment, else the product of the
  /// transmittances of every medium instance (role Medium) the segment crosses, each counted once
  /// (Object::transmittance on the object-space ray, same t). Sensors are ignored. 1 for a ray that
  /// cannot be queried (NaN, zero direction) or an empty scene. Defined in InstanceTreeTransmittance.cpp.
  [[nodiscard]] float transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Light transport's query, in one traversal: the closest blocking hit of a world-space ray among
  /// instances selected by query.surface_mask, and in `crossings` (cleared first) every crossing of
  /// a sensor instance selected by query.crossing_mask with t in [tnear, hit t (1 + kCrossingSlack)]
  /// (all of [tnear, tfar] on a miss), each once, sorted by t (ties by instance id), with the
  /// transmittance of the media selected by query.medium_mask from tnear to each crossing and to
  /// the hit. Defined in TopLevelCrossings.cpp.
  [[nodiscard]] SegmentEnd intersectWithCrossings(const Ray& ray_ws, std::vector<Crossing>& crossings,
                                                  QueryContext& ctx, const CrossingQuery& query = {}) const;
  /// Ids of the instances (mask meeting `mask`, any role) selected by the convex region
  /// {x : dot(n_i, x) <= d_i for all planes}, planes given as (n.x, n.y, n.z, d) in world space;
  /// sorted by id. Mode Boxes: the instance's world box meets the region (conservative: a box is
  /// reported unless one plane has it fully outside, exact for frustum picking of boxes up to the
  /// corner cases of the separating-axis test). Touching / Inside: its geometry meets / lies in the
  /// region (Object::inRegion in object space, after the box test; a type without a region test
  /// counts as touching when its box meets the region and as inside when its box is inside).
  /// Throws InvalidArgument for a plane with a non-finite or zero normal or a non-finite offset.
  [[nodiscard]] std::vector<std::uint32_t> instancesInRegion(std::span<const glm::dvec4> planes,
                                                             std::uint32_t mask = 0xFFFFFFFFu,
                                                             RegionMode mode = RegionMode::Boxes) const;
  /// Every triangle meeting the region (planes as instancesInRegion) of the instances whose mask
  /// meets `mask` and whose objects report triangles (Object::trianglesInRegion: meshes), in world
  /// space, sorted by instance id then prim id. For tolerance picking. Throws as instancesInRegion.
  [[nodiscard]] std::vector<InstanceTriangle> trianglesInRegion(std::span<const glm::dvec4> planes,
                                                                std::uint32_t mask = 0xFFFFFFFFu) const;

  /// The point of the Surface instances (mask meeting `mask`) nearest to world point `point_ws`
  /// within world distance `max_distance` (inclusive; +inf for no limit), in double precision:
  /// distance, point, unit normal (world space), prim_id and instance_id. Types without a
  /// closest-point query (Object::closestPoint: fog, sensors) are ignored. Nothing within
  /// reach, a non-finite point or a NaN or negative max_distance: distance +inf and ids kInvalidId.
  /// Defined in InstanceTreeClosest.cpp.
  [[nodiscard]] ClosestPoint closestPoint(const glm::dvec3& point_ws, double max_distance, QueryContext& ctx,
                                          std::uint32_t mask = 0xFFFFFFFFu) const;

  /// object_from_world of instance `id` (last commit), double precision. Throws for an unknown id.
  [[nodiscard]] const Affine& objectFromWorld(std::uint32_t id) const;
  /// World box of instance `id` as the tree holds it (last commit). Throws for an unknown id.
  [[nodiscard]] Box instanceBounds(std::uint32_t id) const;
  /// The id of the instance that tree().prim_indices entry `slot` refers to (for tests and tools);
  /// kInvalidId for a free slot.
  [[nodiscard]] std::uint32_t idAt(std::uint32_t slot) const;
  /// World-space bounds of everything, non-blocking instances included (last commit).
  [[nodiscard]] Box bounds() const;
  /// Instances of the last commit, non-blocking ones included.
  [[nodiscard]] std::size_t size() const { return blocking_.size() + (crossing_ ? crossing_->size() : 0); }
  /// The tree over the blocking and medium instances (idAt() maps its slots to ids).
  [[nodiscard]] const KdTree& tree() const { return blocking_.tree(); }
  /// The crossing level: the tree of the non-blocking instances (nullptr before the first one
  /// arrives); its tree() and idAt() are those of these instances.
  [[nodiscard]] const InstanceTree* crossingLevel() const { return crossing_.get(); }
  /// Figures of both trees and of the last commit.
  [[nodiscard]] TopLevelStats stats() const;
  /// Bytes the top level holds per instance, excluding tree references (instance record and id map).
  [[nodiscard]] static std::size_t bytesPerInstance();

 private:
  InstanceTree& crossingLevelForEdit();
  /// Surfaces and media; its config() is this top level's.
  InstanceTree blocking_;
  /// Non-blocking instances, in a tree of their own (see the class comment).
  std::unique_ptr<InstanceTree> crossing_;
};

}  // namespace duplex
