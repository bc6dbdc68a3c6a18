#pragma once
// For fuzz targets of readers that take a file name: the input written to a temporary file, one
// per process (parallel fuzzing jobs do not share it), removed at exit.

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>

namespace duplex::fuzz {

/// The temporary file "duplex-fuzz-<pid><extension>" in the system's temporary folder.
inline const std::filesystem::path& inputFile(const char* extension) {
  static const std::filesystem::path file = [extension] {
    std::ostringstream name;
    name << "duplex-fuzz-" << ::getpid() << extension;
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove(inputFile(""), ec);
    });
    return std::filesystem::temp_directory_path() / name.str();
  }();
  return file;
}

/// Writes `size` bytes to inputFile(extension) and returns its path; aborts when it cannot (not a
/// finding of the reader, but no input may be skipped silently).
inline const std::filesystem::path& writeInputFile(const std::uint8_t* data, std::size_t size, const char* extension) {
  const std::filesystem::path& file = inputFile(extension);
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) {
    std::perror("fuzz target: cannot write the temporary input file");
    std::abort();
  }
  return file;
}

}  // namespace duplex::fuzz
