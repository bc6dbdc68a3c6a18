#pragma once
/// \file PngWriter.h
/// An 8-bit RGB image, encoding it as PNG or JPEG and writing it as PNG (stb_image_write).

#include <cstdint>
#include <filesystem>
#include <vector>

namespace duplex::demo {

/// Row-major from the top-left pixel, 3 bytes (sRGB-encoded R, G, B) per pixel.
struct RgbImage {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<std::uint8_t> pixels;
};

/// `image` encoded as PNG (stb_image_write). Throws duplex::InvalidArgument when stb refuses it.
[[nodiscard]] std::vector<unsigned char> encodePng(const RgbImage& image);
/// `image` encoded as baseline JPEG, `quality` in [1, 100]. Throws duplex::InvalidArgument when stb
/// refuses it.
[[nodiscard]] std::vector<unsigned char> encodeJpeg(const RgbImage& image, int quality);

/// Writes `image` to `path`, creating missing parent folders. Throws duplex::FileError naming the
/// file when it cannot be written.
void writePng(const std::filesystem::path& path, const RgbImage& image);

}  // namespace duplex::demo
