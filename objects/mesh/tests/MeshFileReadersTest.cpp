// The strict mesh readers (OBJ, PLY, OFF, STL): the file's face numbering survives faces that name
// a vertex twice (the primitive id of a hit is the face's triangle in the file), every syntax
// variant the formats allow reads to the expected vertices and triangles, and hostile input (huge counts, damaged
// headers, thousands of random mutations) is refused with a FileError naming the file, never a crash, a hang, another
// exception or an allocation larger than the file justifies.

#include "MeshFileReaders.h"
#include "MemoryLimitScope.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/objects/MeshLoader.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"

#include <gtest/gtest.h>

#include <atomic>
#include <bit>
#include <cstdlib>
#include <cstring>
#include <new>
#include <random>
#include <sstream>
#include <string>
#include <vector>

// The largest single allocation since the last reset, to check that no count in a file leads to
// an allocation its size does not justify. Replacing the global operator new is the only way to
// see every allocation the readers make (std::vector included).
namespace {
std::atomic<std::size_t> g_largest_allocation{0};
}

// GCC sees free() of what operator new returned; both are ours and use malloc/free.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  std::size_t seen = g_largest_allocation.load(std::memory_order_relaxed);
  while (n > seen && !g_largest_allocation.compare_exchange_weak(seen, n, std::memory_order_relaxed)) {
  }
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace duplex::test {
namespace {

using mesh_files::Format;

// Reads `text` as `name` through loadMesh (a file in a temporary folder).
TriangleMesh loadText(const TempDir& dir, const std::string& name, const std::string& text,
                      MeshLoadReport* report = nullptr) {
  writeTextFile(dir / name, text);
  return loadMesh(dir / name, report);
}

std::string sixVertices() { return "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\n"; }

// ---------------------------------------------------------------------------------------------

TEST(MeshFileReaders, ObjFaceThatNamesAVertexTwiceKeepsTheNumberingOfLaterFaces) {
  TempDir dir;
  MeshLoadReport rep;
  const TriangleMesh m = loadText(dir, "repeated.obj", sixVertices() + "f 1 2 3\nf 4 4 5\nf 4 5 6\n", &rep);
  ASSERT_EQ(m.triangleCount(), 3u);
  EXPECT_EQ(m.triangles()[1], (TriangleMesh::Triangle{3, 3, 4}));
  EXPECT_FALSE(m.isValid(1));
  EXPECT_EQ(m.triangles()[2], (TriangleMesh::Triangle{3, 4, 5}));
  EXPECT_EQ(rep.repeated_corner_faces, 1u);
  EXPECT_EQ(m.degenerateCount(), 1u);
  // A ray down onto the third face (z = 1) reports primitive 2, the face's index in the file; one
  // up onto the first (z = 0) reports primitive 0.
  MeshObject object(std::make_shared<const TriangleMesh>(m));
  QueryContext ctx;
  Ray ray;
  ray.origin = glm::vec3(0.25f, 0.25f, 2.0f);
  ray.dir = glm::vec3(0.0f, 0.0f, -1.0f);
  Hit hit;
  ASSERT_TRUE(object.intersect(ray, hit, ctx));
  EXPECT_EQ(hit.prim_id, 2u);
  EXPECT_FLOAT_EQ(hit.t, 1.0f);
  ray.origin = glm::vec3(0.25f, 0.25f, -1.0f);
  ray.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  hit = Hit{};
  ASSERT_TRUE(object.intersect(ray, hit, ctx));
  EXPECT_EQ(hit.prim_id, 0u);
}

TEST(MeshFileReaders, BadObjFacesAreRefusedNamingTheLine) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"f 1 2 3\nf 4 5 9\n", "line 8"},  // past the last vertex
      {"f 1 2 3\nf 0 1 2\n", "line 8"},  // 0 is no OBJ index
      {"f 1 2\n", "line 7"},             // two corners
      {"f 1 2 -7\n", "line 7"},          // before the first vertex
      {"f 1 2 x\n", "line 7"},           // not a number
      {"v 1 2\nf 1 2 3\n", "line 7"},    // a vertex of two numbers
      {"f 1 2 3\n# comment\nf 1 2 99999999999\n", "line 9"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(cases[i].first);
    const std::string name = "bad" + std::to_string(i) + ".obj";
    writeTextFile(dir / name, sixVertices() + cases[i].first);
    try {
      (void)loadMesh(dir / name);
      ADD_FAILURE() << "loaded";
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(cases[i].second), std::string::npos) << e.what();
    }
  }
}

