#pragma once
/// \file VolumeObjectVdb.h
/// Volume objects from OpenVDB grids made in memory. This header includes OpenVDB: include it only
/// where OpenVDB is wanted anyway (the library's VolumeObject.cpp, tests, tools that make grids),
/// and link OpenVDB::openvdb there.

#include "duplex/objects/VolumeObject.h"

#include <openvdb/openvdb.h>

#include <memory>
#include <string>

namespace duplex {

/// A volume object over `grid` (shared, not copied: the caller must not modify the grid
/// afterwards). `kind` Auto: from the grid class. `name` empty: the grid's name. Throws
/// InvalidArgument naming the grid for a null or empty grid, a non-linear (frustum) transform, a
/// transform that is not finite and invertible, or one that takes the active voxels beyond float
/// range, and for an invalid `config` (see VolumeObject::withConfig).
[[nodiscard]] std::shared_ptr<const VolumeObject> makeVolumeObject(openvdb::FloatGrid::ConstPtr grid,
                                                                   VolumeKind kind = VolumeKind::Auto,
                                                                   std::string name = {},
                                                                   const VolumeQueryConfig& config = {});

}  // namespace duplex
