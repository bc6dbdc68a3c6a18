// OpenMesh is kept in this translation unit only: its headers are heavy and its streams global.
// The text and binary formats are read by the project's own strict readers (MeshFileReaders.cpp);
// OpenMesh reads OM files and subdivides.

#include "duplex/objects/MeshLoader.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/Log.h"
#include "duplex/accel/MemoryLimit.h"

#include "MeshFileReaders.h"

// OpenMesh's property containers trip GCC 12's -Wmaybe-uninitialized under the sanitizers (a
// default-constructed VectorT pushed back); the warning is in its headers, not in our code.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <sstream>

namespace duplex {

namespace {

using PolyMesh = OpenMesh::PolyMesh_ArrayKernelT<>;
using TriMesh = OpenMesh::TriMesh_ArrayKernelT<>;

// Reads are serialised: OpenMesh's message streams are global.
std::mutex& openMeshMutex() {
  static std::mutex m;
  return m;
}

// OpenMesh reports through global streams that print to std::cerr, once per bad face. The first
// read redirects them, once per process, into a buffer that each read empties and counts (under
// openMeshMutex). Once, because OpenMesh's disconnect() does not free what connect() allocated:
// redirecting per read leaked on every read. The price: OpenMesh messages of an application that
// uses OpenMesh itself also land in this buffer instead of on std::cerr.
class OpenMeshCapture {
 public:
  OpenMeshCapture() {
    static std::ostringstream* buffer = [] {
      auto* b = new std::ostringstream;  // lives as long as OpenMesh's streams do
      for (auto* s : {&omerr(), &omlog(), &omout()}) {
        s->disconnect(std::cerr);
        s->disconnect(std::cout);
        s->connect(*b);
      }
      return b;
    }();
    buffer_ = buffer;
    buffer_->str({});
  }
  std::string text() {
    for (auto* s : {&omerr(), &omlog(), &omout()}) s->flush();
    std::string t = buffer_->str();
    buffer_->str({});
    return t;
  }

 private:
  std::ostringstream* buffer_;
};

std::size_t countOccurrences(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t pos = text.find(what); pos != std::string::npos; pos = text.find(what, pos + what.size())) ++n;
  return n;
}

// The mesh's vertex positions, indexed as OpenMesh numbers its vertices (face indices refer to them).
// For the polygon mesh of a file and the triangle mesh of a subdivision alike.
template <class OpenMeshMesh>
std::vector<glm::vec3> vertexPositions(const OpenMeshMesh& mesh) {
  std::vector<glm::vec3> positions(mesh.n_vertices());
  for (const auto vh : mesh.vertices()) {
    const auto& p = mesh.point(vh);
    positions[vh.idx()] = {p[0], p[1], p[2]};
  }
  return positions;
}

// An OM file through OpenMesh (the only format without a reader of our own: OpenMesh's own).
mesh_files::ParsedMesh readOm(const std::filesystem::path& path, MeshLoadReport& rep) {
  PolyMesh mesh;
  std::string messages;
  bool ok = false;
  {
    std::lock_guard<std::mutex> lock(openMeshMutex());
    OpenMeshCapture capture;
    OpenMesh::IO::Options options;
    ok = OpenMesh::IO::read_mesh(mesh, path.string(), options);
    messages = capture.text();
  }
  if (!ok) throw FileError("mesh file '" + path.string() + "': OpenMesh could not read it (malformed or truncated)");
  rep.complex_edge_warnings = countOccurrences(messages, "complex edge") + countOccurrences(messages, "complex vertex");
  const std::size_t lines = static_cast<std::size_t>(std::count(messages.begin(), messages.end(), '\n'));
  rep.other_warnings = lines > rep.complex_edge_warnings ? lines - rep.complex_edge_warnings : 0;
  mesh_files::ParsedMesh parsed;
  parsed.positions = vertexPositions(mesh);
  parsed.triangles.reserve(mesh.n_faces());
  std::vector<std::uint32_t> corners;
  for (const auto fh : mesh.faces()) {
    corners.clear();
    for (const auto vh : mesh.fv_range(fh)) corners.push_back(static_cast<std::uint32_t>(vh.idx()));
    mesh_files::addFace(parsed, corners);
  }
  return parsed;
}

}  // namespace

