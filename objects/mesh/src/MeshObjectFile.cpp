#include "duplex/objects/MeshObjectFile.h"

#include "duplex/accel/AtomicFile.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/Xxh64.h"

#include <array>
#include <cstring>
#include <fstream>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace duplex {

static_assert(std::endian::native == std::endian::little,
              "the structure file is written in native (little endian) order");
static_assert(std::is_trivially_copyable_v<KdNode> && sizeof(KdNode) == 8);
static_assert(sizeof(glm::vec3) == 12 && sizeof(TriangleMesh::Triangle) == 12);

namespace {

constexpr std::array<char, 8> kMagic = {'D', 'P', 'L', 'X', 'K', 'D', 'T', '\0'};
constexpr std::size_t kHeaderBytes = 64;
constexpr std::size_t kChecksumBytes = 8;

template <class T>
std::span<const unsigned char> bytesOf(const std::vector<T>& v) {
  return {reinterpret_cast<const unsigned char*>(v.data()), v.size() * sizeof(T)};
}

// Fixed-size fields at their offsets (see the table in MeshObjectFile.h).
struct Header {
  std::uint32_t version = 0;
  std::uint32_t header_bytes = 0;
  std::uint64_t mesh_checksum = 0;
  std::uint32_t vertices = 0, triangles = 0, nodes = 0, prim_indices = 0;
  float bounds[6] = {};
};

void putHeader(unsigned char* out, const Header& h) {
  std::memcpy(out, kMagic.data(), 8);
  std::memcpy(out + 8, &h.version, 4);
  std::memcpy(out + 12, &h.header_bytes, 4);
  std::memcpy(out + 16, &h.mesh_checksum, 8);
  std::memcpy(out + 24, &h.vertices, 4);
  std::memcpy(out + 28, &h.triangles, 4);
  std::memcpy(out + 32, &h.nodes, 4);
  std::memcpy(out + 36, &h.prim_indices, 4);
  std::memcpy(out + 40, h.bounds, 24);
}

Header getHeader(const unsigned char* in) {
  Header h;
  std::memcpy(&h.version, in + 8, 4);
  std::memcpy(&h.header_bytes, in + 12, 4);
  std::memcpy(&h.mesh_checksum, in + 16, 8);
  std::memcpy(&h.vertices, in + 24, 4);
  std::memcpy(&h.triangles, in + 28, 4);
  std::memcpy(&h.nodes, in + 32, 4);
  std::memcpy(&h.prim_indices, in + 36, 4);
  std::memcpy(h.bounds, in + 40, 24);
  return h;
}

std::uint64_t fileBytes(const Header& h) {
  return kHeaderBytes + std::uint64_t{h.nodes} * sizeof(KdNode) + std::uint64_t{h.prim_indices} * 4 + kChecksumBytes;
}

}  // namespace

std::uint64_t meshChecksum(const TriangleMesh& mesh) {
  return xxh64(bytesOf(mesh.triangles()), xxh64(bytesOf(mesh.positions()), 0));
}

void saveMeshObject(const MeshObject& object, const std::filesystem::path& path) {
  const TriangleMesh& mesh = object.mesh();
  const KdTree& tree = object.tree();
  Header h;
  h.version = kMeshObjectFileVersion;
  h.header_bytes = kHeaderBytes;
  h.mesh_checksum = meshChecksum(mesh);
  h.vertices = static_cast<std::uint32_t>(mesh.positions().size());
  h.triangles = static_cast<std::uint32_t>(mesh.triangleCount());
  h.nodes = static_cast<std::uint32_t>(tree.nodes.size());
  h.prim_indices = static_cast<std::uint32_t>(tree.prim_indices.size());
  const float bounds[6] = {tree.bounds.lo.x, tree.bounds.lo.y, tree.bounds.lo.z,
                           tree.bounds.hi.x, tree.bounds.hi.y, tree.bounds.hi.z};
  std::memcpy(h.bounds, bounds, sizeof(bounds));

  // The whole file in memory, then one write: structures are a few MB.
  std::vector<unsigned char> bytes(fileBytes(h));
  putHeader(bytes.data(), h);
  unsigned char* p = bytes.data() + kHeaderBytes;
  const auto nodes = bytesOf(tree.nodes);
  const auto prims = bytesOf(tree.prim_indices);
  if (!nodes.empty()) std::memcpy(p, nodes.data(), nodes.size());
  if (!prims.empty()) std::memcpy(p + nodes.size(), prims.data(), prims.size());
  const std::uint64_t checksum = xxh64(std::span(bytes).first(bytes.size() - kChecksumBytes), 0);
  std::memcpy(bytes.data() + bytes.size() - kChecksumBytes, &checksum, kChecksumBytes);

  // Not flushed to the disk per file: a prepared library may hold tens of thousands, and a file a
  // power loss damages is refused on loading (checksum) and prepared again.
  writeFileAtomically(path, bytes, "bottom-level structure file", /*sync=*/false);
}

