#include "duplex/accel/Object.h"

#include "duplex/accel/Error.h"

namespace duplex {

void Object::savePrepared(const std::filesystem::path& path) const {
  throw InvalidArgument("object '" + name() + "' of type '" + std::string(typeName()) +
                        "' has no prepared structure format (cannot write " + path.string() + ")");
}

std::shared_ptr<const Object> Object::deformed(std::span<const glm::vec3>) const {
  throw InvalidArgument("object '" + name() + "' of type '" + std::string(typeName()) + "' cannot be deformed");
}

}  // namespace duplex
