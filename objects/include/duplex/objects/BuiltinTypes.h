#pragma once
/// \file BuiltinTypes.h
/// The object types of duplex::objects in one registry: "mesh", "sphere", "box", "plane" and
/// "volume". A new type in objects/ adds its register function here (one line in
/// objects/src/BuiltinTypes.cpp); types of other libraries (sensors, an application's own) are
/// added to a copy of the registry.

#include "duplex/scenegraph/ObjectTypeRegistry.h"

namespace duplex {

/// Adds every type of duplex::objects to `registry`, in the order above. Throws InvalidArgument when
/// a name is taken.
void registerBuiltinTypes(ObjectTypeRegistry& registry);

/// A registry holding the types registerBuiltinTypes adds (made once, thread-safe).
[[nodiscard]] const ObjectTypeRegistry& builtinObjectTypes();

}  // namespace duplex