TEST(MeshFileReaders, ObjSyntaxVariants) {
  TempDir dir;
  MeshLoadReport rep;
  const std::string text =
      "# colours after positions, slashes, negative and forward indices, a continued line\n"
      "mtllib scene.mtl\no part\ng group\ns 1\nusemtl steel\n"
      "v 0 0 0 1 0 0\nv +1 0 0\nv 0 1.0e0 0\n"
      "vt 0 0\nvn 0 0 1\n"
      "f 1/1/1 2//1 3/1\n"
      "f -3 -2 \\\n -1\n"
      "f 1 2 4\n"
      "l 1 2\np 3\n"
      "curv 0 1 1 2\n"
      "v 0 0 1\n";
  const TriangleMesh m = loadText(dir, "variants.obj", text, &rep);
  ASSERT_EQ(m.positions().size(), 4u);
  EXPECT_EQ(m.positions()[1], glm::vec3(1, 0, 0));
  EXPECT_EQ(m.positions()[3], glm::vec3(0, 0, 1));
  ASSERT_EQ(m.triangleCount(), 3u);
  EXPECT_EQ(m.triangles()[0], (TriangleMesh::Triangle{0, 1, 2}));
  EXPECT_EQ(m.triangles()[1], (TriangleMesh::Triangle{0, 1, 2}));
  EXPECT_EQ(m.triangles()[2], (TriangleMesh::Triangle{0, 1, 3}));
  EXPECT_EQ(rep.other_warnings, 1u);  // curv
  EXPECT_EQ(rep.repeated_corner_faces, 0u);
}

// A PLY file of the tetrahedron with every layout feature: `format` "ascii",
// "binary_little_endian" or "binary_big_endian", double coordinates, extra vertex properties, an
// element between vertex and face, a per-face property after the index list.
std::string variantPly(const std::string& format) {
  const std::string header = "ply\r\nformat " + format +
                             " 1.0\r\ncomment made by hand\r\nelement vertex 4\r\nproperty double x\r\n"
                             "property uchar red\r\nproperty float y\r\nproperty float z\r\nelement edge 1\r\n"
                             "property int vertex1\r\nproperty int vertex2\r\nelement face 4\r\n"
                             "property list uint8 uint32 vertex_index\r\nproperty short flags\r\nend_header\r\n";
  const float xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::uint32_t faces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string out = header;
  if (format == "ascii") {
    for (const auto& p : xyz)
      out += std::to_string(p[0]) + " 200 " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
    out += "0 1\n";
    for (const auto& f : faces)
      out += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + " -5\n";
    return out;
  }
  const bool big = format == "binary_big_endian";
  auto put = [&](const void* data, std::size_t n) {
    const char* b = static_cast<const char*>(data);
    for (std::size_t i = 0; i < n; ++i) out.push_back(b[big ? n - 1 - i : i]);
  };
  for (const auto& p : xyz) {
    const double x = p[0];
    const unsigned char red = 200;
    put(&x, 8);
    put(&red, 1);
    put(&p[1], 4);
    put(&p[2], 4);
  }
  const std::int32_t edge[2] = {0, 1};
  put(&edge[0], 4);
  put(&edge[1], 4);
  for (const auto& f : faces) {
    const unsigned char three = 3;
    put(&three, 1);
    for (const std::uint32_t v : f) put(&v, 4);
    const std::int16_t flags = -5;
    put(&flags, 2);
  }
  return out;
}

