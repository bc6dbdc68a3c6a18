// duplex::xxh64 against the published XXH64 test vectors (xxHash's sanity check): the empty input,
// and prefixes of xxHash's generated sanity buffer, with seed 0 and seed PRIME32_1. Files written
// by other XXH64 implementations must check, so these values are the contract.
#include "duplex/accel/Xxh64.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <span>
#include <vector>

namespace {

constexpr std::uint64_t kPrime32 = 2654435761u;
constexpr std::uint64_t kPrime64 = 11400714785074694797ull;

// xxHash's sanity buffer: byte i is the top byte of kPrime32 * kPrime64^i (mod 2^64).
std::vector<unsigned char> sanityBuffer(std::size_t size) {
  std::vector<unsigned char> buffer(size);
  std::uint64_t generator = kPrime32;
  for (unsigned char& byte : buffer) {
    byte = static_cast<unsigned char>(generator >> 56);
    generator *= kPrime64;
  }
  return buffer;
}

struct Vector {
  std::size_t length;
  std::uint64_t seed;
  std::uint64_t hash;
};

TEST(Xxh64, MatchesPublishedTestVectors) {
  const std::vector<unsigned char> buffer = sanityBuffer(222);
  // Lengths 0, 1, 4 and 14 take the short-input path (tail of 8-, 4- and 1-byte steps); 222 the
  // 32-byte stripes with a tail.
  const Vector vectors[] = {
      {0, 0, 0xEF46DB3751D8E999ull},          {0, kPrime32, 0xAC75FDA2929B17EFull},
      {1, 0, 0xE934A84ADB052768ull},          {1, kPrime32, 0x5014607643A9B4C3ull},
      {4, 0, 0x9136A0DCA57457EEull},          {14, 0, 0x8282DCC4994E35C8ull},
      {14, kPrime32, 0xC3BD6BF63DEB6DF0ull},  {222, 0, 0xB641AE8CB691C174ull},
      {222, kPrime32, 0x20CB8AB7AE10C14Aull},
  };
  for (const Vector& v : vectors)
    EXPECT_EQ(duplex::xxh64(std::span(buffer).first(v.length), v.seed), v.hash)
        << "length " << v.length << ", seed " << v.seed;
}

TEST(Xxh64, DefaultSeedIsZero) {
  const std::vector<unsigned char> buffer = sanityBuffer(14);
  EXPECT_EQ(duplex::xxh64(buffer), duplex::xxh64(buffer, 0));
}

}  // namespace
