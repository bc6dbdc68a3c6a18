#pragma once
// Private to accel/src (and its tests): the radix sort of float event lists of the kd-tree build.

#include <bit>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace duplex::kd_detail {

// Sorts many events by their bits: least significant byte first, four stable counting passes
// over keys that order as the floats do (sign bit flipped for positives, all bits for negatives),
// a pass skipped when every key has the same byte there (the exponent bytes of a node's events
// often agree). std::sort's comparisons are coin flips on these lists (events come in mesh order):
// a mispredicted branch per comparison makes sorting a large share of a mesh build. The result is the
// same list as std::sort's, except that -0 sorts before +0 where std::sort leaves them in either
// order (both orders are sorted).
inline void radixSortFloats(float* v, std::size_t n) {
  thread_local std::vector<std::uint32_t> scratch;
  if (scratch.size() < 2 * n) scratch.resize(2 * n);
  std::uint32_t* keys = scratch.data();
  std::uint32_t* other = keys + n;
  std::uint32_t count[4][256] = {};
  for (std::size_t i = 0; i < n; ++i) {
    const auto bits = std::bit_cast<std::uint32_t>(v[i]);
    const std::uint32_t key = bits ^ ((bits >> 31) != 0u ? 0xFFFFFFFFu : 0x80000000u);
    keys[i] = key;
    for (int b = 0; b < 4; ++b) ++count[b][(key >> (8 * b)) & 0xFFu];
  }
  for (int b = 0; b < 4; ++b) {
    const std::uint32_t first = (keys[0] >> (8 * b)) & 0xFFu;
    if (count[b][first] == n) continue;  // every key has this byte: the pass would not move any
    std::uint32_t offset = 0;
    for (std::uint32_t& c : count[b]) {
      const std::uint32_t here = c;
      c = offset;
      offset += here;
    }
    for (std::size_t i = 0; i < n; ++i) other[count[b][(keys[i] >> (8 * b)) & 0xFFu]++] = keys[i];
    std::swap(keys, other);
  }
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t key = keys[i];
    v[i] = std::bit_cast<float>(key ^ ((key >> 31) != 0u ? 0x80000000u : 0xFFFFFFFFu));
  }
}

}  // namespace duplex::kd_detail
