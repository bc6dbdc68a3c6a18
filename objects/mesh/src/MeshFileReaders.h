#pragma once
// The project's own strict readers of the text and binary mesh formats (OBJ, PLY, OFF, STL).
// They read a whole file held in memory, bound every count and size by the bytes that remain
// before allocating for it, and keep the file's face numbering: face k's triangles come after
// those of faces 0..k-1, a face that names a vertex twice stays (as degenerate triangles, never
// hit), and anything they cannot read exactly is an error naming the file and the line (text) or
// the element and byte offset (binary). Positions are in the file's units.

#include "duplex/objects/TriangleMesh.h"

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

namespace duplex::mesh_files {

/// What a reader found: vertices in the file's order, triangles in face order.
struct ParsedMesh {
  std::vector<glm::vec3> positions;
  std::vector<TriangleMesh::Triangle> triangles;
  std::size_t polygons_triangulated = 0;  ///< faces of more than 3 corners, fan-triangulated
  std::size_t repeated_corner_faces = 0;  ///< faces naming one vertex twice: kept, never hit
  std::size_t ignored_statements = 0;     ///< OBJ statements not used (free-form geometry, unknown keywords)
};

/// Appends one face of `corners` (vertex indices, already checked against the vertex count) as
/// the fan (c0, ck, ck+1), counting polygons and repeated corners: how every reader numbers faces.
void addFace(ParsedMesh& mesh, const std::vector<std::uint32_t>& corners);

/// The formats, as loadMesh() picks them from the extension.
enum class Format { Obj, Ply, Off, Stl, StlAscii, StlBinary };

/// Reads `bytes`, the whole content of the file `file` (named in errors). Throws FileError.
[[nodiscard]] ParsedMesh read(Format format, std::string_view bytes, const std::string& file);

}  // namespace duplex::mesh_files
