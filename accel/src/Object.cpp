#include "duplex/accel/Object.h"

#include "duplex/accel/Error.h"

#include <bit>
#include <string>

namespace duplex {

void Object::savePrepared(const std::filesystem::path& path) const {
  throw InvalidArgument("object '" + name() + "' of type '" + std::string(typeName()) +
                        "' has no prepared structure format (cannot write " + path.string() + ")");
}

void throwPacketSizeError(const std::string& what, std::size_t rays, std::size_t hits) {
  if (rays > static_cast<std::size_t>(kMaxPacketRays))
    throw InvalidArgument(what + ": " + std::to_string(rays) + " rays, at most " + std::to_string(kMaxPacketRays));
  throw InvalidArgument(what + ": " + std::to_string(hits) + " hits for " + std::to_string(rays) + " rays");
}

std::uint32_t Object::intersectPacket(std::span<const Ray> rays_os, std::span<Hit> hits, std::uint32_t active,
                                      QueryContext& ctx) const {
  if (!packetSizeOk(rays_os.size(), hits.size()))
    throwPacketSizeError("packet query of object '" + name() + "'", rays_os.size(), hits.size());
  active &= packetLanes(rays_os.size());
  std::uint32_t found = 0;
  for (; active != 0; active &= active - 1) {
    const int i = std::countr_zero(active);
    if (intersect(rays_os[i], hits[i], ctx)) found |= 1u << i;
  }
  return found;
}

std::uint32_t Object::occludedPacket(std::span<const Ray> rays_os, std::uint32_t active, QueryContext& ctx) const {
  if (!packetSizeOk(rays_os.size(), rays_os.size()))
    throwPacketSizeError("packet query of object '" + name() + "'", rays_os.size(), rays_os.size());
  active &= packetLanes(rays_os.size());
  std::uint32_t blocked = 0;
  for (; active != 0; active &= active - 1) {
    const int i = std::countr_zero(active);
    if (occluded(rays_os[i], ctx)) blocked |= 1u << i;
  }
  return blocked;
}

std::shared_ptr<const Object> Object::deformed(std::span<const glm::vec3>) const {
  throw InvalidArgument("object '" + name() + "' of type '" + std::string(typeName()) + "' cannot be deformed");
}

}  // namespace duplex
