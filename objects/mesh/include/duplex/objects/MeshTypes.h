#pragma once
/// \file MeshTypes.h
/// The "mesh" object type of scene files: `{"file": PATH}` (any format loadMesh reads, each file
/// read once per load and shared by the entries naming it) or `{"positions": [x, y, z, ...],
/// "indices": [i, j, k, ...]}` (object space, the file's units). Part of scene-json-v1. The entry's
/// "structure" key chooses the structure to build ("bvh", the default; "kdtree"; "bvh:<BVH
/// parameters>") or names a prepared one to load (".dbvh" or ".dkdt", MeshObjectFile.h).

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/ObjectTypeRegistry.h"

#include <string>
#include <string_view>

namespace duplex {

/// Parses a mesh structure choice as the scene files' "structure" key and the tool's --structure
/// option spell it: "bvh" (the medium preset), "kdtree", or "bvh:<text>" with the text of
/// BvhBuildConfig::parse ("bvh:fast", "bvh:high,leaf=4"). The kd-tree takes no parameters: it is
/// built with `kd`. Throws InvalidArgument naming the problem.
[[nodiscard]] MeshBuildConfig parseMeshStructureChoice(std::string_view text, const KdBuildConfig& kd = {});

/// The choice that parseMeshStructureChoice reads back to `config`: "kdtree", or "bvh:" followed by
/// every BVH parameter (BvhBuildConfig::toString()).
[[nodiscard]] std::string toString(const MeshBuildConfig& config);

/// Adds the "mesh" type to `registry`. Throws InvalidArgument when the name is taken.
void registerMeshTypes(ObjectTypeRegistry& registry);

}  // namespace duplex
