// A fixed workload for callgrind: build (uninstrumented), then trace a fixed set of random rays on the
// calling thread with instrumentation switched on around each trace loop only, one dump per tracer and
// query. Run it under `valgrind --tool=callgrind --instr-atstart=no` (scripts/bench_callgrind.sh);
// without callgrind.h the loops are the noinline functions *callgrindLoop*, for --toggle-collect.

#include "BenchBuild.h"
#include "BenchChecks.h"
#include "BenchMeshes.h"
#include "BenchModes.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif
#if DUPLEX_BENCH_HAVE_CALLGRIND
#include <valgrind/callgrind.h>
#endif

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/KdTree.h"

#include <algorithm>
#include <iostream>

namespace duplex::bench {

namespace {

// One instrumented section: zero the counters, count the loop, dump under `name`.
template <class Accel>
[[gnu::noinline]] std::uint64_t callgrindLoop(const char* name, const Accel& accel, std::span<const Ray> rays,
                                              Query q) {
  // One uncounted query first, so that lazy symbol binding (PLT) is not charged to the loop.
  if (!rays.empty()) {
    Hit warm;
    (void)accel.intersect(rays[0], warm);
    (void)accel.occluded(rays[0]);
  }
#if DUPLEX_BENCH_HAVE_CALLGRIND
  CALLGRIND_ZERO_STATS;
  CALLGRIND_START_INSTRUMENTATION;
#endif
  std::uint64_t hits = 0;
  if (q == Query::Closest) {
    for (const Ray& r : rays) {
      Hit hit;
      hits += accel.intersect(r, hit) ? 1u : 0u;
    }
  } else {
    for (const Ray& r : rays) hits += accel.occluded(r) ? 1u : 0u;
  }
#if DUPLEX_BENCH_HAVE_CALLGRIND
  CALLGRIND_STOP_INSTRUMENTATION;
  CALLGRIND_DUMP_STATS_AT(name);
#else
  (void)name;
#endif
  return hits;
}

}  // namespace

nlohmann::json runCallgrind(const Options& options) {
  setFtzDaz();
  const auto wants = [&](const char* what) {
    return std::find(options.callgrind_what.begin(), options.callgrind_what.end(), what) !=
           options.callgrind_what.end();
  };
  MeshCache cache(options.data_dir);
  const LoadedMesh& loaded = cache.get(MeshSpec::parse(options.callgrind_mesh));
  const std::vector<Ray> rays = randomRays(loaded.mesh->bounds(), options.callgrind_rays, options.seed);
  nlohmann::json doc;
  doc["kind"] = "duplex_bench_callgrind";
  doc["machine"] = machineInfo(thisBuild());
  doc["mesh"] = loaded.spec.label();
  doc["triangles"] = loaded.mesh->triangleCount();
  doc["rays"] = rays.size();
  doc["seed"] = options.seed;
#if DUPLEX_BENCH_HAVE_CALLGRIND
  doc["instrumented_sections"] = true;
  doc["running_on_valgrind"] = RUNNING_ON_VALGRIND != 0;
#else
  doc["instrumented_sections"] = false;
#endif
  Arenas arenas;
  if (wants("ours")) {
    // "ours" is one structure (--callgrind-structure), so that the dump names stay fixed.
    const std::string& spec = options.callgrind_structure;
    const bool kd = spec == "kdtree";
    if (!kd && spec != "bvh" && spec.rfind("bvh:", 0) != 0)
      throw InvalidArgument("--callgrind-structure: '" + spec + "' is not kdtree, bvh or bvh:PRESET[/KEY=VALUE...]");
    std::string text = kd || spec == "bvh" ? "medium" : spec.substr(4);
    std::replace(text.begin(), text.end(), '/', ',');
    const BvhBuildConfig bvh_config = BvhBuildConfig::parse(text);
    std::unique_ptr<MeshObject> object;
    arenas.get(1).execute([&] {
      object = kd ? std::make_unique<MeshObject>(loaded.mesh, KdBuildConfig{})
                  : std::make_unique<MeshObject>(loaded.mesh, bvh_config);
    });
    doc["ours"]["structure"] = kd ? "kdtree" : "bvh";
    doc["ours"]["structure_spec"] = spec;
    if (kd) {
      const KdTreeStats stats = object->tree().stats(KdBuildConfig{}.traversal_cost, KdBuildConfig{}.intersection_cost);
      doc["ours"]["nodes"] = stats.nodes;
      doc["ours"]["sah_cost"] = stats.sah_cost;
    } else {
      doc["ours"]["config"] = bvh_config.toString();
      doc["ours"]["nodes"] = object->bvh().nodes.size();
      doc["ours"]["sah_cost"] = object->bvh().sahCost(bvh_config);
    }
    doc["ours"]["closest_hits"] = callgrindLoop("ours-closest", *object, rays, Query::Closest);
    doc["ours"]["any_hits"] = callgrindLoop("ours-any", *object, rays, Query::Any);
    // The counters replicate the kd-tree's query only.
    if (kd) doc["ours"]["traversal"] = countTraversal(arenas.get(1), *object, rays).toJson();
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  if (wants("embree") && options.with_embree) {
    EmbreeDevice device(1, options.embree_config);
    const EmbreeMesh scene(device, *loaded.mesh, RTC_BUILD_QUALITY_MEDIUM);
    doc["embree_medium"]["closest_hits"] = callgrindLoop("embree-closest", scene, rays, Query::Closest);
    doc["embree_medium"]["any_hits"] = callgrindLoop("embree-any", scene, rays, Query::Any);
  }
#endif
  std::cerr << "callgrind workload: " << loaded.spec.label() << ", " << rays.size() << " random rays\n"
            << doc.dump(2) << "\n";
  return doc;
}

}  // namespace duplex::bench
