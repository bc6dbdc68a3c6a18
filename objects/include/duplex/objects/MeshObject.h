#pragma once
/// \file MeshObject.h
/// The triangle-mesh object type: a TriangleMesh with its SAH kd-tree.

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/Object.h"
#include "duplex/objects/TriangleMesh.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace duplex {

/// Immutable after construction; all queries are thread-safe.
class MeshObject final : public Object {
 public:
  static constexpr std::string_view kTypeName = "mesh";

  /// Builds the kd-tree over the mesh's valid triangles (object space).
  explicit MeshObject(std::shared_ptr<const TriangleMesh> mesh, const KdBuildConfig& config = {});

  /// From a kd-tree built before (e.g. read from a file by loadMeshObject) over `mesh`'s triangles:
  /// no build. The tree is checked first, so that no later query can read out of bounds or loop:
  /// nodes in depth-first layout (each inner node's upper child right after its lower subtree, every
  /// node reached once), depth within the traversal stack, finite split planes, leaf ranges inside
  /// prim_indices, every index a valid (non-degenerate) triangle of `mesh`, and finite bounds that
  /// hold the mesh's bounds. Throws InvalidArgument naming the first violation. Linear time.
  [[nodiscard]] static std::shared_ptr<const MeshObject> fromParts(std::shared_ptr<const TriangleMesh> mesh,
                                                                   KdTree tree);

  [[nodiscard]] std::string_view typeName() const override { return kTypeName; }
  [[nodiscard]] Box bounds() const override { return mesh_->bounds(); }
  bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const override;
  [[nodiscard]] bool occluded(const Ray& ray_os, QueryContext& ctx) const override;
  void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const override;
  [[nodiscard]] std::size_t memoryBytes() const override;

  /// The same queries without the virtual call and context (for benchmarks and the bottom level).
  bool intersect(const Ray& ray_os, Hit& hit) const;
  [[nodiscard]] bool occluded(const Ray& ray_os) const;

  [[nodiscard]] const TriangleMesh& mesh() const { return *mesh_; }
  [[nodiscard]] const KdTree& tree() const { return tree_; }
  /// Bytes of the acceleration structure (nodes, index list, leaf-ordered triangle copies).
  [[nodiscard]] std::size_t accelBytes() const;

 private:
  struct PartsTag {};
  MeshObject(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, PartsTag);
  /// Fills leaf_refs_, triangles_ and prim_ids_ from tree_ (the leaf-order renumbering below).
  void orderTrianglesByLeaves();

  // Vertices of each triangle by triangle id (36 bytes), so that a leaf reference is a 4-byte
  // index: random rays are bound by memory latency, and copying triangles per reference
  // (40 bytes each, 2-4 references per triangle) made the working set several times larger.
  struct TriangleVertices {
    glm::vec3 v0, v1, v2;
  };
  std::shared_ptr<const TriangleMesh> mesh_;
  KdTree tree_;  // prim_indices hold mesh triangle ids (what tests and tools inspect)
  std::vector<std::uint32_t> leaf_refs_;  // tree_.prim_indices renumbered into triangles_
  // Triangles renumbered in the order the leaves first reference them (depth first), so that
  // the triangles of one leaf and of neighbouring leaves share cache lines.
  std::vector<TriangleVertices> triangles_;
  std::vector<std::uint32_t> prim_ids_;  // renumbered index -> triangle index in the mesh
};

}  // namespace duplex
