#pragma once
/// \file MeshObject.h
/// The triangle-mesh object type: a TriangleMesh with its bottom-level structure, a wide BVH (the
/// default) or an SAH kd-tree.

#include "duplex/accel/BvhBuildConfig.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/Object.h"
#include "duplex/objects/TriangleMesh.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

namespace duplex {

struct KdTree;   // duplex/accel/KdTree.h
struct WideBvh;  // duplex/accel/WideBvh.h

namespace detail {
struct MeshParts;  // the structures and leaf blocks (objects/mesh/src/MeshParts.h)
}  // namespace detail

/// The bottom-level structures a mesh can have.
enum class MeshStructure {
  Bvh,     ///< 8-wide BVH (WideBvh.h): the default, fastest to build and to trace
  KdTree,  ///< SAH kd-tree with clipped triangles (KdTree.h)
};

/// "bvh" or "kdtree", the names of the scene files' "structure" key.
std::string_view toString(MeshStructure s);
/// Parses "bvh" or "kdtree"; throws InvalidArgument otherwise.
MeshStructure parseMeshStructure(std::string_view name);

/// Which structure a mesh gets and the parameters of its build.
struct MeshBuildConfig {
  MeshStructure structure = MeshStructure::Bvh;  ///< the structure to build
  BvhBuildConfig bvh;                            ///< parameters when structure is Bvh
  KdBuildConfig kd;                              ///< parameters when structure is KdTree
};

/// Immutable after construction; all queries are thread-safe.
class MeshObject final : public Object {
 public:
  /// The registered type name.
  static constexpr std::string_view kTypeName = "mesh";

  /// Builds config.structure over the mesh's valid triangles (object space). Throws
  /// InvalidArgument for a null mesh or an invalid config (naming the mesh).
  explicit MeshObject(std::shared_ptr<const TriangleMesh> mesh, const MeshBuildConfig& config = {});
  /// Builds a kd-tree with `config`.
  MeshObject(std::shared_ptr<const TriangleMesh> mesh, const KdBuildConfig& config);
  /// Builds a BVH with `config`.
  MeshObject(std::shared_ptr<const TriangleMesh> mesh, const BvhBuildConfig& config);
  ~MeshObject() override;

  /// From a kd-tree built before (e.g. read from a file by loadMeshObject) over `mesh`'s triangles:
  /// no build. The tree is checked first, so that no later query can read out of bounds or loop:
  /// nodes in depth-first layout (each inner node's upper child right after its lower subtree, every
  /// node reached once), depth within the traversal stack, finite split planes, leaf ranges inside
  /// prim_indices, every index a valid (non-degenerate) triangle of `mesh`, and finite bounds that
  /// hold the mesh's bounds. Throws InvalidArgument naming the first violation. Linear time.
  [[nodiscard]] static std::shared_ptr<const MeshObject> fromParts(std::shared_ptr<const TriangleMesh> mesh,
                                                                   KdTree tree);
  /// From a BVH built before over `mesh`'s triangles: no build. Checked first as the kd-tree is:
  /// every node reached exactly once from the root in depth-first order (parents before
  /// children), depth within WideBvh::kMaxDepth, used slots before empty ones with finite boxes,
  /// empty slots with box [+inf, -inf], leaf ranges inside prim_indices with padding after them,
  /// every index a valid triangle of `mesh`, and bounds that hold the mesh's valid triangles.
  /// Throws InvalidArgument naming the first violation. Linear time.
  [[nodiscard]] static std::shared_ptr<const MeshObject> fromParts(std::shared_ptr<const TriangleMesh> mesh,
                                                                   WideBvh bvh);

  [[nodiscard]] std::string_view typeName() const override { return kTypeName; }
  [[nodiscard]] Box bounds() const override { return mesh_->bounds(); }
  bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const override;
  [[nodiscard]] bool occluded(const Ray& ray_os, QueryContext& ctx) const override;
  /// The BVH's kernels with this object's view (ObjectRayEntry); empty for the kd-tree structure.
  [[nodiscard]] ObjectRayEntry rayEntry() const override;
  void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const override;
  /// With the BVH: the rays of one octant traced together through the tree, in packets of the SIMD
  /// path's width (4, 8 or 16 rays), bit for bit the hits of intersect(); with the kd-tree: ray by
  /// ray. See Object::intersectPacket (object space).
  std::uint32_t intersectPacket(std::span<const Ray> rays_os, std::span<Hit> hits, std::uint32_t active,
                                QueryContext& ctx) const override;
  /// As intersectPacket, for any hit. See Object::occludedPacket (object space).
  [[nodiscard]] std::uint32_t occludedPacket(std::span<const Ray> rays_os, std::uint32_t active,
                                             QueryContext& ctx) const override;
  /// The nearest point of the mesh's valid triangles to query.point_ws, measured in world space
  /// (each candidate triangle mapped by query.world_from_object, in double), found through the BVH
  /// or the kd-tree with the boxes pruned by the best distance so far. See Object::closestPoint.
  bool closestPoint(const PointQuery& query, ClosestPoint& best, QueryContext& ctx) const override;
  /// Whether a valid triangle meets `region_os` (Touching) or every valid triangle lies in it
  /// (Inside), exactly up to rounding, through the structure's boxes (object space). See
  /// Object::inRegion.
  [[nodiscard]] std::optional<bool> inRegion(const ConvexRegion& region_os, RegionMode mode) const override;
  /// Every valid triangle meeting `region_os` (object space), each once, by prim id. See
  /// Object::trianglesInRegion.
  bool trianglesInRegion(const ConvexRegion& region_os, std::vector<RegionTriangle>& out) const override;
  [[nodiscard]] std::size_t memoryBytes() const override;
  /// meshChecksum() of the mesh (XXH64 of positions and triangle indices, as prepared structure
  /// files check it).
  [[nodiscard]] std::uint64_t contentHash() const override;
  /// "triangles" and "degenerate_triangles" of the mesh.
  [[nodiscard]] std::vector<ObjectFigure> figures() const override;
  /// The prepared-structure files of MeshObjectFile.h: ".dbvh" for a BVH, ".dkdt" for a kd-tree.
  [[nodiscard]] std::string_view preparedExtension() const override {
    return structure_ == MeshStructure::Bvh ? ".dbvh" : ".dkdt";
  }
  /// saveMeshObject(*this, path) (MeshObjectFile.h).
  void savePrepared(const std::filesystem::path& path) const override;
  /// The mesh's vertex count (positions().size(), degenerate triangles' vertices included).
  [[nodiscard]] std::size_t deformableVertexCount() const override { return mesh_->positions().size(); }
  /// deformedMesh(positions_os).
  [[nodiscard]] std::shared_ptr<const Object> deformed(std::span<const glm::vec3> positions_os) const override;

