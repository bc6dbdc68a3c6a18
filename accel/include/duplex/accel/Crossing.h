#pragma once
/// \file Crossing.h
/// Records of the crossing query (TopLevel::intersectWithCrossings): a ray's closest blocking hit
/// together with every crossing of a non-blocking instance (a sensor) before it, and the transmittance of media along
/// the way.

#include "duplex/accel/Hit.h"

#include <cstdint>
#include <limits>
#include <ostream>

namespace duplex {

/// Which instances a crossing query sees, by role; an instance takes part when (its mask & the
/// role's mask) != 0. A zero mask switches the role off (e.g. medium_mask = 0: no attenuation).
struct CrossingQuery {
  std::uint32_t surface_mask = 0xFFFFFFFFu;   ///< blocking instances (the closest hit)
  std::uint32_t crossing_mask = 0xFFFFFFFFu;  ///< non-blocking instances whose crossings are reported
  std::uint32_t medium_mask = 0xFFFFFFFFu;    ///< media whose transmittance is applied
};

/// One crossing of a non-blocking instance (ObjectRole::Crossing). `hit` as intersectAll reports it: world t (units of
/// the ray's direction), u, v (the object's local crossing data; sensors: local x, y), prim_id (a sensor's bin),
/// instance_id, world-space ng.
struct Crossing {
  Hit hit;  ///< the crossing, as described above
  /// Fraction of the ray's power that reaches the crossing through the selected media, in [0, 1].
  float transmittance = 1.0f;
};

/// The blocking end of the segment: hit.valid() false for a miss.
struct SegmentEnd {
  Hit hit;  ///< the closest blocking hit (world t, world-space ng)
  /// Fraction of the ray's power that reaches the hit (or, for a miss, leaves the media), in [0, 1].
  float transmittance = 1.0f;
};

/// A crossing counts when its t is at most the blocking hit's t times (1 + kCrossingSlack): a
/// sensor lying on a surface records the rays that arrive at the surface, although the two t are
/// computed by different formulas and may differ by rounding.
inline constexpr float kCrossingSlack = 16.0f * std::numeric_limits<float>::epsilon();

/// Writes the hit and the transmittance, for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Crossing& c) {
  return os << "Crossing{" << c.hit << ", T=" << c.transmittance << "}";
}

}  // namespace duplex
