#pragma once
/// \file BenchCommon.h
/// The measuring instrument shared by every benchmark mode: options, clocks, medians, the
/// thread-limited trace harness (one harness for our kd-tree and for Embree, so both are timed by the
/// same loop), and machine facts for the JSON.

#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <xmmintrin.h>
#include <pmmintrin.h>

#include <atomic>
#include <chrono>
#include <ctime>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace duplex::bench {

/// Everything the command line sets (see mesh_bench.cpp for the help texts and defaults).
struct Options {
  std::string data_dir;
  std::vector<std::string> meshes;
  std::size_t random_rays = 1'000'000;
  std::uint32_t primary_width = 1024;
  std::uint32_t primary_height = 1024;
  std::vector<int> threads{1, 2};
  int repeat = 3;
  std::uint64_t seed = 1;
  bool quick = false;
  std::string out;
  std::string embree_config;  ///< extra rtcNewDevice configuration, e.g. "isa=avx2"
  bool with_embree = true;
  /// Our structures: "bvh:PRESET[/KEY=VALUE...]" (BvhBuildConfig::parse with '/' for ',') or "kdtree".
  std::vector<std::string> structures{"bvh:fast", "bvh:medium", "bvh:high", "kdtree"};
  /// Embree's builds besides the medium one (always measured when Embree is): medium, high, robust.
  std::vector<std::string> embree_builds{"medium", "high", "robust"};
  /// Rays aimed at shared vertices and edges per closed mesh (0: no watertightness count).
  std::size_t watertight_rays = 200'000;
  // --sweep
  std::vector<std::string> sweep_meshes;
  std::size_t sweep_random_rays = 250'000;
  std::uint32_t sweep_primary_width = 512;
  std::uint32_t sweep_primary_height = 512;
  // --closest
  std::size_t closest_points = 100'000;  ///< points per mesh and kind (near, far)
  // --callgrind
  std::string callgrind_mesh;
  std::size_t callgrind_rays = 20'000;
  std::vector<std::string> callgrind_what{"ours", "embree"};
  std::string callgrind_structure = "bvh:medium";  ///< what "ours" is in the callgrind workload
};

/// Wall-clock milliseconds since construction.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  [[nodiscard]] double ms() const {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// CPU milliseconds consumed since construction, by the calling thread or by the whole process.
/// The machine is shared: when other processes take our core, wall time grows but CPU time does
/// not, so one-thread figures in CPU time repeat much better than wall-clock ones.
class CpuStopwatch {
 public:
  enum class Scope { Thread, Process };
  explicit CpuStopwatch(Scope scope) : scope_(scope), start_(now(scope)) {}
  [[nodiscard]] double ms() const { return now(scope_) - start_; }

 private:
  static double now(Scope scope) {
    timespec ts{};
    ::clock_gettime(scope == Scope::Thread ? CLOCK_THREAD_CPUTIME_ID : CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
  }
  Scope scope_;
  double start_;
};

/// Wall and CPU time of one measurement. `cpu_ms` is the calling thread's CPU time for one thread
/// (all work of a one-thread arena runs on the calling thread), and the process's CPU time divided
/// by the thread count for more: right for trace loops, which keep every thread busy to the end;
/// not for builds, whose serial parts leave threads idle (builds report it for one thread only).
struct Timing {
  double wall_ms = 0.0;
  double cpu_ms = 0.0;
  double process_cpu_ms = 0.0;  ///< CPU of the whole process (all threads), for sanity checks
};

/// Times `fn()` run by the calling thread with `threads` threads available.
template <class Fn>
Timing timeIt(int threads, const Fn& fn) {
  const CpuStopwatch cpu(threads == 1 ? CpuStopwatch::Scope::Thread : CpuStopwatch::Scope::Process);
  const CpuStopwatch process(CpuStopwatch::Scope::Process);
  const Stopwatch wall;
  fn();
  const double wall_ms = wall.ms();
  return {wall_ms, cpu.ms() / threads, process.ms()};
}

/// Median of the samples (mean of the two middle ones for an even count); NaN for none.
[[nodiscard]] double median(std::vector<double> samples);

/// Flush-to-zero and denormals-are-zero for the calling thread, as Embree recommends for every
/// thread that traces; we set it for our traversal too so that both run under the same FP mode.
inline void setFtzDaz() {
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

/// One TBB arena per thread count, created once and warmed up, so that "N threads" means the same
/// thing for every measurement (our build, our traversal, Embree's traversal).
class Arenas {
 public:
  /// Arena limited to `threads` threads (the calling thread plus threads-1 workers).
  tbb::task_arena& get(int threads);

 private:
  std::map<int, std::unique_ptr<tbb::task_arena>> arenas_;
};

/// Rays per parallel_for chunk: large enough that scheduling costs nothing, small enough that two
/// threads balance.
inline constexpr std::size_t kTraceChunk = 4096;

/// Result of one timed trace.
struct TraceTiming {
  Timing time;
  std::uint64_t hits = 0;
};

/// Times `query(ray) -> bool` over all rays inside `arena`: parallel_for over chunks of kTraceChunk
/// rays, one call per ray, hits summed per chunk. The same loop times every tracer.
template <class QueryFn>
TraceTiming timeTrace(tbb::task_arena& arena, std::span<const Ray> rays, const QueryFn& query) {
  std::atomic<std::uint64_t> hits{0};
  const Timing time = timeIt(arena.max_concurrency(), [&] {
    arena.execute([&] {
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, rays.size(), kTraceChunk),
          [&](const tbb::blocked_range<std::size_t>& range) {
            setFtzDaz();
            std::uint64_t chunk_hits = 0;
            for (std::size_t i = range.begin(); i != range.end(); ++i) chunk_hits += query(rays[i]) ? 1u : 0u;
            hits.fetch_add(chunk_hits, std::memory_order_relaxed);
          },
          tbb::simple_partitioner());
    });
  });
  return {time, hits.load()};
}

