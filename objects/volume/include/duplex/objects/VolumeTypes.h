#pragma once
/// \file VolumeTypes.h
/// The "volume" object type of scene files: an OpenVDB grid, `{"file": PATH.vdb, "grid": G?,
/// "kind": "fog" | "levelset"?}` (VolumeObject.h; part of scene-json-v1). Entries with the same
/// file, grid and kind share one object.

#include "duplex/scenegraph/ObjectTypeRegistry.h"

namespace duplex {

/// Adds the "volume" type to `registry`. Throws InvalidArgument when the name is taken.
void registerVolumeTypes(ObjectTypeRegistry& registry);

}  // namespace duplex