TEST(MeshFileReaders, PlyLayouts) {
  TempDir dir;
  for (const std::string format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    const TriangleMesh m = loadText(dir, format + ".ply", variantPly(format));
    EXPECT_EQ(m.positions(), (std::vector<glm::vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
    EXPECT_EQ(m.triangles(), (std::vector<TriangleMesh::Triangle>{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}));
  }
}

// Binary OFF as the format defines it (big-endian, a colour count after every face) and as
// OpenMesh writes it (little-endian, no colour count: the cube test of MeshLoaderTest).
TEST(MeshFileReaders, BinaryOffInTheFormatsOwnLayout) {
  std::string out = "OFF BINARY\n";
  auto put32 = [&](std::uint32_t v) {
    for (int i = 3; i >= 0; --i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  put32(4);
  put32(2);
  put32(0);
  const float xyz[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (const auto& p : xyz)
    for (const float c : p) put32(std::bit_cast<std::uint32_t>(c));
  put32(3), put32(0), put32(1), put32(2), put32(0);
  put32(3), put32(0), put32(2), put32(3), put32(3);
  for (int k = 0; k < 3; ++k) put32(std::bit_cast<std::uint32_t>(0.5f));  // an RGB colour
  const auto m = mesh_files::read(Format::Off, out, "spec.off");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[2], glm::vec3(1, 1, 0));
  EXPECT_EQ(m.triangles, (std::vector<TriangleMesh::Triangle>{{0, 1, 2}, {0, 2, 3}}));
}

TEST(MeshFileReaders, AsciiOffVariants) {
  // COFF with colours after every vertex and face, comments, the counts on the keyword's line.
  const std::string text =
      "COFF 4 2 0 # counts on the first line\n"
      "# a comment line\n"
      "0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n"
      "4 0 1 2 3 0.5 0.5 0.5\n3 0 2 2\n";
  const auto m = mesh_files::read(Format::Off, text, "colours.off");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[3], glm::vec3(0, 1, 0));
  EXPECT_EQ(m.triangles, (std::vector<TriangleMesh::Triangle>{{0, 1, 2}, {0, 2, 3}, {0, 2, 2}}));
  EXPECT_EQ(m.polygons_triangulated, 1u);
  EXPECT_EQ(m.repeated_corner_faces, 1u);
}

TEST(MeshFileReaders, AsciiStlWithSeveralSolidsAndUpperCase) {
  const std::string text =
      "SOLID first part\nFACET NORMAL 0 0 1\nOUTER LOOP\nVERTEX 0 0 0\nVERTEX 1 0 0\nVERTEX 0 1 0\nENDLOOP\nENDFACET\n"
      "ENDSOLID first part\n"
      "solid second\n  facet normal -nan -nan -nan\n    outer loop\n      vertex 1 0 0\n      vertex 1 1 0\n"
      "      vertex 0 1 0\n\n    endloop\n  endfacet\nendsolid second\n";
  const auto m = mesh_files::read(Format::Stl, text, "two.stl");
  EXPECT_EQ(m.positions, (std::vector<glm::vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}));
  EXPECT_EQ(m.triangles, (std::vector<TriangleMesh::Triangle>{{0, 1, 2}, {1, 3, 2}}));
}

// ---------------------------------------------------------------------------------------------
// Hostile input.

// Reads `bytes` as `format`; true when it loaded as a valid mesh, false when refused with a
// FileError naming the file (or an InvalidArgument of TriangleMesh, which loadMesh turns into a
// FileError naming the file: a mesh without a valid triangle). Any other exception fails the test. Checks that no
// allocation was larger than `bytes` justifies (a few times its size, for the vertex merge table and vectors).
bool readsOrIsRefused(Format format, const std::string& bytes, const std::string& what) {
  g_largest_allocation.store(0);
  bool loaded = false;
  try {
    auto parsed = mesh_files::read(format, bytes, "fuzzed.mesh");
    if (!parsed.triangles.empty()) {
      (void)TriangleMesh::fromTriangles(std::move(parsed.positions), std::move(parsed.triangles), "fuzzed");
      loaded = true;
    }
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("fuzzed.mesh"), std::string::npos) << what << ": " << e.what();
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("fuzzed"), std::string::npos) << what << ": " << e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << what << ": " << typeid(e).name() << ": " << e.what();
  }
  const std::size_t largest = g_largest_allocation.load();
  EXPECT_LE(largest, 64 * bytes.size() + 4096)
      << what << ": allocation of " << largest << " bytes for a file of " << bytes.size();
  return loaded;
}

