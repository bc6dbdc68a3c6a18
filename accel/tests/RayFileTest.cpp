// Ray and hit files of the interchange contract (RayFile.h), and the ray generators (RayGenerator.h)
// that the tool, tests and benchmarks share.

#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/RayFile.h"
#include "duplex/accel/RayGenerator.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <span>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

TEST(RayFile, RaysRoundTripBitExactly) {
  TempDir dir;
  std::vector<Ray> rays = randomRays(Box(glm::vec3(-5.0f), glm::vec3(5.0f)), 1000, 1);
  rays[3].tfar = 17.25f;
  rays[4].tnear = 0.5f;
  rays[5].dir = glm::vec3(-0.0f, 0.0f, 1.0f);
  rays[6].origin.x = std::numeric_limits<float>::denorm_min();
  const auto path = dir / "rays.bin";
  writeRayFile(path, rays);
  EXPECT_EQ(std::filesystem::file_size(path), rays.size() * 32);
  const auto back = readRayFile(path);
  ASSERT_EQ(back.size(), rays.size());
  EXPECT_EQ(std::memcmp(back.data(), rays.data(), rays.size() * sizeof(Ray)), 0);
  // Empty file: no rays.
  writeRayFile(dir / "empty.bin", {});
  EXPECT_TRUE(readRayFile(dir / "empty.bin").empty());
}

TEST(RayFile, RecordLayoutIsOriginTnearDirTfar) {
  TempDir dir;
  Ray r;
  r.origin = glm::vec3(1.0f, 2.0f, 3.0f);
  r.tnear = 4.0f;
  r.dir = glm::vec3(5.0f, 6.0f, 7.0f);
  r.tfar = 8.0f;
  writeRayFile(dir / "one.bin", std::vector<Ray>{r});
  const auto bytes = readBinaryFile(dir / "one.bin");
  ASSERT_EQ(bytes.size(), 32u);
  float f[8];
  std::memcpy(f, bytes.data(), 32);  // little endian on every supported machine
  for (int i = 0; i < 8; ++i) EXPECT_EQ(f[i], static_cast<float>(i + 1)) << "float " << i;
}

TEST(RayFile, HitsRoundTripAndMissRecord) {
  TempDir dir;
  const HitRecord miss = HitRecord::miss();
  EXPECT_EQ(miss.t, std::numeric_limits<float>::infinity());
  EXPECT_EQ(miss.instance_id, 0xFFFFFFFFu);
  EXPECT_EQ(miss.prim_id, 0xFFFFFFFFu);
  Hit h;
  const HitRecord from_miss = HitRecord::from(h);
  EXPECT_EQ(std::memcmp(&from_miss, &miss, sizeof(HitRecord)), 0);
  h.t = 2.5f;
  h.u = 0.25f;
  h.v = 0.5f;
  h.prim_id = 17;
  h.instance_id = 3;
  const HitRecord rec = HitRecord::from(h);
  EXPECT_EQ(rec.t, 2.5f);
  EXPECT_EQ(rec.u, 0.25f);
  EXPECT_EQ(rec.v, 0.5f);
  EXPECT_EQ(rec.prim_id, 17u);
  EXPECT_EQ(rec.instance_id, 3u);

  std::vector<HitRecord> hits = {miss, rec, {1.0f, 0.0f, 1.0f, 0u, 0u}};
  writeHitFile(dir / "hits.bin", hits);
  const auto bytes = readBinaryFile(dir / "hits.bin");
  ASSERT_EQ(bytes.size(), 60u);
  // Layout: float t, u, v; uint32 instance_id, prim_id.
  float t;
  std::uint32_t inst, prim;
  std::memcpy(&t, bytes.data() + 20, 4);
  std::memcpy(&inst, bytes.data() + 32, 4);
  std::memcpy(&prim, bytes.data() + 36, 4);
  EXPECT_EQ(t, 2.5f);
  EXPECT_EQ(inst, 3u);
  EXPECT_EQ(prim, 17u);
  const auto back = readHitFile(dir / "hits.bin");
  ASSERT_EQ(back.size(), hits.size());
  EXPECT_EQ(std::memcmp(back.data(), hits.data(), hits.size() * sizeof(HitRecord)), 0);
}

TEST(RayFile, WrongSizesAndMissingFilesThrowNamingTheFile) {
  TempDir dir;
  for (const std::size_t size : {1u, 31u, 33u, 63u, 100u}) {
    const auto path = dir / ("rays_" + std::to_string(size) + ".bin");
    writeBinaryFile(path, std::vector<char>(size, 0));
    expectErrorNaming<FileError>([&] { (void)readRayFile(path); }, path.filename().string());
  }
  for (const std::size_t size : {1u, 19u, 21u, 32u, 64u}) {  // 32, 64: ray-record multiples
    const auto path = dir / ("hits_" + std::to_string(size) + ".bin");
    writeBinaryFile(path, std::vector<char>(size, 0));
    expectErrorNaming<FileError>([&] { (void)readHitFile(path); }, path.filename().string());
  }
  expectErrorNaming<FileError>([&] { (void)readRayFile(dir / "no_such_rays.bin"); }, "no_such_rays.bin");
  expectErrorNaming<FileError>([&] { (void)readHitFile(dir / "no_such_hits.bin"); }, "no_such_hits.bin");
  expectErrorNaming<FileError>([&] { writeRayFile(dir / "missing_dir" / "r.bin", std::vector<Ray>(1)); }, "r.bin");
  expectErrorNaming<FileError>([&] { writeHitFile(dir / "missing_dir" / "h.bin", std::vector<HitRecord>(1)); },
                               "h.bin");
}

