#pragma once
/// \file Lambertian.h
/// Diffuse reflection from both faces: a ray survives with probability `reflectance` and leaves
/// cosine-distributed about the normal on the side it came from.

#include "duplex/sensors/materials/MaterialModel.h"

namespace duplex {

/// Lambertian reflector (a scene file's {"type": "lambertian", "reflectance": r}).
struct Lambertian {
  static constexpr std::string_view kName = "lambertian";  ///< its scene file "type"
  static constexpr bool kEndsPaths = false;                ///< paths go on from it
  static constexpr bool kMetersSeeAll = true;              ///< meters connect to its reflections
  BandValue reflectance{0.0};                              ///< albedo in [0, 1], per band in spectral scenes

  /// Reads "reflectance" (required).
  static Lambertian read(const MaterialReader& r) {
    r.onlyKeys({"type", "reflectance"});
    return {r.perBand("reflectance", 1.0)};
  }
  /// Throws InvalidArgument for a reflectance outside [0, 1] or not one per band.
  void validate(const std::string& what, std::uint32_t bands) {
    reflectance.check(what, "reflectance", 0.0, 1.0, bands);
  }
  /// Adds the reflectance.
  void hash(StateHash& h) const { h.add(reflectance); }
  /// "reflectance=...".
  void print(std::ostream& os) const { os << "reflectance=" << reflectance.value; }
  /// Reflects with probability reflectance (one random number), cosine-distributed (two more).
  template <class Event>
  SurfaceStep step(Event& ev) const {
    if (ev.uniform() >= reflectance.in(ev.band)) return {};
    SurfaceStep s;
    s.absorbed = false;
    s.next = ev.diffuse();
    s.diffuse = true;
    return s;
  }
};

}  // namespace duplex
