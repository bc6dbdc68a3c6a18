#include "duplex/accel/AtomicFile.h"

#include "duplex/accel/Error.h"

#include <fstream>
#include <string>
#include <system_error>

namespace duplex {

void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes,
                         std::string_view what) {
  std::filesystem::path tmp = path;
  tmp += ".tmp";
  const auto dropTmp = [&tmp] {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
  };
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw FileError(path.string() + ": cannot write the " + std::string(what) + " (" + tmp.string() + ")");
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      dropTmp();
      throw FileError(path.string() + ": writing the " + std::string(what) + " failed (disk full?)");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    dropTmp();
    throw FileError(path.string() + ": cannot replace the " + std::string(what) + " (" + ec.message() + ")");
  }
}

}  // namespace duplex
