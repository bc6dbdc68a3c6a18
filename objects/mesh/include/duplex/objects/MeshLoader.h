#pragma once
/// \file MeshLoader.h
/// Reading triangle meshes from files: OBJ, PLY, OFF and STL with the project's own strict
/// readers, OM through OpenMesh.

#include "duplex/objects/TriangleMesh.h"

#include <cstddef>
#include <filesystem>

namespace duplex {

/// What a load found beside the triangles, instead of printing it per face.
struct MeshLoadReport {
  std::size_t complex_edge_warnings = 0;  ///< OM files: non-manifold faces OpenMesh re-added with new vertices
  /// OM files: other lines OpenMesh wrote while reading; OBJ: statements not used (free-form
  /// geometry, unknown keywords)
  std::size_t other_warnings = 0;
  std::size_t polygons_triangulated = 0;  ///< faces with more than 3 corners, fan-triangulated
  std::size_t repeated_corner_faces = 0;  ///< faces naming one vertex twice: kept as degenerate triangles
};

/// Loads `path` (the format from its extension: .obj, .ply, .off, .stl/.stla/.stlb, .om).
/// Triangle ids follow the file's faces: polygons are fan-triangulated in face order (face k's
/// triangles get consecutive ids after those of faces 0..k-1), and no face is dropped: a face that
/// names a vertex twice stays as degenerate triangles (never hit; counted in the report). Vertices
/// keep the file's order (STL: corners with equal coordinates are merged into one vertex, numbered
/// by first appearance). Positions are in the file's units. Throws FileError naming the file and
/// the line (text) or element and byte (binary) when it is missing, not a regular file, malformed,
/// truncated, has an index out of range or a face of fewer than 3 corners, or has no triangle.
/// Counts in a file are checked against its size before anything is allocated for them.
/// Thread-safe (OpenMesh's OM reader is serialised inside).
[[nodiscard]] TriangleMesh loadMesh(const std::filesystem::path& path, MeshLoadReport* report = nullptr);

/// Uniform Loop subdivision, `steps` times (each step multiplies the triangle count by 4), with
/// OpenMesh's subdivider; used to make large inputs from real meshes for benchmarks. Degenerate
/// triangles (TriangleMesh::isValid false: never hit anyway) are left out; the result's triangles
/// are OpenMesh's, numbered anew. Throws InvalidArgument for negative `steps` and for a mesh with
/// non-manifold triangles (OpenMesh's half-edge structure cannot hold them), naming their count.
/// Positions stay in the input's units.
[[nodiscard]] TriangleMesh loopSubdivide(const TriangleMesh& mesh, int steps);

}  // namespace duplex
