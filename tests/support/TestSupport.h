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
std::shared_ptr<const TriangleMesh> sharedMeshCached(const std::string& relative);

/// `GTEST_SKIP()`s the current test when the shared mesh is missing; otherwise binds it to `var`.
#define DUPLEX_SHARED_MESH_OR_SKIP(var, relative)                                                          \
  const std::shared_ptr<const ::duplex::TriangleMesh> var = ::duplex::test::sharedMeshCached(relative);    \
  if (!(var))                                                                                              \
  GTEST_SKIP() << "shared mesh '" << (relative) << "' not found under " << ::duplex::test::sharedDataDir() \
               << "/meshes (the shared data folder is absent on this machine)"

/// A scratch directory removed at the end of its scope; unique per process and call.
class TempDir {
 public:
  TempDir();
  ~TempDir();
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
TriangleMesh icosphere(int subdivisions, double radius = 1.0, glm::dvec3 centre = glm::dvec3(0.0));

/// UV sphere with single pole vertices (valence `slices` at the poles): closed 2-manifold.
TriangleMesh uvSphere(int slices, int stacks, double radius = 1.0, glm::dvec3 centre = glm::dvec3(0.0));

/// A flat n x n grid of unit cells (2 triangles each) in the plane where coordinate `axis` equals
/// `level`, spanning [0, n * cell] on the two other axes. Vertex coordinates are exact floats.
TriangleMesh flatGrid(int n, int axis = 2, float level = 0.25f, float cell = 0.125f);

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
TriangleMesh boxMesh(glm::vec3 lo, glm::vec3 hi, std::string name = "box");

/// A soup of `count` random triangles in [0, 1]^3: mostly small, some large, some lying in
/// axis-aligned planes on a coarse grid of levels (so that several share one plane), some slivers.
TriangleMesh triangleSoup(std::size_t count, std::uint64_t seed, std::string name = "soup");

/// The triangles of triangleSoup(count, seed) as corner triples.
std::vector<std::array<glm::vec3, 3>> randomTriangles(std::size_t count, std::uint64_t seed);

/// Row-major 3x4 of rotation(axis, angle) * diag(scale), then translation.
std::array<double, 12> rotationScaleTranslation(glm::dvec3 axis, double angle, glm::dvec3 scale,
                                                glm::dvec3 translation);

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
