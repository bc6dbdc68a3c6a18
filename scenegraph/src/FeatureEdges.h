#pragma once
/// \file FeatureEdges.h
/// An object's feature edges, indexed for tolerance picking (SceneTracer::pickElement): the edges of
/// its triangles (Object::trianglesInRegion) whose two faces meet at more than a feature angle, that
/// bound the mesh (one face) or that more than two faces share, each edge once, in a binary BVH over
/// the segments. A pick then visits only the edges near the cursor instead of every triangle in the
/// pick frustum (on CAD parts, thousands of slivers along the whole depth of the part).
/// Object space throughout; built once per object and feature angle, read by any number of threads.

#include "duplex/accel/Box.h"
#include "duplex/accel/ConvexRegion.h"
#include "duplex/accel/Object.h"

#include <glm/vec3.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace duplex {

class FeatureEdges {
 public:
  /// One edge: its vertex indices (low < high) and their object-space positions in that order.
  struct Edge {
    std::array<glm::vec3, 2> p;  ///< object space, the object's units: p[0] at `low`, p[1] at `high`
    std::uint32_t low = 0;       ///< the lower vertex index
    std::uint32_t high = 0;      ///< the higher vertex index
    std::uint32_t prim = 0;      ///< the lowest prim id among the (valid) triangles around the edge
  };

  /// The feature edges of `object` at `feature_angle_deg` (degrees in [0, 180); 0: every edge of
  /// the tessellation); the angle is measured between the faces' object-space normals. nullptr when
  /// the object reports no triangles (types other than meshes).
  [[nodiscard]] static std::shared_ptr<const FeatureEdges> build(const Object& object, double feature_angle_deg);

  /// Appends to `out` the index of every edge that shares a point with `region_os` (object space;
  /// exact up to rounding: the segment is clipped by every plane).
  void query(const ConvexRegion& region_os, std::vector<std::uint32_t>& out) const;

  [[nodiscard]] const Edge& edge(std::uint32_t i) const { return edges_[i]; }
  [[nodiscard]] std::size_t size() const { return edges_.size(); }
  /// Bytes held (edges and nodes).
  [[nodiscard]] std::size_t memoryBytes() const;

 private:
  /// A BVH node; inner nodes have count == 0, their left child follows them and `first` is the
  /// right child; leaves hold edges_[first, first + count).
  struct Node {
    Box box;
    std::uint32_t first = 0;
    std::uint32_t count = 0;
  };
  std::uint32_t buildNode(std::vector<std::uint32_t>& order, std::vector<glm::vec3>& centre, std::uint32_t begin,
                          std::uint32_t end);

  std::vector<Edge> edges_;  ///< in the order of the BVH's leaves
  std::vector<Node> nodes_;
};

}  // namespace duplex
