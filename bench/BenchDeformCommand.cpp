#include "BenchDeformCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "LoadScene.h"
#include "StructureOption.h"
#include "WorkerThreads.h"

#include "BenchBuild.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/scenegraph/SceneGraph.h>
#include <duplex/scenegraph/SceneTracer.h>

#include <CLI/CLI.hpp>
#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::cli {

namespace {

double uniform(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

/// One step of the deformation described in BenchDeformCommand.h, applied to `p` in place.
void deformStep(std::vector<glm::vec3>& p, const glm::dvec3& centre, double diagonal, double amplitude,
                std::mt19937_64& rng) {
  constexpr double kPi = 3.14159265358979323846;
  const double k = 4.0 * kPi / diagonal;
  for (int a = 0; a < 3; ++a) {
    glm::dvec3 w;
    w.x = uniform(rng) - 0.5;
    w.y = uniform(rng) - 0.5;
    w.z = uniform(rng) - 0.5;
    w = glm::length(w) > 0.0 ? glm::normalize(w) : glm::dvec3(1.0, 0.0, 0.0);
    const double phase = 2.0 * kPi * uniform(rng);
    for (glm::vec3& v : p)
      v[a] =
          static_cast<float>(v[a] + amplitude * diagonal * std::sin(k * glm::dot(glm::dvec3(v) - centre, w) + phase));
  }
}

const MeshObject& asMesh(const ObjectLibrary& library, ObjectId id) {
  return dynamic_cast<const MeshObject&>(*library.get(id));
}

/// Primary rays through the tracer in parallel; the hits.
std::vector<Hit> traceAll(const SceneTracer& tracer, const std::vector<Ray>& rays) {
  std::vector<Hit> hits(rays.size());
  tracer.intersect(rays, hits);
  return hits;
}

}  // namespace

void addBenchDeformOptions(CLI::App& cmd, BenchDeformOptions& options) {
  cmd.footer("The seeded deformation is described in bench/BenchDeformCommand.h.");
  cmd.add_option("--scene", options.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  addStructureOption(cmd, options.structure);
  cmd.add_option("--object", options.object, "Name of the mesh object that deforms (the scene file's object name)")
      ->required();
  cmd.add_option("--steps", options.steps, "Deformation steps, one commit each (default 100)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 100000));
  cmd.add_option("--seed", options.seed, "Seed of the deformation (default 1)")->transform(kDecimal);
  cmd.add_option("--amplitude", options.amplitude,
                 "Displacement per step as a fraction of the object's diagonal (default 0.002)")
      ->check(CLI::Range(0.0, 1.0));
  addThreadsOption(cmd, options.threads);
  addPrimaryOption(cmd, options.primary);
  cmd.add_option("--trace-rounds", options.trace_rounds,
                 "Paired trace rounds, refitted and fresh alternating, after the last step (default 5)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000));
}

nlohmann::ordered_json runBenchDeform(const BenchDeformOptions& options) {
  WorkerThreads workers(options.threads);
  nlohmann::ordered_json out;
  workers.arena.execute([&] {
    SceneDocument doc = loadDocumentNamed(options.scene, documentOptions(options.structure));
    SceneGraph& graph = *doc.graph;
    ObjectLibrary& library = graph.library();
    const std::string scene = options.scene.string();
    const auto found = library.find(options.object);
    if (!found) throw InvalidArgument(scene + ": no object named '" + options.object + "'");
    const ObjectId id = *found;
    const auto* start = dynamic_cast<const MeshObject*>(library.get(id).get());
    if (!start)
      throw InvalidArgument(scene + ": object '" + options.object + "' is of type " + library.typeName(id) +
                            ": bench deform deforms meshes");
    std::size_t instances = 0;
    for (const NodeId node : graph.visibleInstances()) instances += graph.node(node).object == id;
    if (instances == 0) throw InvalidArgument(scene + ": object '" + options.object + "' has no visible instance");
    const MeshBuildConfig config = start->buildConfig();
    const std::shared_ptr<const Object> rest_object = library.get(id);  // keeps rest_mesh alive
    const TriangleMesh* rest_mesh = &start->mesh();
    const std::size_t triangle_count = rest_mesh->triangleCount();
    const Box rest_box = start->bounds();
    const glm::dvec3 centre = (glm::dvec3(rest_box.lo) + glm::dvec3(rest_box.hi)) * 0.5;
    const double diagonal = glm::length(glm::dvec3(rest_box.hi) - glm::dvec3(rest_box.lo));
    if (!(diagonal > 0.0)) throw InvalidArgument(scene + ": object '" + options.object + "' has no extent");
    std::vector<glm::vec3> positions = start->mesh().positions();
    out["scene"] = scene;
    out["object"] = options.object;
    out["triangles"] = triangle_count;
    out["vertices"] = positions.size();
    out["instances"] = instances;
    out["structure"] = std::string(toString(config.structure));
    std::ostringstream config_text;
    if (config.structure == MeshStructure::Bvh) config_text << config.bvh;
    else config_text << config.kd;
    out["config"] = config_text.str();
    out["refit_limit"] = config.bvh.refit_limit;
    out["steps"] = options.steps;
    out["seed"] = options.seed;
    out["amplitude"] = options.amplitude;
    out["threads"] = workers.count;

    SceneTracer tracer(graph);
    std::mt19937_64 rng(options.seed);
    std::vector<double> refit_ms, guard_ms, rebuild_ms, commit_ms;
    std::shared_ptr<const MeshObject> fresh;
    for (int step = 1; step <= options.steps; ++step) {
      deformStep(positions, centre, diagonal, options.amplitude, rng);
      bench::Stopwatch deform_clock;
      graph.deformObject(id, positions);
      const double deform = deform_clock.ms();
      bench::Stopwatch commit_clock;
      (void)graph.commit();
      commit_ms.push_back(commit_clock.ms());
      (asMesh(library, id).wasRefitted() ? refit_ms : guard_ms).push_back(deform);
      // The same positions built from scratch, as an application without refits would.
      bench::Stopwatch rebuild_clock;
      fresh = std::make_shared<const MeshObject>(
          std::make_shared<const TriangleMesh>(rest_mesh->withPositions(positions)), config);
      rebuild_ms.push_back(rebuild_clock.ms());
      if (step % 10 == 0 || step == options.steps)
        std::cerr << "bench deform: step " << step << "/" << options.steps << ", " << guard_ms.size()
                  << " rebuilds so far\n";
    }
    const auto nullable = [](const std::vector<double>& v) {
      return v.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(bench::median(v));
    };
    out["refit_ms_median"] = nullable(refit_ms);
    out["refit_ms_max"] = refit_ms.empty()
                              ? nlohmann::ordered_json()
                              : nlohmann::ordered_json(*std::max_element(refit_ms.begin(), refit_ms.end()));
    out["rebuild_ms_median"] = bench::median(rebuild_ms);
    out["refit_speedup"] = refit_ms.empty()
                               ? nlohmann::ordered_json()
                               : nlohmann::ordered_json(bench::median(rebuild_ms) / bench::median(refit_ms));
    out["guard_rebuild_ms_median"] = nullable(guard_ms);
    out["commit_ms_median"] = bench::median(commit_ms);
    out["rebuilds"] = guard_ms.size();
    const std::shared_ptr<const Object> refitted = library.get(id);
    out["sah_cost_refitted"] = asMesh(library, id).sahCost();
    out["sah_cost_fresh"] = fresh->sahCost();

    // Paired rounds: the refitted object and the fresh one take turns under the same instances.
    const std::vector<Ray> rays = primaryRays(visibleWorldBounds(doc), options.primary, options.primary);
    out["primary_rays"] = rays.size();
    std::vector<double> ratios, refit_trace_ms, fresh_trace_ms;
    std::size_t same = 0;
    (void)traceAll(tracer, rays);  // warm-up
    for (int round = 0; round < options.trace_rounds; ++round) {
      double ms[2] = {0.0, 0.0};
      std::vector<Hit> hits[2];
      for (int turn = 0; turn < 2; ++turn) {
        const int which = (round + turn) % 2;  // 0: refitted, 1: fresh; alternating which goes first
        graph.replaceObject(id, which == 0 ? refitted : std::static_pointer_cast<const Object>(fresh));
        (void)graph.commit();
        bench::Stopwatch clock;
        hits[which] = traceAll(tracer, rays);
        ms[which] = clock.ms();
      }
      refit_trace_ms.push_back(ms[0]);
      fresh_trace_ms.push_back(ms[1]);
      ratios.push_back(ms[0] / ms[1]);
      if (round == 0)
        for (std::size_t i = 0; i < rays.size(); ++i) {
          const Hit& a = hits[0][i];
          const Hit& b = hits[1][i];
          same += a.valid() == b.valid() &&
                  (!a.valid() || (a.instance_id == b.instance_id && a.prim_id == b.prim_id && a.t == b.t));
        }
    }
    graph.replaceObject(id, refitted);
    (void)graph.commit();
    const double mrays = static_cast<double>(rays.size()) * 1e-3;
    out["mrays_per_s_refitted"] = mrays / bench::median(refit_trace_ms);
    out["mrays_per_s_fresh"] = mrays / bench::median(fresh_trace_ms);
    out["trace_slowdown_after_refits"] = bench::median(ratios) - 1.0;
    out["agreement_refit_vs_fresh"] = rays.empty() ? 1.0 : static_cast<double>(same) / static_cast<double>(rays.size());
  });
  out["machine"] = bench::machineInfo(bench::thisBuild());
  return out;
}

void addBenchDeformCommand(CLI::App& bench, ChosenCommand& chosen) {
  auto options = std::make_shared<BenchDeformOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "deform",
      "Deform a mesh object step by step: refit against rebuild, trace after the refits against a fresh build");
  addBenchDeformOptions(*cmd, *options);
  onParsed(*cmd, chosen, options, runBenchDeform);
}

}  // namespace duplex::cli
