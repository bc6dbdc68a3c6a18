#pragma once
/// \file QuadScene.h
/// The analytic fixture of the CLI contract tests: a unit quad (2 triangles at z = 0) placed by
/// four instances, rays whose hits are known exactly, and the bad inputs. The records are written
/// here byte by byte, independently of the library, so the tests check the file formats as an
/// outside tool sees them.

#include <cstdint>
#include <filesystem>
#include <vector>

namespace duplex::clitest {

/// Ray-file record: float ox, oy, oz, tnear, dx, dy, dz, tfar (32 bytes, little endian).
struct RayRecord {
  float ox, oy, oz, tnear, dx, dy, dz, tfar;
};
static_assert(sizeof(RayRecord) == 32);

/// Hit-file record: float t, u, v; uint32 instance_id, prim_id (20 bytes, little endian).
struct HitRecord {
  float t, u, v;
  std::uint32_t instance_id, prim_id;
};
static_assert(sizeof(HitRecord) == 20);

/// Point-file record of `duplex closest`: float x, y, z, max_distance (16 bytes, little endian).
struct PointRecord {
  float x, y, z, max_distance;
};
static_assert(sizeof(PointRecord) == 16);

/// Closest-file record: float x, y, z, distance; uint32 instance_id, prim_id (24 bytes).
struct ClosestRecord {
  float x, y, z, distance;
  std::uint32_t instance_id, prim_id;
};
static_assert(sizeof(ClosestRecord) == 24);

inline constexpr std::uint32_t kNone = 0xFFFFFFFFu;

/// Rays and the records `duplex trace` must write for them, closest hit and --any-hit.
struct QuadCase {
  std::vector<RayRecord> rays;
  std::vector<HitRecord> closest;
  std::vector<HitRecord> any_hit;
};

/// The rays of the analytic test. Every hit point, t, u and v is a dyadic rational that a
/// correct implementation computes exactly, so the records are compared bit for bit.
[[nodiscard]] QuadCase quadCase();

/// Writes into `dir`: quad.json, rays.bin, expected_closest.bin, expected_any.bin and the bad
/// inputs (bad_format.json, bad_mesh_missing.json, bad_transform_overflow.json,
/// bad_transform_singular.json, bad_truncated.json, bad_object_name.json, rays33.bin).
void writeFixtures(const std::filesystem::path& dir);

template <class Record>
void writeRecords(const std::filesystem::path& path, const std::vector<Record>& records);
template <class Record>
[[nodiscard]] std::vector<Record> readRecords(const std::filesystem::path& path);

}  // namespace duplex::clitest
