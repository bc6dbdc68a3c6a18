#pragma once
/// \file ProceduralMesh.h
/// Simple shapes generated as triangle meshes (object space, centred at the origin), for scene
/// files ("sphere", "box", "plane") and tests. Outward, counter-clockwise winding.

#include "duplex/objects/TriangleMesh.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <string>

namespace duplex {

/// Largest `subdivisions` makeSphere accepts (20 * 4^8 = 1,310,720 triangles).
inline constexpr int kMaxSphereSubdivisions = 8;

/// Icosphere: an icosahedron whose faces are split 4:1 `subdivisions` times (0 to
/// kMaxSphereSubdivisions), vertices pushed to the sphere of `radius` (> 0, finite). 20 *
/// 4^subdivisions triangles, shared vertices. Throws InvalidArgument otherwise.
[[nodiscard]] TriangleMesh makeSphere(double radius, int subdivisions, std::string name);
/// Axis-aligned box with edge lengths `size` (each > 0, finite): 12 triangles, 8 vertices.
[[nodiscard]] TriangleMesh makeBox(const glm::dvec3& size, std::string name);
/// Rectangle in the plane z = 0, `size.x` along x and `size.y` along y (each > 0, finite), normal +z:
/// 2 triangles (the sensors' convention: local plane z = 0, normal +z).
[[nodiscard]] TriangleMesh makePlane(const glm::dvec2& size, std::string name);

}  // namespace duplex
