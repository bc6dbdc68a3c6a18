#pragma once
/// \file Xxh64.h
/// XXH64 (Yann Collet, xxHash specification v0.1.1), computed by the xxHash library: the checksum
/// of Duplex's binary files (saved bottom-level structures, sensor run states). Fast, well mixed,
/// and a published algorithm, so a tool outside the project can recompute it (`xxhsum -H64`). It
/// detects damage, not forgery.

#include <cstdint>
#include <span>

namespace duplex {

/// XXH64 of the bytes `data` with `seed` (XXH64(data, size, seed) of xxhash.h). Thread-safe.
[[nodiscard]] std::uint64_t xxh64(std::span<const unsigned char> data, std::uint64_t seed = 0);

}  // namespace duplex
