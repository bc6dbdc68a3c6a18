// Mesh loading (loadMesh) for OBJ, PLY (ascii and binary), OFF, STL (ascii and binary) and OM:
// triangle counts, vertex positions, fan triangulation of polygons in face order, the load report,
// consistency across formats (files written by OpenMesh's own writer), errors naming the file, the
// non-manifold robot parts (every facet kept, quiet stderr), and Loop subdivision. The strict
// readers' own properties (stable face numbering, hostile input): MeshFileReadersTest.cpp.
//
// Fixtures: objects/mesh/tests/data/*.obj|off|ply|stl (hand-written ascii); binary files are written here.

#include "MemoryLimitScope.h"
#include "Reference.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/TriangleMesh.h"

// As in MeshLoader.cpp: GCC 12 warns inside OpenMesh's property containers under the sanitizers.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

using Corners = std::vector<std::uint32_t>;

/// Triangles [first, first + n - 2) are a fan over `corners` (a polygon of n corners) that keeps
/// the polygon's cyclic order and winding: (c[r], c[r+1], c[r+2]), (c[r], c[r+2], c[r+3]), ... for
/// one rotation r.
::testing::AssertionResult isFan(const TriangleMesh& m, std::size_t first, const Corners& corners) {
  const std::size_t n = corners.size();
  if (first + n - 2 > m.triangleCount()) return ::testing::AssertionFailure() << "too few triangles";
  for (std::size_t r = 0; r < n; ++r) {
    bool ok = true;
    for (std::size_t k = 0; k + 2 < n && ok; ++k) {
      const TriangleMesh::Triangle expected = {corners[r], corners[(r + k + 1) % n], corners[(r + k + 2) % n]};
      ok = m.triangles()[first + k] == expected;
    }
    if (ok) return ::testing::AssertionSuccess();
  }
  ::testing::AssertionResult fail = ::testing::AssertionFailure();
  fail << "triangles " << first << ".. are not a fan over the corners [";
  for (const auto c : corners) fail << c << " ";
  fail << "]: got";
  for (std::size_t k = 0; k + 2 < n; ++k) {
    const auto& t = m.triangles()[first + k];
    fail << " (" << t[0] << " " << t[1] << " " << t[2] << ")";
  }
  return fail;
}

/// Triangles as vertex-coordinate triples, rotated so that the smallest corner comes first (keeps
/// the winding), sorted: geometry independent of vertex numbering.
std::vector<std::array<std::array<float, 3>, 3>> canonicalTriangles(const TriangleMesh& m) {
  std::vector<std::array<std::array<float, 3>, 3>> out;
  for (std::size_t i = 0; i < m.triangleCount(); ++i) {
    const auto v = m.vertices(i);
    std::array<std::array<float, 3>, 3> t;
    for (int k = 0; k < 3; ++k) t[k] = {v[k].x, v[k].y, v[k].z};
    const auto smallest = std::min_element(t.begin(), t.end()) - t.begin();
    std::rotate(t.begin(), t.begin() + smallest, t.end());
    out.push_back(t);
  }
  std::sort(out.begin(), out.end());
  return out;
}

