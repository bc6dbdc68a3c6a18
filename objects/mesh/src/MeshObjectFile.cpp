#include "duplex/objects/MeshObjectFile.h"

#include "duplex/accel/AtomicFile.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/Xxh64.h"

#include <array>
#include <cstring>
#include <fstream>
#include <span>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace duplex {

static_assert(std::endian::native == std::endian::little,
              "the structure file is written in native (little endian) order");
static_assert(std::is_trivially_copyable_v<KdNode> && sizeof(KdNode) == 8);
// No padding inside a BVH node: its bytes in the file are exactly its fields.
static_assert(std::is_trivially_copyable_v<BvhNode8> && sizeof(BvhNode8) == 6 * 8 * 4 + 2 * 8 * 4);
static_assert(sizeof(glm::vec3) == 12 && sizeof(TriangleMesh::Triangle) == 12);

namespace {

using Magic = std::array<char, 8>;

// What differs between the two formats (see the tables in MeshObjectFile.h): everything up to byte
// 40 is common, so framing, checksums and the mesh check are shared.
struct Format {
  Magic magic;
  std::uint32_t version;
  std::size_t header_bytes;
  std::size_t node_bytes;
  const char* what;  // for messages
};
constexpr Format kKdFormat = {
    {'D', 'P', 'L', 'X', 'K', 'D', 'T', '\0'}, kMeshObjectFileVersion, 64, sizeof(KdNode), "kd-tree"};
constexpr Format kBvhFormat = {
    {'D', 'P', 'L', 'X', 'B', 'V', 'H', '\0'}, kMeshBvhFileVersion, 72, sizeof(BvhNode8), "BVH"};
constexpr std::size_t kCommonHeaderBytes = 40;
constexpr std::size_t kChecksumBytes = 8;

template <class T>
std::span<const unsigned char> bytesOf(const std::vector<T>& v) {
  return {reinterpret_cast<const unsigned char*>(v.data()), v.size() * sizeof(T)};
}

// Fixed-size fields at their offsets (see the tables in MeshObjectFile.h).
struct Header {
  std::uint32_t version = 0;
  std::uint32_t header_bytes = 0;
  std::uint64_t mesh_checksum = 0;
  std::uint32_t vertices = 0, triangles = 0, nodes = 0, prim_indices = 0;
  std::uint32_t root = 0, leaf_block = 0;  // BVH only
  float bounds[6] = {};
};

// Calls io(offset, field, bytes) for every header field after the magic, at its offset (H is
// Header or const Header: one list of offsets for writing and reading).
template <class H, class Io>
void headerFields(const Format& f, H& h, Io&& io) {
  io(8, &h.version, 4);
  io(12, &h.header_bytes, 4);
  io(16, &h.mesh_checksum, 8);
  io(24, &h.vertices, 4);
  io(28, &h.triangles, 4);
  io(32, &h.nodes, 4);
  io(36, &h.prim_indices, 4);
  if (&f == &kKdFormat) {
    io(40, h.bounds, 24);
  } else {
    io(40, &h.root, 4);
    io(44, &h.leaf_block, 4);
    io(48, h.bounds, 24);
  }
}

void putHeader(unsigned char* out, const Format& f, const Header& h) {
  std::memcpy(out, f.magic.data(), f.magic.size());
  headerFields(f, h, [out](std::size_t at, const void* field, std::size_t n) { std::memcpy(out + at, field, n); });
}

Header getHeader(const unsigned char* in, const Format& f) {
  Header h;
  headerFields(f, h, [in](std::size_t at, void* field, std::size_t n) { std::memcpy(field, in + at, n); });
  return h;
}

std::uint64_t fileBytes(const Format& f, const Header& h) {
  return f.header_bytes + std::uint64_t{h.nodes} * f.node_bytes + std::uint64_t{h.prim_indices} * 4 + kChecksumBytes;
}

void putBounds(Header& h, const Box& b) {
  const float bounds[6] = {b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z};
  std::memcpy(h.bounds, bounds, sizeof(bounds));
}

Box getBounds(const Header& h) {
  return Box(glm::vec3(h.bounds[0], h.bounds[1], h.bounds[2]), glm::vec3(h.bounds[3], h.bounds[4], h.bounds[5]));
}

// Header, nodes, prim_indices and the checksum of all of them, written in one piece.
template <class Node>
void writeStructure(const std::filesystem::path& path, const Format& f, Header h, const std::vector<Node>& nodes,
                    const std::vector<std::uint32_t>& prim_indices) {
  h.version = f.version;
  h.header_bytes = static_cast<std::uint32_t>(f.header_bytes);
  h.nodes = static_cast<std::uint32_t>(nodes.size());
  h.prim_indices = static_cast<std::uint32_t>(prim_indices.size());
  // The whole file in memory, then one write: structures are a few MB.
  std::vector<unsigned char> bytes(fileBytes(f, h));
  putHeader(bytes.data(), f, h);
  unsigned char* p = bytes.data() + f.header_bytes;
  const auto node_bytes = bytesOf(nodes);
  const auto prims = bytesOf(prim_indices);
  if (!node_bytes.empty()) std::memcpy(p, node_bytes.data(), node_bytes.size());
  if (!prims.empty()) std::memcpy(p + node_bytes.size(), prims.data(), prims.size());
  const std::uint64_t checksum = xxh64(std::span(bytes).first(bytes.size() - kChecksumBytes), 0);
  std::memcpy(bytes.data() + bytes.size() - kChecksumBytes, &checksum, kChecksumBytes);

  // Not flushed to the disk per file: a prepared library may hold tens of thousands, and a file a
  // power loss damages is refused on loading (checksum) and prepared again.
  writeFileAtomically(path, bytes, "bottom-level structure file", /*sync=*/false);
}

template <class Node>
void readArrays(const std::vector<unsigned char>& bytes, const Format& f, const Header& h, std::vector<Node>& nodes,
                std::vector<std::uint32_t>& prim_indices) {
  nodes.resize(h.nodes);
  prim_indices.resize(h.prim_indices);
  const unsigned char* p = bytes.data() + f.header_bytes;
  if (h.nodes != 0) std::memcpy(nodes.data(), p, std::size_t{h.nodes} * sizeof(Node));
  if (h.prim_indices != 0)
    std::memcpy(prim_indices.data(), p + std::size_t{h.nodes} * sizeof(Node), std::size_t{h.prim_indices} * 4);
}

}  // namespace

