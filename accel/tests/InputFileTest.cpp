// Readers refuse what is not a regular file before opening it: a directory (whose "size" would be
// read as a huge allocation) and a FIFO (whose open blocks until a writer comes) end in a
// FileError naming the file, at once.

#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/RayFile.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <vector>

namespace duplex::test {
namespace {

TEST(InputFile, SaysWhatAPathNamesInstead) {
  TempDir dir;
  const auto file = dir / "rays.bin", fifo = dir / "fifo", missing = dir / "missing.bin";
  writeRayFile(file, std::vector<Ray>(3));
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(notRegularFile(file), "");
  EXPECT_EQ(notRegularFile(dir.path()), "a directory, not a file");
  EXPECT_EQ(notRegularFile(fifo), "not a regular file (a FIFO, socket or device)");
  EXPECT_EQ(notRegularFile(missing), "no such file");
  EXPECT_EQ(notRegularFile("/dev/null"), "not a regular file (a FIFO, socket or device)");
  // A symbolic link to a file is the file.
  std::filesystem::create_symlink(file, dir / "link.bin");
  EXPECT_EQ(notRegularFile(dir / "link.bin"), "");

  EXPECT_TRUE(sameFile(file, file));
  EXPECT_TRUE(sameFile(file, dir / "link.bin"));
  EXPECT_TRUE(sameFile(file, dir / "." / "rays.bin"));
  EXPECT_FALSE(sameFile(file, missing));
  EXPECT_FALSE(sameFile(missing, missing));
  EXPECT_FALSE(sameFile(file, fifo));
}

TEST(InputFile, RayAndPointFilesRefuseDirectoriesAndFifos) {
  TempDir dir;
  const auto fifo = dir / "fifo.bin";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  expectErrorNaming<FileError>([&] { (void)readRayFile(dir.path()); }, "a directory, not a file");
  expectErrorNaming<FileError>([&] { (void)readRayFile(fifo); }, fifo.string() + "': not a regular file");
  expectErrorNaming<FileError>([&] { (void)readPointFile(fifo); }, "not a regular file");
  expectErrorNaming<FileError>([&] { (void)readRayFile(dir / "missing.bin"); }, "no such file");
}

}  // namespace
}  // namespace duplex::test
