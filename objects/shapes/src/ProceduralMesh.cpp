#include "duplex/objects/ProceduralMesh.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

namespace duplex {

namespace {

void requirePositive(double v, const char* what, const std::string& name) {
  if (!std::isfinite(v) || !(v > 0.0))
    throw InvalidArgument(name + ": " + what + " must be a finite number > 0, got " + std::to_string(v));
}

}  // namespace

TriangleMesh makeSphere(double radius, int subdivisions, std::string name) {
  requirePositive(radius, "sphere radius", name);
  if (subdivisions < 0 || subdivisions > kMaxSphereSubdivisions)
    throw InvalidArgument(name + ": sphere subdivisions must be in [0, " + std::to_string(kMaxSphereSubdivisions) +
                          "], got " + std::to_string(subdivisions));
  // Unit directions in double; positions are rounded to float once at the end.
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<glm::dvec3> dirs = {{-1, g, 0},  {1, g, 0},  {-1, -g, 0}, {1, -g, 0}, {0, -1, g},  {0, 1, g},
                                  {0, -1, -g}, {0, 1, -g}, {g, 0, -1},  {g, 0, 1},  {-g, 0, -1}, {-g, 0, 1}};
  for (auto& d : dirs) d = glm::normalize(d);
  std::vector<TriangleMesh::Triangle> tris = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                              {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                              {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                              {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    // Each edge's midpoint once, so that neighbouring faces share it.
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> midpoint;
    auto mid = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      const auto [it, inserted] = midpoint.emplace(key, static_cast<std::uint32_t>(dirs.size()));
      if (inserted) dirs.push_back(glm::normalize(dirs[a] + dirs[b]));
      return it->second;
    };
    std::vector<TriangleMesh::Triangle> next;
    next.reserve(tris.size() * 4);
    for (const auto& t : tris) {
      const std::uint32_t ab = mid(t[0], t[1]), bc = mid(t[1], t[2]), ca = mid(t[2], t[0]);
      next.push_back({t[0], ab, ca});
      next.push_back({t[1], bc, ab});
      next.push_back({t[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    tris = std::move(next);
  }
  std::vector<glm::vec3> positions;
  positions.reserve(dirs.size());
  for (const auto& d : dirs) positions.emplace_back(glm::vec3(d * radius));
  return TriangleMesh::fromTriangles(std::move(positions), std::move(tris), std::move(name));
}

TriangleMesh makeBox(const glm::dvec3& size, std::string name) {
  for (int k = 0; k < 3; ++k) requirePositive(size[k], "box size", name);
  const glm::vec3 h(size * 0.5);
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1 ? h.x : -h.x, i & 2 ? h.y : -h.y, i & 4 ? h.z : -h.z);
  // Two triangles per face, counter-clockwise seen from outside.
  std::vector<TriangleMesh::Triangle> t = {{0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5},   // -x, +x
                                           {0, 1, 5}, {0, 5, 4}, {2, 6, 7}, {2, 7, 3},   // -y, +y
                                           {0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}};  // -z, +z
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), std::move(name));
}

TriangleMesh makePlane(const glm::dvec2& size, std::string name) {
  requirePositive(size.x, "plane size", name);
  requirePositive(size.y, "plane size", name);
  const float hx = static_cast<float>(size.x * 0.5), hy = static_cast<float>(size.y * 0.5);
  std::vector<glm::vec3> p = {{-hx, -hy, 0.0f}, {hx, -hy, 0.0f}, {hx, hy, 0.0f}, {-hx, hy, 0.0f}};
  return TriangleMesh::fromTriangles(std::move(p), {{0, 1, 2}, {0, 2, 3}}, std::move(name));
}

}  // namespace duplex
