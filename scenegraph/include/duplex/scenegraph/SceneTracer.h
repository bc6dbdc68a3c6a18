#pragma once
/// \file SceneTracer.h
/// Ray queries against a SceneGraph. The tracer observes the graph: each commit updates its top
/// level incrementally (only the instances the ChangeSet names), bottom-level structures are shared
/// per object. Hits come back in world space with the instance's node id and path.
///
/// Threading: queries (const) may run concurrently from any number of threads; a commit of the
/// graph waits until running queries finish and blocks new ones while it updates the top level
/// (a reader-writer lock that prefers the commit: once it waits, no new query starts, so it waits
/// only for the queries already running), so a query sees either the scene before or after a
/// commit, never a mix.
/// Edits that are not committed yet are invisible to queries.

#include "duplex/accel/Hit.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/accel/WorkControl.h"
#include "duplex/scenegraph/SceneGraph.h"

#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <vector>

namespace duplex {

/// A full hit, computed once for the winner (two-phase hits).
struct SceneHit {
  Hit hit;  ///< t (units of the world ray's direction), u, v, prim_id, instance_id = node id, world ng
  NodeId instance = kInvalidNode;  ///< the instance node hit (kInvalidNode for a miss)
  glm::dvec3 position_ws{0.0};     ///< recomputed in double from the object-space hit
  glm::dvec3 normal_ws{0.0};       ///< unit geometric normal, world space
  std::vector<NodeId> path;        ///< node ids from below the root down to the instance, as of the last commit

  /// Whether the ray hit something.
  [[nodiscard]] bool valid() const { return hit.valid(); }
};

/// The nearest surface point to a world point, with the instance node and its path (see
/// SceneTracer::closestPoint).
struct SceneClosestPoint {
  /// distance (world units; +inf when nothing is within reach), point_ws, normal_ws (unit),
  /// prim_id, instance_id (= the instance node id)
  ClosestPoint point;
  NodeId instance = kInvalidNode;  ///< the instance node (kInvalidNode when nothing was found)
  std::vector<NodeId> path;        ///< node ids from below the root down to the instance, as of the last commit

  /// Whether a point was found.
  [[nodiscard]] bool valid() const { return point.valid(); }
};

/// One request of a batch of closest-point queries.
struct ClosestPointRequest {
  glm::dvec3 point_ws{0.0};                                       ///< the query point, world space
  double max_distance = std::numeric_limits<double>::infinity();  ///< world units, inclusive; +inf: no limit
};

/// Which hits pick() returns.
enum class PickMode : std::uint8_t {
  Nearest,      ///< the closest hit: a surface, or a sensor when the mask selects sensors
  AllSorted,    ///< every hit along the ray, sorted by t
  PerInstance,  ///< the closest hit of each instance, sorted by t
};

/// The kind of element a tolerance pick found (SceneTracer::pickElement).
enum class PickElement : std::uint8_t {
  None,    ///< nothing within the pick radius
  Vertex,  ///< a mesh vertex
  Edge,    ///< a mesh edge (two vertices)
  Face,    ///< the surface under the cursor (meshes: a triangle; other types: their primitive)
};

/// What SceneTracer::pickElement looks for.
struct PickOptions {
  /// Pick radius around the cursor, in pixels (>= 0, finite): vertices and edges whose projection
  /// lies within it count. 0: the face under the cursor only.
  double radius_px = 5.0;
  bool vertices = true;  ///< look for vertices
  bool edges = true;     ///< look for edges
  bool faces = true;     ///< fall back to the face under the cursor
  /// Feature filter, degrees in [0, 180): an edge counts only where its two faces' normals differ
  /// by more than this angle, or where it bounds the mesh (one face) or is shared by more than two;
  /// a vertex only at an end of such an edge. 0: every edge and vertex (the tessellation's own).
  /// The angle is that of the object's own (object-space) faces, so an instance's scale does not
  /// change which edges count. CAD parts read as meshes show their design edges at 20-40 degrees.
  double feature_angle_deg = 0.0;
  std::uint32_t mask = 0xFFFFFFFFu;  ///< instances whose mask meets it (also what can hide an element)
};

/// The element a tolerance pick found (SceneTracer::pickElement); world space, double precision.
struct ElementPick {
  PickElement kind = PickElement::None;  ///< what was found
  NodeId instance = kInvalidNode;        ///< its instance node
  std::vector<NodeId> path;              ///< node ids from below the root down to the instance (last commit)
  std::uint32_t prim_id = kInvalidId;    ///< the face; for a vertex or an edge, a triangle that has it
  std::uint32_t vertex = kInvalidId;     ///< Vertex: its index in the object's vertex list
  std::array<std::uint32_t, 2> edge{kInvalidId, kInvalidId};  ///< Edge: its two vertex indices, ascending
  /// The vertex; the point of the edge whose projection is nearest the cursor; the face's hit point.
  glm::dvec3 point_ws{0.0};
  double distance_px = 0.0;  ///< distance on screen from the cursor to point_ws's projection, pixels
  double depth = 0.0;        ///< distance from the eye to point_ws, world units