const std::vector<glm::vec3> kCubePositions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                               {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
const std::vector<Corners> kCubeFaces = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                         {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
const std::vector<glm::vec3> kTetraPositions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const std::vector<TriangleMesh::Triangle> kTetraFaces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

void expectCube(const TriangleMesh& m, const MeshLoadReport& rep) {
  ASSERT_EQ(m.triangleCount(), 12u);
  EXPECT_EQ(m.positions(), kCubePositions);
  for (std::size_t f = 0; f < kCubeFaces.size(); ++f) EXPECT_TRUE(isFan(m, 2 * f, kCubeFaces[f])) << "face " << f;
  EXPECT_EQ(rep.polygons_triangulated, 6u);
  EXPECT_EQ(rep.complex_edge_warnings, 0u);
  EXPECT_EQ(m.degenerateCount(), 0u);
  EXPECT_NEAR(signedVolume(m), 1.0, 1e-12);  // winding kept: outward, closed
}

void expectTetra(const TriangleMesh& m) {
  TriangleMesh expected = TriangleMesh::fromTriangles(kTetraPositions, kTetraFaces, "tetra");
  ASSERT_EQ(m.triangleCount(), 4u);
  EXPECT_EQ(canonicalTriangles(m), canonicalTriangles(expected));
  EXPECT_NEAR(std::abs(signedVolume(m)), 1.0 / 6.0, 1e-12);
}

// ---------------------------------------------------------------------------------------------

TEST(MeshLoader, ObjQuadsAreFanTriangulatedInFaceOrder) {
  MeshLoadReport rep;
  const TriangleMesh m = loadMesh(fixtureDir() / "quad_cube.obj", &rep);
  expectCube(m, rep);
  EXPECT_NE(m.name().find("quad_cube.obj"), std::string::npos) << m.name();
  EXPECT_EQ(m.bounds(), Box(glm::vec3(0.0f), glm::vec3(1.0f)));
}

TEST(MeshLoader, ObjPentagonAndHexagon) {
  MeshLoadReport rep;
  const TriangleMesh m = loadMesh(fixtureDir() / "polygons.obj", &rep);
  ASSERT_EQ(m.triangleCount(), 8u);  // 3 + 1 + 4
  ASSERT_EQ(m.positions().size(), 14u);
  EXPECT_EQ(m.positions()[2], glm::vec3(3.0f, 1.5f, 0.0f));
  EXPECT_EQ(m.positions()[13], glm::vec3(4.5f, 1.0f, 0.0f));
  EXPECT_TRUE(isFan(m, 0, {0, 1, 2, 3, 4}));
  EXPECT_EQ(m.triangles()[3], (TriangleMesh::Triangle{5, 6, 7}));
  EXPECT_TRUE(isFan(m, 4, {8, 9, 10, 11, 12, 13}));
  EXPECT_EQ(rep.polygons_triangulated, 2u);
  // The fans cover the polygons: areas add up (6.5 and 3 by the shoelace formula).
  double pentagon = 0.0, hexagon = 0.0;
  for (std::size_t i = 0; i < 8; ++i) {
    const auto v = m.vertices(i);
    const double a = 0.5 * glm::length(glm::cross(glm::dvec3(v[1] - v[0]), glm::dvec3(v[2] - v[0])));
    if (i < 3) pentagon += a;
    if (i >= 4) hexagon += a;
  }
  EXPECT_NEAR(pentagon, 6.5, 1e-12);
  EXPECT_NEAR(hexagon, 3.0, 1e-12);
}

TEST(MeshLoader, Off) {
  const TriangleMesh m = loadMesh(fixtureDir() / "tetra.off");
  EXPECT_EQ(m.positions(), kTetraPositions);
  EXPECT_EQ(m.triangles(), kTetraFaces);
}

TEST(MeshLoader, AsciiPlyWithAQuad) {
  MeshLoadReport rep;
  const TriangleMesh m = loadMesh(fixtureDir() / "pyramid_ascii.ply", &rep);
  ASSERT_EQ(m.triangleCount(), 6u);
  EXPECT_EQ(m.positions(), (std::vector<glm::vec3>{{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {1, 1, 1.5f}}));
  EXPECT_TRUE(isFan(m, 0, {0, 3, 2, 1}));
  EXPECT_EQ(m.triangles()[2], (TriangleMesh::Triangle{0, 1, 4}));
  EXPECT_EQ(m.triangles()[5], (TriangleMesh::Triangle{3, 0, 4}));
  EXPECT_EQ(rep.polygons_triangulated, 1u);
  EXPECT_NEAR(signedVolume(m), 4.0 * 1.5 / 3.0, 1e-12);
}

TEST(MeshLoader, AsciiStl) { expectTetra(loadMesh(fixtureDir() / "tetra_ascii.stl")); }

std::vector<char> binaryStl(const std::string& header, std::uint32_t declared,
                            const std::vector<std::array<glm::vec3, 3>>& facets) {
  std::vector<char> out(80, ' ');
  std::memcpy(out.data(), header.data(), std::min<std::size_t>(80, header.size()));
  out.resize(84);
  std::memcpy(out.data() + 80, &declared, 4);
  for (const auto& f : facets) {
    float rec[12] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) std::memcpy(rec + 3 + 3 * k, &f[k].x, 12);
    const char* p = reinterpret_cast<const char*>(rec);
    out.insert(out.end(), p, p + 48);
    out.push_back(0);
    out.push_back(0);
  }
  return out;
}

std::vector<std::array<glm::vec3, 3>> tetraFacets() {
  std::vector<std::array<glm::vec3, 3>> f;
  for (const auto& t : kTetraFaces) f.push_back({kTetraPositions[t[0]], kTetraPositions[t[1]], kTetraPositions[t[2]]});
  return f;
}

TEST(MeshLoader, BinaryStl) {
  TempDir dir;
  writeBinaryFile(dir / "tetra.stl", binaryStl("binary tetra", 4, tetraFacets()));
  expectTetra(loadMesh(dir / "tetra.stl"));
  // A binary STL whose 80-byte header starts with "solid" (many exporters do this).
  writeBinaryFile(dir / "solid_header.stl", binaryStl("solid exported by a CAD tool", 4, tetraFacets()));
  expectTetra(loadMesh(dir / "solid_header.stl"));
}

std::vector<char> binaryPly(std::size_t faces_written) {
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  std::vector<char> out(header.begin(), header.end());
  for (const glm::vec3& p : kTetraPositions) {
    const char* b = reinterpret_cast<const char*>(&p.x);
    out.insert(out.end(), b, b + 12);
  }
  for (std::size_t i = 0; i < faces_written; ++i) {
    out.push_back(3);
    for (const std::uint32_t v : kTetraFaces[i]) {
      const auto x = static_cast<std::int32_t>(v);
      const char* b = reinterpret_cast<const char*>(&x);
      out.insert(out.end(), b, b + 4);
    }
  }
  return out;
}

TEST(MeshLoader, BinaryPly) {
  TempDir dir;
  writeBinaryFile(dir / "tetra.ply", binaryPly(4));
  const TriangleMesh m = loadMesh(dir / "tetra.ply");
  EXPECT_EQ(m.positions(), kTetraPositions);
  EXPECT_EQ(m.triangles(), kTetraFaces);
}

/// OpenMesh's writer, with its progress chatter on omlog/omout switched off meanwhile.
template <class Mesh>
bool writeWithOpenMesh(const Mesh& mesh, const std::filesystem::path& path, OpenMesh::IO::Options options = {}) {
  omlog().disable();
  omout().disable();
  const bool ok = OpenMesh::IO::write_mesh(mesh, path.string(), options);
  omlog().enable();
  omout().enable();
  return ok;
}

/// The quad cube as an OpenMesh PolyMesh (vertices and faces in the fixture's order).
OpenMesh::PolyMesh_ArrayKernelT<> cubePolyMesh() {
  OpenMesh::PolyMesh_ArrayKernelT<> mesh;
  std::vector<OpenMesh::VertexHandle> vh;
  for (const glm::vec3& p : kCubePositions) vh.push_back(mesh.add_vertex({p.x, p.y, p.z}));
  for (const Corners& f : kCubeFaces) {
    std::vector<OpenMesh::VertexHandle> corners;
    for (const auto c : f) corners.push_back(vh[c]);
    mesh.add_face(corners);
  }
  return mesh;
}

TEST(MeshLoader, OmWrittenByOpenMesh) {
  TempDir dir;
  auto mesh = cubePolyMesh();
  ASSERT_TRUE(writeWithOpenMesh(mesh, dir / "cube.om"));
  MeshLoadReport rep;
  expectCube(loadMesh(dir / "cube.om", &rep), rep);
}

TEST(MeshLoader, SameGeometryFromEveryFormat) {
  TempDir dir;
  auto cube = cubePolyMesh();
  struct Out {
    std::string name;
    OpenMesh::IO::Options options;
  };
  const std::vector<Out> outs = {{"cube.obj", {}},       {"cube.off", {}},
                                 {"cube_ascii.ply", {}}, {"cube_binary.ply", OpenMesh::IO::Options::Binary},
                                 {"cube.om", {}},        {"cube_binary.off", OpenMesh::IO::Options::Binary}};
  for (const Out& o : outs) {
    SCOPED_TRACE(o.name);
    ASSERT_TRUE(writeWithOpenMesh(cube, dir / o.name, o.options));
    MeshLoadReport rep;
    const TriangleMesh m = loadMesh(dir / o.name, &rep);
    expectCube(m, rep);
  }
  // STL holds triangles only: write the triangulated cube, compare the geometry.
  OpenMesh::TriMesh_ArrayKernelT<> tri;
  std::vector<OpenMesh::VertexHandle> vh;
  for (const glm::vec3& p : kCubePositions) vh.push_back(tri.add_vertex({p.x, p.y, p.z}));
  for (const Corners& f : kCubeFaces) {
    tri.add_face(vh[f[0]], vh[f[1]], vh[f[2]]);
    tri.add_face(vh[f[0]], vh[f[2]], vh[f[3]]);
  }
  const TriangleMesh reference = loadMesh(fixtureDir() / "quad_cube.obj");
  for (const auto& [name, options] : std::vector<std::pair<std::string, OpenMesh::IO::Options>>{
           {"cube_ascii.stl", {}}, {"cube_binary.stl", OpenMesh::IO::Options::Binary}}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(writeWithOpenMesh(tri, dir / name, options));
    const TriangleMesh m = loadMesh(dir / name);
    EXPECT_EQ(canonicalTriangles(m), canonicalTriangles(reference));
  }
}

// Files OpenMesh writes read as OpenMesh reads them (a manifold mesh, which OpenMesh's half-edge
// reader keeps as it is): the same vertices and triangles, in the same order.
TEST(MeshLoader, FilesWrittenByOpenMeshReadAsOpenMeshReadsThem) {
  const TriangleMesh sphere = icosphere(2);  // 320 triangles, closed and manifold
  OpenMesh::PolyMesh_ArrayKernelT<> mesh;
  std::vector<OpenMesh::VertexHandle> vh;
  for (const glm::vec3& p : sphere.positions()) vh.push_back(mesh.add_vertex({p.x, p.y, p.z}));
  for (const auto& t : sphere.triangles()) mesh.add_face(vh[t[0]], vh[t[1]], vh[t[2]]);
  TempDir dir;
  for (const auto& [name, options] :
       std::vector<std::pair<std::string, OpenMesh::IO::Options>>{{"s.obj", {}},
                                                                  {"s.off", {}},
                                                                  {"s.ply", {}},
                                                                  {"sb.ply", OpenMesh::IO::Options::Binary},
                                                                  {"sb.off", OpenMesh::IO::Options::Binary},
                                                                  {"s.stl", {}},
                                                                  {"sb.stl", OpenMesh::IO::Options::Binary}}) {
    SCOPED_TRACE(name);
    ASSERT_TRUE(writeWithOpenMesh(mesh, dir / name, options));
    OpenMesh::PolyMesh_ArrayKernelT<> back;
    omlog().disable();
    ASSERT_TRUE(OpenMesh::IO::read_mesh(back, (dir / name).string()));
    omlog().enable();
    std::vector<glm::vec3> positions;
    for (const auto v : back.vertices()) positions.push_back({back.point(v)[0], back.point(v)[1], back.point(v)[2]});
    std::vector<TriangleMesh::Triangle> triangles;
    for (const auto f : back.faces()) {
      TriangleMesh::Triangle t{};
      int k = 0;
      for (const auto v : back.fv_range(f)) t[k++] = static_cast<std::uint32_t>(v.idx());
      triangles.push_back(t);
    }
    const TriangleMesh ours = loadMesh(dir / name);
    EXPECT_EQ(ours.positions(), positions);
    EXPECT_EQ(ours.triangles(), triangles);
  }
}

TEST(MeshLoader, ExtensionIsCaseInsensitive) {
  TempDir dir;
  std::filesystem::copy_file(fixtureDir() / "tetra.off", dir / "TETRA.OFF");
  expectTetra(loadMesh(dir / "TETRA.OFF"));
  std::filesystem::copy_file(fixtureDir() / "quad_cube.obj", dir / "Cube.Obj");
  EXPECT_EQ(loadMesh(dir / "Cube.Obj").triangleCount(), 12u);
}

// ---------------------------------------------------------------------------------------------

TEST(MeshLoaderErrors, MissingFileAndUnsupportedExtension) {
  TempDir dir;
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "does_not_exist.obj"); }, "does_not_exist.obj");
  std::filesystem::create_directories(dir / "a_directory.obj");
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "a_directory.obj"); }, "a_directory.obj");
  for (const std::string name : {"mesh.xyz", "mesh.gltf", "mesh_without_extension", "mesh.obj.bak"}) {
    std::filesystem::copy_file(fixtureDir() / "quad_cube.obj", dir / name);
    expectErrorNaming<FileError>([&] { (void)loadMesh(dir / name); }, name);
  }
}

