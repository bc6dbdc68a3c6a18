// duplex_bench_mesh: build and trace figures of our structures (BVH presets, kd-tree) against Embree 3
// on single meshes, the heuristic/cost sweep (--sweep), closest-point queries against Embree's
// rtcPointQuery (--closest) and a fixed workload for callgrind (--callgrind). Writes one JSON
// document (--out) and prints a compact table to stderr. Not a timed test: it measures, it does not
// judge (the JSON's "goals" section states the targets next to the figures).

#include "BenchCommon.h"
#include "BenchModes.h"

#include <CLI/CLI.hpp>

#include <exception>
#include <iostream>

int main(int argc, char** argv) {
  using namespace duplex::bench;
  setFtzDaz();
  Options options;
  options.data_dir = DUPLEX_BENCH_DATA_DIR;
  // The robot's largest CAD parts (binary STL) beside the scanned and subdivided meshes.
  options.meshes = {"spot.obj",
                    "plane.obj",
                    "hammer.obj",
                    "koala.obj",
                    "koala.obj:1",
                    "koala.obj:2",
                    "abb_irb6640/link_3.stl",
                    "abb_irb6640/link_1.stl",
                    "abb_irb6640/link_2.stl",
                    "abb_irb6640/base_link.stl"};
  options.sweep_meshes = {"koala.obj", "hammer.obj"};
  options.callgrind_mesh = "koala.obj";

  CLI::App app{
      "duplex_bench_mesh: our BVH presets and kd-tree against Embree 3 on single meshes (JSON out, table on stderr)"};
  app.add_option("--data", options.data_dir, "data folder holding meshes/")->capture_default_str();
  app.add_option("--meshes", options.meshes,
                 "mesh specs, comma separated: FILE or FILE:K for K steps of Loop subdivision (koala.obj:2 ~1.6M "
                 "triangles); FILE is looked up as given, then in DATA/meshes")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--random", options.random_rays, "random rays per mesh (duplex::randomRays)")->capture_default_str();
  // An option of two numbers, an image's width and height.
  const auto addSizeOption = [&app](const char* name, std::uint32_t& width, std::uint32_t& height, const char* help) {
    app.add_option(
           name,
           [&width, &height](const CLI::results_t& r) {
             width = static_cast<std::uint32_t>(std::stoul(r.at(0)));
             height = static_cast<std::uint32_t>(std::stoul(r.at(1)));
             return true;
           },
           help)
        ->expected(2);
  };
  addSizeOption("--primary", options.primary_width, options.primary_height,
                "primary rays: W H (duplex::primaryRays, default 1024 1024)");
  app.add_option("--threads", options.threads, "thread counts, comma separated")->delimiter(',')->capture_default_str();
  app.add_option("--repeat", options.repeat, "repetitions; figures are medians")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--seed", options.seed, "seed of the random rays")->capture_default_str();
  app.add_flag("--quick", options.quick, "smoke run: small meshes, few rays, one repetition");
  app.add_option("--out", options.out, "JSON output file (default: none, table only)");
  app.add_option("--embree-config", options.embree_config, "extra rtcNewDevice configuration, e.g. isa=avx2");
  bool no_embree = false;
  app.add_flag("--no-embree", no_embree, "measure only our structures");
  app.add_option("--structures", options.structures,
                 "our structures, comma separated: kdtree, bvh:fast, bvh:medium, bvh:high, or bvh:PRESET/KEY=VALUE... "
                 "(BvhBuildConfig overrides joined by '/', e.g. bvh:medium/leaf=4); one that cannot be built is "
                 "listed with the reason")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--embree-builds", options.embree_builds,
                 "Embree's builds: medium (always, the reference of the ratios), high, robust (medium quality, "
                 "RTC_SCENE_FLAG_ROBUST)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--watertight-rays", options.watertight_rays,
                 "rays aimed at shared vertices and edges per closed mesh, traced by every structure (0: none)")
      ->capture_default_str();

  bool sweep = false;
  app.add_flag("--sweep", sweep, "heuristic/cost sweep: build ms vs trace ms (1 thread) over KdBuildConfig settings");
  app.add_option("--sweep-meshes", options.sweep_meshes, "meshes of the sweep")->delimiter(',')->capture_default_str();
  app.add_option("--sweep-random", options.sweep_random_rays, "random rays per sweep setting")->capture_default_str();
  addSizeOption("--sweep-primary", options.sweep_primary_width, options.sweep_primary_height,
                "primary rays of the sweep: W H (default 512 512)");

  bool closest = false;
  app.add_flag("--closest", closest,
               "closest-point queries: ours (BVH) against Embree's rtcPointQuery, near and far points, 1 thread");
  app.add_option("--closest-points", options.closest_points, "points per mesh and kind")->capture_default_str();

  bool callgrind = false;
  app.add_flag(
      "--callgrind", callgrind,
      "fixed workload for valgrind --tool=callgrind --instr-atstart=no: only the trace loops are instrumented, "
      "one dump per tracer and query");
  app.add_option("--callgrind-mesh", options.callgrind_mesh, "mesh of the callgrind workload")->capture_default_str();
  app.add_option("--callgrind-rays", options.callgrind_rays, "random rays of the callgrind workload")
      ->capture_default_str();
  app.add_option("--callgrind-structure", options.callgrind_structure,
                 "our structure in the callgrind workload (dumps ours-*): kdtree or bvh:PRESET[/KEY=VALUE...]")
      ->capture_default_str();
  app.add_option("--callgrind-what", options.callgrind_what, "tracers: ours, embree")
      ->delimiter(',')
      ->capture_default_str();

  CLI11_PARSE(app, argc, argv);
  options.with_embree = !no_embree;
  if (int{sweep} + int{callgrind} + int{closest} > 1) {
    std::cerr << "--sweep, --callgrind and --closest are separate runs\n";
    return 2;
  }
  if (options.quick) {
    // Small enough for a smoke test, large enough to exercise every code path.
    if (app.count("--meshes") == 0) options.meshes = {"spot.obj", "plane.obj", "abb_irb6640/link_6.stl"};
    if (app.count("--sweep-meshes") == 0) options.sweep_meshes = {"hammer.obj"};
    if (app.count("--random") == 0) options.random_rays = 100'000;
    if (app.count("--primary") == 0) options.primary_width = options.primary_height = 256;
    if (app.count("--sweep-random") == 0) options.sweep_random_rays = 50'000;
    if (app.count("--sweep-primary") == 0) options.sweep_primary_width = options.sweep_primary_height = 192;
    if (app.count("--repeat") == 0) options.repeat = 1;
    if (app.count("--watertight-rays") == 0) options.watertight_rays = 20'000;
  }

  try {
    nlohmann::json doc = sweep       ? runSweep(options)
                         : callgrind ? runCallgrind(options)
                         : closest   ? runClosestBench(options)
                                     : runMainBench(options);
    doc["machine"]["loadavg_at_end"] = loadAverage();
    if (!options.out.empty()) {
      writeJson(options.out, doc);
      std::cerr << "wrote " << options.out << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "duplex_bench_mesh: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
