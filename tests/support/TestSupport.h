#pragma once
/// \file TestSupport.h
/// Shared helpers of the unit tests: paths to the shared meshes, generated geometry (spheres, flat
/// grids, triangle soups) and scratch directories. Everything here is deterministic.

#include "duplex/accel/Box.h"
#include "duplex/accel/Error.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/TriangleMesh.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/vec3.hpp>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <string>
#include <unistd.h>
#include <utility>
#include <vector>

#if !defined(DUPLEX_SHARED_DATA) || !defined(DUPLEX_TEST_DATA) || !defined(DUPLEX_SOURCE_DIR)
#error \
    "DUPLEX_SHARED_DATA, DUPLEX_TEST_DATA and DUPLEX_SOURCE_DIR come with duplex_test_support (cmake/DuplexTests.cmake)"
#endif

namespace duplex::test {

/// Runs `f` and expects an exception of type E (FileError, InvalidArgument, ...) whose message
/// contains `needle` (the file or object the error must name).
template <class E, class F>
void expectErrorNaming(F&& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no exception thrown (expected one naming '" << needle << "')";
  } catch (const E& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << "message: " << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
  }
}

/// The shared data folder (meshes of the project's benchmarks); may be absent on a fresh machine.
inline std::filesystem::path sharedDataDir() { return std::filesystem::path(DUPLEX_SHARED_DATA); }
/// Small mesh fixtures shipped with the mesh type's tests (objects/mesh/tests/data).
inline std::filesystem::path fixtureDir() { return std::filesystem::path(DUPLEX_TEST_DATA); }
/// The repository's top folder (for the documents tests read).
inline std::filesystem::path sourceDir() { return std::filesystem::path(DUPLEX_SOURCE_DIR); }

/// Path of a shared mesh, relative to <shared>/meshes, or nullopt when it is not there.
inline std::optional<std::filesystem::path> sharedMesh(const std::string& relative) {
  const std::filesystem::path p = sharedDataDir() / "meshes" / relative;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(p, ec)) return std::nullopt;
  return p;
}

/// Loads a shared mesh once per process (several tests use the same big meshes).
inline std::shared_ptr<const TriangleMesh> sharedMeshCached(const std::string& relative) {
  static std::map<std::string, std::shared_ptr<const TriangleMesh>> cache;
  const auto it = cache.find(relative);
  if (it != cache.end()) return it->second;
  const auto path = sharedMesh(relative);
  if (!path) return nullptr;
  auto mesh = std::make_shared<const TriangleMesh>(loadMesh(*path));
  cache.emplace(relative, mesh);
  return mesh;
}

/// `GTEST_SKIP()`s the current test when the shared mesh is missing; otherwise binds it to `var`.
#define DUPLEX_SHARED_MESH_OR_SKIP(var, relative)                                                          \
  const std::shared_ptr<const ::duplex::TriangleMesh> var = ::duplex::test::sharedMeshCached(relative);    \
  if (!(var))                                                                                              \
  GTEST_SKIP() << "shared mesh '" << (relative) << "' not found under " << ::duplex::test::sharedDataDir() \
               << "/meshes (the shared data folder is absent on this machine)"

/// A scratch directory removed at the end of its scope; unique per process and call.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = "duplex_unit_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
    if (info) name += std::string("_") + info->test_suite_name() + "_" + info->name();
    for (char& c : name)
      if (c == '/') c = '_';
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

