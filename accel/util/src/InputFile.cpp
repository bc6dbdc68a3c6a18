#include "duplex/accel/InputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include <fstream>
#include <sstream>

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

std::string readWholeFile(const std::filesystem::path& path, std::string_view what) {
  auto fail = [&](const std::string& problem) {
    std::ostringstream msg;
    msg << what << " '" << path.string() << "': " << problem;
    throw FileError(msg.str());
  };
  if (const std::string problem = notRegularFile(path); !problem.empty()) fail(problem);
  std::ifstream in(path, std::ios::binary);
  if (!in) fail("cannot be opened");
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) fail("cannot be read (its size is unknown)");
  if (size == 0) fail("empty");
  {
    std::ostringstream name;
    name << what << " '" << path.string() << "'";
    requireMemory(static_cast<std::uint64_t>(size), name.str());
  }
  in.seekg(0, std::ios::beg);
  std::string bytes(static_cast<std::size_t>(size), '\0');
  if (!in.read(bytes.data(), size)) fail("cannot be read");
  return bytes;
}

}  // namespace duplex
