#include "SensorExr.h"

#include <duplex/accel/AtomicFile.h>
#include <duplex/accel/Error.h>

#ifdef DUPLEX_HAVE_OPENEXR
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringAttribute.h>
#endif

#include <exception>

namespace duplex::cli {

bool sensorExrAvailable() noexcept {
#ifdef DUPLEX_HAVE_OPENEXR
  return true;
#else
  return false;
#endif
}

void writeSensorExr(const std::filesystem::path& path, const std::string& sensor, const std::vector<double>& values,
                    const std::vector<double>& stderr_values, std::uint32_t nx, std::uint32_t ny,
                    const std::string& units) {
  const std::size_t n = static_cast<std::size_t>(nx) * ny;
  if (nx == 0 || ny == 0 || values.size() != n || stderr_values.size() != n)
    throw InvalidArgument(path.string() + ": '" + sensor + "' map has " + std::to_string(values.size()) +
                          " values for " + std::to_string(nx) + " x " + std::to_string(ny) + " bins");
#ifdef DUPLEX_HAVE_OPENEXR
  // Flip rows once into float planes: EXR's first scanline is the top of the picture.
  std::vector<float> y(n), e(n);
  for (std::uint32_t row = 0; row < ny; ++row) {
    const std::size_t src = static_cast<std::size_t>(ny - 1 - row) * nx, dst = static_cast<std::size_t>(row) * nx;
    for (std::uint32_t ix = 0; ix < nx; ++ix) {
      y[dst + ix] = static_cast<float>(values[src + ix]);
      e[dst + ix] = static_cast<float>(stderr_values[src + ix]);
    }
  }
  try {
    Imf::Header header(static_cast<int>(nx), static_cast<int>(ny));
    header.compression() = Imf::ZIP_COMPRESSION;
    header.channels().insert("Y", Imf::Channel(Imf::FLOAT));
    header.channels().insert("stderr", Imf::Channel(Imf::FLOAT));
    header.insert("sensor", Imf::StringAttribute(sensor));
    header.insert("units", Imf::StringAttribute(units));
    Imf::FrameBuffer fb;
    const std::size_t xs = sizeof(float), ys = sizeof(float) * nx;
    fb.insert("Y", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(y.data()), xs, ys));
    fb.insert("stderr", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(e.data()), xs, ys));
    // Encoded in memory, then written through the atomic path (a full disk is an error naming the
    // file, never a cut image).
    Imf::StdOSStream stream;
    {
      Imf::OutputFile file(stream, header);
      file.setFrameBuffer(fb);
      file.writePixels(static_cast<int>(ny));
    }
    const std::string encoded = stream.str();
    writeFileAtomically(path, {reinterpret_cast<const unsigned char*>(encoded.data()), encoded.size()}, "EXR image",
                        false);
  } catch (const FileError&) {
    throw;
  } catch (const std::exception& ex) {
    // OpenEXR reports I/O failures as Iex exceptions; keep our error type and name the file.
    throw FileError(path.string() + ": cannot write EXR (" + ex.what() + ")");
  }
#else
  throw Error(path.string() + ": this build of duplex has no OpenEXR support (install libopenexr-dev and rebuild)");
#endif
}

}  // namespace duplex::cli
