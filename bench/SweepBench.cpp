// The heuristic/cost sweep: how much build time buys how much trace time. Every setting is built and
// traced on one thread, settings interleaved within each repetition (so that machine drift spreads over
// all of them), with Embree medium and high measured in the same repetitions as reference points.
// Under callgrind (scripts/sweep_callgrind.sh) each setting's build and its four trace loops (random
// and primary rays, closest and any hit) are instrumented sections of their own, dumped by name: their
// instruction counts repeat exactly, where times on the shared machine do not.

#include "BenchBuild.h"
#include "BenchMeshes.h"
#include "BenchModes.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif
#if DUPLEX_BENCH_HAVE_CALLGRIND
#include <valgrind/callgrind.h>
#endif

#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/accel/KdTree.h"

#include <cmath>
#include <iostream>
#include <span>
#include <sstream>

namespace duplex::bench {

namespace {

struct Setting {
  std::string label;
  KdBuildConfig config;
  bool is_default = false;
};

bool onValgrind() {
#if DUPLEX_BENCH_HAVE_CALLGRIND
  return RUNNING_ON_VALGRIND != 0;
#else
  return false;
#endif
}

// Runs `fn` as one instrumented callgrind section dumped as `name` (outside valgrind: just runs it).
template <class Fn>
[[gnu::noinline]] void callgrindSection(const std::string& name, const Fn& fn) {
#if DUPLEX_BENCH_HAVE_CALLGRIND
  CALLGRIND_ZERO_STATS;
  CALLGRIND_START_INSTRUMENTATION;
  fn();
  CALLGRIND_STOP_INSTRUMENTATION;
  CALLGRIND_DUMP_STATS_AT(name.c_str());
#else
  (void)name;
  fn();
#endif
}

// Closest or any hit of every ray, on the calling thread (the instrumented trace loops).
template <class Accel>
[[gnu::noinline]] std::uint64_t traceLoop(const Accel& accel, std::span<const Ray> rays, Query q) {
  std::uint64_t hits = 0;
  for (const Ray& r : rays) {
    Hit hit;
    hits += (q == Query::Closest ? accel.intersect(r, hit) : accel.occluded(r)) ? 1u : 0u;
  }
  return hits;
}

std::string costLabel(float value) {
  std::ostringstream os;
  os << value;
  return os.str();
}

// A setting derived from the shipped defaults (KdBuildConfig{}), so that the sweep follows them when
// they change; `is_default` marks the one that equals them.
Setting sah(float traversal, float intersection, float empty_bonus, bool clip) {
  Setting s;
  s.config.heuristic = KdHeuristic::Sah;
  s.config.traversal_cost = traversal;
  s.config.intersection_cost = intersection;
  s.config.empty_bonus = empty_bonus;
  s.config.clip_primitives = clip;
  s.label = "SAH " + costLabel(traversal) + "/" + costLabel(intersection) + "/" + costLabel(empty_bonus) +
            (clip ? "" : " noclip");
  const KdBuildConfig d{};
  s.is_default = d.heuristic == KdHeuristic::Sah && traversal == d.traversal_cost &&
                 intersection == d.intersection_cost && empty_bonus == d.empty_bonus && clip == d.clip_primitives;
  return s;
}

Setting simple(KdHeuristic heuristic, std::uint32_t max_leaf_size) {
  Setting s;
  s.config.heuristic = heuristic;
  s.config.max_leaf_size = max_leaf_size;
  s.label = std::string(heuristic == KdHeuristic::Median ? "Median" : "Middle") + " L" + std::to_string(max_leaf_size);
  return s;
}

// The defaults first, then SAH cost variations around them (labels read
// traversal/intersection/empty-bonus), clipping off, and the cheap heuristics at several leaf sizes.
std::vector<Setting> settings(bool quick) {
  const KdBuildConfig d{};
  const float ct = d.traversal_cost, ci = d.intersection_cost, eb = d.empty_bonus;
  std::vector<Setting> list{sah(ct, ci, eb, d.clip_primitives)};
  auto add = [&list](const Setting& s) {
    for (const Setting& other : list)
      if (other.label == s.label) return;
    list.push_back(s);
  };
  if (quick) {
    add(sah(ct, 1.5f, eb, true));
    add(sah(ct, ci, eb, false));
    add(simple(KdHeuristic::Median, 4));
    add(simple(KdHeuristic::SpatialMiddle, 4));
    return list;
  }
  for (const float c : {0.1f, 0.2f, 0.35f, 0.5f, 1.0f, 1.5f, 3.0f}) add(sah(ct, c, eb, true));
  // Cheaper builds than the defaults: a higher node cost (larger leaves, fewer nodes), no clipping,
  // and both together.
  add(sah(1.5f * ct, ci, eb, true));
  add(sah(2.0f * ct, ci, eb, true));
  // Beyond node cost 2: where do build and trace stop improving together?
  for (const float k : {3.0f, 4.0f, 6.0f, 8.0f}) add(sah(k * ct, ci, eb, true));
  for (const float b : {0.0f, 0.5f}) add(sah(ct, ci, b, true));
  add(sah(ct, ci, eb, false));
  add(sah(1.5f * ct, ci, eb, false));
  for (const float k : {3.0f, 4.0f}) add(sah(k * ct, ci, eb, false));
  add(sah(ct, 1.5f, eb, false));
  // Leaf size 2 is left out: the median heuristic then builds far slower than the SAH and would
  // dominate the run time.
  for (const std::uint32_t leaf : {4u, 8u, 16u}) add(simple(KdHeuristic::Median, leaf));
  for (const std::uint32_t leaf : {4u, 8u, 16u}) add(simple(KdHeuristic::SpatialMiddle, leaf));
  return list;
}

// Per setting: thread CPU time (the headline: everything runs on the calling thread) and wall time.
struct Figures {
  std::vector<double> build_ms, random_ms, primary_ms;
  std::vector<double> build_wall_ms, random_wall_ms, primary_wall_ms;
  void add(const Timing& build, const Timing& random, const Timing& primary) {
    build_ms.push_back(build.cpu_ms);
    random_ms.push_back(random.cpu_ms);
    primary_ms.push_back(primary.cpu_ms);
    build_wall_ms.push_back(build.wall_ms);
    random_wall_ms.push_back(random.wall_ms);
    primary_wall_ms.push_back(primary.wall_ms);
  }
};

}  // namespace

nlohmann::json runSweep(const Options& options) {
#if DUPLEX_BENCH_HAVE_EMBREE
  std::unique_ptr<EmbreeDevice> device;
  if (options.with_embree) device = std::make_unique<EmbreeDevice>(1, options.embree_config);
#endif
  Arenas arenas;
  tbb::task_arena& one = arenas.get(1);
  const std::vector<Setting> all = settings(options.quick);
  const KdBuildConfig defaults{};

  nlohmann::json doc;
  doc["kind"] = "duplex_bench_sweep";
  doc["machine"] = machineInfo(thisBuild());
  doc["config"] = {{"meshes", options.sweep_meshes},
                   {"random_rays", options.sweep_random_rays},
                   {"primary", {options.sweep_primary_width, options.sweep_primary_height}},
                   {"threads", 1},
                   {"repeat", options.repeat},
                   {"seed", options.seed},
                   {"query", "closest"},
                   {"clock",
                    "build_ms, random_ms, primary_ms: medians of the calling thread's CPU time (one thread: "
                    "robust to other processes on the shared machine); *_wall_ms: wall-clock medians"},
                   {"sah_cost_note",
                    "sah_cost weighs every tree with the default costs (1, 1.5) so that settings compare; "
                    "sah_cost_own with the setting's own costs"}};
  MeshCache cache(options.data_dir);
  nlohmann::json meshes = nlohmann::json::array();
  for (const std::string& spec_text : options.sweep_meshes) {
    const LoadedMesh& loaded = cache.get(MeshSpec::parse(spec_text));
    const TriangleMesh& mesh = *loaded.mesh;
    const double triangles = static_cast<double>(mesh.triangleCount());
    const std::vector<Ray> random = randomRays(mesh.bounds(), options.sweep_random_rays, options.seed);
    const std::vector<Ray> primary =
        primaryRays(mesh.bounds(), options.sweep_primary_width, options.sweep_primary_height);
    std::cerr << "\n== sweep " << loaded.spec.label() << ": " << mesh.triangleCount() << " triangles, " << all.size()
              << " settings x " << options.repeat << " repetitions\n";

    std::vector<Figures> figures(all.size());
    std::vector<nlohmann::json> trees(all.size());
    Figures embree[2];
    const Stopwatch phase;
    if (onValgrind()) {
      // Instruction counts: one repetition, every section dumped by name; no timing, no Embree.
      for (std::size_t i = 0; i < all.size(); ++i) {
        // Only the SAH settings that could replace the defaults: the median / middle heuristics and
        // intersection costs above twice the default trace much slower (bench/results/sweep.txt) and
        // would take most of the run, which valgrind slows many times.
        if (all[i].config.heuristic != KdHeuristic::Sah ||
            all[i].config.intersection_cost > 2.0f * defaults.intersection_cost)
          continue;
        const std::string tag = "sweep|" + loaded.spec.label() + "|" + all[i].label + "|";
        std::unique_ptr<MeshObject> object;
        one.execute([&] {
          callgrindSection(tag + "build", [&] { object = std::make_unique<MeshObject>(loaded.mesh, all[i].config); });
        });
        setFtzDaz();
        // One uncounted query first, so that lazy symbol binding is not charged to a loop.
        (void)traceLoop(*object, std::span<const Ray>(random).first(1), Query::Any);
        for (const Query q : {Query::Closest, Query::Any}) {
          callgrindSection(tag + "random-" + toString(q), [&] { (void)traceLoop(*object, random, q); });
          callgrindSection(tag + "primary-" + toString(q), [&] { (void)traceLoop(*object, primary, q); });
        }
        const KdTreeStats own = object->tree().stats(all[i].config.traversal_cost, all[i].config.intersection_cost);
        const KdTreeStats common = object->tree().stats(defaults.traversal_cost, defaults.intersection_cost);
        std::cerr << "  " << pad(all[i].label, 24) << " nodes " << own.nodes << ", SAH " << fmt(common.sah_cost, 1)
                  << ", references per triangle "
                  << fmt(static_cast<double>(object->tree().prim_indices.size()) / triangles) << "\n";
      }
      continue;
    }
    for (int rep = 0; rep < options.repeat; ++rep) {
      for (std::size_t i = 0; i < all.size(); ++i) {
        std::unique_ptr<MeshObject> object;
        const Timing build =
            timeIt(1, [&] { one.execute([&] { object = std::make_unique<MeshObject>(loaded.mesh, all[i].config); }); });
        const Timing random_time = timeQuery(one, random, *object, Query::Closest).time;
        const Timing primary_time = timeQuery(one, primary, *object, Query::Closest).time;
        figures[i].add(build, random_time, primary_time);
        if (rep == 0) {
          const KdTreeStats own = object->tree().stats(all[i].config.traversal_cost, all[i].config.intersection_cost);
          const KdTreeStats common = object->tree().stats(defaults.traversal_cost, defaults.intersection_cost);
          trees[i] = {{"nodes", own.nodes},
                      {"leaves", own.leaves},
                      {"empty_leaves", own.empty_leaves},
                      {"avg_leaf_size", own.avg_leaf_size},
                      {"max_depth", own.max_depth},
                      {"sah_cost", common.sah_cost},
                      {"sah_cost_own", own.sah_cost},
                      {"bytes_per_triangle", static_cast<double>(object->accelBytes()) / triangles}};
        }
      }
#if DUPLEX_BENCH_HAVE_EMBREE
      if (device) {
        for (int q = 0; q < 2; ++q) {
          std::unique_ptr<EmbreeMesh> scene;
          const Timing build = timeIt(1, [&] {
            scene =
                std::make_unique<EmbreeMesh>(*device, mesh, q == 0 ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
          });
          const Timing random_time = timeQuery(one, random, *scene, Query::Closest).time;
          const Timing primary_time = timeQuery(one, primary, *scene, Query::Closest).time;
          embree[q].add(build, random_time, primary_time);
        }
      }
#endif
      std::cerr << "  repetition " << rep + 1 << " done (" << fmt(phase.ms() / 1e3, 1) << " s)\n";
    }

    // Relative figures are against the default setting of the same run.
    std::size_t def = 0;
    for (std::size_t i = 0; i < all.size(); ++i)
      if (all[i].is_default) def = i;
    const double def_build = median(figures[def].build_ms), def_random = median(figures[def].random_ms),
                 def_primary = median(figures[def].primary_ms);
    nlohmann::json rows = nlohmann::json::array();
    std::cerr << "  (CPU ms of the one tracing thread; wall clock in the JSON)\n";
    std::cerr << "  " << pad("setting", 24) << lpad("build ms", 10) << lpad("random ms", 11) << lpad("primary ms", 11)
              << lpad("rel build", 10) << lpad("rel rand", 10) << lpad("rel prim", 10) << lpad("SAH", 8) << "\n";
    for (std::size_t i = 0; i < all.size(); ++i) {
      const KdBuildConfig& c = all[i].config;
      const double b = median(figures[i].build_ms), r = median(figures[i].random_ms), p = median(figures[i].primary_ms);
      nlohmann::json row = {{"label", all[i].label},
                            {"is_default", all[i].is_default},
                            {"heuristic", std::string(toString(c.heuristic))},
                            {"traversal_cost", c.traversal_cost},
                            {"intersection_cost", c.intersection_cost},
                            {"empty_bonus", c.empty_bonus},
                            {"clip_primitives", c.clip_primitives},
                            {"max_leaf_size", c.max_leaf_size},
                            {"build_ms", b},
                            {"random_ms", r},
                            {"primary_ms", p},
                            {"random_mrays", random.size() / (r * 1e3)},
                            {"primary_mrays", primary.size() / (p * 1e3)},
                            {"rel_build", b / def_build},
                            {"rel_random", r / def_random},
                            {"rel_primary", p / def_primary},
                            {"build_ms_samples", figures[i].build_ms},
                            {"random_ms_samples", figures[i].random_ms},
                            {"primary_ms_samples", figures[i].primary_ms},
                            {"build_wall_ms", median(figures[i].build_wall_ms)},
                            {"random_wall_ms", median(figures[i].random_wall_ms)},
                            {"primary_wall_ms", median(figures[i].primary_wall_ms)}};
      row.update(trees[i]);
      rows.push_back(row);
      std::ostringstream line;
      line << "  " << pad(all[i].label, 24) << lpad(fmt(b, 1), 10) << lpad(fmt(r, 1), 11) << lpad(fmt(p, 1), 11)
           << lpad(fmt(b / def_build), 10) << lpad(fmt(r / def_random), 10) << lpad(fmt(p / def_primary), 10)
           << lpad(fmt(trees[i]["sah_cost"].get<double>(), 1), 8) << (all[i].is_default ? "  (default)" : "");
      std::cerr << line.str() << "\n";
    }
    nlohmann::json m = {{"mesh", loaded.spec.label()},
                        {"triangles", mesh.triangleCount()},
                        {"random_rays", random.size()},
                        {"primary_rays", primary.size()},
                        {"settings", rows}};
    for (int q = 0; q < 2; ++q) {
      if (embree[q].build_ms.empty()) continue;
      const double b = median(embree[q].build_ms), r = median(embree[q].random_ms), p = median(embree[q].primary_ms);
      m["embree"][q == 0 ? "medium" : "high"] = {{"build_ms", b},
                                                 {"random_ms", r},
                                                 {"primary_ms", p},
                                                 {"random_mrays", random.size() / (r * 1e3)},
                                                 {"primary_mrays", primary.size() / (p * 1e3)},
                                                 {"rel_build", b / def_build},
                                                 {"rel_random", r / def_random},
                                                 {"rel_primary", p / def_primary},
                                                 {"build_wall_ms", median(embree[q].build_wall_ms)},
                                                 {"random_wall_ms", median(embree[q].random_wall_ms)},
                                                 {"primary_wall_ms", median(embree[q].primary_wall_ms)}};
      std::cerr << "  " << pad(q == 0 ? "Embree medium" : "Embree high", 24) << lpad(fmt(b, 1), 10)
                << lpad(fmt(r, 1), 11) << lpad(fmt(p, 1), 11) << lpad(fmt(b / def_build), 10)
                << lpad(fmt(r / def_random), 10) << lpad(fmt(p / def_primary), 10) << "\n";
    }
    meshes.push_back(m);
  }
  doc["meshes"] = meshes;
  return doc;
}

}  // namespace duplex::bench
