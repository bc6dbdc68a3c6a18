// duplex_bench_update: the update benchmark of issue 3, section 6. Loads a scene-json-v1 scene and
// measures, for every two-level structure on the same seeded edit plan:
//   full build; update after moving M instances (median over --repeat commits); add and remove
//   of one instance; primary-ray Mrays/s right after the updates (and, for ours, after a fresh
//   top-level build: the slowdown the incremental commits left behind).
// Structures: ours incremental (SceneGraph + SceneTracer, TopLevelUpdate::Incremental), ours with a
// full top-level rebuild per commit (TopLevelUpdate::FullRebuild, the paper's method), and, when
// Embree 3 is found, Embree two-level scenes with the default top-level flags and with
// dynamic + low quality. Prints one JSON object on stdout; progress goes to stderr.
//
//   duplex_bench_update --scene S.json [--moves M | --moves P%] [--repeat R] [--seed X]
//                       [--threads N] [--primary W] [--build-repeat B]
//
// The edit plan (so that other tracers can replay it): rng = std::mt19937_64(seed), u(rng) =
// (rng() >> 11) * 2^-53, side = 5% of the diagonal of the scene's world bounds,
// delta() = ((u - 0.5) * side, (u - 0.5) * side, (u - 0.5) * side) drawn x, y, z in that order.
//   R move steps: ids = 0..N-1; for j < M: k = j + rng() % (N - j), swap(ids[j], ids[k]); then for
//     each of ids[0..M) in that order, translation += delta(). One commit per step.
//   R add/remove steps (after the moves): object = rng() % objects, base = rng() % N, transform =
//     base's current transform with translation + delta(); add it (commit), remove it (commit).

