#pragma once
/// \file TriangleMesh.h
/// Indexed triangle geometry in object space, validated once.

#include "duplex/accel/Box.h"

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

namespace duplex {

/// Positions (object space, any unit) and triangles as vertex-index triples. The triangle index is
/// the primitive id reported in hits. Degenerate triangles (an index repeated, a non-finite vertex,
/// or exactly zero area) stay in the list, so ids keep their meaning, but are never hit; they are
/// counted in degenerateCount().
class TriangleMesh {
 public:
  /// Vertex indices of one triangle, into positions().
  using Triangle = std::array<std::uint32_t, 3>;

  /// From flat arrays: positions x0 y0 z0 x1 ..., indices i0 i1 i2 (three per triangle). The CAD
  /// path: no file involved. `name` is used in error messages. Throws InvalidArgument when the
  /// array sizes are not multiples of 3, an index is out of range, or no triangle is valid.
  static TriangleMesh fromArrays(std::span<const float> positions, std::span<const std::uint32_t> indices,
                                 std::string name);
  /// Same, from vectors of points and triangles.
  static TriangleMesh fromTriangles(std::vector<glm::vec3> positions, std::vector<Triangle> triangles,
                                    std::string name);

  /// This mesh's triangles and name with other vertex positions (object space, as many as
  /// positions() has, all finite): a deformation step. The triangle list is shared, not copied;
  /// validity and bounds are computed for the new positions. Throws InvalidArgument naming the mesh
  /// for another count, a non-finite position, or no valid triangle.
  [[nodiscard]] TriangleMesh withPositions(std::vector<glm::vec3> positions) const;
  /// Whether a triangle with the finite corners a, b, c has an area: its edges' cross product, in
  /// double, is not exactly zero. With finite positions this is the whole validity test (a
  /// repeated index gives a zero edge), which deformations repeat for the moved corners.
  [[nodiscard]] static bool hasArea(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
    const glm::dvec3 n = glm::cross(glm::dvec3(b) - glm::dvec3(a), glm::dvec3(c) - glm::dvec3(a));
    return n != glm::dvec3(0.0);
  }
  /// Whether the same triangles are valid in both meshes (same triangle count, same flags).
  [[nodiscard]] bool sameValidity(const TriangleMesh& other) const { return valid_ == other.valid_; }

  /// The name given at construction (used in error messages).
  [[nodiscard]] const std::string& name() const { return name_; }
  /// Vertex positions, object space.
  [[nodiscard]] const std::vector<glm::vec3>& positions() const { return positions_; }
  /// Triangles as index triples, degenerate ones included; the index is the primitive id.
  [[nodiscard]] const std::vector<Triangle>& triangles() const { return *triangles_; }
  /// Number of triangles, degenerate ones included.
  [[nodiscard]] std::size_t triangleCount() const { return triangles_->size(); }
  /// Whether triangle `i` can be hit (not degenerate). Precondition here and in vertices():
  /// i < triangleCount() (not checked: per-triangle loops).
  [[nodiscard]] bool isValid(std::size_t i) const { return valid_[i] != 0; }
  /// Number of triangles that are never hit (see the class comment).
  [[nodiscard]] std::size_t degenerateCount() const { return degenerate_count_; }
  /// Object-space bounds of the valid triangles.
  [[nodiscard]] const Box& bounds() const { return bounds_; }
  /// The three object-space vertices of triangle `i`.
  [[nodiscard]] std::array<glm::vec3, 3> vertices(std::size_t i) const {
    const Triangle& t = (*triangles_)[i];
    return {positions_[t[0]], positions_[t[1]], positions_[t[2]]};
  }

 private:
  friend class MeshObject;
  TriangleMesh() = default;
  /// Throws InvalidArgument naming the mesh unless `positions` has positions().size() entries,
  /// all finite.
  void checkPositions(std::span<const glm::vec3> positions) const;
  /// withPositions() without its validity pass, for a caller that has tested every triangle
  /// itself (MeshObject's refit, in its pass over the leaves): `positions` are checked
  /// (checkPositions), every triangle has this mesh's validity with them (hasArea), and `bounds`
  /// are the bounds of the valid triangles. Only the positions are checked here.
  [[nodiscard]] TriangleMesh withPositionsOfSameValidity(std::vector<glm::vec3> positions, const Box& bounds) const;
  /// Checks every index (when `check_indices`) and computes validity, bounds and the degenerate count.
  void validate(bool check_indices = true);

  std::string name_;
  std::vector<glm::vec3> positions_;
  // Shared by the meshes withPositions() makes from this one (a deformation keeps the triangles).
  std::shared_ptr<const std::vector<Triangle>> triangles_;
  std::vector<std::uint8_t> valid_;
  std::size_t degenerate_count_ = 0;
  Box bounds_;
};

}  // namespace duplex
