// libFuzzer target of the IES LM-63 reader (IesProfile::parse): the whole input is the file's text.
// A FileError is the expected refusal. A profile that parses must answer queries with finite,
// non-negative intensities and a positive, finite integral, and sample() must return unit
// directions with finite weights; anything else (a crash, a sanitizer report, another exception, a
// violated property) is a finding.

#include "duplex/accel/Error.h"
#include "duplex/sensors/IesProfile.h"

#include <glm/geometric.hpp>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerInitialize(int*, char***) { return 0; }

namespace {

[[noreturn]] void violated(const char* what) {
  std::fprintf(stderr, "IesProfile property violated: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const duplex::IesProfile p = duplex::IesProfile::parse(text, "fuzz-input");
    if (!(std::isfinite(p.integral()) && p.integral() > 0)) violated("integral() not positive and finite");
    for (const glm::dvec3 d : {glm::dvec3(0, 0, -1), glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 0), glm::dvec3(-1, 2, -3),
                               glm::dvec3(0, -1, 0.25), glm::dvec3(0, 0, 0)}) {
      const double i = p.intensity(d);
      if (!(std::isfinite(i) && i >= 0)) violated("intensity() not finite and non-negative");
    }
    for (const auto& [u1, u2] : {std::pair{0.0, 0.0}, std::pair{0.5, 0.25}, std::pair{0.999, 0.999}}) {
      const duplex::IesProfile::Sample s = p.sample(u1, u2);
      if (!(std::abs(glm::length(s.direction_lf) - 1.0) < 1e-9)) violated("sample() direction not a unit vector");
      if (!(std::isfinite(s.weight) && s.weight >= 0)) violated("sample() weight not finite and non-negative");
    }
  } catch (const duplex::FileError& e) {
    // The refusal; DUPLEX_FUZZ_VERBOSE prints it (to see why a seed is refused).
    if (std::getenv("DUPLEX_FUZZ_VERBOSE") != nullptr) std::fprintf(stderr, "refused: %s\n", e.what());
  }
  return 0;
}
