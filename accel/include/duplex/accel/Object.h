#pragma once
/// \file Object.h
/// The interface every object type implements: bounds and ray queries in object space.
/// One coarse virtual interface, called once per instance visit; what happens inside an object
/// (its own acceleration structure and primitive tests) is statically dispatched.

#include "duplex/accel/Box.h"
#include "duplex/accel/ConvexRegion.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/PointQuery.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace duplex {

/// What an object does to a ray that meets it. Stored in the object (not a virtual call), so the
/// top level can filter instances before it pays for a bottom-level query.
enum class ObjectRole : std::uint8_t {
  /// Blocks rays: closest-hit and any-hit queries stop at it (meshes, level-set volumes).
  Surface,
  /// Attenuates rays without a hard hit: answered through transmittance() (fog volumes).
  Medium,
  /// Never blocks or changes a ray; records the rays that cross it (light sensors). Closest-hit
  /// and any-hit queries ignore it; intersectAll() reports its crossings, and the top level keeps
  /// such instances in a tree of their own (the crossing level).
  Crossing,
};

/// Where a flat object's crossings can lie (see Object::flatCrossings): object space, the closed
/// rectangle |x| <= half_width, |y| <= half_height of the plane z = 0, and, when front_only, only
/// for rays travelling towards -z.
struct FlatCrossings {
  float half_width = 0.0f;   ///< half extent along object-space x, object units
  float half_height = 0.0f;  ///< half extent along object-space y, object units
  bool front_only = false;   ///< only rays travelling towards -z cross
};

/// How a region query judges an instance (TopLevel::instancesInRegion, SceneTracer::selectRectangle).
enum class RegionMode : std::uint8_t {
  Boxes,     ///< its world box meets the region (conservative near the region's corners; the fastest)
  Touching,  ///< some of its geometry meets the region (meshes: a triangle)
  Inside,    ///< all of its geometry lies in the region (meshes: every vertex of every valid triangle)
};

/// A triangle an object reports to a region query (Object::trianglesInRegion), object space.
struct RegionTriangle {
  std::uint32_t prim_id = kInvalidId;      ///< the triangle's index in its object
  std::array<std::uint32_t, 3> vertex{};   ///< its vertex indices in the object's vertex list
  std::array<glm::vec3, 3> position_os{};  ///< its corners, object space, the object's units
};

/// A triangle of an instance found by a region query (TopLevel::trianglesInRegion), world space.
struct InstanceTriangle {
  std::uint32_t instance_id = kInvalidId;   ///< the instance's id
  std::uint32_t prim_id = kInvalidId;       ///< the triangle's index in the instance's object
  std::array<std::uint32_t, 3> vertex{};    ///< its vertex indices in the object's vertex list
  std::array<glm::dvec3, 3> position_ws{};  ///< its corners, world space (double, through the instance's transform)
};

/// One named count an object reports about itself for load summaries and JSON figures, e.g.
/// {"triangles", 12}. The name is a string literal of the type (it outlives the object).
struct ObjectFigure {
  std::string_view name;  ///< what is counted, e.g. "triangles"
  std::size_t value = 0;  ///< the count
};

/// A direct entry into an object's closest-hit and any-hit queries, for the top level's inner loop:
/// plain functions and the object's data, fetched once when an instance is committed and called per
/// visit without a virtual dispatch or a query context. A type offers one (Object::rayEntry) when
/// those queries read nothing but the object itself (meshes with a BVH). Both functions answer
/// exactly what Object::intersect and Object::occluded answer for the same object-space ray.
struct ObjectRayEntry {
  /// As Object::intersect(ray_os, hit, ctx); `data` is ObjectRayEntry::data.
  bool (*intersect)(const void* data, const Ray& ray_os, Hit& hit) = nullptr;
  /// As Object::occluded(ray_os, ctx).
  bool (*occluded)(const void* data, const Ray& ray_os) = nullptr;
  /// What both functions read; owned by the object and valid as long as it lives.
  const void* data = nullptr;
};

/// Throws InvalidArgument naming `what` (the query and its object) for a packet query given more
/// than kMaxPacketRays rays or fewer hits than rays (packetSizeOk in Ray.h is false).
[[noreturn]] void throwPacketSizeError(const std::string& what, std::size_t rays, std::size_t hits);

