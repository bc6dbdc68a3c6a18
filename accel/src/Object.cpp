#include "duplex/accel/Object.h"

#include "duplex/accel/Error.h"

#include <bit>
#include <string>

namespace duplex {

void Object::savePrepared(const std::filesystem::path& path) const {
  throw InvalidArgument("object '" + name() + "' of type '" + std::string(typeName()) +
                        "' has no prepared structure format (cannot write " + path.string() + ")");
}

namespace {
std::uint32_t checkedLanes(const Object& object, std::size_t rays, std::uint32_t active) {
  if (rays > static_cast<std::size_t>(kMaxPacketRays))
    throw InvalidArgument("packet query of object '" + object.name() + "': " + std::to_string(rays) +
                          " rays, at most " + std::to_string(kMaxPacketRays));
  return rays == static_cast<std::size_t>(kMaxPacketRays) ? active : active & ((1u << rays) - 1u);
}
}  // namespace

std::uint32_t Object::intersectPacket(std::span<const Ray> rays_os, std::span<Hit> hits, std::uint32_t active,
                                      QueryContext& ctx) const {
  active = checkedLanes(*this, rays_os.size(), active);
  if (hits.size() < rays_os.size())
    throw InvalidArgument("packet query of object '" + name() + "': " + std::to_string(hits.size()) + " hits for " +
                          std::to_string(rays_os.size()) + " rays");
  std::uint32_t found = 0;
  for (; active != 0; active &= active - 1) {
    const int i = std::countr_zero(active);
    if (intersect(rays_os[i], hits[i], ctx)) found |= 1u << i;
  }
  return found;
}

std::uint32_t Object::occludedPacket(std::span<const Ray> rays_os, std::uint32_t active, QueryContext& ctx) const {
  active = checkedLanes(*this, rays_os.size(), active);
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
