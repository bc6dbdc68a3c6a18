#pragma once
/// \file Xxh64.h
/// XXH64 (Yann Collet, xxHash specification v0.1.1): the checksum of Duplex's binary files (saved
/// bottom-level structures, sensor run states). Fast, well mixed, and a published algorithm, so a
/// tool outside the project can recompute it. It detects damage, not forgery.

#include <cstdint>
#include <span>

namespace duplex {

/// XXH64 of `data` with `seed`. Thread-safe.
[[nodiscard]] std::uint64_t xxh64(std::span<const unsigned char> data, std::uint64_t seed = 0);

}  // namespace duplex
