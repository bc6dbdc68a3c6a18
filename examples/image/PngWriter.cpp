#include "PngWriter.h"

#include <duplex/accel/Error.h>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace duplex::demo {

void writePng(const std::filesystem::path& path, const RgbImage& image) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) throw FileError("image file '" + path.string() + "': cannot create its folder (" + ec.message() + ")");
  const int ok = stbi_write_png(path.c_str(), static_cast<int>(image.width), static_cast<int>(image.height), 3,
                                image.pixels.data(), static_cast<int>(image.width * 3));
  if (!ok) throw FileError("image file '" + path.string() + "': cannot write PNG");
}

}  // namespace duplex::demo