/// An immutable, shareable object (a mesh, a volume, a sensor). Any number of instances refer to
/// one Object and share its bottom-level structure. All methods are const and thread-safe; per-query
/// mutable state (caches, accessors, counters) lives in the QueryContext, one per thread.
class Object {
 public:
  virtual ~Object() = default;

  /// The registered type name ("mesh", ...).
  [[nodiscard]] virtual std::string_view typeName() const = 0;
  /// The user-visible name (the scene file's object name, or the file name).
  [[nodiscard]] const std::string& name() const { return name_; }
  /// What the object does to a ray that meets it (fixed at construction).
  [[nodiscard]] ObjectRole role() const { return role_; }
  /// Whether a hit on this object stops a ray (role() == Surface).
  [[nodiscard]] bool blocks() const { return role_ == ObjectRole::Surface; }
  /// Bounds in object space. Empty for an object that cannot be hit.
  [[nodiscard]] virtual Box bounds() const = 0;
  /// A 64-bit hash of what the object's queries answer from (a mesh: its positions and triangles),
  /// so that saved results can be checked against the objects they were computed with; 0 when the
  /// type computes none (the default). May take time linear in the object's size.
  [[nodiscard]] virtual std::uint64_t contentHash() const { return 0; }

  /// Closest hit of `ray_os` (object space, direction not normalised) with t in
  /// [ray_os.tnear, hit.t]. On a closer hit, overwrites hit.t, u, v, prim_id and hit.ng (object
  /// space geometric normal) and returns true; otherwise leaves `hit` alone and returns false.
  /// Objects that do not block (role() != Surface) are never asked.
  virtual bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const = 0;
  /// The object's direct entry for closest-hit and any-hit queries (see ObjectRayEntry), or an
  /// empty one (the default), which makes the top level call intersect() and occluded().
  [[nodiscard]] virtual ObjectRayEntry rayEntry() const { return {}; }
  /// Whether anything blocks `ray_os` within [tnear, tfar] (object space).
  [[nodiscard]] virtual bool occluded(const Ray& ray_os, QueryContext& ctx) const = 0;
  /// Appends every surface crossing of `ray_os` with t in [tnear, tfar] to `hits`, each once, in
  /// no particular order, with t, u, v, prim_id and ng filled as intersect() does. A ray through an
  /// edge or vertex shared by several primitives crosses once: meshes merge hits closer than 4 float
  /// epsilons (relative) in t into one.
  /// For picking through layers and, for sensors, the crossings a ray deposits energy in.
  virtual void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const = 0;
  /// Closest hits of a packet of up to kMaxPacketRays rays (object space, as intersect()): for
  /// every lane i set in `active` (bit i; lanes at or past rays_os.size() are ignored), exactly
  /// what intersect(rays_os[i], hits[i], ctx) does, bit for bit (same t, u, v, prim_id, ng).
  /// Returns the lanes whose hit was overwritten. `hits` must be as long as `rays_os`. Types with
  /// a packet traversal (meshes with a BVH) override it; the default asks intersect() lane by lane.
  /// Packets trace fastest when their rays are coherent: neighbouring camera pixels, shadow rays
  /// towards one light. Throws InvalidArgument for more than kMaxPacketRays rays or a short `hits`.
  virtual std::uint32_t intersectPacket(std::span<const Ray> rays_os, std::span<Hit> hits, std::uint32_t active,
                                        QueryContext& ctx) const;
  /// Any hit of a packet (object space, as occluded()): bit i of the result is set when lane i is
  /// in `active` and occluded(rays_os[i], ctx) holds. Default: occluded() lane by lane. Throws
  /// InvalidArgument for more than kMaxPacketRays rays.
  [[nodiscard]] virtual std::uint32_t occludedPacket(std::span<const Ray> rays_os, std::uint32_t active,
                                                     QueryContext& ctx) const;
  /// Optional: a bound of where intersectAll() can report crossings, for objects whose crossings
  /// all lie in a rectangle of their plane z = 0 (flat sensors). The crossing query then skips,
  /// without calling intersectAll(), an instance that a ray clearly misses (by a margin well above
  /// rounding); the crossings themselves always come from intersectAll(). Default: none.
  [[nodiscard]] virtual std::optional<FlatCrossings> flatCrossings() const { return std::nullopt; }
  /// Fraction of light that passes along [tnear, tfar] of `ray_os`, in [0, 1]. Surfaces: 0 when
  /// occluded, else 1; media override it.
  [[nodiscard]] virtual float transmittance(const Ray& ray_os, QueryContext& ctx) const {
    return role_ == ObjectRole::Surface && occluded(ray_os, ctx) ? 0.0f : 1.0f;
  }

