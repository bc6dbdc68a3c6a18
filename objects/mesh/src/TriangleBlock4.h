#pragma once
// Four triangles of one kd-tree leaf in structure-of-arrays layout (object space), the unit the
// 4-wide watertight test reads. Private to the objects library: MeshObject builds the blocks after
// the tree, leaf by leaf, so a leaf's triangles are contiguous and load without a transpose.

#include <glm/vec3.hpp>

#include <cstdint>

namespace duplex::detail {

struct alignas(32) TriangleBlock4 {
  /// v[3 * k + c][lane]: coordinate c (x, y, z) of vertex k (0, 1, 2) of the lane's triangle, the
  /// vertex order of the mesh (it fixes the sign of the edge functions, see WatertightTriangle.h).
  float v[9][4];
  /// Triangle index in the mesh, per lane. Lanes past the leaf's end repeat a valid triangle of the
  /// block; the leaf's count masks them off.
  std::uint32_t prim[4];

  [[nodiscard]] glm::vec3 vertex(int lane, int k) const {
    return {v[3 * k][lane], v[3 * k + 1][lane], v[3 * k + 2][lane]};
  }
  void set(int lane, const glm::vec3& a, const glm::vec3& b, const glm::vec3& c, std::uint32_t prim_id) {
    const glm::vec3* vs[3] = {&a, &b, &c};
    for (int k = 0; k < 3; ++k)
      for (int d = 0; d < 3; ++d) v[3 * k + d][lane] = (*vs[k])[d];
    prim[lane] = prim_id;
  }
};
static_assert(sizeof(TriangleBlock4) == 160);

}  // namespace duplex::detail
