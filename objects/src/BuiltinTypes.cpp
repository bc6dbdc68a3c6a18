#include "duplex/objects/BuiltinTypes.h"

#include "duplex/objects/MeshTypes.h"
#include "duplex/objects/ShapeTypes.h"
#include "duplex/objects/VolumeTypes.h"

namespace duplex {

void registerBuiltinTypes(ObjectTypeRegistry& registry) {
  registerMeshTypes(registry);
  registerShapeTypes(registry);
  registerVolumeTypes(registry);
}

const ObjectTypeRegistry& builtinObjectTypes() {
  static const ObjectTypeRegistry registry = [] {
    ObjectTypeRegistry r;
    registerBuiltinTypes(r);
    return r;
  }();
  return registry;
}

}  // namespace duplex
