#pragma once
/// \file ShapeTypes.h
/// Procedural shapes of the own scene format, generated as triangle meshes (ProceduralMesh.h) and
/// built as mesh objects: "sphere" (`{"radius": r, "subdivisions": s}`), "box" (`{"size": [x, y,
/// z] | s}`) and "plane" (`{"size": [w, h] | s}`), object space, the scene's units.

#include "duplex/scenegraph/ObjectTypeRegistry.h"

namespace duplex {

/// Adds "sphere", "box" and "plane" to `registry`. Throws InvalidArgument when a name is taken.
void registerShapeTypes(ObjectTypeRegistry& registry);

}  // namespace duplex
