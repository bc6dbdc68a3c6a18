#include "TraceCommand.h"

#include "LoadScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/QueryContext.h>
#include <duplex/accel/RayFile.h>
#include <duplex/accel/TopLevel.h>
#include <duplex/objects/MeshObject.h>

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>
#include <vector>

namespace duplex::cli {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 == 1 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// The record of an occlusion query (see TraceOptions::any_hit).
HitRecord occlusionRecord(bool blocked) {
  if (!blocked) return HitRecord::miss();
  return {0.0f, 0.0f, 0.0f, 0u, kInvalidId};
}

// Triangles as the rays see them: each instance counts its mesh's triangles.
std::size_t instancedTriangles(const Scene& scene) {
  std::size_t n = 0;
  for (const SceneInstance& inst : scene.instances())
    if (const auto* mesh = dynamic_cast<const MeshObject*>(scene.object(inst.object).get()))
      n += mesh->mesh().triangleCount();
  return n;
}

// Rays per task: large enough that a task's QueryContext and scheduling cost vanish, small enough
// to balance primary rays whose cost varies across the image.
constexpr std::size_t kRaysPerTask = 1024;

}  // namespace

nlohmann::ordered_json runTrace(const TraceOptions& options) {
  if (options.repeat < 1) throw InvalidArgument("--repeat must be at least 1");
  const int threads = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
  // The arena alone cannot exceed the default thread limit; raise (or lower) the global one.
  tbb::global_control thread_limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
  tbb::task_arena arena(threads);

  // The ray file first: a bad one fails before the (longer) scene load.
  const std::vector<Ray> rays = readRayFile(options.rays);

  SceneLoadReport load_report;
  std::optional<Scene> scene;
  TopLevel top;
  double top_build_ms = 0.0;
  arena.execute([&] {
    scene.emplace(loadSceneNamed(options.scene, &load_report));
    const auto t0 = Clock::now();
    const std::vector<InstanceDesc> descs = scene->instanceDescs();
    top.build(descs);
    top_build_ms = msSince(t0);
  });

  std::vector<HitRecord> records(rays.size(), HitRecord::miss());

  std::vector<double> trace_ms;
  for (int run = 0; run < options.repeat; ++run) {
    const auto t0 = Clock::now();
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), kRaysPerTask),
                        [&](const tbb::blocked_range<std::size_t>& range) {
                          QueryContext ctx;  // one per task: contexts are not shared between threads
                          if (options.any_hit) {
                            for (std::size_t i = range.begin(); i != range.end(); ++i)
                              records[i] = occlusionRecord(top.occluded(rays[i], ctx));
                          } else {
                            for (std::size_t i = range.begin(); i != range.end(); ++i)
                              records[i] = HitRecord::from(top.intersect(rays[i], ctx));
                          }
                        });
    });
    trace_ms.push_back(msSince(t0));
  }

  writeHitFile(options.hits, records);

  const auto hits = static_cast<std::size_t>(std::count_if(
      records.begin(), records.end(), [](const HitRecord& r) { return r.instance_id != kInvalidId; }));
  const double trace_median = median(trace_ms);
  const double mrays_per_s = trace_median > 0.0 ? static_cast<double>(rays.size()) / (trace_median * 1e3) : 0.0;

  nlohmann::ordered_json report;
  report["rays"] = rays.size();
  report["hits"] = hits;
  report["threads"] = threads;
  report["load_ms"] = load_report.load_ms;
  report["build_ms"] = load_report.build_ms + top_build_ms;
  report["trace_ms"] = trace_median;
  report["mrays_per_s"] = mrays_per_s;
  report["repeat"] = options.repeat;
  report["any_hit"] = options.any_hit;
  report["objects"] = scene->objectCount();
  report["instances"] = scene->instances().size();
  report["triangles"] = load_report.triangles;
  report["instanced_triangles"] = instancedTriangles(*scene);
  report["bottom_build_ms"] = load_report.build_ms;
  report["top_build_ms"] = top_build_ms;
  report["trace_ms_all"] = trace_ms;
  return report;
}

}  // namespace duplex::cli