/// The two queries every tracer answers.
enum class Query { Closest, Any };
[[nodiscard]] inline const char* toString(Query q) { return q == Query::Closest ? "closest" : "any"; }

/// Times one query kind of `accel` (MeshObject or EmbreeMesh: anything with intersect(ray, hit) and
/// occluded(ray)); closest hit gets a fresh Hit per ray.
template <class Accel>
TraceTiming timeQuery(tbb::task_arena& arena, std::span<const Ray> rays, const Accel& accel, Query query) {
  if (query == Query::Closest)
    return timeTrace(arena, rays, [&accel](const Ray& r) {
      Hit hit;
      return accel.intersect(r, hit);
    });
  return timeTrace(arena, rays, [&accel](const Ray& r) { return accel.occluded(r); });
}

/// Runs `fn(i)` for i in [0, n) in parallel on the widest arena (untimed work: checks, counters).
template <class Fn>
void parallelFor(tbb::task_arena& arena, std::size_t n, const Fn& fn) {
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kTraceChunk),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        setFtzDaz();
                        for (std::size_t i = r.begin(); i != r.end(); ++i) fn(i);
                      });
  });
}

/// What a program knows about its own build, beyond what machineInfo() reads from the machine.
/// Unknown facts are JSON null: the installed `duplex` tool knows neither (it has no source tree
/// and no Embree); the benchmarks fill them in with thisBuild() (BenchBuild.h).
struct BuildFacts {
  std::string git_revision;           ///< `git rev-parse --short HEAD` at configure time; "" unknown
  std::optional<bool> library_dirty;  ///< uncommitted changes in accel/ or objects/ at configure time
  std::string embree_version;         ///< the linked Embree's version; "" without Embree
};

/// nproc, CPU model, compiler, load average, and `build`: the measured library's git revision and
/// the Embree version.
[[nodiscard]] nlohmann::json machineInfo(const BuildFacts& build = {});
/// The 1, 5 and 15 minute load averages from /proc/loadavg, as one string.
[[nodiscard]] std::string loadAverage();

/// Writes `doc` to `path` (pretty-printed; parent folders created). Throws on I/O failure.
void writeJson(const std::string& path, const nlohmann::json& doc);

/// "12.3" style formatting for the stderr tables ("-" for NaN).
[[nodiscard]] std::string fmt(double value, int decimals = 2);
/// Left-aligned (pad) and right-aligned (lpad) to `width` characters.
[[nodiscard]] std::string pad(const std::string& s, std::size_t width);
[[nodiscard]] std::string lpad(const std::string& s, std::size_t width);
/// 1234567 -> "1,234,567".
[[nodiscard]] std::string thousands(std::uint64_t n);

}  // namespace duplex::bench
