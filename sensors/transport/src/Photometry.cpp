// The CIE 1931 observer and the band means of its colour-matching functions.

#include "duplex/sensors/Photometry.h"

#include <algorithm>
#include <array>

namespace duplex {

namespace {

constexpr CieObserverSample kCie1931[] = {
#include "Cie1931Table.inc"
};

// The integral of the piecewise-linear table from its start to `nm` (clamped to the table).
glm::dvec3 cumulative(double nm) {
  glm::dvec3 sum(0.0);
  const std::size_t n = std::size(kCie1931);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const CieObserverSample &a = kCie1931[i], &b = kCie1931[i + 1];
    if (nm <= a.nm) break;
    const double end = std::min(nm, b.nm), t = (end - a.nm) / (b.nm - a.nm), width = end - a.nm;
    // Trapezoid from a to `end`, the value at `end` interpolated.
    const glm::dvec3 va(a.xbar, a.ybar, a.zbar), vb(b.xbar, b.ybar, b.zbar);
    sum += 0.5 * width * (va + (va + t * (vb - va)));
  }
  return sum;
}

}  // namespace

std::span<const CieObserverSample> cie1931Observer() { return kCie1931; }

glm::dvec3 cieBandMean(double lo_nm, double hi_nm) { return (cumulative(hi_nm) - cumulative(lo_nm)) / (hi_nm - lo_nm); }

}  // namespace duplex
