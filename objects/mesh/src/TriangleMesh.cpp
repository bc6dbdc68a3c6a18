#include "duplex/objects/TriangleMesh.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"

#include <glm/geometric.hpp>

#include <cmath>
#include <string>

namespace duplex {

TriangleMesh TriangleMesh::fromArrays(std::span<const float> positions, std::span<const std::uint32_t> indices,
                                      std::string name) {
  if (positions.size() % 3 != 0)
    throw InvalidArgument("mesh '" + name + "': positions array has " + std::to_string(positions.size()) +
                          " numbers, not a multiple of 3");
  if (indices.size() % 3 != 0)
    throw InvalidArgument("mesh '" + name + "': indices array has " + std::to_string(indices.size()) +
                          " entries, not a multiple of 3");
  std::vector<glm::vec3> p(positions.size() / 3);
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = {positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]};
  std::vector<Triangle> t(indices.size() / 3);
  for (std::size_t i = 0; i < t.size(); ++i) t[i] = {indices[3 * i], indices[3 * i + 1], indices[3 * i + 2]};
  return fromTriangles(std::move(p), std::move(t), std::move(name));
}

TriangleMesh TriangleMesh::fromTriangles(std::vector<glm::vec3> positions, std::vector<Triangle> triangles,
                                         std::string name) {
  TriangleMesh m;
  m.name_ = std::move(name);
  m.positions_ = std::move(positions);
  m.triangles_ = std::move(triangles);
  m.validate();
  return m;
}

void TriangleMesh::validate() {
  if (triangles_.empty()) throw InvalidArgument("mesh '" + name_ + "': has no triangles");
  valid_.assign(triangles_.size(), 0);
  degenerate_count_ = 0;
  bounds_ = Box();
  for (std::size_t i = 0; i < triangles_.size(); ++i) {
    const Triangle& t = triangles_[i];
    for (int k = 0; k < 3; ++k)
      if (t[k] >= positions_.size())
        throw InvalidArgument("mesh '" + name_ + "': triangle " + std::to_string(i) + " refers to vertex " +
                              std::to_string(t[k]) + " but there are " + std::to_string(positions_.size()) +
                              " vertices");
    const glm::vec3 a = positions_[t[0]], b = positions_[t[1]], c = positions_[t[2]];
    bool ok = t[0] != t[1] && t[1] != t[2] && t[0] != t[2];
    for (int k = 0; k < 3 && ok; ++k) ok = std::isfinite(a[k]) && std::isfinite(b[k]) && std::isfinite(c[k]);
    if (ok) {
      // Exactly zero area in double: such a triangle has no interior and the watertight test
      // would report det == 0 anyway; keeping it out of the tree saves work.
      const glm::dvec3 n = glm::cross(glm::dvec3(b) - glm::dvec3(a), glm::dvec3(c) - glm::dvec3(a));
      ok = n != glm::dvec3(0.0);
    }
    if (!ok) {
      ++degenerate_count_;
      continue;
    }
    valid_[i] = 1;
    bounds_.extend(a);
    bounds_.extend(b);
    bounds_.extend(c);
  }
  if (degenerate_count_ == triangles_.size())
    throw InvalidArgument("mesh '" + name_ + "': none of its " + std::to_string(triangles_.size()) +
                          " triangles is valid (all degenerate)");
  if (degenerate_count_ > 0)
    logger()->warn("mesh '{}': {} of {} triangles are degenerate and will never be hit", name_, degenerate_count_,
                   triangles_.size());
}

}  // namespace duplex