TEST(MeshLoaderErrors, MalformedFixtures) {
  for (const std::string name : {"bad_header.ply", "garbage.off", "no_faces.obj", "bad_index.obj", "truncated.off"}) {
    SCOPED_TRACE(name);
    expectErrorNaming<FileError>([&] { (void)loadMesh(fixtureDir() / name); }, name);
  }
}

TEST(MeshLoaderErrors, EmptyAndTruncatedBinaryFiles) {
  TempDir dir;
  for (const std::string name : {"empty.obj", "empty.stl", "empty.ply", "empty.off", "empty.om"}) {
    writeBinaryFile(dir / name, {});
    expectErrorNaming<FileError>([&] { (void)loadMesh(dir / name); }, name);
  }
  // Binary STL declaring 10 facets but holding 2.
  writeBinaryFile(dir / "short.stl", binaryStl("short", 10, {tetraFacets()[0], tetraFacets()[1]}));
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "short.stl"); }, "short.stl");
  // Binary PLY cut inside the vertex list and inside the face list.
  auto ply = binaryPly(4);
  const std::size_t header_end = std::string(ply.begin(), ply.end()).find("end_header\n") + 11;
  writeBinaryFile(dir / "cut_vertices.ply",
                  std::vector<char>(ply.begin(), ply.begin() + static_cast<long>(header_end) + 20));
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "cut_vertices.ply"); }, "cut_vertices.ply");
  writeBinaryFile(dir / "cut_faces.ply", std::vector<char>(ply.begin(), ply.end() - 20));
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "cut_faces.ply"); }, "cut_faces.ply");
  // OM written by OpenMesh, then cut in half.
  auto cube = cubePolyMesh();
  ASSERT_TRUE(writeWithOpenMesh(cube, dir / "full.om"));
  const auto om = readBinaryFile(dir / "full.om");
  writeBinaryFile(dir / "cut.om", std::vector<char>(om.begin(), om.begin() + static_cast<long>(om.size() / 2)));
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "cut.om"); }, "cut.om");
}