inline void writeTextFile(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

inline void writeBinaryFile(const std::filesystem::path& path, const std::vector<char>& bytes) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

inline std::vector<char> readBinaryFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<char>(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// ---------------------------------------------------------------------------------------------
// Generated geometry
// ---------------------------------------------------------------------------------------------

/// Icosphere: an icosahedron whose faces are split 4:1 `subdivisions` times, vertices pushed to the
/// sphere. A closed 2-manifold with shared vertices, outward (counter-clockwise) winding.
/// 20 * 4^subdivisions triangles.
inline TriangleMesh icosphere(int subdivisions, double radius = 1.0, glm::dvec3 centre = glm::dvec3(0.0)) {
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<glm::dvec3> p = {{-1, g, 0},  {1, g, 0},  {-1, -g, 0}, {1, -g, 0}, {0, -1, g},  {0, 1, g},
                               {0, -1, -g}, {0, 1, -g}, {g, 0, -1},  {g, 0, 1},  {-g, 0, -1}, {-g, 0, 1}};
  for (auto& q : p) q = glm::normalize(q);
  std::vector<TriangleMesh::Triangle> t = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                           {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                           {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                           {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      p.push_back(glm::normalize(p[a] + p[b]));
      const auto id = static_cast<std::uint32_t>(p.size() - 1);
      mid.emplace(key, id);
      return id;
    };
    std::vector<TriangleMesh::Triangle> next;
    next.reserve(t.size() * 4);
    for (const auto& tri : t) {
      const std::uint32_t a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    t = std::move(next);
  }
  std::vector<glm::vec3> positions;
  positions.reserve(p.size());
  for (const auto& q : p) positions.emplace_back(centre + radius * q);
  return TriangleMesh::fromTriangles(std::move(positions), std::move(t), "icosphere");
}

/// UV sphere with single pole vertices (valence `slices` at the poles): closed 2-manifold.
inline TriangleMesh uvSphere(int slices, int stacks, double radius = 1.0, glm::dvec3 centre = glm::dvec3(0.0)) {
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  p.emplace_back(centre + glm::dvec3(0, 0, radius));  // north pole 0
  for (int i = 1; i < stacks; ++i) {
    const double theta = std::numbers::pi * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const double phi = 2.0 * std::numbers::pi * j / slices;
      p.emplace_back(centre + radius * glm::dvec3(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
                                                  std::cos(theta)));
    }
  }
  p.emplace_back(centre + glm::dvec3(0, 0, -radius));  // south pole
  const auto south = static_cast<std::uint32_t>(p.size() - 1);
  auto ring = [&](int i, int j) { return static_cast<std::uint32_t>(1 + (i - 1) * slices + (j % slices)); };
  for (int j = 0; j < slices; ++j) t.push_back({0, ring(1, j), ring(1, j + 1)});
  for (int i = 1; i + 1 < stacks; ++i)
    for (int j = 0; j < slices; ++j) {
      t.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      t.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  for (int j = 0; j < slices; ++j) t.push_back({ring(stacks - 1, j), south, ring(stacks - 1, j + 1)});
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), "uvsphere");
}

/// A flat n x n grid of unit cells (2 triangles each) in the plane where coordinate `axis` equals
/// `level`, spanning [0, n * cell] on the two other axes. Vertex coordinates are exact floats.
inline TriangleMesh flatGrid(int n, int axis = 2, float level = 0.25f, float cell = 0.125f) {
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  const int a1 = (axis + 1) % 3, a2 = (axis + 2) % 3;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; j <= n; ++j) {
      glm::vec3 q(0.0f);
      q[axis] = level;
      q[a1] = static_cast<float>(i) * cell;
      q[a2] = static_cast<float>(j) * cell;
      p.push_back(q);
    }
  auto id = [&](int i, int j) { return static_cast<std::uint32_t>(i * (n + 1) + j); };
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      t.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      t.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), "flat-grid");
}

/// Three draws of `dist` as x, y and z, in that order. The arguments of one call
/// (draw3(d, rng)) are evaluated in an order each compiler picks (GCC and clang
/// differ), so the same seed would give each compiler other test inputs.
template <class Vec = glm::vec3, class Dist, class Rng>
Vec draw3(Dist& dist, Rng& rng) {
  const auto x = dist(rng);
  const auto y = dist(rng);
  const auto z = dist(rng);
  return Vec(x, y, z);
}

