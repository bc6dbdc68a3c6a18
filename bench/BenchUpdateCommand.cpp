#include "BenchUpdateCommand.h"

#include "LoadScene.h"
#include "WorkerThreads.h"

#include "BenchBuild.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/objects/MeshObjectFile.h>
#include <duplex/objects/MeshTypes.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeTwoLevel.h"
#endif

#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include <unistd.h>

namespace duplex::cli {
namespace {

using bench::median;
using bench::Stopwatch;
using bench::TraceTiming;

struct Move {
  std::uint32_t instance;  ///< index into the benchmark's instance list
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

// A fresh folder for the prepared library's files: the system's temporary folder, named by process
// id and a counter so that concurrent runs do not share one.
// Removed with everything in it when the guard goes out of scope, also when a save or load throws.
class PreparedLibraryDir {
 public:
  PreparedLibraryDir() {
    const std::filesystem::path base = std::filesystem::temp_directory_path();
    for (int k = 0;; ++k) {
      path_ = base / ("duplex-bench-library-" + std::to_string(::getpid()) + "-" + std::to_string(k));
      if (std::filesystem::create_directory(path_)) return;
    }
  }
  PreparedLibraryDir(const PreparedLibraryDir&) = delete;
  PreparedLibraryDir& operator=(const PreparedLibraryDir&) = delete;
  ~PreparedLibraryDir() {
    std::error_code ignored;  // a leftover temporary folder is not worth failing the benchmark for
    std::filesystem::remove_all(path_, ignored);
  }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

double unitInterval(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

glm::dvec3 randomDelta(std::mt19937_64& rng, double side) {
  const double x = (unitInterval(rng) - 0.5) * side;
  const double y = (unitInterval(rng) - 0.5) * side;
  const double z = (unitInterval(rng) - 0.5) * side;
  return {x, y, z};
}

// The plan described in BenchUpdateCommand.h.
EditPlan makePlan(const std::vector<Affine>& world_from_object, std::size_t objects, std::size_t moves, int repeat,
                  std::uint64_t seed, double side) {
  const std::size_t n = world_from_object.size();
  std::mt19937_64 rng(seed);
  EditPlan plan;
  std::vector<Affine> current = world_from_object;
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

/// Ours: a copy of the document's node tree (sharing its object library) observed by a
/// SceneTracer. Instances are addressed by their index in the benchmark's instance list.
class Ours {
 public:
  Ours(const SceneGraph& source, std::span<const NodeId> instances, TopLevelUpdate update)
      : graph_(source.sharedLibrary()) {
    copyChildren(source, kRootNode, kRootNode);
    graph_.commit();
    for (const NodeId node : instances) {
      nodes_.push_back(copy_.at(node));
      const NodeId parent = graph_.node(nodes_.back()).parent;
      parent_from_world_.push_back(parent == kRootNode ? std::nullopt
                                                       : std::optional(graph_.worldTransform(parent).inverse()));
    }
    TopLevelConfig config;
    config.update = update;
    const Stopwatch watch;
    tracer_ = std::make_unique<SceneTracer>(graph_, config);
    top_build_ms_ = watch.ms();
  }
  [[nodiscard]] double topBuildMs() const { return top_build_ms_; }
  [[nodiscard]] SceneTracer& tracer() { return *tracer_; }

  void setTransform(std::uint32_t instance, const Affine& world_from_object) {
    // Children of the root (every instance of scene-json-v1) take the world transform as it is.
    const std::optional<Affine>& parent_from_world = parent_from_world_[instance];
    graph_.setTransform(nodes_[instance],
                        parent_from_world ? *parent_from_world * world_from_object : world_from_object);
  }
  std::uint32_t add(std::uint32_t object, const Affine& world_from_object) {
    nodes_.push_back(graph_.addInstance(kRootNode, object, world_from_object));
    parent_from_world_.emplace_back();
    return static_cast<std::uint32_t>(nodes_.size() - 1);
  }
  void remove(std::uint32_t instance) { graph_.remove(nodes_[instance]); }
  void commit() { graph_.commit(); }
  TraceTiming trace(tbb::task_arena& arena, std::span<const Ray> rays) { return traceWith(*tracer_, arena, rays); }
  /// A second tracer on the same graph, its top level built from scratch now.
  [[nodiscard]] std::unique_ptr<SceneTracer> freshTracer() { return std::make_unique<SceneTracer>(graph_); }
  static TraceTiming traceWith(const SceneTracer& tracer, tbb::task_arena& arena, std::span<const Ray> rays) {
    std::vector<Hit> hits(rays.size());
    TraceTiming t;
    t.time = bench::timeIt(arena.max_concurrency(), [&] { arena.execute([&] { tracer.intersect(rays, hits); }); });
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
  // The subtree below `source_parent`, added below `copy_parent` (depth first, sibling order).
  void copyChildren(const SceneGraph& source, NodeId source_parent, NodeId copy_parent) {
    for (const NodeId child : source.children(source_parent)) {
      const NodeInfo info = source.node(child);
      const std::string name(info.name);
      NodeId copy = kInvalidNode;
      switch (info.kind) {
        case NodeKind::Group: copy = graph_.addGroup(copy_parent, name); break;
        case NodeKind::Transform: copy = graph_.addTransform(copy_parent, info.local, name); break;
        case NodeKind::Instance:
          copy = graph_.addInstance(copy_parent, info.object, info.local, name, info.mask);
          break;
      }
      if (!info.visible) graph_.setVisible(copy, false);
      if (copy_.size() <= child) copy_.resize(std::size_t{child} + 1, kInvalidNode);
      copy_[child] = copy;
      copyChildren(source, child, copy);
    }
  }

  SceneGraph graph_;
  std::vector<NodeId> copy_;   ///< source node id -> node id here
  std::vector<NodeId> nodes_;  ///< by instance index (plan order, then added ones)
  /// By instance index: parent_from_world of instances below transform nodes (parents never move).
  std::vector<std::optional<Affine>> parent_from_world_;
  std::unique_ptr<SceneTracer> tracer_;
  double top_build_ms_ = 0.0;
};

#if DUPLEX_BENCH_HAVE_EMBREE
/// Embree's two-level scene with the loop's interface.
class Embree {
 public:
  Embree(bench::EmbreeDevice& device, std::span<const TriangleMesh* const> meshes,
         std::span<const bench::EmbreeInstanceDesc> instances, bench::EmbreeTopLevelMode mode,
         RTCBuildQuality object_quality = RTC_BUILD_QUALITY_MEDIUM)
      : scene_(device, meshes, instances, mode, object_quality) {}
  [[nodiscard]] const bench::EmbreeTwoLevel& scene() const { return scene_; }
  void setTransform(std::uint32_t instance, const Affine& a) { scene_.setTransform(instance, a); }
  std::uint32_t add(std::uint32_t object, const Affine& a) { return scene_.addInstance(object, a); }
  void remove(std::uint32_t instance) { scene_.removeInstance(instance); }
  void commit() { scene_.commit(); }
  TraceTiming trace(tbb::task_arena& arena, std::span<const Ray> rays) {
    return bench::timeTrace(arena, rays, [this](const Ray& r) { return scene_.intersect(r).valid(); });
  }

 private:
  bench::EmbreeTwoLevel scene_;
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
    throw InvalidArgument("--moves " + text + " exceeds the scene's " + std::to_string(instances) +
                          " visible instances");
  return m;
}

}  // namespace

nlohmann::ordered_json runBenchUpdate(const BenchUpdateOptions& options) {
  if (options.repeat < 1) throw InvalidArgument("--repeat must be at least 1");
  if (options.baseline_repeat < 0) throw InvalidArgument("--baseline-repeat must not be negative");
  WorkerThreads workers(options.threads);
  tbb::task_arena& arena = workers.arena;
  const int threads = workers.count;

  std::optional<SceneDocument> doc;
  arena.execute([&] { doc.emplace(loadDocumentNamed(options.scene, documentOptions(options.structure))); });
  const SceneGraph& graph = *doc->graph;
  const ObjectLibrary& library = graph.library();

  // The benchmark's instances: the visible ones, in document order.
  const std::vector<NodeId> instances = visibleInstances(*doc, options.scene);
  std::vector<Affine> initial;
  for (const NodeId node : instances) initial.push_back(graph.worldTransform(node));
  const std::size_t n = instances.size();
  const Box bounds = visibleWorldBounds(*doc);
  const double side = 0.05 * glm::length(glm::dvec3(bounds.hi) - glm::dvec3(bounds.lo));
  const std::size_t moves = parseMoves(options.moves, n);
  const EditPlan plan = makePlan(initial, library.size(), moves, options.repeat, options.seed, side);
  const std::vector<Ray> rays = primaryRays(bounds, options.primary, options.primary);

  nlohmann::ordered_json out;
  out["scene"] = options.scene.string();
  out["format"] = doc->format;
  out["objects"] = library.size();
  out["instances"] = n;
  out["triangles"] = doc->figures.count("triangles");
  out["threads"] = threads;
  out["seed"] = options.seed;
  out["moves"] = moves;
  out["moves_spec"] = options.moves;
  out["repeat"] = options.repeat;
  out["move_cube_side"] = side;
  out["primary_rays"] = rays.size();

  // Ours, incremental.
  std::cerr << "ours: incremental top level\n";
  std::unique_ptr<Ours> ours;
  arena.execute([&] { ours = std::make_unique<Ours>(graph, instances, TopLevelUpdate::Incremental); });
  out["build_ms"] = doc->figures.build_ms + ours->topBuildMs();
  out["bottom_build_ms"] = doc->figures.build_ms;
  out["top_build_ms"] = ours->topBuildMs();
  // The library's objects, held while the full builds below and Embree use their meshes. The
  // benchmark rebuilds meshes and compares them with Embree's triangle geometry: a scene with other
  // object types is refused, with or without Embree, so that every build measures the same work.
  std::vector<std::shared_ptr<const Object>> held;
  std::vector<const MeshObject*> mesh_objects;
  for (ObjectId i = 0; i < library.size(); ++i) {
    held.push_back(library.get(i));
    const auto* m = dynamic_cast<const MeshObject*>(held.back().get());
    if (!m)
      throw InvalidArgument(options.scene.string() + ": object '" + library.name(i) + "' is of type " +
                            library.typeName(i) + ": bench update measures scenes of mesh objects only");
    mesh_objects.push_back(m);
  }
  // Which bottom-level structure the scene's mesh objects have (the scene file may choose per
  // object): "bvh", "kdtree" or "mixed", with the count of each.
  {
    std::map<std::string, std::size_t> counts;
    for (const MeshObject* m : mesh_objects) ++counts[std::string(toString(m->structure()))];
    out["bottom_structure"] = counts.size() == 1 ? counts.begin()->first : counts.empty() ? "none" : "mixed";
    out["bottom_structure_counts"] = counts;
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  // Embree's side: the same meshes and instances, one device for the whole run.
  std::vector<const TriangleMesh*> meshes;
  for (const MeshObject* mesh_object : mesh_objects) meshes.push_back(&mesh_object->mesh());
  std::vector<bench::EmbreeInstanceDesc> embree_instances;
  for (std::size_t i = 0; i < n; ++i) embree_instances.push_back({graph.node(instances[i]).object, initial[i]});
  bench::EmbreeDevice device(threads, "");
  // Embree's full build with the default top-level flags, as timed in rounds below.
  std::vector<double> embree_build_ms, embree_objects_ms, embree_top_ms;
  // The same with object scenes of high quality (spatial splits: the BVH counterpart of our
  // kd-trees' clipped references), for scale: the goal is judged against the default above.
  std::vector<double> embree_high_build_ms;
#endif

  // Full builds, ours and Embree's, in interleaved rounds: per round (--build-repeat rounds) ours
  // warm, ours from the prepared library and Embree's two-level build, ours first in even rounds and
  // Embree first in odd ones, so that a burst of load on a shared machine falls on both sides of
  // a round's ratios; the medians of the per-round ratios are what the full-build goal is judged by.
  // Ours warm: every mesh object rebuilt from its mesh in parallel (as ObjectLibrary::buildAll
  // builds), then a top level from scratch; build_ms above is the first, cold build of the scene
  // load. Ours from a prepared library (the paper's point: objects taken from a library saved
  // beforehand need no build): every mesh object's structure written once to a temporary folder,
  // then each round reads them back in parallel (loadMeshObject: checks, checksums, leaf blocks
  // derived from the tree) and builds a fresh top level. The files were just written, so they are
  // read from the page cache, as in an application that opens the same library again.
  {
    const PreparedLibraryDir library_dir;
    const std::filesystem::path& dir = library_dir.path();
    std::vector<std::filesystem::path> files(mesh_objects.size());
    std::uintmax_t bytes = 0;
    for (std::size_t k = 0; k < mesh_objects.size(); ++k) {
      files[k] = dir / (std::to_string(k) + std::string(mesh_objects[k]->preparedExtension()));
      saveMeshObject(*mesh_objects[k], files[k]);
      bytes += std::filesystem::file_size(files[k]);
    }
    // One full build: every mesh object made by make(k, mesh) in parallel, then a fresh top level;
    // returns the whole and the bottom-level part (ms).
    const auto fullBuild = [&](const auto& make) {
      std::vector<std::shared_ptr<const MeshObject>> made(mesh_objects.size());
      std::unique_ptr<SceneTracer> fresh;
      const Stopwatch watch;
      arena.execute([&] {
        tbb::parallel_for(std::size_t{0}, mesh_objects.size(), [&](std::size_t k) {
          // A non-owning pointer: the library keeps the mesh alive.
          made[k] = make(
              k, std::shared_ptr<const TriangleMesh>(std::shared_ptr<const TriangleMesh>{}, &mesh_objects[k]->mesh()));
        });
      });
      const double bottom_ms = watch.ms();
      arena.execute([&] { fresh = ours->freshTracer(); });
      return std::pair{watch.ms(), bottom_ms};
    };
    // Each object rebuilt as the structure it has, with --structure's parameters (entries that
    // chose their own BVH parameters are rebuilt with these).
    const MeshBuildConfig rebuild =
        options.structure.empty() ? MeshBuildConfig{} : parseMeshStructureChoice(options.structure);
    const auto warm = [&](std::size_t k, std::shared_ptr<const TriangleMesh> mesh) {
      MeshBuildConfig config = rebuild;
      config.structure = mesh_objects[k]->structure();
      return std::make_shared<const MeshObject>(std::move(mesh), config);
    };
    const auto prepared = [&](std::size_t k, std::shared_ptr<const TriangleMesh> mesh) {
      return loadMeshObject(files[k], std::move(mesh));
    };
    std::vector<double> warm_ms, warm_bottom_ms, prepared_ms, prepared_bottom_ms, warm_ratio, prepared_ratio,
        high_ratio;
    for (int round = 0; round < options.build_repeat; ++round) {
      const auto oursRound = [&] {
        const auto [w, wb] = fullBuild(warm);
        warm_ms.push_back(w);
        warm_bottom_ms.push_back(wb);
        const auto [p, pb] = fullBuild(prepared);
        prepared_ms.push_back(p);
        prepared_bottom_ms.push_back(pb);
      };
#if DUPLEX_BENCH_HAVE_EMBREE
      const auto embreeRound = [&] {
        std::unique_ptr<Embree> embree;
        arena.execute([&] {
          embree = std::make_unique<Embree>(device, meshes, embree_instances, bench::EmbreeTopLevelMode::Default);
        });
        const bench::EmbreeTwoLevelBuildTimes& t = embree->scene().buildTimes();
        embree_objects_ms.push_back(t.objects_ms);
        embree_top_ms.push_back(t.top_ms);
        embree_build_ms.push_back(t.objects_ms + t.top_ms);
        embree.reset();  // the high-quality build is timed without the default scene in memory
        arena.execute([&] {
          embree = std::make_unique<Embree>(device, meshes, embree_instances, bench::EmbreeTopLevelMode::Default,
                                            RTC_BUILD_QUALITY_HIGH);
        });
        const bench::EmbreeTwoLevelBuildTimes& h = embree->scene().buildTimes();
        embree_high_build_ms.push_back(h.objects_ms + h.top_ms);
      };
      if (round % 2 == 0) {
        oursRound();
        embreeRound();
      } else {
        embreeRound();
        oursRound();
      }
      warm_ratio.push_back(warm_ms.back() / embree_build_ms.back());
      prepared_ratio.push_back(prepared_ms.back() / embree_build_ms.back());
      high_ratio.push_back(warm_ms.back() / embree_high_build_ms.back());
#else
      oursRound();
#endif
    }
    out["full_build_rounds"] = options.build_repeat;
    out["build_ms_warm_median"] = median(warm_ms);
    out["bottom_build_ms_warm_median"] = median(warm_bottom_ms);
    out["prepared_build_ms_median"] = median(prepared_ms);
    out["prepared_bottom_load_ms_median"] = median(prepared_bottom_ms);
    out["prepared_library_bytes"] = bytes;
    for (const auto& [key, ratios] : {std::pair{std::string("full_build_ratio"), &warm_ratio},
                                      std::pair{std::string("prepared_build_ratio"), &prepared_ratio},
                                      std::pair{std::string("full_build_ratio_vs_embree_high"), &high_ratio}}) {
      if (ratios->empty()) continue;
      out[key + "_median"] = median(*ratios);
      out[key + "_min"] = *std::min_element(ratios->begin(), ratios->end());
      out[key + "_max"] = *std::max_element(ratios->begin(), ratios->end());
    }
  }
  const Figures incremental = replay(*ours, plan, initial, arena, rays);
  // The baselines replay a prefix of the same plan.
  EditPlan baseline_plan = plan;
  const int baseline_repeat =
      options.baseline_repeat > 0 ? std::min(options.baseline_repeat, options.repeat) : options.repeat;
  baseline_plan.moves.resize(static_cast<std::size_t>(baseline_repeat));
  baseline_plan.adds.resize(static_cast<std::size_t>(baseline_repeat));
  out["baseline_repeat"] = baseline_repeat;
  putFigures(out, "", incremental, rays.size());
  const TopLevelStats stats = ours->tracer().stats();
  out["top_level_full_rebuilds"] = stats.full_rebuilds;
  out["top_level_subtree_rebuilds"] = stats.subtree_rebuilds;
  // What the incremental commits cost the tracing: the incremental tree against a tree built from
  // scratch over the same instances, traced alternately on one thread (8 pairs, each tree first in half of them; the
  // median of the per-pair thread CPU time ratios), and the instance visits per ray of both (deterministic,
  // single-threaded over the same rays).
  {
    std::unique_ptr<SceneTracer> fresh;
    arena.execute([&] { fresh = ours->freshTracer(); });
    // One thread: its own CPU time is what the load of a shared machine disturbs least.
    tbb::task_arena single(1);
    std::vector<double> ratios, inc_ms, fresh_pair_ms;
    for (int k = 0; k < 8; ++k) {
      // Alternate which tree goes first, so that neither always finds the caches as the other left them.
      TraceTiming a, b;
      if (k % 2 == 0) {
        a = Ours::traceWith(ours->tracer(), single, rays);
        b = Ours::traceWith(*fresh, single, rays);
      } else {
        b = Ours::traceWith(*fresh, single, rays);
        a = Ours::traceWith(ours->tracer(), single, rays);
      }
      ratios.push_back(a.time.cpu_ms / b.time.cpu_ms);
      inc_ms.push_back(a.time.wall_ms);
      fresh_pair_ms.push_back(b.time.wall_ms);
    }
    out["trace_slowdown_paired_pct"] = 100.0 * (median(ratios) - 1.0);
    out["mrays_per_s_paired"] = mraysPerS(rays.size(), median(inc_ms));
    out["mrays_per_s_fresh_paired"] = mraysPerS(rays.size(), median(fresh_pair_ms));
    auto visits = [&](const SceneTracer& t) {
      QueryContext ctx;
      for (const Ray& r : rays) (void)t.intersect(r, ctx);
      return static_cast<double>(ctx.stats.instance_visits) / static_cast<double>(rays.size());
    };
    out["instance_visits_per_ray"] = visits(ours->tracer());
    out["instance_visits_per_ray_fresh"] = visits(*fresh);
    // The same comparison by the top level's SAH cost (deterministic, independent of the load).
    out["top_level_sah_cost"] = ours->tracer().stats().tree.sah_cost;
    out["top_level_sah_cost_fresh"] = fresh->stats().tree.sah_cost;
    // Shape of both trees: the SAH cost is normalised by the root box's area, so a looser root can
    // hide a costlier tree; nodes and the root's extent say what the cost does not.
    for (const auto& [suffix, t] :
         {std::pair<std::string, const SceneTracer*>{"", &ours->tracer()}, {"_fresh", fresh.get()}}) {
      const KdTreeStats ts = t->stats().tree;
      const Box root = t->bounds();
      out["top_level_nodes" + suffix] = ts.nodes;
      out["top_level_empty_leaves" + suffix] = ts.empty_leaves;
      out["top_level_references" + suffix] = ts.references;
      out["top_level_max_depth" + suffix] = ts.max_depth;
      out["top_level_root_extent" + suffix] = {root.hi.x - root.lo.x, root.hi.y - root.lo.y, root.hi.z - root.lo.z};
    }
    // The incremental tree must answer exactly as the fresh one (same instance, triangle and t).
    std::vector<Hit> a(rays.size()), b(rays.size());
    arena.execute([&] {
      ours->tracer().intersect(rays, a);
      fresh->intersect(rays, b);
    });
    std::size_t same = 0;
    for (std::size_t i = 0; i < rays.size(); ++i)
      same +=
          a[i].instance_id == b[i].instance_id && a[i].prim_id == b[i].prim_id && (a[i].t == b[i].t || !a[i].valid());
    out["agreement_incremental_vs_fresh"] = static_cast<double>(same) / static_cast<double>(rays.size());
  }
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

  // Ours, full top-level rebuild on every commit (the paper's method). Kept: it replayed the same
  // (baseline) plan as Embree, so it is what Embree's hits are compared with.
  std::unique_ptr<Ours> full;
  {
    std::cerr << "ours: full top-level rebuild per commit\n";
    arena.execute([&] { full = std::make_unique<Ours>(graph, instances, TopLevelUpdate::FullRebuild); });
    const Figures f = replay(*full, baseline_plan, initial, arena, rays);
    out["full_rebuild_ms_median"] = median(f.update_ms);
    out["full_rebuild_add_ms_median"] = median(f.add_ms);
    out["full_rebuild_remove_ms_median"] = median(f.remove_ms);
    out["full_rebuild_mrays_per_s"] = mraysPerS(rays.size(), f.trace_ms);
  }

#if DUPLEX_BENCH_HAVE_EMBREE
  using bench::EmbreeTopLevelMode;
  for (const EmbreeTopLevelMode mode : {EmbreeTopLevelMode::Default, EmbreeTopLevelMode::DynamicLow}) {
    const std::string prefix = mode == EmbreeTopLevelMode::Default ? "embree_" : "embree_dynamic_low_";
    std::cerr << "embree: top level " << bench::toString(mode) << "\n";
    // The default flags' builds were timed in the rounds above, beside ours; the dynamic / low
    // quality top level's are timed here, --build-repeat times. The last scene replays the plan.
    const bool timed = mode == EmbreeTopLevelMode::Default;
    std::vector<double> build_ms, objects_ms, top_ms;
    if (timed) {
      build_ms = embree_build_ms;
      objects_ms = embree_objects_ms;
      top_ms = embree_top_ms;
    }
    std::unique_ptr<Embree> embree;
    for (int b = 0; b < (timed ? 1 : options.build_repeat); ++b) {
      embree.reset();
      arena.execute([&] { embree = std::make_unique<Embree>(device, meshes, embree_instances, mode); });
      if (timed) continue;
      const bench::EmbreeTwoLevelBuildTimes& t = embree->scene().buildTimes();
      objects_ms.push_back(t.objects_ms);
      top_ms.push_back(t.top_ms);
      build_ms.push_back(t.objects_ms + t.top_ms);
    }
    out[prefix + "build_ms"] = median(build_ms);
    out[prefix + "build_objects_ms"] = median(objects_ms);
    out[prefix + "build_top_ms"] = median(top_ms);
    if (timed && !embree_high_build_ms.empty()) out["embree_high_build_ms"] = median(embree_high_build_ms);
    const Figures f = replay(*embree, baseline_plan, initial, arena, rays);
    putFigures(out, prefix, f, rays.size());
    if (mode == EmbreeTopLevelMode::Default) {
      // Ours with full rebuilds replayed the same plan as Embree: the same instance and triangle
      // should be hit almost everywhere (edges and float rounding differ).
      std::vector<Hit> ours_hits(rays.size());
      arena.execute([&] { full->tracer().intersect(rays, ours_hits); });
      std::size_t same = 0;
      for (std::size_t i = 0; i < rays.size(); ++i) {
        const Hit e = embree->scene().intersect(rays[i]);
        const Hit& o = ours_hits[i];
        same += full->instanceOf(o) == e.instance_id && o.prim_id == e.prim_id;
      }
      out["agreement_with_embree"] = static_cast<double>(same) / static_cast<double>(rays.size());
    }
  }
  out["embree_update_over_ours"] = out["embree_update_ms_median"].get<double>() / out["update_ms_median"].get<double>();
#endif
  out["machine"] = bench::machineInfo(bench::thisBuild());
  return out;
}

}  // namespace duplex::cli