// ---------------------------------------------------------------------------------------------

// Blocks of any size read, write and generate exactly what the whole-file functions do.
TEST(RayFile, BlocksReadWriteAndGenerateTheSameRecords) {
  TempDir dir;
  const Box box(glm::vec3(-2.0f, 0.0f, 1.0f), glm::vec3(3.0f, 4.0f, 2.0f));
  const std::vector<Ray> whole = randomRays(box, 1000, 9);
  RandomRayStream stream(box, 9);
  std::vector<Ray> pieces(1000);
  for (std::size_t first = 0, n = 1; first < pieces.size(); first += n, n = n * 3 + 1)
    stream.next(std::span<Ray>(pieces).subspan(first, std::min(n, pieces.size() - first)));
  EXPECT_EQ(std::memcmp(whole.data(), pieces.data(), whole.size() * sizeof(Ray)), 0);

  const std::vector<Ray> primary = primaryRays(box, 37, 11);
  std::vector<Ray> rows(primary.size());
  for (std::size_t first = 0; first < rows.size(); first += 50)
    primaryRays(box, 37, 11, first,
                std::span<Ray>(rows).subspan(first, std::min<std::size_t>(50, rows.size() - first)));
  EXPECT_EQ(std::memcmp(primary.data(), rows.data(), rows.size() * sizeof(Ray)), 0);
  std::vector<Ray> one(1);
  EXPECT_THROW(primaryRays(box, 37, 11, 407, one), InvalidArgument);

  {
    RecordFileWriter<Ray> out(dir / "blocks.bin", "ray");
    for (std::size_t first = 0; first < whole.size(); first += 333)
      out.write(std::span<const Ray>(whole).subspan(first, std::min<std::size_t>(333, whole.size() - first)));
    EXPECT_EQ(out.count(), whole.size());
    EXPECT_FALSE(std::filesystem::exists(dir / "blocks.bin")) << "visible before commit";
    out.commit();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "blocks.bin.tmp"));
  const std::vector<Ray> back = readRayFile(dir / "blocks.bin");
  ASSERT_EQ(back.size(), whole.size());
  EXPECT_EQ(std::memcmp(back.data(), whole.data(), whole.size() * sizeof(Ray)), 0);
  RayFileReader reader(dir / "blocks.bin", "ray");
  ASSERT_EQ(reader.count(), 1000u);
  std::vector<Ray> part(10);
  reader.read(990, part);
  EXPECT_EQ(std::memcmp(part.data(), whole.data() + 990, 10 * sizeof(Ray)), 0);
  EXPECT_THROW(reader.read(991, part), InvalidArgument);
  // The file shrinking under the reader is an error naming it, not garbage.
  std::filesystem::resize_file(dir / "blocks.bin", 32 * 995);
  expectErrorNaming<FileError>([&] { reader.read(990, part); }, "blocks.bin");
}

// A writer dropped before commit() (an error in the middle of a trace) leaves the previous file.
TEST(RayFile, UncommittedWriterLeavesThePreviousFile) {
  TempDir dir;
  writeRayFile(dir / "rays.bin", std::vector<Ray>(2));
  {
    RecordFileWriter<Ray> out(dir / "rays.bin", "ray");
    out.write(std::vector<Ray>(5));
  }
  EXPECT_EQ(std::filesystem::file_size(dir / "rays.bin"), 64u);
  EXPECT_FALSE(std::filesystem::exists(dir / "rays.bin.tmp"));
  // A folder that does not exist: the error names the file.
  expectErrorNaming<FileError>([&] { writeRayFile(dir / "no_such_folder" / "rays.bin", std::vector<Ray>(1)); },
                               "no_such_folder");
}

// A full disk (a file-size limit, in a child process): the write fails with an error naming the
// file, and the previous file and no temporary remain.
TEST(RayFile, FullDiskIsAnErrorAndKeepsThePreviousFile) {
  TempDir dir;
  const auto path = dir / "hits.bin";
  writeHitFile(path, std::vector<HitRecord>(3, HitRecord::miss()));
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    std::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{4096, 4096};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    try {
      writeHitFile(path, std::vector<HitRecord>(10000, HitRecord::miss()));
    } catch (const FileError& e) {
      _exit(std::string(e.what()).find("hits.bin") != std::string::npos ? 3 : 4);
    }
    _exit(5);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3) << "4: the error does not name the file, 5: no error";
  EXPECT_EQ(std::filesystem::file_size(path), 60u);
  EXPECT_FALSE(std::filesystem::exists(dir / "hits.bin.tmp"));
}

