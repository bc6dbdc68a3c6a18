#pragma once
/// \file Medium.h
/// Scattering fog, on a fog volume object only: at each collision (free flights sampled through
/// the density) a ray scatters with probability `albedo` into a Henyey-Greenstein lobe of mean
/// cosine `g`, else it is absorbed. As a surface it absorbs.

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <string>

namespace duplex {

/// Scattering medium (a scene file's {"type": "medium", "albedo": a, "g": g}).
struct Medium {
  static constexpr std::string_view kName = "medium";  ///< its scene file "type"
  static constexpr bool kEndsPaths = true;             ///< a surface hit absorbs
  static constexpr bool kMetersSeeAll = false;         ///< meters cannot connect through its scattering
  BandValue albedo{0.0};                               ///< single-scattering albedo in [0, 1], per band
  double g = 0.0;                                      ///< Henyey-Greenstein mean cosine, in (-1, 1)

  /// Reads "albedo" (required) and "g" (default 0).
  static Medium read(const MaterialReader& r) {
    r.onlyKeys({"type", "albedo", "g"});
    Medium m;
    m.albedo = r.perBand("albedo", 1.0);
    if (r.has("g")) {
      m.g = r.number("g");
      if (!(m.g > -1.0 && m.g < 1.0)) r.fail("g", "expected a Henyey-Greenstein g in (-1, 1)");
    }
    return m;
  }
  /// Throws InvalidArgument for an albedo outside [0, 1] or not one per band, or g outside (-1, 1).
  void validate(const std::string& what, std::uint32_t bands) {
    albedo.check(what, "albedo", 0.0, 1.0, bands);
    if (!(g > -1.0 && g < 1.0)) throw InvalidArgument(what + ": g must be in (-1, 1)");
  }
  /// Adds the albedo and g.
  void hash(StateHash& h) const {
    h.add(albedo);
    h.add(g);
  }
  /// "albedo=..., g=...".
  void print(std::ostream& os) const { os << "albedo=" << albedo.value << ", g=" << g; }
  /// A surface of a medium object absorbs (its scattering happens at collisions inside).
  template <class Event>
  SurfaceStep step(Event& /*ev*/) const {
    return {};
  }
};

}  // namespace duplex
