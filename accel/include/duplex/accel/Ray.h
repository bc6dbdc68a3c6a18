#pragma once
/// \file Ray.h
/// A ray segment origin + t * dir for t in [tnear, tfar].

#include <glm/vec3.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <ostream>

namespace duplex {

/// A ray in whatever space its user states (world space for scene queries, object space inside
/// an object's intersector). The direction is not required to be unit length: `t` is measured in
/// units of `dir`, which keeps t comparable between world and object space when an instance
/// transform scales (we never renormalise on entering object space).
///
/// The memory layout is exactly one record of the ray file (32 bytes, little endian:
/// ox, oy, oz, tnear, dx, dy, dz, tfar), so ray files are read without conversion.
struct Ray {
  glm::vec3 origin{0.0f};                               ///< origin, in the ray's space
  float tnear = 0.0f;                                   ///< start of the segment, in units of dir
  glm::vec3 dir{0.0f, 0.0f, 1.0f};                      ///< direction, any non-zero length
  float tfar = std::numeric_limits<float>::infinity();  ///< end of the segment, in units of dir (+inf: unbounded)
};
static_assert(sizeof(Ray) == 32, "Ray must match the 32-byte ray-file record");

/// The most rays a packet query takes at once (Object::intersectPacket(), occludedPacket(): one
/// bit each of their lane masks): the widest packet of the SIMD paths (AVX-512: 16 rays).
inline constexpr int kMaxPacketRays = 16;
/// A packet whose rays point into more octants than this is incoherent (16 random directions cover
/// about 7 of the 8): the packet queries trace its rays one by one.
inline constexpr int kMaxPacketOctants = 4;

/// The lanes of a packet of `rays` rays (at most kMaxPacketRays): bits 0 to rays - 1.
constexpr std::uint32_t packetLanes(std::size_t rays) { return (1u << rays) - 1u; }
/// Whether a packet query may take `rays` rays with room for `hits` hits (throwPacketSizeError in
/// Object.h reports it when not).
constexpr bool packetSizeOk(std::size_t rays, std::size_t hits) {
  return rays <= static_cast<std::size_t>(kMaxPacketRays) && hits >= rays;
}

/// A world-space ray in double precision, for queries far from the origin (picking): the top level
/// converts it to object space in double, so a hit's accuracy depends on the object's size, not on
/// its distance from the origin.
struct RayD {
  glm::dvec3 origin{0.0};                                 ///< origin, world space
  glm::dvec3 dir{0.0, 0.0, 1.0};                          ///< direction, world space, any non-zero length
  double tnear = 0.0;                                     ///< start of the segment, in units of dir
  double tfar = std::numeric_limits<double>::infinity();  ///< end of the segment, in units of dir (+inf: unbounded)
};

/// A ray that queries can answer: finite origin and direction, non-zero direction, tnear not NaN
/// and tnear <= tfar (tfar may be +inf). Queries report a miss for anything else.
[[nodiscard]] inline bool isQueryable(const Ray& r) {
  const bool finite = std::isfinite(r.origin.x) && std::isfinite(r.origin.y) && std::isfinite(r.origin.z) &&
                      std::isfinite(r.dir.x) && std::isfinite(r.dir.y) && std::isfinite(r.dir.z);
  return finite && (r.dir.x != 0.0f || r.dir.y != 0.0f || r.dir.z != 0.0f) && r.tnear <= r.tfar;
}

/// Writes origin, direction and [tnear, tfar], for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Ray& r) {
  return os << "Ray{o=(" << r.origin.x << ", " << r.origin.y << ", " << r.origin.z << "), d=(" << r.dir.x << ", "
            << r.dir.y << ", " << r.dir.z << "), t=[" << r.tnear << ", " << r.tfar << "]}";
}

}  // namespace duplex