// Text formats whose header states the face count: a file cut inside the face list must not load
// as if complete (OpenMesh repeats the last face it read for the missing ones).
TEST(MeshLoaderErrors, TextFilesCutInsideTheFaceList) {
  TempDir dir;
  writeTextFile(dir / "cut_faces.off", "OFF\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n");
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "cut_faces.off"); }, "cut_faces.off");
  writeTextFile(dir / "cut_faces_ascii.ply",
                "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
                "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n");
  expectErrorNaming<FileError>([&] { (void)loadMesh(dir / "cut_faces_ascii.ply"); }, "cut_faces_ascii.ply");
}

// ---------------------------------------------------------------------------------------------

// The robot's CAD parts are binary STL files with non-manifold edges: every facet must come out as
// a triangle with the facet's own corners, in the file's order, with equal corners merged into
// shared vertices, and nothing printed.
TEST(MeshLoader, NonManifoldRobotPartsKeepEveryFacetQuietly) {
  const auto dir = sharedDataDir() / "meshes" / "abb_irb6640";
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) GTEST_SKIP() << "robot parts not found under " << dir;
  std::size_t parts = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".stl") continue;
    ++parts;
    SCOPED_TRACE(entry.path().filename().string());
    const auto bytes = readBinaryFile(entry.path());
    ASSERT_GE(bytes.size(), 84u);
    std::uint32_t facets = 0;
    std::memcpy(&facets, bytes.data() + 80, 4);
    ASSERT_EQ(bytes.size(), 84u + 50u * facets);
    ::testing::internal::CaptureStderr();
    ::testing::internal::CaptureStdout();
    const TriangleMesh m = loadMesh(entry.path());
    const std::string err = ::testing::internal::GetCapturedStderr();
    const std::string out = ::testing::internal::GetCapturedStdout();
    EXPECT_EQ(err, "");
    EXPECT_EQ(out, "");
    ASSERT_EQ(m.triangleCount(), facets);
    EXPECT_LT(m.positions().size(), 3u * facets) << "corners were not merged into shared vertices";
    for (std::uint32_t f = 0; f < facets; ++f) {
      const auto v = m.vertices(f);
      for (int c = 0; c < 3; ++c) {
        float p[3];
        std::memcpy(p, bytes.data() + 84 + 50 * f + 12 + 12 * c, 12);
        for (int k = 0; k < 3; ++k)
          ASSERT_EQ(v[c][k] == 0.0f ? 0.0f : v[c][k], p[k] == 0.0f ? 0.0f : p[k]) << "facet " << f;
      }
    }
  }
  if (parts == 0) GTEST_SKIP() << "no STL under " << dir;
}

