#pragma once
/// \file MeshObjectFile.h
/// Saved bottom-level structures: a MeshObject's BVH or kd-tree written to a file once (a
/// "prepared" object) and read back later instead of building it; the paper's point that objects
/// taken from a prepared library need no build at all. Two formats, told apart by their magic: the
/// BVH's ".dbvh" and the kd-tree's ".dkdt" (MeshObject::preparedExtension() names the object's).
/// Both are little endian, all offsets from the file start, and share the first 40 bytes.
///
/// Kd-tree (".dkdt", version 1):
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
///  64+8N+4P    8  u64 checksum (XXH64) of every byte before it
///
/// Wide BVH (".dbvh", version 2; version 1 had 224-byte nodes without the child orders and is
/// refused: prepare it again):
///
///   offset    size  field
///        0       8  magic "DPLXBVH\0"
///        8       4  u32 version (2)
///       12       4  u32 header bytes (72)
///       16       8  u64 mesh checksum (meshChecksum())
///       24       4  u32 mesh vertex count
///       28       4  u32 mesh triangle count
///       32       4  u32 node count N
///       36       4  u32 primitive index count P (a multiple of the leaf block)
///       40       4  u32 root reference (BvhRef encoding: node 0, a leaf, or empty)
///       44       4  u32 leaf block (primitives per leaf block: 4)
///       48      24  float bounds lo.x lo.y lo.z hi.x hi.y hi.z (object space)
///       72   256 N  nodes (BvhNode8: child boxes lo[3][8], hi[3][8] as floats, child[8] u32, then
///                   order[8] u32, the per-octant child orders; depth-first, parents before children)
///  72+256N     4 P  prim_indices (u32 triangle ids of the mesh; 0xFFFFFFFF pads a leaf's last block)
///  72+256N+4P    8  u64 checksum (XXH64) of every byte before it
///
/// MeshObject's derived arrays (the leaf blocks of precomputed triangle data) are not stored: they
/// are a function of the structure and the mesh, derived in one linear pass on load, so they cannot
/// disagree with it.

#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"

#include <cstdint>
#include <filesystem>
#include <memory>

namespace duplex {

/// Kd-tree file version written by saveMeshObject and the only one loadMeshObject reads.
inline constexpr std::uint32_t kMeshObjectFileVersion = 1;
/// BVH file version written by saveMeshObject and the only one loadMeshObject reads.
inline constexpr std::uint32_t kMeshBvhFileVersion = 2;

/// 64-bit checksum (XXH64 of the raw bytes) of the mesh's positions followed by its triangle index
/// triples; what a saved structure is tied to. Not a cryptographic hash: it detects a different or
/// edited mesh, not a forged one. Thread-safe.
[[nodiscard]] std::uint64_t meshChecksum(const TriangleMesh& mesh);

/// Writes `object`'s structure (its BVH or kd-tree, in that format) to `path` (through a temporary file renamed at the
/// end, so a reader never sees a half-written file). Throws FileError naming the file when it cannot be written.
void saveMeshObject(const MeshObject& object, const std::filesystem::path& path);

/// Reads a structure saved for `mesh` (either format, by its magic) and returns the object with
/// that structure, with no build. Refuses, with a FileError naming the file and the problem: a
/// missing or unreadable file, wrong magic or version, a size that disagrees with the header
/// (truncated, extended), a checksum mismatch (damaged), a mesh other than the one it was saved for
/// (vertex/triangle counts or mesh checksum), and any tree or BVH that MeshObject::fromParts rejects
/// (out-of-range child or index, cycles, too deep, boxes that do not hold their triangles). A file
/// that passes can be queried safely, whatever its bytes. Thread-safe; throws InvalidArgument for a
/// null mesh.
[[nodiscard]] std::shared_ptr<const MeshObject> loadMeshObject(const std::filesystem::path& path,
                                                               std::shared_ptr<const TriangleMesh> mesh);

}  // namespace duplex
