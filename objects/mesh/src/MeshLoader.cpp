// OpenMesh is kept in this translation unit only: its headers are heavy and its streams global.

#include "duplex/objects/MeshLoader.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/Log.h"

// OpenMesh's property containers trip GCC 12's -Wmaybe-uninitialized under the sanitizers (a
// default-constructed VectorT pushed back); the warning is in its headers, not in our code.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#pragma GCC diagnostic pop

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <iostream>
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

// What a file's header declares, for the formats that have a face count (OFF, PLY, binary STL),
// so that a file cut short is refused instead of loading fewer faces: OpenMesh's readers stop at
// the end of the data without reporting it (and its OFF reader even invents faces past the end).
struct FaceCount {
  long long declared = -1;  // -1: unknown
  long long present = -1;   // faces actually in the file, where we walked the list (-1: not known)
};

FaceCount declaredFaceCount(const std::filesystem::path& path, const std::string& ext) {
  FaceCount fc;
  std::ifstream in(path, std::ios::binary);
  if (!in) return fc;
  if (ext == ".off") {
    std::string word;
    if (!(in >> word) || word != "OFF") return fc;  // COFF, NOFF, binary OFF: left to OpenMesh
    long long v = -1, f = -1, e = -1;
    if (!(in >> v >> f >> e) || v < 0 || f < 0) return fc;
    fc.declared = f;
    fc.present = 0;
    double x;
    for (long long i = 0; i < 3 * v; ++i)
      if (!(in >> x)) return fc;
    for (long long i = 0; i < f; ++i) {
      long long k = 0, index = 0;
      if (!(in >> k) || k < 0) break;
      bool ok = true;
      for (long long j = 0; j < k && ok; ++j) ok = static_cast<bool>(in >> index);
      if (!ok) break;
      ++fc.present;
      in.ignore(std::numeric_limits<std::streamsize>::max(), '\n');  // optional colour values
    }
    return fc;
  }
  if (ext == ".ply") {
    std::string line;
    while (std::getline(in, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.rfind("element face ", 0) == 0) fc.declared = std::atoll(line.c_str() + 13);
      if (line == "end_header") break;
    }
    return fc;
  }
  if (ext == ".stl" || ext == ".stlb") {
    char header[84];
    if (!in.read(header, 84)) return fc;
    std::uint32_t n = 0;
    std::memcpy(&n, header + 80, 4);
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (ec) return fc;
    // "solid" starts ASCII files but also some binary ones; the exact binary size decides.
    if (std::string(header, 5) == "solid" && size != 84ull + 50ull * n) return fc;
    fc.declared = n;
    fc.present = static_cast<long long>(std::min<std::uintmax_t>(n, (size - 84) / 50));
    return fc;
  }
  return fc;
}

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

}  // namespace

TriangleMesh loadMesh(const std::filesystem::path& path, MeshLoadReport* report) {
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError("mesh file '" + path.string() + "': " + problem);
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext != ".obj" && ext != ".ply" && ext != ".off" && ext != ".stl" && ext != ".stla" && ext != ".stlb" &&
      ext != ".om")
    throw FileError("mesh file '" + path.string() + "': unsupported extension '" + ext +
                    "' (expected .obj, .ply, .off, .stl or .om)");

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

  const FaceCount faces = declaredFaceCount(path, ext);
  if (faces.present >= 0 && faces.present < faces.declared)
    throw FileError("mesh file '" + path.string() + "': declares " + std::to_string(faces.declared) +
                    " faces but contains only " + std::to_string(faces.present) + " (truncated or malformed)");
  if (faces.declared >= 0 && static_cast<long long>(mesh.n_faces()) < faces.declared)
    throw FileError("mesh file '" + path.string() + "': declares " + std::to_string(faces.declared) +
                    " faces but only " + std::to_string(mesh.n_faces()) + " could be read (truncated or malformed)");

  MeshLoadReport rep;
  rep.complex_edge_warnings = countOccurrences(messages, "complex edge") + countOccurrences(messages, "complex vertex");
  const std::size_t lines = static_cast<std::size_t>(std::count(messages.begin(), messages.end(), '\n'));
  rep.other_warnings = lines > rep.complex_edge_warnings ? lines - rep.complex_edge_warnings : 0;

  std::vector<glm::vec3> positions = vertexPositions(mesh);
  std::vector<TriangleMesh::Triangle> triangles;
  triangles.reserve(mesh.n_faces());
  std::vector<std::uint32_t> corners;
  for (const auto fh : mesh.faces()) {
    corners.clear();
    for (const auto vh : mesh.fv_range(fh)) corners.push_back(static_cast<std::uint32_t>(vh.idx()));
    if (corners.size() < 3) continue;
    if (corners.size() > 3) ++rep.polygons_triangulated;
    for (std::size_t k = 1; k + 1 < corners.size(); ++k) triangles.push_back({corners[0], corners[k], corners[k + 1]});
  }
  if (rep.complex_edge_warnings > 0)
    logger()->info("mesh file '{}': {} non-manifold faces (OpenMesh 'complex edge/vertex'), all kept", path.string(),
                   rep.complex_edge_warnings);
  if (report) *report = rep;
  if (triangles.empty()) throw FileError("mesh file '" + path.string() + "': contains no triangles");
  try {
    return TriangleMesh::fromTriangles(std::move(positions), std::move(triangles), path.string());
  } catch (const InvalidArgument& e) {
    throw FileError(e.what());
  }
}

TriangleMesh loopSubdivide(const TriangleMesh& input, int steps) {
  if (steps < 0) throw InvalidArgument("loopSubdivide: negative step count");
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
