#pragma once
/// \file SensorImage.h
/// A false-colour picture of a sensor's irradiance map with a scale bar, for `duplex sensor`.

#include "PngWriter.h"

#include <cstdint>
#include <vector>

namespace duplex::cli {

/// The nx x ny map (row-major, bin (0, 0) at the sensor's local (-w/2, -h/2)) drawn with local +y
/// up (row iy = ny - 1 at the top), each bin a square of pixels, in the viridis colour map from 0
/// (dark blue) to the map's maximum (yellow); at the right a scale bar with the maximum written at
/// its top and 0 at its bottom (W/m^2). Bins with NaN are drawn grey.
[[nodiscard]] demo::RgbImage falseColourImage(const std::vector<double>& values, std::uint32_t nx, std::uint32_t ny);

}  // namespace duplex::cli
