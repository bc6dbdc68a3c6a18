// The memory limit: sizes as people write them, byte counts that saturate instead of wrapping, and
// the refusal's message (the input, the bytes, the limit, how to raise it).

#include "MemoryLimitDetail.h"
#include "MemoryLimitScope.h"
#include "TestSupport.h"

#include "duplex/accel/MemoryLimit.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <string>

namespace duplex::test {
namespace {

TEST(MemoryLimit, ParsesSizesAsPeopleWriteThem) {
  EXPECT_EQ(parseByteSize("1000000"), 1000000u);
  EXPECT_EQ(parseByteSize("0"), 0u);
  EXPECT_EQ(parseByteSize("512B"), 512u);
  EXPECT_EQ(parseByteSize("4G"), std::uint64_t{4} << 30);
  EXPECT_EQ(parseByteSize("4GB"), std::uint64_t{4} << 30);
  EXPECT_EQ(parseByteSize("512M"), std::uint64_t{512} << 20);
  EXPECT_EQ(parseByteSize("64k"), std::uint64_t{64} << 10);
  EXPECT_EQ(parseByteSize("1.5GiB"), std::uint64_t{3} << 29);
  EXPECT_EQ(parseByteSize("0.5K"), 512u);
  EXPECT_EQ(parseByteSize("2T"), std::uint64_t{2} << 40);
  EXPECT_EQ(parseByteSize("15.99999999999999999999E"), std::nullopt);  // no exbibytes
  EXPECT_EQ(parseByteSize("18446744073709551615"), kUncountableBytes);
  for (const char* bad :
       {"", "G", "-1", "+4G", "1e9", "4 G", "4GiBs", "0x10", "1.5", "18446744073709551616", "16384P", "4Gi", ".", "4X"})
    EXPECT_EQ(parseByteSize(bad), std::nullopt) << bad;
}

TEST(MemoryLimit, FormatsBytesInBinaryUnits) {
  EXPECT_EQ(formatBytes(0), "0 B");
  EXPECT_EQ(formatBytes(1023), "1023 B");
  EXPECT_EQ(formatBytes(1024), "1.00 KiB");
  EXPECT_EQ(formatBytes(std::uint64_t{3435973837}), "3.20 GiB");
  EXPECT_EQ(formatBytes(std::uint64_t{100} << 20), "100 MiB");
  EXPECT_EQ(formatBytes((std::uint64_t{1} << 30) - 1), "1.00 GiB");  // rounds up into the next unit
  EXPECT_EQ(formatBytes(kUncountableBytes), "more than 16 EiB");
}

TEST(MemoryLimit, ByteCountsSaturateInsteadOfWrapping) {
  EXPECT_EQ(arrayBytes(0, 8), 0u);
  EXPECT_EQ(arrayBytes(std::uint64_t{1} << 31, 8), std::uint64_t{1} << 34);
  // 2^31 x 2^31 bins of 24 bytes: 2^62 x 24 does not fit 64 bits.
  EXPECT_EQ(arrayBytes(arrayBytes(std::uint64_t{1} << 31, std::uint64_t{1} << 31), 24), kUncountableBytes);
  EXPECT_EQ(saturatingAdd(kUncountableBytes - 1, 2), kUncountableBytes);
  EXPECT_EQ(saturatingAdd(1, 2), 3u);
}

TEST(MemoryLimit, DefaultIsAtMostThePhysicalMemory) {
  const auto physical =
      static_cast<std::uint64_t>(::sysconf(_SC_PHYS_PAGES)) * static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
  EXPECT_GT(defaultMemoryLimit(), 0u);
  EXPECT_LE(defaultMemoryLimit(), physical);
  EXPECT_EQ(memoryLimit(), defaultMemoryLimit());
}

TEST(MemoryLimit, RefusesAboveTheLimitNamingTheInputTheBytesAndTheOption) {
  {
    MemoryLimitScope limit(std::uint64_t{1} << 20);
    EXPECT_EQ(memoryLimit(), std::uint64_t{1} << 20);
    EXPECT_NO_THROW(requireMemory(std::uint64_t{1} << 20, "exactly the limit"));
    try {
      requireMemory((std::uint64_t{1} << 20) + 1, "sensor 'screen': 512 x 512 bins");
      FAIL() << "no ResourceError";
    } catch (const ResourceError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("sensor 'screen': 512 x 512 bins needs 1.00 MiB of memory"), std::string::npos) << m;
      EXPECT_NE(m.find("memory limit of 1.00 MiB"), std::string::npos) << m;
      EXPECT_NE(m.find("--max-memory"), std::string::npos) << m;
    }
    // A count that overflowed is refused, whatever the limit.
    setMemoryLimit(kUncountableBytes - 1);
    try {
      requireMemory(arrayBytes(kUncountableBytes / 2, 4), "the rays of 'r.bin'");
      FAIL() << "no ResourceError";
    } catch (const ResourceError& e) {
      EXPECT_NE(std::string(e.what()).find("needs more than 16 EiB"), std::string::npos) << e.what();
    }
    // A ResourceError is an Error: the tool reports it as bad input.
    EXPECT_THROW(requireMemory(kUncountableBytes, "x"), Error);
  }
  EXPECT_EQ(memoryLimit(), defaultMemoryLimit());  // the scope restored the default
}

// The control group's limit, read from a tree of cgroup files of the test's own: the smallest of
// the group's and its ancestors', v2 and v1, "max" and v1's huge "no limit" ignored.
TEST(MemoryLimit, ReadsTheSmallestLimitOfTheControlGroupAndItsAncestors) {
  TempDir dir;
  const std::string root = (dir / "cgroup").string();
  const auto put = [&](const std::string& file, const std::string& text) { writeTextFile(root + file, text); };
  put("/memory.max", "max\n");
  put("/a/memory.max", "1073741824\n");
  put("/a/b/memory.max", "max\n");
  EXPECT_EQ(detail::cgroupMemoryLimit("0::/a/b\n", root), std::uint64_t{1} << 30);  // the parent's
  put("/a/b/memory.max", "536870912\n");
  EXPECT_EQ(detail::cgroupMemoryLimit("0::/a/b\n", root), std::uint64_t{1} << 29);  // the child's, smaller
  EXPECT_EQ(detail::cgroupMemoryLimit("0::/\n", root), std::nullopt);               // the root says max
  EXPECT_EQ(detail::cgroupMemoryLimit("0::/elsewhere\n", root), std::nullopt);      // no such files
  // cgroup v1: the memory controller's own hierarchy, alone or among others; ~2^63 means none.
  put("/memory/x/memory.limit_in_bytes", "9223372036854771712\n");
  EXPECT_EQ(detail::cgroupMemoryLimit("4:memory:/x\n", root), std::nullopt);
  put("/memory/x/memory.limit_in_bytes", "2147483648\n");
  EXPECT_EQ(detail::cgroupMemoryLimit("9:name=systemd:/\n5:cpu,memory:/x\n0::/\n", root), std::uint64_t{2} << 30);
  EXPECT_EQ(detail::cgroupMemoryLimit("5:cpu,cpuacct:/x\n", root), std::nullopt);  // not the memory controller
  // Both present: the smaller.
  EXPECT_EQ(detail::cgroupMemoryLimit("4:memory:/x\n0::/a/b\n", root), std::uint64_t{1} << 29);
  // Lines that are no cgroup entries are skipped.
  EXPECT_EQ(detail::cgroupMemoryLimit("garbage\n0:\n::x\n", root), std::nullopt);
}

}  // namespace
}  // namespace duplex::test