TEST(LoopSubdivide, MultipliesTrianglesByFourAndStaysClosed) {
  const TriangleMesh ico = icosphere(1);  // 80 triangles, closed
  for (const int steps : {0, 1, 2}) {
    SCOPED_TRACE(steps);
    const TriangleMesh m = loopSubdivide(ico, steps);
    EXPECT_EQ(m.triangleCount(), ico.triangleCount() << (2 * steps));
    EXPECT_EQ(m.degenerateCount(), 0u);
    // Closed and consistently wound: every directed edge once, with its twin.
    std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
    for (const auto& t : m.triangles())
      for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
    for (const auto& [e, n] : directed) {
      ASSERT_EQ(n, 1);
      ASSERT_EQ(directed.count({e.second, e.first}), 1u);
    }
    // Loop subdivision averages points: everything stays inside the unit sphere, volume shrinks.
    for (const glm::vec3& p : m.positions()) EXPECT_LE(glm::length(glm::dvec3(p)), 1.0 + 1e-6);
    EXPECT_GT(signedVolume(m), 0.0);
    EXPECT_LE(signedVolume(m), signedVolume(ico) + 1e-9);
  }
  EXPECT_THROW((void)loopSubdivide(ico, -1), InvalidArgument);
}

// Each step quadruples the triangles: what the half-edge mesh and the result will hold is checked
// against the memory limit before the mesh is built, naming the mesh, its triangles and the steps.
TEST(LoopSubdivide, SubdivisionsBeyondTheMemoryLimitAreRefused) {
  const TriangleMesh ico = icosphere(1);  // 80 triangles
  {
    MemoryLimitScope limit(std::uint64_t{1} << 20);
    EXPECT_EQ(loopSubdivide(ico, 2).triangleCount(), 80u * 16u);  // 1280 triangles fit in 1 MiB
    try {
      (void)loopSubdivide(ico, 6);  // 327680 triangles: tens of MiB
      ADD_FAILURE() << "no ResourceError";
    } catch (const ResourceError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("loopSubdivide of '" + ico.name() + "' (80 triangles, 6 steps: up to 327680 triangles) needs"),
                std::string::npos)
          << m;
    }
  }
  // Steps whose counts overflow 64 bits are refused whatever the limit, with a message.
  EXPECT_THROW((void)loopSubdivide(ico, 40), ResourceError);
  EXPECT_EQ(loopSubdivide(ico, 3).triangleCount(), 80u * 64u);
}

TEST(LoopSubdivide, RefusesNonManifoldTrianglesInsteadOfDroppingThem) {
  // Three triangles on one edge (a fin): OpenMesh's half-edge mesh refuses the third, which the
  // subdivision would otherwise lose without a word.
  const std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1};
  const std::vector<std::uint32_t> fin = {0, 1, 2, 1, 0, 3, 0, 1, 4};
  const TriangleMesh m = TriangleMesh::fromArrays(p, fin, "fin");
  ASSERT_EQ(m.triangleCount(), 3u);
  try {
    (void)loopSubdivide(m, 1);
    ADD_FAILURE() << "a non-manifold triangle was dropped silently";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("1 of 3 triangles are non-manifold"), std::string::npos) << e.what();
  }
  // The two-triangle part alone subdivides.
  const std::vector<std::uint32_t> two = {0, 1, 2, 1, 0, 3};
  EXPECT_EQ(loopSubdivide(TriangleMesh::fromArrays(p, two, "two"), 1).triangleCount(), 8u);
}

}  // namespace
}  // namespace duplex::test
