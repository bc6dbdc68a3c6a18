#include "duplex/accel/Xxh64.h"

// xxHash's own implementation (Debian: libxxhash-dev), compiled into this file: XXH_INLINE_ALL
// makes every XXH function static here, so duplex_accel, a static library, adds no link dependency
// for its consumers.
#define XXH_INLINE_ALL
#include <xxhash.h>

namespace duplex {

std::uint64_t xxh64(std::span<const unsigned char> data, std::uint64_t seed) {
  return XXH64(data.data(), data.size(), seed);
}

}  // namespace duplex