TEST(MeshFileReaders, CountsAreBoundedByTheFileSize) {
  const std::vector<std::pair<Format, std::string>> cases = {
      {Format::Ply,
       "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n"},
      {Format::Ply,
       "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
       "property float z\nelement face 300000000\nproperty list uchar int vertex_indices\nend_header\n"
       "012345678901234567890123456789012345\x03"},
      {Format::Ply,
       "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
       "element face 1\nproperty list uint int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
       "4000000000 0 1 2\n"},
      // An element without properties declared 2^62 times (no bytes to bound it by): no loop over it.
      {Format::Ply,
       "ply\nformat ascii 1.0\nelement nothing 4611686018427387904\nelement vertex 3\nproperty float x\n"
       "property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
       "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n"},
      {Format::Ply,
       "ply\nformat binary_little_endian 1.0\nelement nothing 4611686018427387904\nelement vertex 3\n"
       "property float x\nproperty float y\nproperty float z\nelement face 1\n"
       "property list uchar int vertex_indices\nend_header\n"},
      {Format::Off, "OFF\n2000000000 2000000000 0\n0 0 0\n"},
      {Format::Off, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2000000000 0 1 2\n"},
      {Format::Off, std::string("OFF BINARY\n\x7f\xff\xff\xff\x7f\xff\xff\xff\0\0\0\0", 23)},
      {Format::StlBinary, std::string(80, ' ') + std::string("\xff\xff\xff\xff", 4) + std::string(100, '\0')},
  };
  for (const auto& [format, bytes] : cases) EXPECT_FALSE(readsOrIsRefused(format, bytes, bytes.substr(0, 60)));
}

// The arrays a file's counts call for are checked against the memory limit before they are
// allocated (a count the file's size allows can still be more than the process may take), and the
// file's bytes before they are read: a ResourceError naming the file, no allocation past the text.
TEST(MeshFileReaders, ArraysBeyondTheMemoryLimitAreRefusedBeforeAllocating) {
  TempDir dir;
  const std::size_t n = 20000;  // a strip of n triangles over n + 2 vertices
  std::ostringstream off, obj;
  off << "OFF\n" << n + 2 << " " << n << " 0\n";
  for (std::size_t i = 0; i < n + 2; ++i) {
    off << i / 2 << " " << i % 2 << " 0\n";
    obj << "v " << i / 2 << " " << i % 2 << " 0\n";
  }
  for (std::size_t i = 0; i < n; ++i) {
    off << "3 " << i << " " << i + 1 << " " << i + 2 << "\n";
    obj << "f " << i + 1 << " " << i + 2 << " " << i + 3 << "\n";
  }
  for (const auto& [name, text] : {std::pair{std::string("strip.off"), off.str()}, {"strip.obj", obj.str()}}) {
    writeTextFile(dir / name, text);
    const std::string file = (dir / name).string();
    {
      // The text fits, its 12-byte positions and triangles do not.
      MemoryLimitScope limit(text.size() + 1000);
      g_largest_allocation = 0;
      try {
        (void)loadMesh(dir / name);
        ADD_FAILURE() << name << ": no ResourceError";
      } catch (const ResourceError& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("mesh file '" + file + "' ("), std::string::npos) << m;
        EXPECT_NE(m.find("more than the memory limit of"), std::string::npos) << m;
        if (name == "strip.off") {
          std::ostringstream expected;
          expected << "(" << n + 2 << " vertices, " << n << " faces) needs " << formatBytes(text.size() + 24 * n + 24);
          EXPECT_NE(m.find(expected.str()), std::string::npos) << m;
        }
      }
      EXPECT_LE(g_largest_allocation.load(), text.size() + 1000) << name;
    }
    {
      MemoryLimitScope limit(text.size() - 1);
      const std::filesystem::path path = dir / name;  // clang 14 lambdas cannot capture structured bindings
      expectErrorNaming<ResourceError>([&] { (void)loadMesh(path); }, "mesh file '" + file + "' needs");
    }
    EXPECT_EQ(loadMesh(dir / name).triangleCount(), n) << name;
  }
}