std::shared_ptr<const MeshObject> loadMeshObject(const std::filesystem::path& path,
                                                 std::shared_ptr<const TriangleMesh> mesh) {
  if (!mesh) throw InvalidArgument("loadMeshObject: null mesh");
  auto fail = [&path](const std::string& problem) -> void { throw FileError(path.string() + ": " + problem); };

  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) fail("cannot open bottom-level structure file");
  const std::streamoff size = in.tellg();
  if (size < 0) fail("cannot read the file size");
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  in.seekg(0);
  if (!bytes.empty() && !in.read(reinterpret_cast<char*>(bytes.data()), size)) fail("read error");

  // Framing: magic, version, sizes; then the checksum of the whole file; then the mesh it was made
  // for; last the tree itself (MeshObject::fromParts), which is checked even when the checksum
  // matched, since a checksum is no defence against a file written on purpose.
  if (bytes.size() < kHeaderBytes + kChecksumBytes)
    fail("too short for a bottom-level structure file (" + std::to_string(bytes.size()) + " bytes)");
  if (std::memcmp(bytes.data(), kMagic.data(), kMagic.size()) != 0)
    fail("not a Duplex bottom-level structure file (bad magic)");
  const Header h = getHeader(bytes.data());
  if (h.version != kMeshObjectFileVersion)
    fail("file version " + std::to_string(h.version) + ", this build reads version " +
         std::to_string(kMeshObjectFileVersion));
  if (h.header_bytes != kHeaderBytes)
    fail("header size " + std::to_string(h.header_bytes) + ", expected " + std::to_string(kHeaderBytes));
  if (fileBytes(h) != bytes.size())
    fail("file has " + std::to_string(bytes.size()) + " bytes, its header announces " + std::to_string(fileBytes(h)) +
         " (" + std::to_string(h.nodes) + " nodes, " + std::to_string(h.prim_indices) +
         " indices): truncated or damaged");
  std::uint64_t stored_checksum;
  std::memcpy(&stored_checksum, bytes.data() + bytes.size() - kChecksumBytes, kChecksumBytes);
  if (xxh64(std::span(bytes).first(bytes.size() - kChecksumBytes), 0) != stored_checksum)
    fail("checksum mismatch: the file is damaged");
  if (h.vertices != mesh->positions().size() || h.triangles != mesh->triangleCount())
    fail("saved for a mesh of " + std::to_string(h.vertices) + " vertices and " + std::to_string(h.triangles) +
         " triangles, but mesh '" + mesh->name() + "' has " + std::to_string(mesh->positions().size()) + " and " +
         std::to_string(mesh->triangleCount()));
  if (h.mesh_checksum != meshChecksum(*mesh))
    fail("saved for another mesh: checksum of mesh '" + mesh->name() + "' differs (vertices or triangles edited)");

  KdTree tree;
  tree.bounds = Box(glm::vec3(h.bounds[0], h.bounds[1], h.bounds[2]), glm::vec3(h.bounds[3], h.bounds[4], h.bounds[5]));
  tree.nodes.resize(h.nodes);
  tree.prim_indices.resize(h.prim_indices);
  const unsigned char* p = bytes.data() + kHeaderBytes;
  if (h.nodes != 0) std::memcpy(tree.nodes.data(), p, std::size_t{h.nodes} * sizeof(KdNode));
  if (h.prim_indices != 0)
    std::memcpy(tree.prim_indices.data(), p + std::size_t{h.nodes} * sizeof(KdNode), std::size_t{h.prim_indices} * 4);
  try {
    return MeshObject::fromParts(std::move(mesh), std::move(tree));
  } catch (const InvalidArgument& e) {
    fail(e.what());
  }
  return nullptr;  // not reached: fail() throws
}

}  // namespace duplex
