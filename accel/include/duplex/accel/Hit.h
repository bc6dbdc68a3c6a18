#pragma once
/// \file Hit.h
/// The preliminary hit kept during traversal; full surface data is derived once, for the winner.

#include <glm/vec3.hpp>

#include <cstdint>
#include <limits>
#include <ostream>

namespace duplex {

/// Id meaning "no instance / no primitive" (a miss).
inline constexpr std::uint32_t kInvalidId = 0xFFFFFFFFu;

/// Closest-hit record. `t` is in units of the ray's direction (see Ray). `u`, `v` are the
/// barycentric coordinates of the hit point: p = (1 - u - v) * v0 + u * v1 + v * v2 for triangle
/// (v0, v1, v2). `ng` is the unnormalised geometric normal cross(v1 - v0, v2 - v0) in the space of
/// the query (object space from an object's intersector, world space from a scene query).
/// Other object types fill u, v (and prim_id) with their own coordinates: sensors the hit's local
/// position (SensorObject.h), volumes 0 (VolumeObject.h).
struct Hit {
  /// Ray parameter of the hit, in units of the ray's direction; +inf for a miss.
  float t = std::numeric_limits<float>::infinity();
  float u = 0.0f;  ///< first barycentric coordinate (or the type's own coordinate)
  float v = 0.0f;  ///< second barycentric coordinate (or the type's own coordinate)
  /// Primitive within the object (a triangle, a sensor's bin); kInvalidId for a miss.
  std::uint32_t prim_id = kInvalidId;
  /// Instance of the scene, set by scene queries (objects leave it); kInvalidId for a miss.
  std::uint32_t instance_id = kInvalidId;
  glm::vec3 ng{0.0f};  ///< geometric normal, not normalised, in the space of the query

  /// Whether the record holds a hit (prim_id set).
  [[nodiscard]] bool valid() const { return prim_id != kInvalidId; }
};

/// Writes t, u, v and the ids (or "miss"), for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Hit& h) {
  if (!h.valid()) return os << "Hit{miss}";
  return os << "Hit{t=" << h.t << ", u=" << h.u << ", v=" << h.v << ", prim=" << h.prim_id << ", inst=" << h.instance_id
            << "}";
}

}  // namespace duplex