// An ASCII PLY whose header lost a line (OpenMesh printed "Unsupported keyword : e" and crashed).
TEST(MeshFileReaders, PlyHeaderThatLostALineIsRefused) {
  const std::string full =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  ASSERT_TRUE(readsOrIsRefused(Format::Ply, full, "complete"));
  std::size_t line_start = 0;
  for (int line = 0; line < 9; ++line) {
    const std::size_t end = full.find('\n', line_start) + 1;
    const std::string damaged = full.substr(0, line_start) + full.substr(end);
    SCOPED_TRACE(full.substr(line_start, end - line_start));
    if (line != 0 && line != 8) EXPECT_FALSE(readsOrIsRefused(Format::Ply, damaged, "lost a line"));
    else (void)readsOrIsRefused(Format::Ply, damaged, "lost a line");
    line_start = end;
  }
}

// Seeds: a small file of each format; each is mutated (bytes changed, inserted, deleted, cut
// short, lines repeated or dropped, numbers made huge) and read. The run's property is the
// absence of any failure other than a FileError naming the file.
TEST(MeshFileReaders, MutatedFilesLoadOrAreRefusedCleanly) {
  std::vector<std::pair<Format, std::string>> seeds = {
      {Format::Obj, sixVertices() + "f 1 2 3\nf 4 5 6 1\nf -1 -2 -3\n"},
      {Format::Ply, variantPly("ascii")},
      {Format::Ply, variantPly("binary_little_endian")},
      {Format::Ply, variantPly("binary_big_endian")},
      {Format::Off, "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 2 3\n"},
      {Format::Stl,
       "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n"
       "endfacet\nendsolid s\n"},
  };
  {
    std::string off = "OFF BINARY\n";
    for (const std::uint32_t v : {3u, 1u, 0u}) off.append(reinterpret_cast<const char*>(&v), 4);
    const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    off.append(reinterpret_cast<const char*>(xyz), sizeof xyz);
    for (const std::uint32_t v : {3u, 0u, 1u, 2u}) off.append(reinterpret_cast<const char*>(&v), 4);
    seeds.emplace_back(Format::Off, off);
    std::string stl(80, 'h');
    const std::uint32_t n = 2;
    stl.append(reinterpret_cast<const char*>(&n), 4);
    for (int f = 0; f < 2; ++f) {
      const float rec[12] = {0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, static_cast<float>(f)};
      stl.append(reinterpret_cast<const char*>(rec), sizeof rec);
      stl.append(2, '\0');
    }
    seeds.emplace_back(Format::Stl, stl);
  }
  std::mt19937 rng(20261203);
  const char* const kNumbers[] = {"4294967295", "-1", "2147483648", "1e39", "nan", "-0", "99999999999999999999"};
  std::size_t loaded = 0, refused = 0;
  for (const auto& [format, seed] : seeds) {
    for (int round = 0; round < 1000; ++round) {
      std::string bytes = seed;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits && !bytes.empty(); ++e) {
        const std::size_t at = rng() % bytes.size();
        switch (rng() % 7) {
          case 0: bytes[at] = static_cast<char>(rng()); break;
          case 1: bytes.insert(at, 1, static_cast<char>(rng())); break;
          case 2: bytes.erase(at, 1 + rng() % 8); break;
          case 3: bytes.resize(at); break;
          case 4: {  // drop or repeat the line around `at`
            const std::size_t s = bytes.rfind('\n', at), b = s == std::string::npos ? 0 : s + 1;
            const std::size_t t = bytes.find('\n', at), end = t == std::string::npos ? bytes.size() : t + 1;
            if (rng() % 2) bytes.erase(b, end - b);
            else bytes.insert(b, bytes.substr(b, end - b));
            break;
          }
          case 5: bytes.insert(at, kNumbers[rng() % std::size(kNumbers)]); break;
          default: {  // a byte of a binary count set to 0xff
            bytes[at] = '\xff';
            break;
          }
        }
      }
      if (readsOrIsRefused(format, bytes, "mutation " + std::to_string(round))) ++loaded;
      else ++refused;
      if (HasFailure()) return;
    }
  }
  // Both outcomes occur: the mutations are neither all harmless nor all fatal.
  EXPECT_GT(loaded, 0u);
  EXPECT_GT(refused, 0u);
}

}  // namespace
}  // namespace duplex::test
