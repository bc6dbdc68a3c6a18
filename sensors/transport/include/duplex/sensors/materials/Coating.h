#pragma once
/// \file Coating.h
/// An ideal thin coating: a fraction `reflect` reflected specularly, `transmit` passed through
/// undeviated, the rest absorbed (per band when given per band), from both faces.

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace duplex {

/// Coating (a scene file's {"type": "coating", "reflect", "transmit", "absorb"}).
struct Coating {
  static constexpr std::string_view kName = "coating";  ///< its scene file "type"
  static constexpr bool kEndsPaths = false;             ///< paths go on from it
  static constexpr bool kMetersSeeAll = false;          ///< meters cannot connect through it
  BandValue reflect{0.0};                               ///< fraction reflected, in [0, 1]
  BandValue transmit{0.0};                              ///< fraction transmitted, in [0, 1 - reflect]

  /// Fractions reflected, transmitted and absorbed: any of the three may be left out (0, or for
  /// "absorb" what the others leave); given, they sum to 1.
  static Coating read(const MaterialReader& r) {
    r.onlyKeys({"type", "reflect", "transmit", "absorb"});
    Coating c;
    if (r.has("reflect")) c.reflect = r.perBand("reflect", 1.0);
    if (r.has("transmit")) c.transmit = r.perBand("transmit", 1.0);
    const BandValue absorb = r.has("absorb") ? r.perBand("absorb", 1.0) : BandValue{};
    const std::size_t n =
        std::max({c.reflect.bands.size(), c.transmit.bands.size(), absorb.bands.size(), std::size_t{1}});
    auto pick = [](const BandValue& v, std::size_t k) {
      return v.bands.empty() ? v.value : v.bands[std::min(k, v.bands.size() - 1)];
    };
    for (std::size_t k = 0; k < n; ++k) {
      const std::string band = n > 1 ? " in band " + std::to_string(k) : "";
      const double rk = pick(c.reflect, k), tk = pick(c.transmit, k);
      if (rk + tk > 1.0 + 1e-12)
        r.fail("", "a coating reflects and transmits more than all the light (reflect + transmit = " +
                       std::to_string(rk + tk) + band + ")");
      if (r.has("absorb") && std::abs(rk + tk + pick(absorb, k) - 1.0) > 1e-9)
        r.fail("absorb",
               "reflect + transmit + absorb must be 1 (got " + std::to_string(rk + tk + pick(absorb, k)) + band + ")");
    }
    return c;
  }
  /// Throws InvalidArgument for fractions outside [0, 1], not one per band, or reflect + transmit
  /// above 1 in a band.
  void validate(const std::string& what, std::uint32_t bands) {
    reflect.check(what, "reflectance", 0.0, 1.0, bands);
    if (!transmit.bands.empty() && transmit.bands.size() != bands)
      throw InvalidArgument(what + ": " + std::to_string(transmit.bands.size()) + " per-band values, the scene has " +
                            std::to_string(bands) + " band(s)");
    for (std::uint32_t k = 0; k < bands; ++k) {
      const double rk = reflect.in(k), tk = transmit.in(k);
      if (!(tk >= 0.0 && rk + tk <= 1.0 + 1e-12))
        throw InvalidArgument(what + ": a coating's transmittance must be >= 0 and reflect + transmit at most 1 (got " +
                              std::to_string(rk) + " + " + std::to_string(tk) + ")");
    }
  }
  /// Adds both fractions.
  void hash(StateHash& h) const { hashFractions(h, reflect, transmit); }
  /// "reflect=..., transmit=...".
  void print(std::ostream& os) const { printFractions(os, reflect, transmit); }
  /// One random number: reflected (specular), passed undeviated, or absorbed.
  template <class Event>
  SurfaceStep step(Event& ev) const {
    SurfaceStep s = splitByFractions(ev, reflect, transmit);
    if (!s.absorbed) s.next = s.transmits ? ev.straight() : ev.mirror();
    return s;
  }
};

}  // namespace duplex
