#pragma once
/// \file SensorTypes.h
/// The sensor object type in the scene-file registry, and the reader of a sensor description.
///
/// Object entry (duplex-scene-v1; the sensor is then instanced like any object):
///   {"name": N, "sensor": {"shape": "rectangle" | "disk" | "sphere", "size": [w, h] | s,
///                          "bins": [nx, ny] | n, "two_sided": true | false,
///                          "angular_bins": n_theta | [n_theta, n_phi]}}
/// Defaults: shape "rectangle", bins [1, 1], two_sided true, no angular bins (n_phi default 1);
/// "size" is required (a disk's or sphere's size is its diameter: a number or [d, d]). The same keys (plus "name" and
/// "transform") make an entry of the top-level "sensors" list (SensorScene.h).

#include "duplex/scenegraph/ObjectTypeRegistry.h"
#include "duplex/sensors/SensorObject.h"

#include <nlohmann/json_fwd.hpp>

namespace duplex {

/// Adds the type "sensor" (not part of scene-json-v1's object keys: v1 files list sensors in their
/// own "sensors" key) to `registry`. Throws InvalidArgument when "sensor" is already registered.
void registerSensorTypes(ObjectTypeRegistry& registry);

/// builtinObjectTypes() (duplex/objects/BuiltinTypes.h) plus the sensor type.
[[nodiscard]] const ObjectTypeRegistry& sensorTypeRegistry();

/// Reads the shape keys of a sensor description at ctx.pointer ("shape", "size", "bins",
/// "two_sided", "angular_bins"); `extra_keys` are further keys the caller reads itself (strict
/// mode refuses others). `allow_far_field`: also "shape": "farfield" with "bins": [n_c, n_gamma]
/// and no size (the top-level "sensors" list; an object entry refuses it, naming the list).
/// Errors throw FileError naming the file and the JSON pointer.
[[nodiscard]] SensorSpec readSensorSpec(const nlohmann::json& spec, const ObjectSpecContext& ctx,
                                        std::initializer_list<std::string_view> extra_keys = {},
                                        bool allow_far_field = false);

}  // namespace duplex
