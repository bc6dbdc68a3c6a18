#pragma once
/// \file BenchBuild.h
/// thisBuild(): the BuildFacts of the program that includes it, for machineInfo(). The benchmark
/// executables (DUPLEX_BENCH_HAVE_REVISION) know the revision CMake read at configure time; with
/// DUPLEX_BENCH_HAVE_EMBREE they know Embree's version. The installed tool has neither define and
/// reports both as unknown.

#include "BenchCommon.h"

#if DUPLEX_BENCH_HAVE_REVISION
#include "BenchRevision.h"
#endif
#if DUPLEX_BENCH_HAVE_EMBREE
#include <embree3/rtcore_config.h>
#endif

namespace duplex::bench {

[[nodiscard]] inline BuildFacts thisBuild() {
  BuildFacts facts;
#if DUPLEX_BENCH_HAVE_REVISION
  facts.git_revision = DUPLEX_BENCH_GIT_REVISION;
  if (!facts.git_revision.empty()) facts.library_dirty = DUPLEX_BENCH_LIBRARY_DIRTY;
#endif
#if DUPLEX_BENCH_HAVE_EMBREE
  facts.embree_version = RTC_VERSION_STRING;
#endif
  return facts;
}

}  // namespace duplex::bench
