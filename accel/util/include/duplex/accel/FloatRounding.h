#pragma once
/// \file FloatRounding.h
/// A double rounded to the neighbouring float below or above it, for boxes that must contain what
/// was computed in double (clipped triangles, the crossing grid's entries). Part of the utilities.

#include <bit>
#include <cstdint>

namespace duplex::detail {

/// Largest float <= d (floatBelow) and smallest float >= d (floatAbove), for d within the float
/// range. Unitless. (std::nextafter is a library call, and these run for every straddling triangle
/// of a kd-tree build.) The step to the neighbouring float is integer arithmetic on the bits rather than a branch:
/// whether a crossing rounds up or down is a coin flip. A step down from f happens only when d < f, so f is not +0 (d <
/// 0 rounds to -0 or below); -0 steps to -denorm_min. Likewise a step up never starts at -0.
inline float floatBelow(double d) {
  const auto f = static_cast<float>(d);
  const auto u = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t step = 2u * (u >> 31) - 1u;  // +1 for negative f (away from 0), -1 for positive
  const std::uint32_t need = 0u - static_cast<std::uint32_t>(static_cast<double>(f) > d);
  return std::bit_cast<float>(u + (step & need));
}
/// \copydoc floatBelow
inline float floatAbove(double d) {
  const auto f = static_cast<float>(d);
  const auto u = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t step = 1u - 2u * (u >> 31);  // +1 for positive f (away from 0), -1 for negative
  const std::uint32_t need = 0u - static_cast<std::uint32_t>(static_cast<double>(f) < d);
  return std::bit_cast<float>(u + (step & need));
}

}  // namespace duplex::detail
