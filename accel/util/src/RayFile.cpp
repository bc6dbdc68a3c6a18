#include "duplex/accel/RayFile.h"
#include "duplex/accel/InputFile.h"

#include "duplex/accel/Error.h"

#include <bit>
#include <cstring>
#include <fstream>
#include <limits>

namespace duplex {

static_assert(std::endian::native == std::endian::little, "ray and hit files are little endian; add byte swapping");

HitRecord HitRecord::from(const Hit& h) {
  if (!h.valid()) return miss();
  return {h.t, h.u, h.v, h.instance_id, h.prim_id};
}

ClosestRecord ClosestRecord::none() {
  return {0.0f, 0.0f, 0.0f, std::numeric_limits<float>::infinity(), kInvalidId, kInvalidId};
}

HitRecord HitRecord::miss() { return {std::numeric_limits<float>::infinity(), 0.0f, 0.0f, kInvalidId, kInvalidId}; }

namespace {

template <class Record>
std::vector<Record> readRecords(const std::filesystem::path& path, const char* kind) {
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError(std::string(kind) + " file '" + path.string() + "': " + problem);
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw FileError(std::string(kind) + " file '" + path.string() + "': cannot open");
  const std::streamoff size = in.tellg();
  if (size < 0) throw FileError(std::string(kind) + " file '" + path.string() + "': cannot read its size");
  if (size % static_cast<std::streamoff>(sizeof(Record)) != 0)
    throw FileError(std::string(kind) + " file '" + path.string() + "': size " + std::to_string(size) +
                    " bytes is not a multiple of the " + std::to_string(sizeof(Record)) + "-byte record");
  std::vector<Record> out(static_cast<std::size_t>(size) / sizeof(Record));
  in.seekg(0);
  if (!in.read(reinterpret_cast<char*>(out.data()), size))
    throw FileError(std::string(kind) + " file '" + path.string() + "': read failed");
  return out;
}

template <class Record>
void writeRecords(const std::filesystem::path& path, std::span<const Record> records, const char* kind) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw FileError(std::string(kind) + " file '" + path.string() + "': cannot create");
  out.write(reinterpret_cast<const char*>(records.data()), static_cast<std::streamsize>(records.size_bytes()));
  if (!out) throw FileError(std::string(kind) + " file '" + path.string() + "': write failed");
}

}  // namespace

std::vector<Ray> readRayFile(const std::filesystem::path& path) { return readRecords<Ray>(path, "ray"); }
void writeRayFile(const std::filesystem::path& path, std::span<const Ray> rays) { writeRecords(path, rays, "ray"); }
std::vector<HitRecord> readHitFile(const std::filesystem::path& path) { return readRecords<HitRecord>(path, "hit"); }
void writeHitFile(const std::filesystem::path& path, std::span<const HitRecord> hits) {
  writeRecords(path, hits, "hit");
}
std::vector<PointRecord> readPointFile(const std::filesystem::path& path) {
  return readRecords<PointRecord>(path, "point");
}
void writeClosestFile(const std::filesystem::path& path, std::span<const ClosestRecord> records) {
  writeRecords(path, records, "closest");
}
std::vector<ClosestRecord> readClosestFile(const std::filesystem::path& path) {
  return readRecords<ClosestRecord>(path, "closest");
}
void writeTransmittanceFile(const std::filesystem::path& path, std::span<const float> transmittance) {
  writeRecords(path, transmittance, "transmittance");
}

}  // namespace duplex
