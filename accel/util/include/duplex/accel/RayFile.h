#pragma once
/// \file RayFile.h
/// The raw ray and hit files of the interchange contract (little endian, no header):
///   ray record: float ox, oy, oz, tnear, dx, dy, dz, tfar              (32 bytes)
///   hit record: float t, u, v; uint32 instance_id, prim_id             (20 bytes)
/// A miss has instance_id 0xFFFFFFFF and t = +inf.

#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"

#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

namespace duplex {

/// One hit-file record.
struct HitRecord {
  /// \var t
  /// Hit::t: units of the ray's direction, +inf for a miss.
  /// \var u
  /// Hit::u (0 for a miss).
  /// \var v
  /// Hit::v (0 for a miss).
  float t, u, v;
  /// \var instance_id
  /// Hit::instance_id; kInvalidId (0xFFFFFFFF) for a miss.
  /// \var prim_id
  /// Hit::prim_id; kInvalidId (0xFFFFFFFF) for a miss.
  std::uint32_t instance_id, prim_id;

  /// The record of `h` (world t, u, v, ids); miss() when `h` is not valid.
  static HitRecord from(const Hit& h);
  /// The record of a miss: t = +inf, u = v = 0, both ids kInvalidId.
  static HitRecord miss();
};
static_assert(sizeof(HitRecord) == 20, "HitRecord must match the 20-byte hit-file record");

/// Reads a ray file; throws FileError naming the file when it cannot be read or its size is not
/// a multiple of 32 bytes.
[[nodiscard]] std::vector<Ray> readRayFile(const std::filesystem::path& path);
/// Writes `rays` (world space, as traced) as 32-byte records; throws FileError naming the file when
/// it cannot be written.
void writeRayFile(const std::filesystem::path& path, std::span<const Ray> rays);
/// Reads a hit file; throws FileError naming the file when it cannot be read or its size is not a
/// multiple of 20 bytes.
[[nodiscard]] std::vector<HitRecord> readHitFile(const std::filesystem::path& path);
/// Writes 20-byte hit records; throws FileError naming the file when it cannot be written.
void writeHitFile(const std::filesystem::path& path, std::span<const HitRecord> hits);
/// Writes a transmittance file (`duplex trace --transmittance`): one little-endian float32 per ray,
/// in ray order, nothing else. Throws FileError naming the file when it cannot be written.
void writeTransmittanceFile(const std::filesystem::path& path, std::span<const float> transmittance);

}  // namespace duplex
