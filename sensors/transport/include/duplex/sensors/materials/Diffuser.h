#pragma once
/// \file Diffuser.h
/// A diffusing sheet (opal glass, a diffuser film): a fraction `reflect` reflected and a fraction
/// `transmit` transmitted, both Lambertian (cosine-distributed about the normal on their side),
/// the rest absorbed, per band when given per band, from both faces.

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <string>

namespace duplex {

/// Diffuser (a scene file's {"type": "diffuser", "reflect": r, "transmit": t}).
struct Diffuser {
  static constexpr std::string_view kName = "diffuser";  ///< its scene file "type"
  static constexpr bool kEndsPaths = false;              ///< paths go on from it
  /// Meters connect to reflections on the incoming side only: the transmitted light would be missed.
  static constexpr bool kMetersSeeAll = false;
  BandValue reflect{0.0};   ///< fraction reflected diffusely, in [0, 1]
  BandValue transmit{0.0};  ///< fraction transmitted diffusely, in [0, 1 - reflect]

  /// Reads "reflect" and "transmit" (each default 0; their sum at most 1 in every band).
  static Diffuser read(const MaterialReader& r) {
    r.onlyKeys({"type", "reflect", "transmit"});
    Diffuser d;
    if (r.has("reflect")) d.reflect = r.perBand("reflect", 1.0);
    if (r.has("transmit")) d.transmit = r.perBand("transmit", 1.0);
    // Per-band values are one per band of the scene (the reader checks): band k's pair is in(k).
    const std::size_t n = std::max({d.reflect.bands.size(), d.transmit.bands.size(), std::size_t{1}});
    for (std::uint32_t k = 0; k < n; ++k)
      if (!(d.reflect.in(k) + d.transmit.in(k) <= 1.0 + 1e-12))
        r.fail("", "a diffuser reflects and transmits more than all the light (reflect + transmit = " +
                       std::to_string(d.reflect.in(k) + d.transmit.in(k)) + ")");
    return d;
  }
  /// Throws InvalidArgument for fractions outside [0, 1], not one per band, or summing above 1.
  void validate(const std::string& what, std::uint32_t bands) {
    reflect.check(what, "reflect", 0.0, 1.0, bands);
    transmit.check(what, "transmit", 0.0, 1.0, bands);
    for (std::uint32_t k = 0; k < bands; ++k)
      if (!(reflect.in(k) + transmit.in(k) <= 1.0 + 1e-12))
        throw InvalidArgument(what +
                              ": a diffuser reflects and transmits more than all the light (reflect + transmit = " +
                              std::to_string(reflect.in(k) + transmit.in(k)) + ")");
  }
  /// Adds both fractions.
  void hash(StateHash& h) const { hashFractions(h, reflect, transmit); }
  /// "reflect=..., transmit=...".
  void print(std::ostream& os) const { printFractions(os, reflect, transmit); }
  /// One random number: reflected, transmitted or absorbed; two more for the cosine-distributed
  /// direction, mirrored through the surface plane for the transmitted part.
  template <class Event>
  SurfaceStep step(Event& ev) const {
    SurfaceStep s = splitByFractions(ev, reflect, transmit);
    if (s.absorbed) return s;
    s.next = ev.diffuse();
    if (s.transmits) s.next -= 2.0 * glm::dot(s.next, ev.nf) * ev.nf;  // through the sheet
    return s;
  }
};

}  // namespace duplex
