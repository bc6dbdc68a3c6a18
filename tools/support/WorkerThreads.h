#pragma once
/// \file WorkerThreads.h
/// The `--threads N` of the tool's commands: a TBB arena of N threads, with the process-wide
/// limit set to N (an arena alone cannot exceed the default limit). Loading, building and tracing
/// run inside arena.execute().

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <cstddef>

namespace duplex::cli {

struct WorkerThreads {
  /// `requested` threads, or all hardware threads for 0.
  explicit WorkerThreads(int requested)
      : count(requested > 0 ? requested : tbb::info::default_concurrency()),
        limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(count)),
        arena(count) {}
  WorkerThreads(const WorkerThreads&) = delete;
  WorkerThreads& operator=(const WorkerThreads&) = delete;

  int count;
  tbb::global_control limit;
  tbb::task_arena arena;
};

}  // namespace duplex::cli
