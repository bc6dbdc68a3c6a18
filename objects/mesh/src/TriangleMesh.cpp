#include "duplex/objects/TriangleMesh.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"

#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
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
  m.triangles_ = std::make_shared<const std::vector<Triangle>>(std::move(triangles));
  m.validate();
  return m;
}

void TriangleMesh::checkPositions(std::span<const glm::vec3> positions) const {
  if (positions.size() != positions_.size())
    throw InvalidArgument("mesh '" + name_ + "': given " + std::to_string(positions.size()) +
                          " positions, but it has " + std::to_string(positions_.size()) + " vertices");
  // In parallel chunks (a deformation step is otherwise parallel), the first bad vertex reported.
  constexpr std::size_t kChunk = 16384;
  std::vector<std::size_t> first_bad((positions.size() + kChunk - 1) / kChunk, SIZE_MAX);
  tbb::parallel_for(std::size_t{0}, first_bad.size(), [&](std::size_t c) {
    const std::size_t end = std::min(positions.size(), (c + 1) * kChunk);
    for (std::size_t i = c * kChunk; i < end; ++i) {
      const glm::vec3& p = positions[i];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
        first_bad[c] = i;
        return;
      }
    }
  });
  for (const std::size_t i : first_bad)
    if (i != SIZE_MAX)
      throw InvalidArgument("mesh '" + name_ + "': position of vertex " + std::to_string(i) + " is not finite");
}

TriangleMesh TriangleMesh::withPositions(std::vector<glm::vec3> positions) const {
  checkPositions(positions);
  TriangleMesh m;
  m.name_ = name_;
  m.positions_ = std::move(positions);
  m.triangles_ = triangles_;
  m.validate(/*check_indices=*/false);  // the same vertex count: the indices were checked here
  return m;
}

TriangleMesh TriangleMesh::withPositionsOfSameValidity(std::vector<glm::vec3> positions, const Box& bounds) const {
  if (positions.size() != positions_.size())
    throw InvalidArgument("mesh '" + name_ + "': positions of another vertex count");
  TriangleMesh m;
  m.name_ = name_;
  m.positions_ = std::move(positions);
  m.triangles_ = triangles_;
  m.valid_ = valid_;
  m.degenerate_count_ = degenerate_count_;
  m.bounds_ = bounds;
  return m;
}

void TriangleMesh::validate(bool check_indices) {
  const std::vector<Triangle>& triangles = *triangles_;
  if (triangles.empty()) throw InvalidArgument("mesh '" + name_ + "': has no triangles");
  const std::size_t nv = positions_.size(), nt = triangles.size();
  // Finiteness once per vertex rather than once per corner; then the triangles in parallel chunks,
  // merged in chunk order (the result does not depend on the thread count).
  std::vector<std::uint8_t> finite(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    const glm::vec3& p = positions_[i];
    finite[i] = std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
  }
  valid_.assign(nt, 0);
  constexpr std::size_t kChunk = 16384;
  struct Part {
    Box bounds;
    std::size_t degenerate = 0;
    std::size_t bad = SIZE_MAX;  // first triangle with an index out of range
  };
  std::vector<Part> parts((nt + kChunk - 1) / kChunk);
  tbb::parallel_for(std::size_t{0}, parts.size(), [&](std::size_t c) {
    Part& part = parts[c];
    const std::size_t end = std::min(nt, (c + 1) * kChunk);
    for (std::size_t i = c * kChunk; i < end; ++i) {
      const Triangle& t = triangles[i];
      if (check_indices && (t[0] >= nv || t[1] >= nv || t[2] >= nv)) {
        part.bad = std::min(part.bad, i);
        continue;
      }
      const glm::vec3 a = positions_[t[0]], b = positions_[t[1]], c3 = positions_[t[2]];
      // Exactly zero area in double: such a triangle has no interior and the watertight test
      // would report det == 0 anyway; keeping it out of the tree saves work.
      const bool ok = t[0] != t[1] && t[1] != t[2] && t[0] != t[2] && finite[t[0]] && finite[t[1]] && finite[t[2]] &&
                      hasArea(a, b, c3);
      if (!ok) {
        ++part.degenerate;
        continue;
      }
      valid_[i] = 1;
      part.bounds.extend(a);
      part.bounds.extend(b);
      part.bounds.extend(c3);
    }
  });
  degenerate_count_ = 0;
  bounds_ = Box();
  for (const Part& part : parts) {
    if (part.bad != SIZE_MAX) {
      const Triangle& t = triangles[part.bad];
      const std::uint32_t k = t[0] >= nv ? t[0] : t[1] >= nv ? t[1] : t[2];
      throw InvalidArgument("mesh '" + name_ + "': triangle " + std::to_string(part.bad) + " refers to vertex " +
                            std::to_string(k) + " but there are " + std::to_string(nv) + " vertices");
    }
    degenerate_count_ += part.degenerate;
    bounds_.extend(part.bounds);
  }
  if (degenerate_count_ == triangles.size())
    throw InvalidArgument("mesh '" + name_ + "': none of its " + std::to_string(triangles.size()) +
                          " triangles is valid (all degenerate)");
  if (degenerate_count_ > 0)
    logger()->warn("mesh '{}': {} of {} triangles are degenerate and will never be hit", name_, degenerate_count_,
                   triangles.size());
}

}  // namespace duplex
