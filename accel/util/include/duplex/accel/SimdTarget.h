#pragma once
/// \file SimdTarget.h
/// Regions of a source file compiled for one instruction set (SimdIsa.h), so that a run-time
/// kernel of each width lives in one translation unit beside the others:
///
///     DUPLEX_TARGET_AVX2_BEGIN
///     namespace avx2 { ... }
///     DUPLEX_TARGET_END
///
/// GCC takes `#pragma GCC target` between push_options / pop_options; clang applies a target
/// attribute to every function of the region. Library-internal: for the kernels' sources only.

/// `_Pragma` of its argument, stringised (a pragma written inside a macro).
#define DUPLEX_SIMD_PRAGMA(x) _Pragma(#x)

#if defined(__clang__)
/// Opens a region compiled for the target feature list `isa` (a string literal, e.g. "avx2").
#define DUPLEX_TARGET_BEGIN(isa) \
  DUPLEX_SIMD_PRAGMA(clang attribute push(__attribute__((target(isa))), apply_to = function))
/// Closes the region DUPLEX_TARGET_BEGIN (or one of the ISA forms below) opened.
#define DUPLEX_TARGET_END DUPLEX_SIMD_PRAGMA(clang attribute pop)
#else
/// Opens a region compiled for the target feature list `isa` (a string literal, e.g. "avx2").
#define DUPLEX_TARGET_BEGIN(isa) DUPLEX_SIMD_PRAGMA(GCC push_options) DUPLEX_SIMD_PRAGMA(GCC target(isa))
/// Closes the region DUPLEX_TARGET_BEGIN (or one of the ISA forms below) opened.
#define DUPLEX_TARGET_END DUPLEX_SIMD_PRAGMA(GCC pop_options)
#endif

/// SimdIsa::Avx2's kernels.
#define DUPLEX_TARGET_AVX2_BEGIN DUPLEX_TARGET_BEGIN("avx2")
/// SimdIsa::Avx512's kernels: AVX-512 F, VL, DQ and BW (with AVX2 for the 8-lane forms).
#define DUPLEX_TARGET_AVX512_BEGIN DUPLEX_TARGET_BEGIN("avx2,avx512f,avx512vl,avx512dq,avx512bw")