  /// Whether something was found.
  [[nodiscard]] bool valid() const { return kind != PickElement::None; }
};

/// Ray queries against a SceneGraph, kept up to date by its commits (see the file comment). Rays and hits are in world
/// space; t is in units of the world ray's direction.
class SceneTracer {
 public:
  /// Subscribes to `graph` (which must outlive the tracer) and builds the top level over its
  /// visible instances as of its last commit. Throws InvalidArgument when the graph has uncommitted
  /// edits.
  explicit SceneTracer(SceneGraph& graph, const TopLevelConfig& config = {});
  ~SceneTracer();
  SceneTracer(const SceneTracer&) = delete;
  SceneTracer& operator=(const SceneTracer&) = delete;

  /// Closest blocking hit (preliminary: world t, u, v, prim_id, instance_id = node id, world ng).
  [[nodiscard]] Hit intersect(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Whether a surface blocks the world ray within [tnear, tfar].
  [[nodiscard]] bool occluded(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Fraction of light passing along [tnear, tfar] of a world ray: 0 when a surface blocks it, else
  /// the product of the transmittances of the media (fog volumes) it crosses (TopLevel::transmittance).
  [[nodiscard]] float transmittance(const Ray& ray_ws, QueryContext& ctx, std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Every hit along the ray within [tnear, tfar], sorted by t (sensors included when the mask selects them).
  [[nodiscard]] std::vector<Hit> intersectAll(const Ray& ray_ws, QueryContext& ctx,
                                              std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Closest hit with position, normal and path; the ray is transformed in double. The node path is
  /// read from the graph: call it (and pick()) from the thread that edits the graph, or while no
  /// edit or commit runs; intersect(), occluded(), intersectAll() and the batch queries have no
  /// such restriction.
  [[nodiscard]] SceneHit intersectDetailed(const RayD& ray_ws, QueryContext& ctx,
                                           std::uint32_t mask = 0xFFFFFFFFu) const;

  /// Batch versions, in parallel over the rays with TBB (one QueryContext per task). `hits` /
  /// `occluded` / `transmittance` must have the size of `rays` (else InvalidArgument, nothing
  /// written). control.progress gets (rays done, rays.size()) after each chunk of rays; once
  /// control.cancel is set no further chunk starts and Cancelled is thrown (the output is then
  /// incomplete).
  ///
  /// intersect(), occluded() and their streamed forms intersectBlocks() / occludedBlocks() trace
  /// packets of kMaxPacketRays consecutive rays (TopLevel::intersectPacket) unless
  /// setBatchPackets(false): the results are the same bit for bit, only the speed differs. Order
  /// the rays so that neighbours are coherent (camera rays in small tiles, e.g. 4 x 4 pixels, or
  /// rows; shadow rays in the order of the points they start from); incoherent rays (random
  /// directions) trace at the single-ray speed.
  void intersect(std::span<const Ray> rays, std::span<Hit> hits, std::uint32_t mask = 0xFFFFFFFFu,
                 const WorkControl& control = {}) const;
  /// Batch occluded(): occluded[i] is 1 when rays[i] is blocked, else 0.
  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded, std::uint32_t mask = 0xFFFFFFFFu,
                const WorkControl& control = {}) const;
  /// Batch transmittance(): transmittance[i] in [0, 1] for rays[i].
  void transmittance(std::span<const Ray> rays, std::span<float> transmittance, std::uint32_t mask = 0xFFFFFFFFu,
                     const WorkControl& control = {}) const;
  /// Batch intersectAll (picking through layers, many rays): on return `offsets` holds rays.size()
  /// + 1 entries and the hits of rays[i] are hits[offsets[i], offsets[i + 1]), sorted by t as
  /// intersectAll(ray) returns them (world t, world normal; sensors when the mask selects them).
  /// Both vectors are replaced (an empty span gives offsets {0} and no hits). Flat rather than a
  /// vector per ray, so the result is one allocation (each ray's hits are gathered in a list of
  /// its own while tracing, then copied).
  /// Progress and cancellation as the batch queries above (the vectors are then unchanged).
  void intersectAll(std::span<const Ray> rays, std::vector<Hit>& hits, std::vector<std::size_t>& offsets,
                    std::uint32_t mask = 0xFFFFFFFFu, const WorkControl& control = {}) const;

  /// Reads rays [first, first + rays.size()) of a streamed batch into `rays` (world space; at most
  /// kStreamBlock of them per call).
  using RayBlockLoader = std::function<void(std::size_t first, std::span<Ray> rays)>;
  /// Receives the hits of rays [first, first + hits.size()) of a streamed batch.
  using HitBlockStore = std::function<void(std::size_t first, std::span<const Hit> hits)>;
  /// Receives the occlusion flags (1: blocked) of rays [first, first + occluded.size()).
  using OccludedBlockStore = std::function<void(std::size_t first, std::span<const std::uint8_t> occluded)>;
  /// Whether the batch closest-hit and any-hit queries (span and streamed) trace packets (the
  /// default) or one ray at a time; the results are identical. Safe to call while queries run (a
  /// batch reads it once, when it starts).
  void setBatchPackets(bool on);
  /// See setBatchPackets.
  [[nodiscard]] bool batchPackets() const;

  /// Rays per call of a streamed batch's loader and store.
  static constexpr std::size_t kStreamBlock = 256;
  /// Batch intersect() of `count` rays that the caller supplies and collects block by block, so
  /// that neither the rays nor the hits need a whole-batch array (rays converted from another
  /// layout, hits scattered into several arrays or written out as they come). `load` and `store`
  /// are called from the worker threads, concurrently for disjoint blocks, each block's store
  /// after its load; an exception from either stops the batch and reaches the caller. Results
  /// equal the span version's. Progress and cancellation as the batch queries above.
  void intersectBlocks(std::size_t count, const RayBlockLoader& load, const HitBlockStore& store,
                       std::uint32_t mask = 0xFFFFFFFFu, const WorkControl& control = {}) const;
  /// Batch occluded() streamed as intersectBlocks().
  void occludedBlocks(std::size_t count, const RayBlockLoader& load, const OccludedBlockStore& store,
                      std::uint32_t mask = 0xFFFFFFFFu, const WorkControl& control = {}) const;

  /// The point of the visible surface instances (mask meeting `mask`) nearest to `point_ws`
  /// within `max_distance` (world units, inclusive; +inf for no limit), in double precision, with
  /// the instance's node path: meshes answer with their triangles (distance measured in world
  /// space through the instance's transform, any scale), level sets with their zero crossing
  /// (VolumeObject::closestPoint); media (fog) and sensors, which are not surfaces, are ignored.
  /// Nothing within reach, a non-finite point or a NaN or negative
  /// max_distance give an invalid result (distance +inf).
  [[nodiscard]] SceneClosestPoint closestPoint(const glm::dvec3& point_ws,
                                               double max_distance = std::numeric_limits<double>::infinity(),
                                               std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Batch closestPoint() without the paths, in parallel with TBB: out[i] answers requests[i]
  /// (instance_id = the instance node id). `out` must have the size of `requests` (else
  /// InvalidArgument, nothing written). Progress and cancellation as the batch ray queries.
  void closestPoints(std::span<const ClosestPointRequest> requests, std::span<ClosestPoint> out,
                     std::uint32_t mask = 0xFFFFFFFFu, const WorkControl& control = {}) const;

  /// Picking through pixel (px, py) (continuous pixel coordinates, (0, 0) the top-left corner,
  /// (w, h) the bottom-right) of a width x height image seen by `camera` (world space). Throws
  /// InvalidArgument for a zero image size, non-finite pixel coordinates, or a camera with
  /// non-finite vectors, zero or parallel axes, or a field of view outside (0, 180) degrees.
  [[nodiscard]] std::vector<SceneHit> pick(const PinholeCamera& camera, double px, double py, std::uint32_t width,
                                           std::uint32_t height, PickMode mode = PickMode::Nearest,
                                           std::uint32_t mask = 0xFFFFFFFFu) const;
  /// Tolerance picking as CAD users expect it: the visible vertex, else edge, within
  /// options.radius_px of pixel (px, py) (continuous pixel coordinates as pick()), else the face
  /// under the cursor (pick() with PickMode::Nearest). Among vertices (and among edges) the one
  /// nearest the cursor on screen wins, ties by depth. An element is visible when nothing that
  /// options.mask selects blocks the segment from the eye to it (up to 1e-4 of its distance, so
  /// that its own faces do not hide it). Elements come from the objects' triangles
  /// (Object::trianglesInRegion, meshes); other types answer with faces only. Hidden nodes are not
  /// in the top level and are never picked. Throws InvalidArgument as pick() does, and for a
  /// negative or non-finite radius or a feature angle outside [0, 180).
  [[nodiscard]] ElementPick pickElement(const PinholeCamera& camera, double px, double py, std::uint32_t width,
                                        std::uint32_t height, const PickOptions& options = {}) const;
  /// pickElement() looks vertices and edges up in an index of each object's feature edges (per
  /// feature angle, object space), built by the first pick that meets the object and kept while
  /// the object lives. This builds them now, in parallel, for every visible instance's object at
  /// `feature_angle_deg` (degrees in [0, 180), else InvalidArgument), so that the first picks do
  /// not wait (an interactive viewer calls it after loading).
  void preparePicking(double feature_angle_deg) const;
  /// Rectangle selection: the visible instances (mask meeting `mask`, sensors included) selected by
  /// the frustum through the pixel rectangle [x0, x1] x [y0, y1] (continuous pixel coordinates),
  /// sorted by node id. RegionMode::Touching (the default): some of the instance's geometry meets
  /// the frustum (meshes: a triangle, exactly up to rounding); Inside: all of it lies within;
  /// Boxes: its world box meets the frustum (fastest; the first step of the other two). Types
  /// without a geometric test are judged by their boxes. Occlusion plays no part (as a CAD
  /// window / crossing selection). Throws as pick() does, and for non-finite rectangle coordinates.
  [[nodiscard]] std::vector<NodeId> selectRectangle(const PinholeCamera& camera, double x0, double y0, double x1,
                                                    double y1, std::uint32_t width, std::uint32_t height,
                                                    std::uint32_t mask = 0xFFFFFFFFu,
                                                    RegionMode mode = RegionMode::Touching) const;

  /// World bounds of the top level (last commit): contains every visible instance. Tight after
  /// every commit for up to 256 instances; above that it may stay larger than tight for up to 32
  /// commits after instances moved inwards or disappeared (the shrink is amortised).
  [[nodiscard]] Box bounds() const;
  /// Figures of the top level and of its last update.
  [[nodiscard]] TopLevelStats stats() const;
  /// Milliseconds the last commit spent in the tracer (top-level update).
  [[nodiscard]] double lastUpdateMs() const;
  /// Forces a full top-level rebuild now (benchmark baseline).
  void rebuild();
  /// The observed graph.
  [[nodiscard]] const SceneGraph& graph() const { return graph_; }
  /// The top level itself, for tools and tests (no locking: do not use while the graph commits).
  [[nodiscard]] const TopLevel& topLevel() const;

 private:
  struct Impl;
  SceneGraph& graph_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace duplex
