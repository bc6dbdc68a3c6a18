// The main benchmark: per mesh, our structures (BVH presets, kd-tree) against Embree 3 (medium, high
// and robust builds) on the same rays, builds and traces interleaved per repetition, medians of the repetitions, ratios
// taken within the run. The parts of one mesh's run live in MainBenchBuild.cpp, MainBenchAgreement.cpp and
// MainBenchTrace.cpp (MainBenchParts.h); this file runs them, evaluates the goals and prints the
// summary.

#include "BenchBuild.h"
#include "MainBenchParts.h"

#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <iomanip>
#include <iostream>
#include <map>
#include <sstream>
#include <tuple>

namespace duplex::bench {

namespace main_detail {

nlohmann::json MeshBench::run(const LoadedMesh& loaded) {
  const TriangleMesh& mesh = *loaded.mesh;
  const std::size_t triangles = mesh.triangleCount();
  std::cerr << "\n== " << loaded.spec.label() << ": " << thousands(triangles) << " triangles ("
            << mesh.degenerateCount() << " degenerate)\n";
  nlohmann::json out;
  out["mesh"] = loaded.spec.label();
  out["file"] = loaded.path;
  out["loop_steps"] = loaded.spec.loop_steps;
  out["triangles"] = triangles;
  out["vertices"] = mesh.positions().size();
  out["degenerate_triangles"] = mesh.degenerateCount();
  out["load_ms"] = loaded.load_ms;
  out["subdivide_ms"] = loaded.subdivide_ms;

  build(loaded, out);

  // The rays of `duplex rays`: random rays in the bounds and the default camera's primary rays.
  std::vector<RaySet> sets;
  sets.push_back({"random", randomRays(mesh.bounds(), options_.random_rays, options_.seed)});
  sets.push_back({"primary", primaryRays(mesh.bounds(), options_.primary_width, options_.primary_height)});
  out["rays"] = {{"random", sets[0].rays.size()},
                 {"primary", sets[1].rays.size()},
                 {"primary_width", options_.primary_width},
                 {"primary_height", options_.primary_height},
                 {"seed", options_.seed}};

  checkAgreement(mesh, sets, out);
  watertight(mesh, out);

  // Work per ray of the kd-tree's closest-hit query (untimed), on every k-th ray: a prefix of the
  // primary rays would be the top rows of the image, which miss.
  if (const int kd = find("kdtree"); kd >= 0) {
    nlohmann::json counters;
    for (const RaySet& set : sets) {
      const std::size_t stride = std::max<std::size_t>(1, set.rays.size() / 200'000);
      std::vector<Ray> sample;
      for (std::size_t i = 0; i < set.rays.size(); i += stride) sample.push_back(set.rays[i]);
      const TraversalCounts c =
          countTraversal(arenas_.get(threads_.back()), *built_[static_cast<std::size_t>(kd)].object, sample);
      counters[set.name] = c.toJson();
      counters[set.name]["rays"] = sample.size();
      counters[set.name]["stride"] = stride;
    }
    out["structures"]["kdtree"]["traversal"] = counters;
  }

  trace(sets, out);
  timeSplit(sets[0], out);
  built_.clear();  // scenes before their device
#if DUPLEX_BENCH_HAVE_EMBREE
  embree_.device.reset();
#endif
  return out;
}

}  // namespace main_detail

namespace {

using namespace main_detail;

// The goals, evaluated on this run's ratios for each of our structures (the default's decide).
nlohmann::json evaluateGoals(const nlohmann::json& meshes, const std::vector<TracerDef>& defs) {
  nlohmann::json trace = nlohmann::json::array(), build = nlohmann::json::array(), bytes = nlohmann::json::array(),
                 leaks = nlohmann::json::array();
  bool all_met = true, any_measured = false;
  for (const TracerDef& d : defs) {
    if (!d.ours()) continue;
    const std::string r_key = "ratio_" + d.key + "_vs_embree_medium";
    for (const auto& m : meshes) {
      for (const auto& rec : m["trace"]) {
        if (!rec.contains(r_key) || rec[r_key].is_null()) continue;
        const double r = rec[r_key].get<double>();
        trace.push_back({{"structure", d.key},
                         {"default", d.is_default},
                         {"mesh", m["mesh"]},
                         {"rays", rec["rays"]},
                         {"query", rec["query"]},
                         {"threads", rec["threads"]},
                         {"ratio", r},
                         {"ratio_cpu", rec["ratio_cpu_" + d.key + "_vs_embree_medium"]},
                         {"goal", 1.0},
                         {"met", r >= 1.0},
                         {"floor", 0.85},
                         {"above_floor", r >= 0.85}});
        if (d.is_default) {
          all_met = all_met && r >= 1.0;
          any_measured = true;
        }
      }
      for (const auto& rec : m["build"]) {
        if (!rec.contains(r_key) || rec[r_key].is_null()) continue;
        const double r = rec[r_key].get<double>();
        build.push_back({{"structure", d.key},
                         {"default", d.is_default},
                         {"mesh", m["mesh"]},
                         {"threads", rec["threads"]},
                         {"ratio", r},
                         {"ratio_cpu", rec.value("ratio_cpu_" + d.key + "_vs_embree_medium", nlohmann::json())},
                         {"goal", 1.0},
                         {"met", r <= 1.0}});
        if (d.is_default) all_met = all_met && r <= 1.0;
      }
      const auto& ratios = m["ratios"];
      const std::string bk = d.key + "_vs_embree_medium";
      if (ratios.contains(bk) && ratios[bk].contains("bytes_per_triangle") &&
          ratios[bk]["bytes_per_triangle"].is_number()) {
        const double r = ratios[bk]["bytes_per_triangle"].get<double>();
        bytes.push_back({{"structure", d.key},
                         {"default", d.is_default},
                         {"mesh", m["mesh"]},
                         {"ratio", r},
                         {"goal", 1.0},
                         {"met", r <= 1.0}});
        if (d.is_default) all_met = all_met && r <= 1.0;
      }
      const auto& w = m["watertight"];
      if (w.contains("by_structure") && w["by_structure"].contains(d.key)) {
        const std::uint64_t n = w["by_structure"][d.key]["leaks"].get<std::uint64_t>();
        leaks.push_back({{"structure", d.key},
                         {"default", d.is_default},
                         {"mesh", m["mesh"]},
                         {"rays", w["rays"]},
                         {"leaks", n},
                         {"goal", 0},
                         {"met", n == 0}});
        if (d.is_default) all_met = all_met && n == 0;
      }
    }
  }
  return {{"throughput_vs_embree_medium", trace},
          {"build_time_vs_embree_medium", build},
          {"bytes_per_triangle_vs_embree_medium", bytes},
          {"watertight_leaks", leaks},
          {"default_structure", defaultStructureKey()},
          {"all_met_by_default_structure", any_measured ? nlohmann::json(all_met) : nlohmann::json(nullptr)},
          {"note",
           "throughput ratio = our Mrays/s / Embree's medium build (rtcIntersect1 for closest, rtcOccluded1 for any "
           "hit; random and primary rays; goal >= 1.0, unresolved below 0.85 'floor'); build ratio = our ms / "
           "Embree's medium build (goal <= 1.0, every mesh, 1 and 2 threads); bytes per triangle / Embree's medium "
           "(goal <= 1.0); watertight leaks of rays aimed at shared edges and vertices (goal 0); 'ratio' from "
           "wall-clock medians, 'ratio_cpu' from CPU time (see config.clocks); 'met' judges the wall-clock ratio; "
           "all_met_by_default_structure: every goal of the default structure met in this run"}};
}

void printSummary(const nlohmann::json& meshes, const std::vector<int>& threads, const std::vector<TracerDef>& defs) {
  std::vector<std::string> keys;
  std::ostringstream head;
  head << pad("mesh", 22) << lpad("tris", 10);
  for (const char* rays : {"random", "primary"})
    for (const char* q : {"closest", "any"})
      for (const int t : threads) {
        keys.push_back(std::string(rays) + " " + q + " " + std::to_string(t) + "T");
        head << lpad(std::string(rays).substr(0, 3) + "-" + std::string(q).substr(0, 3) + "-" + std::to_string(t) + "T",
                     11);
      }
  for (const int t : threads) head << lpad("build-" + std::to_string(t) + "T", 10);
  head << lpad("B/tri", 8);
  const nlohmann::json none;
  for (const TracerDef& d : defs) {
    if (!d.ours()) continue;
    const bool measured = std::any_of(meshes.begin(), meshes.end(), [&](const nlohmann::json& m) {
      return m.contains("ratios") && m["ratios"].contains(d.key + "_vs_embree_medium");
    });
    if (!measured) {
      const bool built = std::any_of(meshes.begin(), meshes.end(), [&](const nlohmann::json& m) {
        return m["structures"].contains(d.key) && m["structures"][d.key].value("available", false);
      });
      std::cerr << "\n== " << d.key
                << (built ? ": no ratios (no Embree reference in this run)"
                          : ": not measured (see meshes[].structures." + d.key + ".note)")
                << "\n";
      continue;
    }
    for (const bool cpu : {false, true}) {
      std::cerr << "\n== Summary: " << d.key << (d.is_default ? " (default)" : "") << " / Embree medium, "
                << (cpu ? "CPU time" : "wall clock")
                << " (throughput: >1 means we are faster; build: <1 means we are faster)\n"
                << head.str() << "\n";
      for (const auto& m : meshes) {
        std::ostringstream row;
        row << pad(m["mesh"].get<std::string>(), 22) << lpad(thousands(m["triangles"].get<std::uint64_t>()), 10);
        const std::string rk = d.key + "_vs_embree_medium";
        const auto& r = m.contains("ratios") && m["ratios"].contains(rk) ? m["ratios"][rk] : none;
        if (!r.is_object()) {
          std::cerr << row.str() << "  (not measured)\n";
          continue;
        }
        const auto cell = [](const nlohmann::json& v, std::size_t width) {
          return lpad(v.is_number() ? fmt(v.get<double>()) : "-", width);
        };
        const auto& trace = r.contains(cpu ? "trace_cpu" : "trace") ? r[cpu ? "trace_cpu" : "trace"] : none;
        const auto& build = r.contains(cpu ? "build_cpu" : "build") ? r[cpu ? "build_cpu" : "build"] : none;
        for (const auto& k : keys) row << cell(trace.is_object() && trace.contains(k) ? trace[k] : none, 11);
        for (const int t : threads) {
          const std::string k = std::to_string(t) + "T";
          row << cell(build.is_object() && build.contains(k) ? build[k] : none, 10);
        }
        row << cell(r.contains("bytes_per_triangle") ? r["bytes_per_triangle"] : none, 8);
        std::cerr << row.str() << "\n";
      }
    }
  }
}

}  // namespace

nlohmann::json runMainBench(const Options& options) {
  std::vector<int> threads = options.threads;
  std::sort(threads.begin(), threads.end());
  threads.erase(std::unique(threads.begin(), threads.end()), threads.end());

  EmbreeSide embree;
#if DUPLEX_BENCH_HAVE_EMBREE
  embree.enabled_ = options.with_embree;
  embree.config = options.embree_config;
#endif
  Arenas arenas;
  for (const int t : threads) arenas.get(t);
  std::vector<TracerDef> defs = tracerDefs(options, embree.enabled());
  nlohmann::json structures = nlohmann::json::array();
  for (const TracerDef& d : defs) structures.push_back({{"key", d.key}, {"spec", d.spec}, {"default", d.is_default}});

  nlohmann::json doc;
  doc["kind"] = "duplex_bench_mesh";
  doc["machine"] = machineInfo(thisBuild());
  doc["config"] = {
      {"data", options.data_dir},
      {"meshes", options.meshes},
      {"random_rays", options.random_rays},
      {"primary", {options.primary_width, options.primary_height}},
      {"threads", threads},
      {"repeat", options.repeat},
      {"seed", options.seed},
      {"trace_chunk", kTraceChunk},
      {"quick", options.quick},
      {"embree", embree.enabled()},
      {"embree_config", options.embree_config},
      {"structures", structures},
      {"default_structure", defaultStructureKey()},
      {"reference", kReferenceKey},
      {"simd_isa", std::string(toString(widestSimdIsa()))},
      {"watertight_rays", options.watertight_rays},
      {"clocks",
       "every figure has a wall-clock median (fields *_ms, *_mrays, ratio_*) and a CPU-time median "
       "(*_cpu_ms, *_mrays_cpu, ratio_cpu_*): CPU time of the calling thread for 1 thread, process CPU "
       "time / N for N-thread traces; N-thread builds have wall clock only. The machine is shared: "
       "compare machine.loadavg_*; CPU-time ratios repeat better under load"},
      {"method",
       "builds: MeshObject constructor (MeshObject(mesh, BvhBuildConfig) or (mesh, KdBuildConfig)) inside a "
       "tbb::task_arena of N threads vs Embree geometry setup + "
       "rtcCommitScene on a device made with threads=N for that measurement (the only Embree device alive: "
       "with a second device of more threads alive, a threads=1 device builds on two); traces: the same "
       "tbb::parallel_for over chunks of "
       "4096 rays in a task_arena of N threads, one call per ray (MeshObject::intersect with a fresh Hit / "
       "occluded vs rtcIntersect1 / rtcOccluded1), FTZ+DAZ set per chunk; ours and Embree interleaved per "
       "repetition, figures are medians of the repetitions"}};
  MeshBench bench(options, threads, arenas, embree, std::move(defs));
  MeshCache cache(options.data_dir);
  nlohmann::json meshes = nlohmann::json::array();
  for (const std::string& spec : options.meshes) meshes.push_back(bench.run(cache.get(MeshSpec::parse(spec))));
  doc["meshes"] = meshes;
  doc["goals"] = evaluateGoals(meshes, bench.defs());
  printSummary(meshes, threads, bench.defs());
  return doc;
}

}  // namespace duplex::bench
