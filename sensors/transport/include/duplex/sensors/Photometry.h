#pragma once
/// \file Photometry.h
/// Photometric and colorimetric weights of spectral bands: the CIE 1931 2-degree standard observer
/// (src/Cie1931Table.inc, from CIE 15:2004), band means of its colour-matching functions, and the
/// maximum luminous efficacy that turns watts into lumens.

#include <glm/vec3.hpp>

#include <span>

namespace duplex {

/// Maximum luminous efficacy of photopic vision, lm/W (the SI definition of the candela).
inline constexpr double kLumensPerWatt = 683.0;

/// One row of the CIE 1931 2-degree standard observer.
struct CieObserverSample {
  double nm;    ///< wavelength
  double xbar;  ///< x-bar
  double ybar;  ///< y-bar = V(lambda), the photopic luminous efficiency (1 at 555 nm)
  double zbar;  ///< z-bar
};

/// The CIE 1931 2-degree observer, 380 to 780 nm every 5 nm (CIE 15:2004).
[[nodiscard]] std::span<const CieObserverSample> cie1931Observer();

/// The means of x-bar, y-bar (= V) and z-bar over [lo_nm, hi_nm] (lo_nm < hi_nm), the table
/// interpolated linearly and zero outside 380-780 nm: the weights of a band whose power is spread
/// evenly over its wavelengths (its luminous efficacy is kLumensPerWatt times the y component).
[[nodiscard]] glm::dvec3 cieBandMean(double lo_nm, double hi_nm);

}  // namespace duplex
