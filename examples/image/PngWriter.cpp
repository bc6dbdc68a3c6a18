#include "PngWriter.h"

#include <duplex/accel/AtomicFile.h>
#include <duplex/accel/Error.h>

#include <vector>

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

namespace duplex::demo {

void writePng(const std::filesystem::path& path, const RgbImage& image) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) throw FileError("image file '" + path.string() + "': cannot create its folder (" + ec.message() + ")");
  // Encoded in memory and written through the atomic path: a full disk is an error, never a cut
  // image, and a file of the same name stays as it was until the new one is complete.
  std::vector<unsigned char> png;
  const auto append = [](void* context, void* data, int size) {
    const auto* bytes = static_cast<const unsigned char*>(data);
    static_cast<std::vector<unsigned char>*>(context)->insert(static_cast<std::vector<unsigned char>*>(context)->end(),
                                                              bytes, bytes + size);
  };
  const int ok = stbi_write_png_to_func(append, &png, static_cast<int>(image.width), static_cast<int>(image.height), 3,
                                        image.pixels.data(), static_cast<int>(image.width * 3));
  if (!ok) throw FileError("image file '" + path.string() + "': cannot encode PNG");
  writeFileAtomically(path, png, "image file", false);
}

}  // namespace duplex::demo
