#pragma once
/// \file MeshLoader.h
/// Reading triangle meshes from files through OpenMesh (OBJ, PLY, OFF, STL, OM).

#include "duplex/objects/TriangleMesh.h"

#include <cstddef>
#include <filesystem>

namespace duplex {

/// What OpenMesh reported while reading, instead of printing it per face.
struct MeshLoadReport {
  std::size_t complex_edge_warnings = 0;  ///< non-manifold faces OpenMesh re-added with new vertices
  std::size_t other_warnings = 0;         ///< any other lines OpenMesh wrote while reading
  std::size_t polygons_triangulated = 0;  ///< faces with more than 3 corners, fan-triangulated
};

/// Loads `path`; polygons are fan-triangulated in face order (face k's triangles get consecutive
/// ids). Positions are in the file's units. Throws FileError naming the file when it is missing,
/// unreadable or has no valid triangle. Thread-safe (OpenMesh's reader is serialised inside).
[[nodiscard]] TriangleMesh loadMesh(const std::filesystem::path& path, MeshLoadReport* report = nullptr);

/// Uniform Loop subdivision, `steps` times (each step multiplies the triangle count by 4), with
/// OpenMesh's subdivider; used to make large inputs from real meshes for benchmarks. Degenerate
/// triangles (TriangleMesh::isValid false: never hit anyway) are left out; the result's triangles
/// are OpenMesh's, numbered anew. Throws InvalidArgument for negative `steps` and for a mesh with
/// non-manifold triangles (OpenMesh's half-edge structure cannot hold them), naming their count.
/// Positions stay in the input's units.
[[nodiscard]] TriangleMesh loopSubdivide(const TriangleMesh& mesh, int steps);

}  // namespace duplex