  /// A new mesh object with the same triangles and name, its vertices at `positions_os` (object
  /// space, one per vertex of mesh(), in order). A BVH is refitted (the topology kept, the boxes
  /// recomputed, linear time) unless the refitted tree's SAH cost exceeds
  /// buildConfig().bvh.refit_limit times builtSahCost(), or a triangle changed between degenerate
  /// and valid; then, and for a kd-tree (its clipped splits cannot be refitted), the structure is
  /// built anew with buildConfig(). wasRefitted() of the result says which happened. Throws
  /// InvalidArgument naming the mesh for a wrong count or a non-finite position, or when no
  /// triangle stays valid; this object is unchanged either way.
  [[nodiscard]] std::shared_ptr<const MeshObject> deformedMesh(std::span<const glm::vec3> positions_os) const;
  /// Whether the structure is a refit of an earlier object's (deformedMesh) rather than a build.
  [[nodiscard]] bool wasRefitted() const { return refitted_; }
  /// The parameters the structure was built with (for objects from fromParts: the defaults of
  /// their structure); deformedMesh() rebuilds with them.
  [[nodiscard]] const MeshBuildConfig& buildConfig() const { return config_; }
  /// BVH: the SAH cost (WideBvh::sahCost with buildConfig().bvh's costs) of the tree as it was
  /// last built, before any refit; 0 for a kd-tree.
  [[nodiscard]] double builtSahCost() const { return built_sah_; }
  /// BVH: the SAH cost of the tree as it is now (after refits); 0 for a kd-tree.
  [[nodiscard]] double sahCost() const;

  /// The same queries without the virtual call and context (for benchmarks and the bottom level).
  bool intersect(const Ray& ray_os, Hit& hit) const;
  /// Whether anything blocks `ray_os` (object space) within [tnear, tfar], without the context.
  [[nodiscard]] bool occluded(const Ray& ray_os) const;

  /// The mesh, object space.
  [[nodiscard]] const TriangleMesh& mesh() const { return *mesh_; }
  /// Which structure the object has.
  [[nodiscard]] MeshStructure structure() const { return structure_; }
  /// The kd-tree over the mesh's triangles (object space; prim_indices hold triangle ids); empty
  /// (no nodes) when the structure is the BVH. Include duplex/accel/KdTree.h to read it.
  [[nodiscard]] const KdTree& tree() const;
  /// The BVH over the mesh's triangles (object space; prim_indices hold triangle ids); empty (root
  /// kEmpty, no nodes) when the structure is the kd-tree. Include duplex/accel/WideBvh.h to read it.
  [[nodiscard]] const WideBvh& bvh() const;
  /// Bytes of the acceleration structure (nodes, index list, per-leaf triangle blocks).
  [[nodiscard]] std::size_t accelBytes() const;

 private:
  struct PartsTag {};
  MeshObject(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, PartsTag);
  MeshObject(std::shared_ptr<const TriangleMesh> mesh, WideBvh bvh, PartsTag);
  struct RefitTag {};
  /// An object with `from`'s name, configuration and built cost, marked refitted, and nothing
  /// else: deformedMesh() fills its mesh, BVH and blocks.
  MeshObject(const MeshObject& from, RefitTag);
  void buildKd(const KdBuildConfig& config);
  void buildBvh(const BvhBuildConfig& config);
  /// Fills the leaf blocks and block_tree from the kd-tree (MeshParts.h).
  void buildLeafBlocks();
  /// Fills the leaf blocks from the BVH: block k holds its prim_indices[4k, 4k + 4), and makes the view.
  void buildBvhBlocks();
  /// Points the view at the BVH and the blocks (once both are final).
  void makeView();

  std::shared_ptr<const TriangleMesh> mesh_;
  MeshStructure structure_ = MeshStructure::Bvh;
  MeshBuildConfig config_;
  double built_sah_ = 0.0;  // BVH: SAH cost at the last build (refits compare against it)
  bool refitted_ = false;
  // The BVH or kd-tree, the leaf blocks and the kernels' view: never null. Behind a pointer so that
  // this header does not include the structures (one more load per instance visit, beside the
  // virtual call already paid there).
  std::unique_ptr<detail::MeshParts> parts_;
};

}  // namespace duplex