std::uint64_t meshChecksum(const TriangleMesh& mesh) {
  return xxh64(bytesOf(mesh.triangles()), xxh64(bytesOf(mesh.positions()), 0));
}

void saveMeshObject(const MeshObject& object, const std::filesystem::path& path) {
  const TriangleMesh& mesh = object.mesh();
  Header h;
  h.mesh_checksum = meshChecksum(mesh);
  h.vertices = static_cast<std::uint32_t>(mesh.positions().size());
  h.triangles = static_cast<std::uint32_t>(mesh.triangleCount());
  if (object.structure() == MeshStructure::Bvh) {
    const WideBvh& bvh = object.bvh();
    h.root = bvh.root;
    h.leaf_block = bvh.leaf_block;
    putBounds(h, bvh.bounds);
    writeStructure(path, kBvhFormat, h, bvh.nodes, bvh.prim_indices);
  } else {
    const KdTree& tree = object.tree();
    putBounds(h, tree.bounds);
    writeStructure(path, kKdFormat, h, tree.nodes, tree.prim_indices);
  }
}

std::shared_ptr<const MeshObject> loadMeshObject(const std::filesystem::path& path,
                                                 std::shared_ptr<const TriangleMesh> mesh) {
  if (!mesh) throw InvalidArgument("loadMeshObject: null mesh");
  auto fail = [&path](const std::string& problem) -> void { throw FileError(path.string() + ": " + problem); };

  if (const std::string problem = notRegularFile(path); !problem.empty())
    fail("cannot open bottom-level structure file: " + problem);
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) fail("cannot open bottom-level structure file");
  const std::streamoff size = in.tellg();
  if (size < 0) fail("cannot read the file size");
  // The file's bytes, then its nodes and references copied out of them.
  {
    std::ostringstream what;
    what << "bottom-level structure file '" << path.string() << "' (" << formatBytes(static_cast<std::uint64_t>(size))
         << ")";
    requireMemory(arrayBytes(static_cast<std::uint64_t>(size), 2), what.str());
  }
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  in.seekg(0);
  if (!bytes.empty() && !in.read(reinterpret_cast<char*>(bytes.data()), size)) fail("read error");

  // Framing: magic (which format), version, sizes; then the checksum of the whole file; then the
  // mesh it was made for; last the structure itself (MeshObject::fromParts), which is checked even
  // when the checksum matched, since a checksum is no defence against a file written on purpose.
  if (bytes.size() < kCommonHeaderBytes + kChecksumBytes)
    fail("too short for a bottom-level structure file (" + std::to_string(bytes.size()) + " bytes)");
  const Format* format = nullptr;
  for (const Format* f : {&kKdFormat, &kBvhFormat})
    if (std::memcmp(bytes.data(), f->magic.data(), f->magic.size()) == 0) format = f;
  if (!format) fail("not a Duplex bottom-level structure file (bad magic)");
  const Format& f = *format;
  if (bytes.size() < f.header_bytes + kChecksumBytes)
    fail("too short for a " + std::string(f.what) + " structure file (" + std::to_string(bytes.size()) + " bytes)");
  const Header h = getHeader(bytes.data(), f);
  if (h.version != f.version)
    fail(std::string(f.what) + " file version " + std::to_string(h.version) + ", this build reads version " +
         std::to_string(f.version));
  if (h.header_bytes != f.header_bytes)
    fail("header size " + std::to_string(h.header_bytes) + ", expected " + std::to_string(f.header_bytes));
  if (fileBytes(f, h) != bytes.size())
    fail("file has " + std::to_string(bytes.size()) + " bytes, its header announces " +
         std::to_string(fileBytes(f, h)) + " (" + std::to_string(h.nodes) + " nodes, " +
         std::to_string(h.prim_indices) + " indices): truncated or damaged");
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

  try {
    if (&f == &kBvhFormat) {
      WideBvh bvh;
      bvh.bounds = getBounds(h);
      bvh.root = h.root;
      bvh.leaf_block = h.leaf_block;
      readArrays(bytes, f, h, bvh.nodes, bvh.prim_indices);
      return MeshObject::fromParts(std::move(mesh), std::move(bvh));
    }
    KdTree tree;
    tree.bounds = getBounds(h);
    readArrays(bytes, f, h, tree.nodes, tree.prim_indices);
    return MeshObject::fromParts(std::move(mesh), std::move(tree));
  } catch (const InvalidArgument& e) {
    fail(e.what());
  }
  return nullptr;  // not reached: fail() throws
}

}  // namespace duplex
