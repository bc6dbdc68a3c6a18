#pragma once
/// \file SensorExr.h
/// An OpenEXR copy of a sensor's irradiance map, for `duplex sensor` (written when the tool was
/// built with OpenEXR; see `sensorExrAvailable`).

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace duplex::cli {

/// True when this build of the tool writes EXR files (OpenEXR was found at configure time).
[[nodiscard]] bool sensorExrAvailable() noexcept;

/// Writes `path` as a single-part scanline EXR of nx x ny pixels, one pixel per bin, 32-bit float,
/// ZIP-compressed, with two channels: `Y` = the value (irradiance in W/m^2 for a sensor's map) and
/// `stderr` = its standard error, in `units`. `values` and `stderr_values` are row-major with bin
/// (0, 0) at the sensor's local (-w/2, -h/2), x fastest; the image is stored with local +y up (row
/// iy = ny - 1 first), as the PNG is, so viewers show the same picture. The header carries `sensor`
/// (the name) and `units`. Throws FileError naming the path when it cannot be written,
/// InvalidArgument when the arrays do not hold nx * ny values, and Error when EXR support is not
/// built in.
void writeSensorExr(const std::filesystem::path& path, const std::string& sensor, const std::vector<double>& values,
                    const std::vector<double>& stderr_values, std::uint32_t nx, std::uint32_t ny,
                    const std::string& units = "W/m^2");

}  // namespace duplex::cli