#include "BenchCommon.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/scenegraph/SceneFile.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeTwoLevel.h"
#endif

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <iostream>
#include <memory>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace duplex::bench {
namespace {

struct Move {
  std::uint32_t instance;
  glm::dvec3 delta_ws;
};

struct AddEdit {
  std::uint32_t object;
  Affine world_from_object;
};

struct EditPlan {
  std::vector<std::vector<Move>> moves;  ///< one list per commit
  std::vector<AddEdit> adds;             ///< each added, committed, removed, committed
};

double unitInterval(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

glm::dvec3 randomDelta(std::mt19937_64& rng, double side) {
  const double x = (unitInterval(rng) - 0.5) * side;
  const double y = (unitInterval(rng) - 0.5) * side;
  const double z = (unitInterval(rng) - 0.5) * side;
  return {x, y, z};
}

// The plan described at the top of this file.
EditPlan makePlan(const std::vector<SceneInstance>& instances, std::size_t objects, std::size_t moves, int repeat,
                  std::uint64_t seed, double side) {
  const std::size_t n = instances.size();
  std::mt19937_64 rng(seed);
  EditPlan plan;
  std::vector<Affine> current;
  for (const SceneInstance& i : instances) current.push_back(i.world_from_object);
  std::vector<std::uint32_t> ids(n);
  for (int r = 0; r < repeat; ++r) {
    std::iota(ids.begin(), ids.end(), 0u);
    for (std::size_t j = 0; j < moves; ++j) std::swap(ids[j], ids[j + rng() % (n - j)]);
    std::vector<Move> step;
    for (std::size_t j = 0; j < moves; ++j) {
      step.push_back({ids[j], randomDelta(rng, side)});
      current[ids[j]].translation += step.back().delta_ws;
    }
    plan.moves.push_back(std::move(step));
  }
  for (int r = 0; r < repeat; ++r) {
    const auto object = static_cast<std::uint32_t>(rng() % objects);
    Affine placed = current[rng() % n];
    placed.translation += randomDelta(rng, side);
    plan.adds.push_back({object, placed});
  }
  return plan;
}

/// Figures of one structure on the plan.
struct Figures {
  std::vector<double> update_ms, add_ms, remove_ms;
  double trace_ms = 0.0;
  std::uint64_t hits = 0;
};

// Replays the plan on `s` (setTransform, add, remove, commit, trace): the same loop for every
// structure. Each timed interval runs from the first edit call to the end of the commit.
template <class Structure>
Figures replay(Structure& s, const EditPlan& plan, std::vector<Affine> current, tbb::task_arena& arena,
               std::span<const Ray> rays) {
  Figures f;
  arena.execute([&] {
    for (const std::vector<Move>& step : plan.moves) {
      const Stopwatch watch;
      for (const Move& m : step) {
        current[m.instance].translation += m.delta_ws;
        s.setTransform(m.instance, current[m.instance]);
      }
      s.commit();
      f.update_ms.push_back(watch.ms());
    }
  });
  // Primary rays right after the moves (median of three runs).
  std::vector<double> trace_ms;
  for (int k = 0; k < 3; ++k) {
    const TraceTiming t = s.trace(arena, rays);
    trace_ms.push_back(t.time.wall_ms);
    f.hits = t.hits;
  }
  f.trace_ms = median(trace_ms);
  arena.execute([&] {
    for (const AddEdit& add : plan.adds) {
      const Stopwatch add_watch;
      const std::uint32_t id = s.add(add.object, add.world_from_object);
      s.commit();
      f.add_ms.push_back(add_watch.ms());
      const Stopwatch remove_watch;
      s.remove(id);
      s.commit();
      f.remove_ms.push_back(remove_watch.ms());
    }
  });
  return f;
}

/// Ours: a flat SceneGraph (every instance under the root) observed by a SceneTracer.
class Ours {
 public:
  Ours(const Scene& scene, TopLevelUpdate update) {
    for (std::uint32_t i = 0; i < scene.objectCount(); ++i)
      objects_.push_back(graph_.library().add(scene.objectName(i), scene.object(i)));
    for (const SceneInstance& instance : scene.instances())
      nodes_.push_back(graph_.addInstance(kRootNode, objects_[instance.object], instance.world_from_object));
    graph_.commit();
    TopLevelConfig config;
    config.update = update;
    const Stopwatch watch;
    tracer_ = std::make_unique<SceneTracer>(graph_, config);
    top_build_ms_ = watch.ms();
  }
  [[nodiscard]] double topBuildMs() const { return top_build_ms_; }
  [[nodiscard]] SceneTracer& tracer() { return *tracer_; }

  void setTransform(std::uint32_t instance, const Affine& world_from_object) {
    graph_.setTransform(nodes_[instance], world_from_object);
  }
  std::uint32_t add(std::uint32_t object, const Affine& world_from_object) {
    nodes_.push_back(graph_.addInstance(kRootNode, objects_[object], world_from_object));
    return static_cast<std::uint32_t>(nodes_.size() - 1);
  }
  void remove(std::uint32_t instance) { graph_.remove(nodes_[instance]); }
  void commit() { graph_.commit(); }
  TraceTiming trace(tbb::task_arena& arena, std::span<const Ray> rays) {
    std::vector<Hit> hits(rays.size());
    TraceTiming t;
    t.time = timeIt(arena.max_concurrency(), [&] { arena.execute([&] { tracer_->intersect(rays, hits); }); });
    for (const Hit& h : hits) t.hits += h.valid() ? 1u : 0u;
    return t;
  }
  /// Instance index of a hit's node id (kInvalidId for a miss).
  [[nodiscard]] std::uint32_t instanceOf(const Hit& h) const {
    if (!h.valid()) return kInvalidId;
    const auto it = std::find(nodes_.begin(), nodes_.end(), h.instance_id);
    return it == nodes_.end() ? kInvalidId : static_cast<std::uint32_t>(it - nodes_.begin());
  }

 private:
  SceneGraph graph_;
  std::vector<ObjectId> objects_;
  std::vector<NodeId> nodes_;  ///< by instance index (plan order)
  std::unique_ptr<SceneTracer> tracer_;
  double top_build_ms_ = 0.0;
};

#if DUPLEX_BENCH_HAVE_EMBREE
/// Embree's two-level scene with the loop's interface.
class Embree {
 public:
  Embree(EmbreeDevice& device, std::span<const TriangleMesh* const> meshes, std::span<const EmbreeInstanceDesc> instances,
         EmbreeTopLevelMode mode)
      : scene_(device, meshes, instances, mode) {}
  [[nodiscard]] const EmbreeTwoLevel& scene() const { return scene_; }
  void setTransform(std::uint32_t instance, const Affine& a) { scene_.setTransform(instance, a); }
  std::uint32_t add(std::uint32_t object, const Affine& a) { return scene_.addInstance(object, a); }
  void remove(std::uint32_t instance) { scene_.removeInstance(instance); }
  void commit() { scene_.commit(); }
  TraceTiming trace(tbb::task_arena& arena, std::span<const Ray> rays) {
    return timeTrace(arena, rays, [this](const Ray& r) { return scene_.intersect(r).valid(); });
  }

 private:
  EmbreeTwoLevel scene_;
};
#endif

double mraysPerS(std::size_t rays, double ms) { return ms > 0.0 ? static_cast<double>(rays) / (ms * 1e3) : 0.0; }

void putFigures(nlohmann::ordered_json& out, const std::string& prefix, const Figures& f, std::size_t rays) {
  out[prefix + "update_ms_median"] = median(f.update_ms);
  out[prefix + "update_ms_max"] = f.update_ms.empty() ? 0.0 : *std::max_element(f.update_ms.begin(), f.update_ms.end());
  out[prefix + "add_ms_median"] = median(f.add_ms);
  out[prefix + "remove_ms_median"] = median(f.remove_ms);
  out[prefix + "mrays_per_s"] = mraysPerS(rays, f.trace_ms);
  out[prefix + "hits"] = f.hits;
}

}  // namespace

struct UpdateOptions {
  std::string scene;
  std::string moves = "1";
  int repeat = 50;
  std::uint64_t seed = 1;
  int threads = 2;
  std::uint32_t primary = 512;
  int build_repeat = 3;
};

namespace {

// "1" or "1%" (of the instances, at least 1).
std::size_t parseMoves(const std::string& text, std::size_t instances) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw InvalidArgument("--moves '" + text + "': expected a count or a percentage such as 1%");
  }
  const bool percent = used < text.size() && text.substr(used) == "%";
  if ((used != text.size() && !percent) || !(value > 0.0))
    throw InvalidArgument("--moves '" + text + "': expected a positive count or a percentage such as 1%");
  const double count = percent ? std::round(value * static_cast<double>(instances) / 100.0) : value;
  const std::size_t m = std::max<std::size_t>(1, static_cast<std::size_t>(count));
  if (m > instances)
    throw InvalidArgument("--moves " + text + " exceeds the scene's " + std::to_string(instances) + " instances");
  return m;
}

}  // namespace