TriangleMesh loadMesh(const std::filesystem::path& path, MeshLoadReport* report) {
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError("mesh file '" + path.string() + "': " + problem);
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  using mesh_files::Format;
  static const std::map<std::string, Format> kFormats = {{".obj", Format::Obj},       {".ply", Format::Ply},
                                                         {".off", Format::Off},       {".stl", Format::Stl},
                                                         {".stla", Format::StlAscii}, {".stlb", Format::StlBinary}};
  const auto format = kFormats.find(ext);
  if (format == kFormats.end() && ext != ".om")
    throw FileError("mesh file '" + path.string() + "': unsupported extension '" + ext +
                    "' (expected .obj, .ply, .off, .stl or .om)");

  MeshLoadReport rep;
  mesh_files::ParsedMesh parsed;
  if (format != kFormats.end()) {
    parsed = mesh_files::read(format->second, readWholeFile(path, "mesh file"), path.string());
    rep.other_warnings = parsed.ignored_statements;
  } else {
    parsed = readOm(path, rep);
  }
  rep.polygons_triangulated = parsed.polygons_triangulated;
  rep.repeated_corner_faces = parsed.repeated_corner_faces;
  if (rep.complex_edge_warnings > 0)
    logger()->info("mesh file '{}': {} non-manifold faces (OpenMesh 'complex edge/vertex'), all kept", path.string(),
                   rep.complex_edge_warnings);
  if (rep.repeated_corner_faces > 0)
    logger()->info("mesh file '{}': {} faces name a vertex twice; kept as degenerate triangles (never hit)",
                   path.string(), rep.repeated_corner_faces);
  if (rep.other_warnings > 0)
    logger()->info("mesh file '{}': {} statements not used (free-form geometry or unknown keywords)", path.string(),
                   rep.other_warnings);
  if (report) *report = rep;
  if (parsed.triangles.empty()) throw FileError("mesh file '" + path.string() + "': contains no triangles");
  try {
    return TriangleMesh::fromTriangles(std::move(parsed.positions), std::move(parsed.triangles), path.string());
  } catch (const InvalidArgument& e) {
    throw FileError(e.what());
  }
}

TriangleMesh loopSubdivide(const TriangleMesh& input, int steps) {
  if (steps < 0) throw InvalidArgument("loopSubdivide: negative step count");
  {
    // Each step adds a vertex per edge, splits each edge in two and adds three per face, and
    // makes four faces of each (from at most three edges per input face). The half-edge mesh
    // keeps its kernel items, a status per item and a point per vertex; the subdivider a point
    // per vertex and per edge; the result its positions and triangles.
    std::uint64_t v = input.positions().size(), f = input.triangleCount(), e = arrayBytes(f, 3);
    for (int k = 0; k < steps; ++k) {
      v = saturatingAdd(v, e);
      e = saturatingAdd(arrayBytes(e, 2), arrayBytes(f, 3));
      f = arrayBytes(f, 4);
    }
    using Status = OpenMesh::Attributes::StatusInfo;
    std::uint64_t bytes =
        arrayBytes(v, sizeof(TriMesh::Vertex) + sizeof(Status) + 2 * sizeof(TriMesh::Point) + sizeof(glm::vec3));
    bytes = saturatingAdd(bytes, arrayBytes(e, sizeof(TriMesh::Edge) + 3 * sizeof(Status) + sizeof(TriMesh::Point)));
    bytes =
        saturatingAdd(bytes, arrayBytes(f, sizeof(TriMesh::Face) + sizeof(Status) + sizeof(TriangleMesh::Triangle)));
    std::ostringstream what;
    what << "loopSubdivide of '" << input.name() << "' (" << input.triangleCount() << " triangles, " << steps
         << " steps: up to " << f << " triangles)";
    requireMemory(bytes, what.str());
  }
  TriMesh mesh;
  std::vector<TriMesh::VertexHandle> handles;
  handles.reserve(input.positions().size());
  for (const glm::vec3& p : input.positions()) handles.push_back(mesh.add_vertex(TriMesh::Point(p.x, p.y, p.z)));
  {
    std::lock_guard<std::mutex> lock(openMeshMutex());
    OpenMeshCapture capture;
    std::size_t refused = 0;
    for (std::size_t i = 0; i < input.triangleCount(); ++i) {
      if (!input.isValid(i)) continue;
      const auto& t = input.triangles()[i];
      if (!mesh.add_face(handles[t[0]], handles[t[1]], handles[t[2]]).is_valid()) ++refused;
    }
    // OpenMesh's half-edge mesh cannot hold a non-manifold face; subdividing without it would
    // silently drop geometry, so refuse the input instead.
    if (refused > 0)
      throw InvalidArgument("loopSubdivide: " + std::to_string(refused) + " of " +
                            std::to_string(input.triangleCount()) +
                            " triangles are non-manifold (complex edge or vertex) and cannot be subdivided");
    OpenMesh::Subdivider::Uniform::LoopT<TriMesh> loop;
    loop.attach(mesh);
    loop(static_cast<std::size_t>(steps));
    loop.detach();
  }
  mesh.garbage_collection();
  std::vector<glm::vec3> positions = vertexPositions(mesh);
  std::vector<TriangleMesh::Triangle> triangles;
  triangles.reserve(mesh.n_faces());
  for (const auto fh : mesh.faces()) {
    TriangleMesh::Triangle t{};
    int k = 0;
    for (const auto vh : mesh.fv_range(fh)) t[k++] = static_cast<std::uint32_t>(vh.idx());
    triangles.push_back(t);
  }
  return TriangleMesh::fromTriangles(std::move(positions), std::move(triangles),
                                     input.name() + " (Loop x" + std::to_string(steps) + ")");
}

}  // namespace duplex
