// libFuzzer target of the .vdb loader: the whole input is the file, written to a temporary file
// (OpenVDB reads files by name) and loaded as the scene loader does (VolumeObject::load: the
// structural check, then OpenVDB's read of the first float grid, then the object's build). A
// FileError or InvalidArgument (an empty or non-linear grid) is the expected refusal; anything else
// (a crash, a sanitizer report, an allocation beyond -malloc_limit_mb, another exception) is a
// finding.

#include "FuzzInputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/objects/VolumeObject.h"

#include <cstdint>
#include <cstdio>
#include <cstdlib>

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& file = duplex::fuzz::writeInputFile(data, size, ".vdb");
  try {
    (void)duplex::VolumeObject::load(file);
  } catch (const duplex::Error& e) {
    // The refusals; DUPLEX_FUZZ_VERBOSE prints them (to see why a seed is refused).
    if (!dynamic_cast<const duplex::FileError*>(&e) && !dynamic_cast<const duplex::InvalidArgument*>(&e)) throw;
    if (std::getenv("DUPLEX_FUZZ_VERBOSE") != nullptr) std::fprintf(stderr, "refused: %s\n", e.what());
  }
  return 0;
}