nlohmann::ordered_json run(const UpdateOptions& options) {
  tbb::task_arena arena(options.threads);
  SceneLoadReport report;
  Scene scene;
  arena.execute([&] { scene = loadScene(options.scene, {}, &report); });
  const std::size_t n = scene.instances().size();
  if (n == 0) throw InvalidArgument(options.scene + ": no instances to move");
  const Box bounds = scene.worldBounds();
  const double side = 0.05 * glm::length(glm::dvec3(bounds.hi) - glm::dvec3(bounds.lo));
  const std::size_t moves = parseMoves(options.moves, n);
  const EditPlan plan = makePlan(scene.instances(), scene.objectCount(), moves, options.repeat, options.seed, side);
  std::vector<Affine> initial;
  for (const SceneInstance& i : scene.instances()) initial.push_back(i.world_from_object);
  const std::vector<Ray> rays = primaryRays(bounds, options.primary, options.primary);

  nlohmann::ordered_json out;
  out["scene"] = options.scene;
  out["objects"] = scene.objectCount();
  out["instances"] = n;
  out["triangles"] = report.triangles;
  out["threads"] = options.threads;
  out["seed"] = options.seed;
  out["moves"] = moves;
  out["moves_spec"] = options.moves;
  out["repeat"] = options.repeat;
  out["move_cube_side"] = side;
  out["primary_rays"] = rays.size();

  // Ours, incremental.
  std::cerr << "ours: incremental top level\n";
  std::unique_ptr<Ours> ours;
  arena.execute([&] { ours = std::make_unique<Ours>(scene, TopLevelUpdate::Incremental); });
  out["build_ms"] = report.build_ms + ours->topBuildMs();
  out["bottom_build_ms"] = report.build_ms;
  out["top_build_ms"] = ours->topBuildMs();
  const Figures incremental = replay(*ours, plan, initial, arena, rays);
  putFigures(out, "", incremental, rays.size());
  const TopLevelStats stats = ours->tracer().stats();
  out["top_level_full_rebuilds"] = stats.full_rebuilds;
  out["top_level_subtree_rebuilds"] = stats.subtree_rebuilds;
  // The same tree rebuilt from scratch: what the incremental commits cost the tracing.
  std::vector<double> rebuild_ms;
  for (int k = 0; k < 3; ++k) {
    const Stopwatch watch;
    arena.execute([&] { ours->tracer().rebuild(); });
    rebuild_ms.push_back(watch.ms());
  }
  out["top_rebuild_ms_median"] = median(rebuild_ms);
  std::vector<double> fresh_ms;
  for (int k = 0; k < 3; ++k) fresh_ms.push_back(ours->trace(arena, rays).time.wall_ms);
  out["mrays_per_s_fresh"] = mraysPerS(rays.size(), median(fresh_ms));
  out["trace_slowdown_pct"] = 100.0 * (incremental.trace_ms / median(fresh_ms) - 1.0);

  // Ours, full top-level rebuild on every commit (the paper's method).
  {
    std::cerr << "ours: full top-level rebuild per commit\n";
    std::unique_ptr<Ours> full;
    arena.execute([&] { full = std::make_unique<Ours>(scene, TopLevelUpdate::FullRebuild); });
    const Figures f = replay(*full, plan, initial, arena, rays);
    out["full_rebuild_ms_median"] = median(f.update_ms);
    out["full_rebuild_add_ms_median"] = median(f.add_ms);
    out["full_rebuild_remove_ms_median"] = median(f.remove_ms);
    out["full_rebuild_mrays_per_s"] = mraysPerS(rays.size(), f.trace_ms);
  }

#if DUPLEX_BENCH_HAVE_EMBREE
  std::vector<const TriangleMesh*> meshes;
  for (std::uint32_t i = 0; i < scene.objectCount(); ++i) {
    const auto* mesh_object = dynamic_cast<const MeshObject*>(scene.object(i).get());
    if (!mesh_object) throw InvalidArgument(options.scene + ": object " + scene.objectName(i) + " is not a mesh");
    meshes.push_back(&mesh_object->mesh());
  }
  std::vector<EmbreeInstanceDesc> instances;
  for (const SceneInstance& i : scene.instances()) instances.push_back({i.object, i.world_from_object});
  EmbreeDevice device(options.threads, "");
  for (const EmbreeTopLevelMode mode : {EmbreeTopLevelMode::Default, EmbreeTopLevelMode::DynamicLow}) {
    const std::string prefix = mode == EmbreeTopLevelMode::Default ? "embree_" : "embree_dynamic_low_";
    std::cerr << "embree: top level " << toString(mode) << "\n";
    std::vector<double> build_ms, objects_ms, top_ms;
    std::unique_ptr<Embree> embree;
    for (int b = 0; b < options.build_repeat; ++b) {
      embree.reset();
      arena.execute([&] { embree = std::make_unique<Embree>(device, meshes, instances, mode); });
      const EmbreeTwoLevelBuildTimes& t = embree->scene().buildTimes();
      objects_ms.push_back(t.objects_ms);
      top_ms.push_back(t.top_ms);
      build_ms.push_back(t.objects_ms + t.top_ms);
    }
    out[prefix + "build_ms"] = median(build_ms);
    out[prefix + "build_objects_ms"] = median(objects_ms);
    out[prefix + "build_top_ms"] = median(top_ms);
    const Figures f = replay(*embree, plan, initial, arena, rays);
    putFigures(out, prefix, f, rays.size());
    if (mode == EmbreeTopLevelMode::Default) {
      // Both replayed the same plan: the same instance and triangle should be hit almost everywhere
      // (edges and float rounding differ).
      std::vector<Hit> ours_hits(rays.size());
      arena.execute([&] { ours->tracer().intersect(rays, ours_hits); });
      std::size_t same = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        const Hit e = embree->scene().intersect(rays[i]);
        const Hit& o = ours_hits[i];
        same += ours->instanceOf(o) == e.instance_id && o.prim_id == e.prim_id;
      }
      out["agreement_with_embree"] = static_cast<double>(same) / static_cast<double>(rays.size());
    }
  }
  out["embree_update_over_ours"] = out["embree_update_ms_median"].get<double>() / out["update_ms_median"].get<double>();
#endif
  out["machine"] = machineInfo();
  return out;
}

}  // namespace duplex::bench

int main(int argc, char** argv) {
  duplex::bench::UpdateOptions options;
  CLI::App app{"Update benchmark: moves, adds and removes instances of a scene-json-v1 scene and times the commits "
               "(ours incremental, ours full rebuild, Embree default and dynamic/low)",
               "duplex_bench_update"};
  app.add_option("--scene", options.scene, "scene-json-v1 file")->required();
  app.add_option("--moves", options.moves, "Instances moved per commit: a count or a percentage (e.g. 1%)");
  app.add_option("--repeat", options.repeat, "Commits per measurement (median reported)")->check(CLI::Range(1, 1000000));
  app.add_option("--seed", options.seed, "Seed of the edit plan");
  app.add_option("--threads", options.threads, "Threads for builds, commits and tracing")->check(CLI::Range(1, 4096));
  app.add_option("--primary", options.primary, "Primary rays: W x W image")->check(CLI::Range(1u, 8192u));
  app.add_option("--build-repeat", options.build_repeat, "Full builds timed per structure")->check(CLI::Range(1, 100));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    std::cout << duplex::bench::run(options).dump() << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_update: error: " << e.what() << '\n';
    return 1;
  }
}
