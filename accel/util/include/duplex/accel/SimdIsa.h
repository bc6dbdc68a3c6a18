#pragma once
/// \file SimdIsa.h
/// The widest SIMD instruction set the kernels chosen at run time may use: what the CPU runs,
/// capped by the environment variable DUPLEX_ISA, so that tests and benchmarks can run every path
/// on one machine.

#include <string_view>

namespace duplex {

/// Instruction sets of the run-time kernels, narrowest first.
enum class SimdIsa {
  Sse2,    ///< 4 lanes: part of x86-64, always available there (and the path off x86-64)
  Avx2,    ///< 8 lanes: AVX2 (Haswell and later)
  Avx512,  ///< 16 lanes, or 8 with mask registers: AVX-512 F, VL, DQ, BW (Skylake-SP, Zen 4)
};

/// "sse2", "avx2" or "avx512".
std::string_view toString(SimdIsa isa);

/// The widest set the CPU supports, capped by DUPLEX_ISA ("sse2", "avx2", "avx512"; unset or any
/// other value: no cap). Read once per process: kernels chosen from it do not change afterwards.
SimdIsa widestSimdIsa();

}  // namespace duplex
