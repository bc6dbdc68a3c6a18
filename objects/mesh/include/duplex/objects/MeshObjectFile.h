#pragma once
/// \file MeshObjectFile.h
/// Saved bottom-level structures: a MeshObject's kd-tree written to a file once (a "prepared"
/// object) and read back later instead of building it; the paper's point that objects taken from a
/// prepared library need no build at all.
///
/// Format (version 1, little endian, all offsets from the file start):
///
///   offset  size  field
///        0     8  magic "DPLXKDT\0"
///        8     4  u32 version (1)
///       12     4  u32 header bytes (64)
///       16     8  u64 mesh checksum (meshChecksum(): positions and triangle indices)
///       24     4  u32 mesh vertex count
///       28     4  u32 mesh triangle count
///       32     4  u32 node count N
///       36     4  u32 primitive index count P
///       40    24  float bounds lo.x lo.y lo.z hi.x hi.y hi.z (object space)
///       64   8 N  kd-tree nodes (KdNode, 8 bytes each, depth-first)
///   64+8N    4 P  leaf primitive index list (u32 triangle ids of the mesh)
///  64+8N+4P    8  u64 checksum of every byte before it
///
/// MeshObject's leaf-ordered arrays (triangle renumbering, vertex copies) are not stored: they are a
/// function of the tree and the mesh, derived in one linear pass on load, so they cannot disagree
/// with the tree.

#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"

#include <cstdint>
#include <filesystem>
#include <memory>

namespace duplex {

/// Version written by saveMeshObject and the only one loadMeshObject reads.
inline constexpr std::uint32_t kMeshObjectFileVersion = 1;

/// 64-bit checksum (XXH64 of the raw bytes) of the mesh's positions followed by its triangle index
/// triples; what a saved structure is tied to. Not a cryptographic hash: it detects a different or
/// edited mesh, not a forged one. Thread-safe.
[[nodiscard]] std::uint64_t meshChecksum(const TriangleMesh& mesh);

/// Writes `object`'s kd-tree to `path` (through a temporary file renamed at the end, so a reader
/// never sees a half-written file). Throws FileError naming the file when it cannot be written.
void saveMeshObject(const MeshObject& object, const std::filesystem::path& path);

/// Reads a structure saved for `mesh` and returns the object, with no build. Refuses, with a
/// FileError naming the file and the problem: a missing or unreadable file, wrong magic or version,
/// a size that disagrees with the header (truncated, extended), a checksum mismatch (damaged), a
/// mesh other than the one it was saved for (vertex/triangle counts or mesh checksum), and any tree
/// that MeshObject::fromParts rejects (out-of-range child or index, cycles, too deep). A file that
/// passes can be queried safely, whatever its bytes. Thread-safe; throws InvalidArgument for a null
/// mesh.
[[nodiscard]] std::shared_ptr<const MeshObject> loadMeshObject(const std::filesystem::path& path,
                                                               std::shared_ptr<const TriangleMesh> mesh);

}  // namespace duplex