  /// Optional closest-point query: when a point of the object lies closer to query.point_ws than
  /// best.distance (world units, measured through query.world_from_object), overwrites
  /// best.distance, point_ws, normal_ws and prim_id with the nearest such point and returns true;
  /// otherwise leaves `best` alone and returns false. Default: the type answers none (closest-point
  /// queries ignore it).
  virtual bool closestPoint(const PointQuery& query, ClosestPoint& best, QueryContext& ctx) const {
    (void)query;
    (void)best;
    (void)ctx;
    return false;
  }

  /// Optional region test for selection: whether the object's geometry meets (mode Touching) or
  /// lies entirely in (mode Inside) `region_os`, the region in this object's space. std::nullopt
  /// (the default): the type has none, and callers judge the object by its bounds. Never asked
  /// with mode Boxes.
  [[nodiscard]] virtual std::optional<bool> inRegion(const ConvexRegion& region_os, RegionMode mode) const {
    (void)region_os;
    (void)mode;
    return std::nullopt;
  }
  /// Optional, for tolerance picking: appends to `out` every triangle of the object that meets
  /// `region_os` (object space; degenerate triangles, which are never hit, are left out) with its
  /// vertex indices, and returns true. The default returns false: the type has no triangles to
  /// pick vertices and edges of.
  virtual bool trianglesInRegion(const ConvexRegion& region_os, std::vector<RegionTriangle>& out) const {
    (void)region_os;
    (void)out;
    return false;
  }

  /// Bytes held by the object's geometry and acceleration structure.
  [[nodiscard]] virtual std::size_t memoryBytes() const = 0;

  /// Named counts for load summaries ("triangles", "degenerate_triangles", "active_voxels", ...):
  /// the scene loader sums each name over the distinct objects of a scene. Default: none.
  [[nodiscard]] virtual std::vector<ObjectFigure> figures() const { return {}; }

  /// File name extension (with its dot, e.g. ".dkdt") of this type's prepared bottom-level
  /// structures: files that savePrepared() writes and the type's scene-file reader loads (the
  /// entry's "structure" key) instead of building. Empty (the default): the type has none.
  [[nodiscard]] virtual std::string_view preparedExtension() const { return {}; }
  /// Writes the bottom-level structure to `path` (replacing it atomically). Throws FileError naming
  /// the file when it cannot be written; InvalidArgument naming the object when its type has no
  /// prepared format (preparedExtension() empty, the default).
  virtual void savePrepared(const std::filesystem::path& path) const;

  /// How many object-space vertices deformed() takes; 0 (the default) when the type has none.
  [[nodiscard]] virtual std::size_t deformableVertexCount() const { return 0; }
  /// A new object: this one with its vertices moved to `positions_os` (object space, the object's
  /// own units, deformableVertexCount() of them in the object's vertex order), everything else kept.
  /// The type reuses what it can of its structure (meshes refit their BVH while its quality holds).
  /// This object is not changed. Throws InvalidArgument naming the object for a wrong count, a
  /// non-finite position, or a type that cannot be deformed (the default).
  [[nodiscard]] virtual std::shared_ptr<const Object> deformed(std::span<const glm::vec3> positions_os) const;

 protected:
  /// For the types: the user-visible `name` and the object's `role`.
  explicit Object(std::string name, ObjectRole role = ObjectRole::Surface) : name_(std::move(name)), role_(role) {}

 private:
  std::string name_;
  ObjectRole role_;
};

}  // namespace duplex
