#pragma once
// For fuzz targets of readers that take a file name: the input written to a temporary file, one
// per process (parallel fuzzing jobs do not share it), removed at exit; and the repair of a
// trailing checksum, so that mutations reach the checks behind it.

#include "duplex/accel/Xxh64.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace duplex::fuzz {

/// The temporary file "duplex-fuzz-<pid><extension>" in the system's temporary folder (one per
/// extension), removed at exit.
inline const std::filesystem::path& inputFile(const char* extension) {
  static std::map<std::string, std::filesystem::path> files;
  static const bool cleanup = [] {
    std::atexit([] {
      std::error_code ec;
      for (const auto& [ext, file] : files) std::filesystem::remove(file, ec);
    });
    return true;
  }();
  (void)cleanup;
  const auto [it, fresh] = files.try_emplace(extension);
  if (fresh) {
    std::ostringstream name;
    name << "duplex-fuzz-" << ::getpid() << extension;
    it->second = std::filesystem::temp_directory_path() / name.str();
  }
  return it->second;
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

/// The input with its last 8 bytes replaced by the XXH64 (seed 0) of the bytes before them, the
/// checksum that ends Duplex's binary files (saved structures, run states): a mutated file then
/// passes the checksum and exercises the reader's structural checks. Inputs shorter than 8 bytes
/// are returned as they are.
inline std::vector<std::uint8_t> withRepairedChecksum(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> bytes(data, data + size);
  if (size < 8) return bytes;
  const std::uint64_t sum = duplex::xxh64({bytes.data(), size - 8}, 0);
  std::memcpy(bytes.data() + size - 8, &sum, 8);
  return bytes;
}

/// For files that end in a checksum: runs `load(data, size)` on the input as it is, then on the
/// input with its checksum repaired when that differs.
template <class Load>
void loadAsIsAndRepaired(const std::uint8_t* data, std::size_t size, Load&& load) {
  load(data, size);
  const std::vector<std::uint8_t> repaired = withRepairedChecksum(data, size);
  if (!std::equal(repaired.begin(), repaired.end(), data)) load(repaired.data(), repaired.size());
}

/// The seed-writing mode of targets whose seeds the library writes: when the environment variable
/// DUPLEX_FUZZ_WRITE_SEEDS names a folder, creates it, calls `write(folder)` and exits.
template <class Write>
void writeSeedsIfAsked(Write&& write) {
  const char* dir = std::getenv("DUPLEX_FUZZ_WRITE_SEEDS");
  if (!dir) return;
  std::filesystem::create_directories(dir);
  write(std::filesystem::path(dir));
  std::exit(0);
}

}  // namespace duplex::fuzz