/// An axis-aligned box surface (12 triangles, closed) from `lo` to `hi`.
inline TriangleMesh boxMesh(glm::vec3 lo, glm::vec3 hi, std::string name = "box") {
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z);
  std::vector<TriangleMesh::Triangle> t = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                                           {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), std::move(name));
}

/// A soup of `count` random triangles in [0, 1]^3: mostly small, some large, some lying in
/// axis-aligned planes on a coarse grid of levels (so that several share one plane), some slivers.
inline TriangleMesh triangleSoup(std::size_t count, std::uint64_t seed, std::string name = "soup") {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  std::uniform_int_distribution<int> kind(0, 9);
  std::vector<glm::vec3> p;
  std::vector<TriangleMesh::Triangle> t;
  while (t.size() < count) {
    const glm::vec3 c = draw3(u01, rng);
    const int k = kind(rng);
    const float size = k == 0 ? 0.5f : (k < 3 ? 0.1f : 0.03f);
    glm::vec3 v[3];
    for (auto& q : v) q = c + size * (draw3(u01, rng) - 0.5f);
    if (k == 3 || k == 4) {
      // Axis-aligned: all three corners on one of 8 levels of one axis.
      const int axis = static_cast<int>(rng() % 3);
      const float level = static_cast<float>(rng() % 8) / 8.0f;
      for (auto& q : v) q[axis] = level;
    }
    if (k == 5) v[2] = v[0] + (v[1] - v[0]) * 0.5f + glm::vec3(1e-4f, 0.0f, 0.0f);  // sliver
    const glm::dvec3 n = glm::cross(glm::dvec3(v[1]) - glm::dvec3(v[0]), glm::dvec3(v[2]) - glm::dvec3(v[0]));
    if (n == glm::dvec3(0.0)) continue;
    const auto base = static_cast<std::uint32_t>(p.size());
    p.insert(p.end(), v, v + 3);
    t.push_back({base, base + 1, base + 2});
  }
  return TriangleMesh::fromTriangles(std::move(p), std::move(t), std::move(name));
}

/// The triangles of triangleSoup(count, seed) as corner triples.
inline std::vector<std::array<glm::vec3, 3>> randomTriangles(std::size_t count, std::uint64_t seed) {
  const TriangleMesh soup = triangleSoup(count, seed);
  std::vector<std::array<glm::vec3, 3>> tris(soup.triangleCount());
  for (std::size_t i = 0; i < tris.size(); ++i) tris[i] = soup.vertices(i);
  return tris;
}

/// Row-major 3x4 of rotation(axis, angle) * diag(scale), then translation.
inline std::array<double, 12> rotationScaleTranslation(glm::dvec3 axis, double angle, glm::dvec3 scale,
                                                       glm::dvec3 translation) {
  axis = glm::normalize(axis);
  const double c = std::cos(angle), s = std::sin(angle), C = 1.0 - c;
  const double x = axis.x, y = axis.y, z = axis.z;
  const double r[3][3] = {{c + x * x * C, x * y * C - z * s, x * z * C + y * s},
                          {y * x * C + z * s, c + y * y * C, y * z * C - x * s},
                          {z * x * C - y * s, z * y * C + x * s, c + z * z * C}};
  std::array<double, 12> m{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[i * 4 + j] = r[i][j] * scale[j];
    m[i * 4 + 3] = translation[i];
  }
  return m;
}

/// Largest absolute coordinate of a box (the scale that float rounding errors are relative to).
inline double coordinateScale(const Box& b) {
  double s = 0.0;
  for (int k = 0; k < 3; ++k) s = std::max({s, std::abs(double(b.lo[k])), std::abs(double(b.hi[k]))});
  return s;
}

/// `b` grown by `factor` of its extent on every side (rays from outside a mesh).
inline Box enlarged(const Box& b, float factor) {
  const glm::vec3 e = b.extent() * factor;
  return Box(b.lo - e, b.hi + e);
}

}  // namespace duplex::test
