#include "QuadScene.h"

#include <bit>
#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>

namespace duplex::clitest {

static_assert(std::endian::native == std::endian::little, "the record structs are written as they lie in memory");

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr HitRecord kMiss{kInf, 0.0f, 0.0f, kNone, kNone};
constexpr HitRecord kBlocked{0.0f, 0.0f, 0.0f, 0u, kNone};

void writeText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

// The unit quad [0,1]^2 at z = 0: triangle 0 = (0,0,0) (1,0,0) (1,1,0) covers x > y, where a hit
// at (x, y) has u = x - y, v = y; triangle 1 = (0,0,0) (1,1,0) (0,1,0) covers x < y, u = x, v = y - x.
const char* const kQuadObject =
    R"({"name": "quad", "mesh": {"positions": [0,0,0, 1,0,0, 1,1,0, 0,1,0], "indices": [0,1,2, 0,2,3]}})";

// Instance 0: as authored. 1: scaled by 2, moved to (3, 0, -1): x in [3,5], y in [0,2], z = -1.
// 2: moved to z = -3, under instance 0. 3: rotated +90 degrees about x, moved by (6, 0, 0):
// (x, y, z) -> (x + 6, -z, y), so the quad stands in the plane y = 0, x in [6,7], z in [0,1].
const char* const kQuadInstances = R"([
    {"object": "quad", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]},
    {"object": "quad", "transform": [2,0,0,3, 0,2,0,0, 0,0,2,-1]},
    {"object": "quad", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,-3]},
    {"object": "quad", "transform": [1,0,0,6, 0,0,-1,0, 0,1,0,0]}])";

std::string scene(const std::string& format, const std::string& objects, const std::string& instances) {
  return "{\"format\": \"" + format + "\",\n \"objects\": [" + objects + "],\n \"instances\": " + instances + "}\n";
}

}  // namespace

QuadCase quadCase() {
  QuadCase c;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  auto add = [&](RayRecord ray, HitRecord closest) {
    c.rays.push_back(ray);
    c.closest.push_back(closest);
    c.any_hit.push_back(closest.instance_id == kNone ? kMiss : kBlocked);
  };
  // Straight down onto instance 0, triangle 0 at (0.75, 0.25): u = 0.5, v = 0.25; instance 2
  // lies behind it at t = 4.
  add({0.75f, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, kInf}, {1.0f, 0.5f, 0.25f, 0, 0});
  // Triangle 1 of instance 0 at (0.25, 0.75): u = 0.25, v = 0.5.
  add({0.25f, 0.75f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, kInf}, {1.0f, 0.25f, 0.5f, 0, 1});
  // Scaled instance 1 at world (4.5, 0.5, -1) = object (0.75, 0.25, 0): t in world units = 2.
  add({4.5f, 0.5f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, kInf}, {2.0f, 0.5f, 0.25f, 1, 0});
  // Between instances 0 and 1: nothing there.
  add({2.0f, 0.5f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, kInf}, kMiss);
  // From below: instance 2 (z = -3) comes before instance 0 (z = 0).
  add({0.75f, 0.25f, -5.0f, 0.0f, 0.0f, 0.0f, 1.0f, kInf}, {2.0f, 0.5f, 0.25f, 2, 0});
  // tfar ends the ray before instance 0.
  add({0.75f, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, 0.5f}, kMiss);
  // Direction of length 2: t is in units of the direction, so the hit is at t = 0.5.
  add({0.75f, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, -2.0f, kInf}, {0.5f, 0.5f, 0.25f, 0, 0});
  // tnear = 2 skips instance 0 (t = 1): the closest hit is instance 2 at t = 4.
  add({0.75f, 0.25f, 1.0f, 2.0f, 0.0f, 0.0f, -1.0f, kInf}, {4.0f, 0.5f, 0.25f, 2, 0});
  // Rotated instance 3 at world (6.75, 0, 0.25) = object (0.75, 0.25, 0).
  add({6.75f, 1.0f, 0.25f, 0.0f, 0.0f, -1.0f, 0.0f, kInf}, {1.0f, 0.5f, 0.25f, 3, 0});
  // Not queryable: zero direction, NaN origin. Both are misses, not errors.
  add({0.75f, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, 0.0f, kInf}, kMiss);
  add({nan, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, -1.0f, kInf}, kMiss);
  // Pointing away from everything.
  add({0.75f, 0.25f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, kInf}, kMiss);
  return c;
}

template <class Record>
void writeRecords(const std::filesystem::path& path, const std::vector<Record>& records) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(records.data()),
            static_cast<std::streamsize>(records.size() * sizeof(Record)));
  if (!out) throw std::runtime_error("cannot write " + path.string());
}

template <class Record>
std::vector<Record> readRecords(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw std::runtime_error("cannot open " + path.string());
  const auto size = static_cast<std::size_t>(in.tellg());
  if (size % sizeof(Record) != 0)
    throw std::runtime_error(path.string() + ": " + std::to_string(size) + " bytes is not a multiple of " +
                             std::to_string(sizeof(Record)));
  std::vector<Record> records(size / sizeof(Record));
  in.seekg(0);
  in.read(reinterpret_cast<char*>(records.data()), static_cast<std::streamsize>(size));
  return records;
}

template void writeRecords(const std::filesystem::path&, const std::vector<RayRecord>&);
template void writeRecords(const std::filesystem::path&, const std::vector<HitRecord>&);
template std::vector<RayRecord> readRecords(const std::filesystem::path&);
template std::vector<HitRecord> readRecords(const std::filesystem::path&);
template void writeRecords(const std::filesystem::path&, const std::vector<PointRecord>&);
template std::vector<ClosestRecord> readRecords(const std::filesystem::path&);

void writeFixtures(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  const QuadCase c = quadCase();
  writeText(dir / "quad.json", scene("scene-json-v1", kQuadObject, kQuadInstances));
  writeRecords(dir / "rays.bin", c.rays);
  writeRecords(dir / "expected_closest.bin", c.closest);
  writeRecords(dir / "expected_any.bin", c.any_hit);

  const std::string one_instance = R"([{"object": "quad", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}])";
  writeText(dir / "bad_format.json", scene("scene-json-v0", kQuadObject, one_instance));
  writeText(dir / "bad_mesh_missing.json",
            scene("scene-json-v1", R"({"name": "quad", "mesh": {"file": "no_such_mesh.obj"}})", one_instance));
  // JSON has no NaN; 1e999 is the closest a file gets (it overflows to infinity).
  writeText(
      dir / "bad_transform_overflow.json",
      scene("scene-json-v1", kQuadObject, R"([{"object": "quad", "transform": [1e999,0,0,0, 0,1,0,0, 0,0,1,0]}])"));
  writeText(dir / "bad_transform_singular.json",
            scene("scene-json-v1", kQuadObject, R"([{"object": "quad", "transform": [1,0,0,0, 0,1,0,0, 0,0,0,0]}])"));
  writeText(dir / "bad_truncated.json", scene("scene-json-v1", kQuadObject, one_instance).substr(0, 40));
  writeText(dir / "bad_object_name.json",
            scene("scene-json-v1", kQuadObject, R"([{"object": "quad2", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}])"));
  writeText(dir / "rays33.bin", std::string(33, '\0'));
}

}  // namespace duplex::clitest
