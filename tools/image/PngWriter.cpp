#include "PngWriter.h"

#include <duplex/accel/AtomicFile.h>
#include <duplex/accel/Error.h>

#include <string>
#include <vector>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace duplex::demo {

namespace {

void appendBytes(void* context, void* data, int size) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  auto* out = static_cast<std::vector<unsigned char>*>(context);
  out->insert(out->end(), bytes, bytes + size);
}

}  // namespace

std::vector<unsigned char> encodePng(const RgbImage& image) {
  std::vector<unsigned char> png;
  const int ok =
      stbi_write_png_to_func(appendBytes, &png, static_cast<int>(image.width), static_cast<int>(image.height), 3,
                             image.pixels.data(), static_cast<int>(image.width * 3));
  if (!ok)
    throw InvalidArgument("cannot encode a " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                          " image as PNG");
  return png;
}

std::vector<unsigned char> encodeJpeg(const RgbImage& image, int quality) {
  std::vector<unsigned char> jpeg;
  const int ok = stbi_write_jpg_to_func(appendBytes, &jpeg, static_cast<int>(image.width),
                                        static_cast<int>(image.height), 3, image.pixels.data(), quality);
  if (!ok)
    throw InvalidArgument("cannot encode a " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                          " image as JPEG");
  return jpeg;
}

void writePng(const std::filesystem::path& path, const RgbImage& image) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) throw FileError("image file '" + path.string() + "': cannot create its folder (" + ec.message() + ")");
  // Encoded in memory and written through the atomic path: a full disk is an error, never a cut
  // image, and a file of the same name stays as it was until the new one is complete.
  std::vector<unsigned char> png;
  try {
    png = encodePng(image);
  } catch (const InvalidArgument& e) {
    throw FileError("image file '" + path.string() + "': " + e.what());
  }
  writeFileAtomically(path, png, "image file", false);
}

}  // namespace duplex::demo
