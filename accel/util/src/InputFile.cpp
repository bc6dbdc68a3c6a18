#include "duplex/accel/InputFile.h"

namespace duplex {

std::string notRegularFile(const std::filesystem::path& path) {
  std::error_code ec;
  const std::filesystem::file_status status = std::filesystem::status(path, ec);
  if (status.type() == std::filesystem::file_type::not_found) return "no such file";
  if (ec) return "cannot examine it (" + ec.message() + ")";
  if (status.type() == std::filesystem::file_type::regular) return {};
  if (status.type() == std::filesystem::file_type::directory) return "a directory, not a file";
  return "not a regular file (a FIFO, socket or device)";
}

bool sameFile(const std::filesystem::path& input, const std::filesystem::path& output) {
  std::error_code ec;
  return std::filesystem::equivalent(input, output, ec) && !ec;
}

}  // namespace duplex
