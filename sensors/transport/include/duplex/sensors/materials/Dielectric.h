#pragma once
/// \file Dielectric.h
/// A glass-like interface of index `ior` (outside: 1; the mesh's geometric normal points outside):
/// exact Fresnel reflection or refraction for the path's s and p powers, Beer-Lambert absorption
/// inside, optionally spread by a rough lobe.

#include "duplex/accel/Error.h"
#include "duplex/sensors/materials/MaterialModel.h"
#include "duplex/sensors/materials/Roughness.h"

#include <cmath>
#include <limits>

namespace duplex {

/// Dielectric (a scene file's {"type": "dielectric", "ior", "absorption", "scatter"}).
struct Dielectric {
  static constexpr std::string_view kName = "dielectric";  ///< its scene file "type"
  static constexpr bool kEndsPaths = false;                ///< paths go on from it
  static constexpr bool kMetersSeeAll = false;             ///< meters cannot connect through it
  double ior = 1.5;                                        ///< index of refraction inside, > 0
  /// Absorption coefficient inside, per scene unit of path length (>= 0, per band in spectral
  /// scenes): a ray crossing a thickness L keeps exp(-absorption L) of its power.
  BandValue absorption{0.0};
  Roughness rough{};  ///< smooth, or a lobe about the reflected or refracted direction

  /// Reads "ior" (required), "absorption" (default 0) and "scatter".
  static Dielectric read(const MaterialReader& r) {
    r.onlyKeys({"type", "ior", "absorption", "scatter"});
    Dielectric m;
    m.ior = r.positiveNumber("ior");
    if (r.has("absorption")) m.absorption = r.perBand("absorption", std::numeric_limits<double>::max());
    m.rough = Roughness::read(r);
    return m;
  }
  /// Throws InvalidArgument for an index not finite and positive, an absorption not finite and
  /// >= 0 or not one per band, or a bad lobe.
  void validate(const std::string& what, std::uint32_t bands) {
    if (!(std::isfinite(ior) && ior > 0.0))
      throw InvalidArgument(what + ": index of refraction " + std::to_string(ior) + " must be finite and positive");
    absorption.check(what, "absorption", 0.0, std::numeric_limits<double>::max(), bands);
    rough.validate(what, bands);
  }
  /// Adds the index, the absorption and the roughness.
  void hash(StateHash& h) const {
    h.add(ior);
    h.add(absorption);
    rough.hash(h);
  }
  /// "ior=...[, absorption=...][, lobe]".
  void print(std::ostream& os) const {
    os << "ior=" << ior;
    if (absorption.value > 0.0 || !absorption.bands.empty()) os << ", absorption=" << absorption.value;
    rough.print(os);
  }
  /// A ray reaching the surface from inside crossed the glass from its last surface (Beer-Lambert);
  /// then reflection or refraction by the exact Fresnel equations (one random number), then the lobe.
  template <class Event>
  SurfaceStep step(Event& ev) const {
    if (const double a = absorption.in(ev.band); !ev.front && a > 0.0) ev.attenuate(std::exp(-a * ev.travelled));
    SurfaceStep s;
    s.absorbed = false;
    s.next = ev.refractOrReflect(ev.front ? 1.0 : ior, ev.front ? ior : 1.0, s.transmits);
    rough.spread(ev, s);
    return s;
  }
};

}  // namespace duplex
