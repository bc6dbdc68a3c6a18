// libFuzzer target of the .vdb loader: the whole input is the file, written to a temporary file
// (OpenVDB reads files by name) and loaded as the scene loader does (VolumeObject::load: the
// structural check, then OpenVDB's read of the first float grid, then the object's build). A
// FileError or InvalidArgument (an empty or non-linear grid) is the expected refusal; anything else
// (a crash, a sanitizer report, an allocation beyond -malloc_limit_mb, another exception) is a
// finding.

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/objects/VolumeObject.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <unistd.h>

namespace {

// One file per process (parallel fuzzing jobs do not share it), removed at exit.
const std::filesystem::path& inputFile() {
  static const std::filesystem::path file = [] {
    std::ostringstream name;
    name << "duplex-fuzz-vdb-" << ::getpid() << ".vdb";
    return std::filesystem::temp_directory_path() / name.str();
  }();
  return file;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  std::atexit([] {
    std::error_code ec;
    std::filesystem::remove(inputFile(), ec);
  });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  {
    std::ofstream out(inputFile(), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
    if (!out) {
      std::perror("duplex_fuzz_vdb: cannot write the temporary input file");
      std::abort();
    }
  }
  try {
    (void)duplex::VolumeObject::load(inputFile());
  } catch (const duplex::Error& e) {
    // The refusals; DUPLEX_FUZZ_VERBOSE prints them (to see why a seed is refused).
    if (!dynamic_cast<const duplex::FileError*>(&e) && !dynamic_cast<const duplex::InvalidArgument*>(&e)) throw;
    if (std::getenv("DUPLEX_FUZZ_VERBOSE") != nullptr) std::fprintf(stderr, "refused: %s\n", e.what());
  }
  return 0;
}
