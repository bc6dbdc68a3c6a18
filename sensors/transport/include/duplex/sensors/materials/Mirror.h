#pragma once
/// \file Mirror.h
/// Specular reflection from both faces of a fraction `reflectance` (an ideal, polarisation-blind
/// mirror), optionally spread about the specular direction by a rough lobe.

#include "duplex/sensors/materials/MaterialModel.h"
#include "duplex/sensors/materials/Roughness.h"

namespace duplex {

/// Mirror (a scene file's {"type": "mirror", "reflectance": r (default 1), "scatter": {...}}).
struct Mirror {
  static constexpr std::string_view kName = "mirror";  ///< its scene file "type"
  static constexpr bool kEndsPaths = false;            ///< paths go on from it
  static constexpr bool kMetersSeeAll = false;         ///< meters cannot connect through it
  BandValue reflectance{1.0};                          ///< in [0, 1], per band in spectral scenes
  Roughness rough{};                                   ///< smooth, or a lobe about the specular direction

  /// Reads "reflectance" (default 1) and "scatter".
  static Mirror read(const MaterialReader& r) {
    r.onlyKeys({"type", "reflectance", "scatter"});
    Mirror m;
    m.reflectance = r.has("reflectance") ? r.perBand("reflectance", 1.0) : BandValue(1.0);
    m.rough = Roughness::read(r);
    return m;
  }
  /// Throws InvalidArgument for a reflectance outside [0, 1] or not one per band, or a bad lobe.
  void validate(const std::string& what, std::uint32_t bands) {
    reflectance.check(what, "reflectance", 0.0, 1.0, bands);
    rough.validate(what, bands);
  }
  /// Adds the reflectance and the roughness.
  void hash(StateHash& h) const {
    h.add(reflectance);
    rough.hash(h);
  }
  /// "reflectance=...[, lobe]".
  void print(std::ostream& os) const {
    os << "reflectance=" << reflectance.value;
    rough.print(os);
  }
  /// Reflects with probability reflectance (one random number), then the lobe.
  template <class Event>
  SurfaceStep step(Event& ev) const {
    if (ev.uniform() >= reflectance.in(ev.band)) return {};
    SurfaceStep s;
    s.absorbed = false;
    s.next = ev.mirror();
    rough.spread(ev, s);
    return s;
  }
};

}  // namespace duplex
