#pragma once
/// \file CounterRng.h
/// A counter-based random number generator: the k-th number of ray i of a run with seed s is a
/// fixed function of (s, i, k), so a run's results do not depend on which thread traces which ray
/// or in which order (bit-identical for any thread count, and a run extended by more rays equals
/// one longer run).
///
/// The function is the SplitMix64 finaliser (Steele, Lea, Flood 2014, "Fast splittable
/// pseudorandom number generators") applied to a key derived from (seed, ray index) plus a Weyl
/// sequence in k; its output passes BigCrush as a stream and has full avalanche per counter.

#include <cstdint>

namespace duplex {

/// The random stream of one ray of a run (see the file comment): not shared between threads, cheap to create.
class CounterRng {
 public:
  /// The stream of ray `index` of a run with seed `seed`.
  CounterRng(std::uint64_t seed, std::uint64_t index)
      : key_(mix(mix(seed ^ 0x6A09E667F3BCC909ull) + index * kGolden)) {}

  /// The next 64 random bits.
  std::uint64_t next() { return mix(key_ + (++counter_) * kGolden); }
  /// Uniform in [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

 private:
  static constexpr std::uint64_t kGolden = 0x9E3779B97F4A7C15ull;
  static std::uint64_t mix(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  std::uint64_t key_;
  std::uint64_t counter_ = 0;
};

}  // namespace duplex
