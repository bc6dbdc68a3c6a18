#pragma once
/// \file MeshTypes.h
/// The "mesh" object type of scene files: `{"file": PATH}` (any format loadMesh reads, each file
/// read once per load and shared by the entries naming it) or `{"positions": [x, y, z, ...],
/// "indices": [i, j, k, ...]}` (object space, the file's units). Part of scene-json-v1; accepts a
/// prepared structure (".dkdt", MeshObjectFile.h) in the entry's "structure" key.

#include "duplex/scenegraph/ObjectTypeRegistry.h"

namespace duplex {

/// Adds the "mesh" type to `registry`. Throws InvalidArgument when the name is taken.
void registerMeshTypes(ObjectTypeRegistry& registry);

}  // namespace duplex
