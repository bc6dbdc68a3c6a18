#include "duplex/accel/SimdIsa.h"

#include <cstdlib>
#include <string_view>

namespace duplex {

std::string_view toString(SimdIsa isa) {
  switch (isa) {
    case SimdIsa::Sse2: return "sse2";
    case SimdIsa::Avx2: return "avx2";
    case SimdIsa::Avx512: return "avx512";
  }
  return "unknown";
}

SimdIsa widestSimdIsa() {
  static const SimdIsa widest = [] {
#if defined(__GNUC__) && defined(__x86_64__)
    SimdIsa cap = SimdIsa::Avx512;
    if (const char* isa = std::getenv("DUPLEX_ISA")) {
      const std::string_view v(isa);
      if (v == "sse2") cap = SimdIsa::Sse2;
      else if (v == "avx2") cap = SimdIsa::Avx2;
    }
    __builtin_cpu_init();
    if (cap >= SimdIsa::Avx512 && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
        __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512bw"))
      return SimdIsa::Avx512;
    if (cap >= SimdIsa::Avx2 && __builtin_cpu_supports("avx2")) return SimdIsa::Avx2;
#endif
    return SimdIsa::Sse2;
  }();
  return widest;
}

}  // namespace duplex