TEST(RayGenerator, RandomRaysAreDeterministicUniformAndInside) {
  const Box b(glm::vec3(-1.0f, 2.0f, 10.0f), glm::vec3(3.0f, 2.5f, 20.0f));
  const auto a = randomRays(b, 20000, 42);
  const auto c = randomRays(b, 20000, 42);
  const auto d = randomRays(b, 20000, 43);
  ASSERT_EQ(a.size(), 20000u);
  EXPECT_EQ(std::memcmp(a.data(), c.data(), a.size() * sizeof(Ray)), 0) << "same seed, different rays";
  EXPECT_NE(std::memcmp(a.data(), d.data(), a.size() * sizeof(Ray)), 0) << "different seeds, same rays";
  glm::dvec3 mean_dir(0.0), mean_origin(0.0);
  for (const Ray& r : a) {
    EXPECT_TRUE(b.contains(r.origin)) << r;
    EXPECT_NEAR(glm::length(glm::dvec3(r.dir)), 1.0, 1e-6) << r;
    EXPECT_EQ(r.tnear, 0.0f);
    EXPECT_EQ(r.tfar, std::numeric_limits<float>::infinity());
    mean_dir += glm::dvec3(r.dir);
    mean_origin += glm::dvec3(r.origin);
  }
  mean_dir /= double(a.size());
  mean_origin /= double(a.size());
  // Uniform on the sphere: mean direction ~ 0 (sd of each component 1/sqrt(3 n) = 0.004).
  EXPECT_LT(glm::length(mean_dir), 0.03);
  EXPECT_LT(glm::length(mean_origin - glm::dvec3(b.center())), 0.1);
}

TEST(RayGenerator, EmptyOrNonFiniteBoundsThrow) {
  const float inf = std::numeric_limits<float>::infinity();
  for (const Box& b : {Box(), Box(glm::vec3(1.0f), glm::vec3(0.0f)), Box(glm::vec3(0.0f), glm::vec3(inf)),
                       Box(glm::vec3(std::numeric_limits<float>::quiet_NaN()), glm::vec3(1.0f))}) {
    EXPECT_THROW((void)randomRays(b, 10, 1), InvalidArgument) << b;
    EXPECT_THROW((void)primaryRays(b, 4, 4), InvalidArgument) << b;
  }
  // A flat box (one zero extent) is not empty: rays start in its plane.
  const auto flat = randomRays(Box(glm::vec3(0.0f, 0.0f, 2.0f), glm::vec3(1.0f, 1.0f, 2.0f)), 50, 2);
  for (const Ray& r : flat) EXPECT_EQ(r.origin.z, 2.0f);
}

TEST(RayGenerator, PrimaryRaysLookAtTheBox) {
  const Box b(glm::vec3(-2.0f, -1.0f, 0.0f), glm::vec3(2.0f, 1.0f, 3.0f));
  const std::uint32_t w = 64, h = 48;
  const auto rays = primaryRays(b, w, h);
  ASSERT_EQ(rays.size(), std::size_t(w) * h);
  const PinholeCamera cam = PinholeCamera::looking_at_box(b);
  const glm::dvec3 centre(b.center());
  // The camera: at one bbox diagonal from the centre along normalize(1, 0.6, 0.8).
  const double diagonal = glm::length(glm::dvec3(b.extent()));
  EXPECT_LT(glm::length(cam.eye - (centre + diagonal * glm::normalize(glm::dvec3(1.0, 0.6, 0.8)))), 1e-9);
  for (const Ray& r : rays) {
    EXPECT_EQ(glm::dvec3(r.origin), glm::dvec3(glm::vec3(cam.eye)));
    EXPECT_NEAR(glm::length(glm::dvec3(r.dir)), 1.0, 1e-6);
    EXPECT_EQ(r.tnear, 0.0f);
    EXPECT_EQ(r.tfar, std::numeric_limits<float>::infinity());
  }
  // Row-major from the top left: the centre pixels look at the box centre, the top row up.
  const glm::dvec3 to_centre = glm::normalize(centre - glm::dvec3(rays[0].origin));
  const Ray& mid = rays[std::size_t(h / 2) * w + w / 2];
  EXPECT_GT(glm::dot(glm::dvec3(mid.dir), to_centre), 0.999);
  EXPECT_GT(rays[0].dir.y, rays[std::size_t(h - 1) * w].dir.y);                    // top row above bottom row
  EXPECT_GT(glm::dot(glm::dvec3(rays[w - 1].dir - rays[0].dir), cam.right), 0.0);  // left to right
  // 45 degrees vertical field of view: top and bottom centre rays are 45 * (h-1)/h degrees apart.
  const double angle =
      std::acos(glm::dot(glm::dvec3(rays[w / 2].dir), glm::dvec3(rays[std::size_t(h - 1) * w + w / 2].dir)));
  const double half = std::atan(std::tan(22.5 * 3.14159265358979 / 180.0) * (h - 1.0) / h);
  EXPECT_NEAR(angle, 2.0 * half, 2e-3);
}

}  // namespace
}  // namespace duplex::test
