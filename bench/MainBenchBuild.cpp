// The main benchmark's tracers and builds: our structures and Embree's at each thread count (see
// MainBenchParts.h).

#include "MainBenchParts.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/KdTree.h"

#include <algorithm>
#include <cctype>
#include <iostream>
#include <map>

namespace duplex::bench::main_detail {

namespace {

// "medium,leaf=4" -> "medium_leaf_4": a JSON key of letters, digits and underscores.
std::string keyOf(std::string_view text) {
  std::string key;
  for (const char c : text) key += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return key;
}

}  // namespace

std::string defaultStructureKey() {
  const BvhBuildConfig defaults = MeshBuildConfig{}.bvh;
  for (const BvhPreset p : {BvhPreset::Fast, BvhPreset::Medium, BvhPreset::High})
    if (BvhBuildConfig::preset(p) == defaults) return "bvh_" + std::string(toString(p));
  return "bvh_default";
}

std::vector<TracerDef> tracerDefs(const Options& options, bool with_embree) {
  std::vector<TracerDef> defs;
  const BvhBuildConfig default_bvh = MeshBuildConfig{}.bvh;
  for (const std::string& spec : options.structures) {
    TracerDef d;
    d.spec = spec;
    if (spec == "kdtree") {
      d.kind = TracerDef::Kind::KdTree;
      d.key = "kdtree";
    } else if (spec == "bvh" || spec.rfind("bvh:", 0) == 0) {
      // Overrides are joined by '/' on the command line (its lists are comma separated).
      std::string text = spec == "bvh" ? "medium" : spec.substr(4);
      d.key = "bvh_" + keyOf(text);
      std::replace(text.begin(), text.end(), '/', ',');
      d.bvh = BvhBuildConfig::parse(text);
      d.is_default = d.bvh == default_bvh;
    } else {
      throw InvalidArgument("--structures: '" + spec + "' is not kdtree, bvh or bvh:PRESET[/KEY=VALUE...]");
    }
    if (std::any_of(defs.begin(), defs.end(), [&](const TracerDef& e) { return e.key == d.key; })) continue;
    defs.push_back(d);
  }
  if (!with_embree) return defs;
  std::vector<std::string> builds = options.embree_builds;
  if (std::find(builds.begin(), builds.end(), "medium") == builds.end()) builds.insert(builds.begin(), "medium");
  for (const std::string& b : builds) {
    TracerDef d;
    d.kind = TracerDef::Kind::Embree;
    d.spec = "embree:" + b;
    d.key = "embree_" + b;
    if (b == "high") {
      d.embree_high = true;
    } else if (b == "robust") {
      d.embree_robust = true;
    } else if (b != "medium") {
      throw InvalidArgument("--embree-builds: '" + b + "' is not medium, high or robust");
    }
    if (std::none_of(defs.begin(), defs.end(), [&](const TracerDef& e) { return e.key == d.key; })) defs.push_back(d);
  }
  return defs;
}

nlohmann::json configJson(const KdBuildConfig& c) {
  return {{"heuristic", std::string(toString(c.heuristic))},
          {"traversal_cost", c.traversal_cost},
          {"intersection_cost", c.intersection_cost},
          {"empty_bonus", c.empty_bonus},
          {"max_depth", c.max_depth},
          {"max_leaf_size", c.max_leaf_size},
          {"parallel_threshold", c.parallel_threshold},
          {"clip_primitives", c.clip_primitives}};
}

nlohmann::json statsJson(const KdTreeStats& s) {
  return {{"nodes", s.nodes},
          {"inner_nodes", s.inner_nodes},
          {"leaves", s.leaves},
          {"empty_leaves", s.empty_leaves},
          {"references", s.references},
          {"max_depth", s.max_depth},
          {"avg_leaf_size", s.avg_leaf_size},
          {"sah_cost", s.sah_cost},
          {"bytes", s.bytes}};
}

int MeshBench::find(const std::string& key) const {
  for (std::size_t k = 0; k < defs_.size(); ++k)
    if (defs_[k].key == key && k < built_.size() && built_[k].available) return static_cast<int>(k);
  return -1;
}

std::vector<int> MeshBench::live() const {
  std::vector<int> out;
  for (std::size_t k = 0; k < built_.size(); ++k)
    if (built_[k].available) out.push_back(static_cast<int>(k));
  return out;
}

bool MeshBench::intersect(int k, const Ray& ray, Hit& hit) const {
  const Built& b = built_[static_cast<std::size_t>(k)];
  if (b.object) return b.object->intersect(ray, hit);
#if DUPLEX_BENCH_HAVE_EMBREE
  if (b.scene) return b.scene->intersect(ray, hit);
#endif
  return false;
}

bool MeshBench::occluded(int k, const Ray& ray) const {
  const Built& b = built_[static_cast<std::size_t>(k)];
  if (b.object) return b.object->occluded(ray);
#if DUPLEX_BENCH_HAVE_EMBREE
  if (b.scene) return b.scene->occluded(ray);
#endif
  return false;
}

TraceTiming MeshBench::timeTracer(int k, tbb::task_arena& arena, std::span<const Ray> rays, Query q) const {
  const Built& b = built_[static_cast<std::size_t>(k)];
  if (b.object) return timeQuery(arena, rays, *b.object, q);
#if DUPLEX_BENCH_HAVE_EMBREE
  if (b.scene) return timeQuery(arena, rays, *b.scene, q);
#endif
  return {};
}

Timing MeshBench::buildOne(int k, const TriangleMesh& mesh, const std::shared_ptr<const TriangleMesh>& shared,
                           int threads) {
  const TracerDef& d = defs_[static_cast<std::size_t>(k)];
  Built& b = built_[static_cast<std::size_t>(k)];
  if (d.ours()) {
    b.object.reset();
    return timeIt(threads, [&] {
      arenas_.get(threads).execute([&] {
        b.object = d.kind == TracerDef::Kind::KdTree ? std::make_unique<MeshObject>(shared, d.kd)
                                                     : std::make_unique<MeshObject>(shared, d.bvh);
      });
    });
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  b.scene.reset();
  return timeIt(threads, [&] {
    b.scene = std::make_unique<EmbreeMesh>(*embree_.device, mesh,
                                           d.embree_high ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM,
                                           d.embree_robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  });
#else
  (void)mesh;
  return {};
#endif
}

void MeshBench::addRatios(nlohmann::json& out, const std::string& section, const std::string& label,
                          const std::vector<double>& values) const {
  for (const char* ref_key : {kReferenceKey, "embree_high"}) {
    const int ref = find(ref_key);
    if (ref < 0) continue;
    const bool vs_medium = std::string(ref_key) == kReferenceKey;
    for (std::size_t k = 0; k < defs_.size(); ++k) {
      if (static_cast<int>(k) == ref || (!vs_medium && !defs_[k].ours()) || !std::isfinite(values[k])) continue;
      const nlohmann::json r = num(ratio(values[k], values[static_cast<std::size_t>(ref)]));
      const auto put = [&](const std::string& name) {
        nlohmann::json& to = out["ratios"][name][section];
        (label.empty() ? to : to[label]) = r;
      };
      put(defs_[k].key + "_vs_" + ref_key);
      if (defs_[k].is_default) put(std::string("vs_") + ref_key);
    }
  }
}

void MeshBench::build(const LoadedMesh& loaded, nlohmann::json& out) {
  const TriangleMesh& mesh = *loaded.mesh;
  const double triangles = static_cast<double>(mesh.triangleCount());
  const std::size_t n = defs_.size();
  built_.clear();
  built_.resize(n);
  // Wall ms per tracer and thread count; CPU ms (calling thread) for one thread only, with the
  // process's CPU ms next to it to check that one thread did all the work.
  std::vector<std::map<int, std::vector<double>>> ms(n), cpu_ms(n), process_cpu_ms(n);
  std::vector<int> ours, embree;
  for (std::size_t k = 0; k < n; ++k) (defs_[k].ours() ? ours : embree).push_back(static_cast<int>(k));
  const Stopwatch phase;
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (const int t : threads_) {
      auto buildGroup = [&](std::vector<int> group) {
        if (rep % 2 == 1) std::reverse(group.begin(), group.end());
        for (const int k : group) {
          Built& b = built_[static_cast<std::size_t>(k)];
          if (!b.available) continue;
          Timing time;
          try {
            time = buildOne(k, mesh, loaded.mesh, t);
          } catch (const std::exception& e) {
            // A structure this build cannot make (e.g. a preset not implemented yet) is listed with
            // the reason; a failure after a first success is a bug.
            if (rep != 0 || t != threads_.front()) throw;
            b = Built{};
            b.available = false;
            b.note = e.what();
            std::cerr << "  " << defs_[static_cast<std::size_t>(k)].key << ": skipped: " << e.what() << "\n";
            continue;
          }
          ms[k][t].push_back(time.wall_ms);
          if (t == 1) {
            cpu_ms[k][t].push_back(time.cpu_ms);
            process_cpu_ms[k][t].push_back(time.process_cpu_ms);
          }
        }
      };
      auto buildEmbree = [&] {
#if DUPLEX_BENCH_HAVE_EMBREE
        if (!haveEmbree() || embree.empty()) return;
        // A fresh device limited to t threads, the only one alive while it builds.
        for (const int k : embree) built_[static_cast<std::size_t>(k)].scene.reset();
        embree_.device.reset();
        embree_.device = std::make_unique<EmbreeDevice>(t, embree_.config);
        buildGroup(embree);
        for (const int k : embree) built_[static_cast<std::size_t>(k)].scene.reset();
        embree_.device.reset();
#endif
      };
      // Alternate the order between repetitions so that drift on the shared machine hits both sides.
      if (rep % 2 == 0) {
        buildGroup(ours);
        buildEmbree();
      } else {
        buildEmbree();
        buildGroup(ours);
      }
    }
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  // The scenes that are traced (untimed builds, on a device with the most threads).
  if (haveEmbree() && !embree.empty()) {
    embree_.device = std::make_unique<EmbreeDevice>(threads_.back(), embree_.config);
    for (const int k : embree)
      if (built_[static_cast<std::size_t>(k)].available) (void)buildOne(k, mesh, loaded.mesh, threads_.back());
  }
#endif
  std::cerr << "  builds: " << options_.repeat << " x " << threads_.size() << " thread counts in "
            << fmt(phase.ms() / 1e3, 1) << " s\n";

  // Per structure: what it is, its size and (ours) its tree's figures.
  std::vector<double> bytes_per_triangle(n, kNaN);
  nlohmann::json& structures = out["structures"];
  for (std::size_t k = 0; k < n; ++k) {
    const TracerDef& d = defs_[k];
    const Built& b = built_[k];
    nlohmann::json& j = structures[d.key];
    j["spec"] = d.spec;
    j["kind"] = d.kind == TracerDef::Kind::Bvh ? "bvh" : d.kind == TracerDef::Kind::KdTree ? "kdtree" : "embree";
    j["is_default"] = d.is_default;
    j["available"] = b.available;
    if (!b.available) {
      j["note"] = b.note;
      continue;
    }
    if (b.object) {
      bytes_per_triangle[k] = static_cast<double>(b.object->accelBytes()) / triangles;
      j["accel_bytes"] = b.object->accelBytes();
      j["memory_bytes"] = b.object->memoryBytes();
      if (d.kind == TracerDef::Kind::KdTree) {
        const KdTreeStats stats = b.object->tree().stats(d.kd.traversal_cost, d.kd.intersection_cost);
        j["config"] = configJson(d.kd);
        j["stats"] = statsJson(stats);
        j["nodes"] = stats.nodes;
        j["sah_cost"] = stats.sah_cost;
      } else {
        const WideBvh& bvh = b.object->bvh();
        std::uint64_t leaves = 0, references = 0;
        for (const BvhNode8& node : bvh.nodes)
          for (const std::uint32_t c : node.child)
            if (BvhRef::isLeaf(c)) {
              ++leaves;
              references += BvhRef::leafCount(c);
            }
        if (BvhRef::isLeaf(bvh.root)) {
          leaves = 1;
          references = BvhRef::leafCount(bvh.root);
        }
        j["config"] = d.bvh.toString();
        j["nodes"] = bvh.nodes.size();
        j["leaves"] = leaves;
        j["references"] = references;
        j["avg_leaf_size"] = leaves ? static_cast<double>(references) / static_cast<double>(leaves) : 0.0;
        j["sah_cost"] = bvh.sahCost(d.bvh);
        j["sah_cost_note"] = "WideBvh::sahCost with the config's costs (wide-node steps and 4-wide leaf blocks)";
      }
    }
#if DUPLEX_BENCH_HAVE_EMBREE
    if (b.scene) {
      bytes_per_triangle[k] = static_cast<double>(b.scene->accelBytes()) / triangles;
      j["quality"] = toString(d.embree_high ? RTC_BUILD_QUALITY_HIGH : RTC_BUILD_QUALITY_MEDIUM);
      j["robust"] = d.embree_robust;
      j["accel_bytes"] = b.scene->accelBytes();
      j["total_bytes"] = b.scene->totalBytes();
    }
#endif
    j["bytes_per_triangle"] = bytes_per_triangle[k];
  }
  addRatios(out, "bytes_per_triangle", "", bytes_per_triangle);

  nlohmann::json builds = nlohmann::json::array();
  std::cerr << "  build ms    " << pad("threads", 9);
  for (const TracerDef& d : defs_) std::cerr << " " << lpad(d.key, 14);
  std::cerr << "\n";
  for (const int t : threads_) {
    std::vector<double> med(n, kNaN), cpu(n, kNaN);
    nlohmann::json rec{{"threads", t}};
    for (std::size_t k = 0; k < n; ++k) {
      if (!ms[k].count(t) || ms[k][t].empty()) continue;
      const std::string& name = defs_[k].key;
      med[k] = median(ms[k][t]);
      rec[name + "_ms"] = med[k];
      rec[name + "_ms_samples"] = ms[k][t];
      structures[name]["build_ms"][std::to_string(t)] = med[k];
      if (cpu_ms[k].count(t)) {
        cpu[k] = median(cpu_ms[k][t]);
        const double process = median(process_cpu_ms[k][t]);
        rec[name + "_cpu_ms"] = cpu[k];
        rec[name + "_cpu_ms_samples"] = cpu_ms[k][t];
        rec[name + "_process_cpu_ms"] = process;
        structures[name]["build_cpu_ms"][std::to_string(t)] = cpu[k];
        // A one-thread build whose process used clearly more CPU than the calling thread ran elsewhere too.
        if (process > 1.2 * cpu[k] + 5.0)
          std::cerr << "  WARNING: the 1-thread build of " << name << " used " << fmt(process / cpu[k])
                    << "x the CPU of the calling thread\n";
      }
    }
    const int ref = find(kReferenceKey);
    for (std::size_t k = 0; k < n; ++k) {
      if (ref < 0 || static_cast<int>(k) == ref || !std::isfinite(med[k])) continue;
      rec["ratio_" + defs_[k].key + "_vs_embree_medium"] = num(ratio(med[k], med[static_cast<std::size_t>(ref)]));
      rec["ratio_cpu_" + defs_[k].key + "_vs_embree_medium"] = num(ratio(cpu[k], cpu[static_cast<std::size_t>(ref)]));
      if (defs_[k].is_default) rec["ratio_vs_embree_medium"] = rec["ratio_" + defs_[k].key + "_vs_embree_medium"];
    }
    const std::string label = std::to_string(t) + "T";
    addRatios(out, "build", label, med);
    if (t == 1) addRatios(out, "build_cpu", label, cpu);
    builds.push_back(rec);
    std::cerr << "              " << pad(std::to_string(t), 9);
    for (std::size_t k = 0; k < n; ++k) std::cerr << lpad(fmt(med[k], 1), 15);
    std::cerr << "\n";
  }
  out["build"] = builds;
  std::cerr << "  bytes/tri   " << pad("", 9);
  for (std::size_t k = 0; k < n; ++k) std::cerr << lpad(fmt(bytes_per_triangle[k], 1), 15);
  std::cerr << "\n  SAH cost    " << pad("", 9);
  for (const TracerDef& d : defs_) {
    const auto& j = structures[d.key];
    std::cerr << lpad(j.contains("sah_cost") ? fmt(j["sah_cost"].get<double>(), 1) : "-", 15);
  }
  std::cerr << "\n";
}

}  // namespace duplex::bench::main_detail
