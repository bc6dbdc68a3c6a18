#pragma once
/// \file RayFile.h
/// The raw ray and hit files of the interchange contract (little endian, no header):
///   ray record: float ox, oy, oz, tnear, dx, dy, dz, tfar              (32 bytes)
///   hit record: float t, u, v; uint32 instance_id, prim_id             (20 bytes)
/// A miss has instance_id 0xFFFFFFFF and t = +inf. The closest-point files (`duplex closest`):
///   point record:   float x, y, z, max_distance                        (16 bytes)
///   closest record: float x, y, z, distance; uint32 instance_id, prim_id (24 bytes)
/// Nothing within max_distance: distance +inf, both ids 0xFFFFFFFF, point (0, 0, 0).

#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"

#include "duplex/accel/AtomicFile.h"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
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

/// One point-file record: a world-space query point and the largest distance of interest
/// (world units; +inf for no limit).
struct PointRecord {
  float x;             ///< world x of the query point
  float y;             ///< world y
  float z;             ///< world z
  float max_distance;  ///< largest distance of interest, world units, inclusive; +inf: no limit
};
static_assert(sizeof(PointRecord) == 16, "PointRecord must match the 16-byte point-file record");

/// One closest-file record: the nearest point (world space) and its distance, instance and
/// triangle; none() when nothing was within reach.
struct ClosestRecord {
  float x;                    ///< world x of the nearest point (0 when none)
  float y;                    ///< world y
  float z;                    ///< world z
  float distance;             ///< world distance to it; +inf when none
  std::uint32_t instance_id;  ///< the instance's position in the scene; kInvalidId when none
  std::uint32_t prim_id;      ///< the triangle; kInvalidId when none
  /// The record of nothing found: point 0, distance +inf, both ids kInvalidId.
  static ClosestRecord none();
};
static_assert(sizeof(ClosestRecord) == 24, "ClosestRecord must match the 24-byte closest-file record");

/// Reads one of these files in blocks, so that memory does not grow with the file: `Record` is Ray,
/// HitRecord, PointRecord, ClosestRecord or float (transmittance files). Not thread-safe.
template <class Record>
class RecordFileReader {
 public:
  /// Opens `path`; `kind` ("ray", "hit", ...) names the file in errors. Throws FileError naming
  /// the file when it is not a regular file, cannot be opened, or its size is not a multiple of
  /// the record.
  RecordFileReader(const std::filesystem::path& path, std::string_view kind);
  RecordFileReader(const RecordFileReader&) = delete;
  RecordFileReader& operator=(const RecordFileReader&) = delete;
  ~RecordFileReader();
  /// Records in the file.
  [[nodiscard]] std::size_t count() const { return count_; }
  /// Reads records [first, first + out.size()) into `out`. Throws FileError naming the file when
  /// they are not all there (the file shrank) or the read fails; InvalidArgument past the end.
  void read(std::size_t first, std::span<Record> out);

 private:
  std::filesystem::path path_;
  std::string kind_;
  int fd_ = -1;
  std::size_t count_ = 0;
};

/// Writes one of these files in blocks through an AtomicFileWriter: the file appears complete at
/// commit() or not at all (a full disk is an error naming the file). Not thread-safe.
template <class Record>
class RecordFileWriter {
 public:
  /// Starts "<path>.tmp"; `kind` names the file in errors. Throws FileError.
  RecordFileWriter(const std::filesystem::path& path, std::string_view kind);
  /// Appends `records`. Throws FileError.
  void write(std::span<const Record> records);
  /// Makes the file. Throws FileError; without it, destruction leaves the path as it was.
  void commit();
  /// Records written so far.
  [[nodiscard]] std::size_t count() const { return out_.size() / sizeof(Record); }

 private:
  AtomicFileWriter out_;
};

/// The reader of ray files.
using RayFileReader = RecordFileReader<Ray>;
/// The writer of hit files.
using HitFileWriter = RecordFileWriter<HitRecord>;

/// Reads a point file; throws FileError naming the file when it cannot be read or its size is not
/// a multiple of 16 bytes.
[[nodiscard]] std::vector<PointRecord> readPointFile(const std::filesystem::path& path);
/// Writes 24-byte closest records (atomically: complete or not at all); throws FileError naming the
/// file when it cannot be written.
void writeClosestFile(const std::filesystem::path& path, std::span<const ClosestRecord> records);
/// Reads a closest file (for tests and tools); FileError as readPointFile.
[[nodiscard]] std::vector<ClosestRecord> readClosestFile(const std::filesystem::path& path);

/// Reads a ray file; throws FileError naming the file when it cannot be read or its size is not
/// a multiple of 32 bytes.
[[nodiscard]] std::vector<Ray> readRayFile(const std::filesystem::path& path);
/// Writes `rays` (world space, as traced) as 32-byte records (atomically); throws FileError naming
/// the file when it cannot be written.
void writeRayFile(const std::filesystem::path& path, std::span<const Ray> rays);
/// Reads a hit file; throws FileError naming the file when it cannot be read or its size is not a
/// multiple of 20 bytes.
[[nodiscard]] std::vector<HitRecord> readHitFile(const std::filesystem::path& path);
/// Writes 20-byte hit records (atomically); throws FileError naming the file when it cannot be written.
void writeHitFile(const std::filesystem::path& path, std::span<const HitRecord> hits);
/// Writes a transmittance file (`duplex trace --transmittance`): one little-endian float32 per ray,
/// in ray order, nothing else (atomically). Throws FileError naming the file when it cannot be written.
void writeTransmittanceFile(const std::filesystem::path& path, std::span<const float> transmittance);

}  // namespace duplex
