// The `duplex` command-line tool: the interchange contract used by tools outside the project.
//   duplex trace --scene S.json --rays R.bin (--hits H.bin | --transmittance T.bin) [--threads N] [--any-hit]
//   [--single]
//                [--repeat R]
// Every command that loads a scene takes [--structure bvh|kdtree|bvh:<parameters>]; every command takes
// [--max-memory SIZE] (inputs that need more memory are refused before they are allocated).
//   duplex closest --scene S.json --points P.bin --out C.bin [--threads N]
//   duplex rays  --scene S.json (--primary W H | --random N --seed X) --out R.bin
//   duplex scene split     --mesh M --objects K [--loop N] --out S.json
//   duplex scene instances --mesh M --count N --seed X --out S.json
//   duplex scene robot     --urdf U [--copies C] [--joints a1,a2,...] [--spacing D] --out S.json
//   duplex prepare --scene S.json --out DIR [--threads N]
//   duplex bench update --scene S.json [--moves M | --moves P%] [--repeat R] [--seed X] [--threads N]
//                       [--primary W] [--build-repeat B] [--baseline-repeat B]
//   duplex bench frame --scene S.json [--moves 1,1%,10%] [--threads 1,2] [--frames N] [--size W H] [--seed X]
//                      [--hit-tolerance F]
//   duplex bench deform --scene S.json --object NAME [--steps K] [--seed X] [--amplitude A] [--threads N]
//                       [--primary W] [--trace-rounds R]
//   duplex sensor --scene S.json --rays N [--threads T] [--seed X] [--out DIR] [--resume]
//                 [--target-error E [--target-sensor NAME]] [--max-depth D|none] [--roulette-depth K]
//                 [--max-scatterings S]
//                 [--roulette R] [--failure-threshold F] [--progress MODE] [--checkpoint SECONDS] [--at T]
//                 [--text-map-limit N]
//                 [--batch-rays B]; under `mpirun -np N` the ranks share the batches
//   duplex view SCENE [--port N] [--bind ADDR] [--threads N]   (serves the scene to a browser until stopped)
// Scenes are read by loadSceneDocument: scene-json-v1 and duplex-scene-v1 (docs/scene-format.md).
// Each command prints one JSON object on stdout; diagnostics go to stderr. Bad input gives a
// message naming the file and the problem and a non-zero exit status.

#include "BenchDeformCommand.h"
#include "BenchFrameCommand.h"
#include "ClosestCommand.h"
#include "BenchUpdateCommand.h"
#include "DecimalOption.h"
#include "MemoryOption.h"
#include "PrepareCommand.h"
#include "RaysCommand.h"
#include "SceneInstancesCommand.h"
#include "SceneRobotCommand.h"
#include "SceneSplitCommand.h"
#include "SensorCommand.h"
#include "SensorRanks.h"
#include "StructureOption.h"
#include "TraceCommand.h"
#include "ViewCommand.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/Log.h>
#include <duplex/accel/MemoryLimit.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <exception>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

namespace {

// Exit statuses besides CLI11's own (which are non-zero for every parse error).
constexpr int kExitBadInput = 1;  // duplex::Error: a file or argument the library refused
constexpr int kExitInternal = 3;  // anything else: a bug, reported rather than crashing

using duplex::cli::kDecimal;

}  // namespace

int main(int argc, char** argv) {
  using duplex::cli::RaysOptions;
  using duplex::cli::TraceOptions;
  // Past a file-size limit (ulimit -f) a write then fails with EFBIG, reported as an error naming
  // the file, instead of the signal killing the tool with a half-written temporary file.
  std::signal(SIGXFSZ, SIG_IGN);

  CLI::App app{
      "Two-level kd-tree ray tracing of scene-json-v1 and duplex-scene-v1 scenes (ray and hit files in, "
      "JSON figures out).",
      "duplex"};
  app.require_subcommand(1);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Log the library's info messages to stderr (before or after the command)");
  app.fallthrough();  // options of the tool itself (-v) are also accepted after a command's name

  // duplex trace
  TraceOptions trace;
  CLI::App* trace_cmd = app.add_subcommand("trace", "Trace a ray file against a scene and write a hit file");
  trace_cmd->add_option("--scene", trace.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  duplex::cli::addStructureOption(*trace_cmd, trace.structure);
  trace_cmd->add_option("--rays", trace.rays, "Ray file: 32-byte records ox oy oz tnear dx dy dz tfar")->required();
  CLI::Option* hits_opt =
      trace_cmd->add_option("--hits", trace.hits, "Hit file to write: 20-byte records t u v instance_id prim_id");
  CLI::Option* transmittance_opt = trace_cmd->add_option(
      "--transmittance", trace.transmittance,
      "Instead of hits: one float32 per ray, the transmittance along [tnear, tfar] through all fog volumes "
      "(0 where a surface blocks the ray)");
  hits_opt->excludes(transmittance_opt);
  duplex::cli::addThreadsOption(*trace_cmd, trace.threads);
  trace_cmd->add_flag("--any-hit", trace.any_hit,
                      "Occlusion queries: blocked -> {0, 0, 0, instance 0, prim 0xFFFFFFFF}, free -> miss");
  trace_cmd->add_flag("--single", trace.single,
                      "Trace one ray at a time instead of in packets (same hits; for speed comparisons)");
  trace_cmd->add_option("--repeat", trace.repeat, "Trace R times and report the median time")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  trace_cmd
      ->add_option("--block-rays", trace.block_rays,
                   "Rays read, traced and written per block (memory: about 100 bytes per ray of a block)")
      ->transform(kDecimal)
      ->check(CLI::Range(std::int64_t{1}, std::int64_t{1} << 32))
      ->capture_default_str();
  trace_cmd->footer(
      "A hit's instance_id is the instance's position in the scene: in \"instances\" for scene-json-v1; in\n"
      "depth-first file order of the node tree for duplex-scene-v1 (hidden instances keep their place).\n"
      "The timed edits of a duplex-scene-v1 file are not applied.");

  // duplex rays
  RaysOptions rays;
  std::vector<std::uint32_t> primary;
  // The seed of `duplex rays --random` without --seed (reported in the JSON and on stderr).
  constexpr std::uint64_t kDefaultRaySeed = 1;
  std::uint64_t random_count = 0, seed = 0;
  CLI::App* rays_cmd = app.add_subcommand("rays", "Write primary or random rays for a scene");
  rays_cmd
      ->add_option("--scene", rays.scene,
                   "scene-json-v1 or duplex-scene-v1 file (the world bounds of its visible instances place the rays)")
      ->required();
  rays_cmd->add_option("--out", rays.out, "Ray file to write")->required();
  duplex::cli::addStructureOption(*rays_cmd, rays.structure);
  CLI::Option* primary_opt =
      rays_cmd->add_option("--primary", primary, "W H: primary rays of a W x H image, row-major from the top left")
          ->expected(2)
          ->transform(kDecimal)
          ->check(CLI::Range(1u, 65536u));
  CLI::Option* random_opt = rays_cmd->add_option("--random", random_count, "N random rays (origins in the world box)")
                                ->transform(kDecimal)
                                ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 32));
  std::string seed_help = "Seed of the random rays (0 to 2^64-1; default ";
  seed_help += std::to_string(kDefaultRaySeed);
  seed_help += ")";
  CLI::Option* seed_opt = rays_cmd->add_option("--seed", seed, seed_help)->transform(kDecimal);
  primary_opt->excludes(random_opt);
  primary_opt->excludes(seed_opt);
  seed_opt->needs(random_opt);

  // duplex scene split|instances|robot
  CLI::App* scene_cmd =
      app.add_subcommand("scene", "Write benchmark scenes as scene-json-v1 (split, instances, robot)");
  scene_cmd->require_subcommand(1);

  duplex::cli::SceneSplitOptions split;
  CLI::App* split_cmd = scene_cmd->add_subcommand(
      "split", "Split a mesh into K objects (the paper's scenes), one identity instance each");
  split_cmd->footer(
      "Rule: split(tris, k): k == 1 gives one object; else kl = k div 2, order the\n"
      "triangles by (centroid on the longest axis of their centroid box, ties x, y, z; triangle index),\n"
      "the first (2 n kl + k) div 2k go left with kl, the rest right with k - kl. Objects part0..part<K-1>\n"
      "(depth-first, left to right) hold inline arrays: triangles in their original order, vertices\n"
      "re-indexed in order of first use. Every triangle the loader returns counts, degenerate (zero-area)\n"
      "ones included; they stay in their object (an object of degenerate triangles only is reported).");
  split_cmd->add_option("--mesh", split.mesh, "Mesh file (OBJ, PLY, OFF, STL, OM)")->required();
  split_cmd->add_option("--objects", split.objects, "K: number of objects (1 to the triangle count)")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(1u, 0xFFFFFFFFu));
  split_cmd->add_option("--loop", split.loop, "Loop-subdivide the mesh N times before splitting (default 0)")
      ->transform(kDecimal)
      ->check(CLI::Range(0, 6));
  split_cmd->add_option("--out", split.out, "scene-json-v1 file to write")->required();

  duplex::cli::SceneInstancesOptions scatter;
  CLI::App* instances_cmd = scene_cmd->add_subcommand(
      "instances", "N randomly rotated instances of one mesh on a grid (cells of the mesh's bounding diagonal)");
  instances_cmd->add_option("--mesh", scatter.mesh, "Mesh file (written relative to the output's folder when possible)")
      ->required();
  instances_cmd->add_option("--count", scatter.count, "N: number of instances")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 32));
  instances_cmd->add_option("--seed", scatter.seed, "Seed of the rotations (std::mt19937_64, 0 to 2^64-1)")
      ->required()
      ->transform(kDecimal);
  instances_cmd->add_option("--out", scatter.out, "scene-json-v1 file to write")->required();

  duplex::cli::SceneRobotOptions robot;
  double spacing = 0.0;
  CLI::App* robot_cmd = scene_cmd->add_subcommand(
      "robot", "A URDF robot's link meshes placed by forward kinematics, in copies side by side along +y");
  robot_cmd->add_option("--urdf", robot.urdf, "URDF file (package:// mesh paths resolved near it)")->required();
  robot_cmd->add_option("--copies", robot.copies, "Number of robots (default 1)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  robot_cmd
      ->add_option("--joints", robot.joints,
                   "Joint values a1,a2,... in radians (metres for prismatic), one per movable joint in file "
                   "order (default: all zero)")
      ->delimiter(',');
  CLI::Option* spacing_opt = robot_cmd->add_option(
      "--spacing", spacing, "Distance between copies (default 1.25 x the larger horizontal extent of one robot)");
  robot_cmd->add_option("--out", robot.out, "scene-json-v1 file to write")->required();

  // duplex prepare
  duplex::cli::PrepareOptions prepare;
  CLI::App* prepare_cmd = app.add_subcommand(
      "prepare", "Save the bottom-level structure of every mesh object and a duplex-scene-v1 copy that names them");
  prepare_cmd->add_option("--scene", prepare.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  prepare_cmd->add_option("--out", prepare.out, "Folder for <scene stem>.json and the .dbvh / .dkdt structure files")
      ->required();
  duplex::cli::addStructureOption(*prepare_cmd, prepare.structure);
  duplex::cli::addThreadsOption(*prepare_cmd, prepare.threads);

  // duplex closest
  duplex::cli::ClosestOptions closest;
  CLI::App* closest_cmd = app.add_subcommand(
      "closest", "Nearest surface point to each point of a point file (16-byte records in, 24-byte records out)");
  closest_cmd->add_option("--scene", closest.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  closest_cmd->add_option("--points", closest.points, "Point file: float x, y, z, max_distance per record")->required();
  closest_cmd
      ->add_option("--out", closest.out,
                   "Closest file to write: float x, y, z, distance; uint32 instance_id, prim_id per point")
      ->required();
  duplex::cli::addStructureOption(*closest_cmd, closest.structure);
  duplex::cli::addThreadsOption(*closest_cmd, closest.threads);

  // duplex bench update
  CLI::App* bench_cmd = app.add_subcommand("bench", "Benchmarks (update, frame, deform)");
  bench_cmd->require_subcommand(1);
  duplex::cli::BenchUpdateOptions bench_update;
  CLI::App* update_cmd = bench_cmd->add_subcommand(
      "update",
      "Time commits of moved, added and removed instances (ours incremental, ours full rebuild; the Embree "
      "baseline is in the benchmark duplex_bench_update)");
  duplex::cli::addBenchUpdateOptions(*update_cmd, bench_update);
  // duplex bench frame
  duplex::cli::BenchFrameOptions bench_frame;
  CLI::App* frame_cmd = bench_cmd->add_subcommand(
      "frame",
      "Time interactive frames: move k instances, commit, trace a camera frame with shadow rays (the Embree "
      "baseline is in the benchmark duplex_bench_frame)");
  duplex::cli::addBenchFrameOptions(*frame_cmd, bench_frame);
  // duplex bench deform
  duplex::cli::BenchDeformOptions bench_deform;
  CLI::App* deform_cmd = bench_cmd->add_subcommand(
      "deform",
      "Deform a mesh object step by step: refit against rebuild, trace after the refits against a fresh build");
  duplex::cli::addBenchDeformOptions(*deform_cmd, bench_deform);

  // duplex sensor
  duplex::cli::SensorOptions sensor;
  CLI::App* sensor_cmd = app.add_subcommand(
      "sensor", "Light-tracing run: power from the scene's lights arriving at its sensors (irradiance maps)");
  sensor_cmd
      ->add_option("--scene", sensor.scene, "scene-json-v1 or duplex-scene-v1 file with \"lights\" and \"sensors\"")
      ->required();
  duplex::cli::addStructureOption(*sensor_cmd, sensor.structure);
  sensor_cmd->add_option("--rays", sensor.rays, "Total emitted rays (with --resume: including the saved ones)")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 48));
  duplex::cli::addThreadsOption(*sensor_cmd, sensor.threads);
  sensor_cmd->add_option("--seed", sensor.seed, "Seed (default 1); results do not depend on --threads")
      ->transform(kDecimal);
  sensor_cmd->add_option(
      "--out", sensor.out,
      "Folder for <sensor>.json/.csv/.png (and .exr when built with OpenEXR), run.json, run_state.bin (default .)");
  CLI::Option* resume_opt = sensor_cmd->add_flag(
      "--resume", sensor.resume, "Continue the run saved in DIR/run_state.bin (same scene and seed) up to --rays");
  sensor_cmd
      ->add_flag("--overwrite", sensor.overwrite,
                 "Replace an earlier run's results in DIR (without it, or --resume, such a folder is refused)")
      ->excludes(resume_opt);
  CLI::Option* target_error_opt =
      sensor_cmd
          ->add_option("--target-error", sensor.target_error,
                       "Stop once the target sensor's total flux has this relative standard error (e.g. 0.01)")
          ->check(CLI::Range(0.0, 1.0));
  sensor_cmd->add_option("--target-sensor", sensor.target_sensor, "Sensor of --target-error (default: the first)")
      ->needs(target_error_opt);
  sensor_cmd
      ->add_option("--max-depth", sensor.max_depth,
                   "Surface interactions after which a path is cut, a bias (default none: unbiased)")
      ->transform(CLI::Transformer(std::map<std::string, std::string>{{"none", std::to_string(duplex::kNoDepthLimit)}}))
      ->transform(kDecimal);
  sensor_cmd
      ->add_option("--roulette-depth", sensor.roulette_depth,
                   "Surface interactions after which each further one continues with probability 0.95, the "
                   "survivor's power divided by it (unbiased; default 32)")
      ->transform(kDecimal);
  sensor_cmd
      ->add_option("--max-scatterings", sensor.max_scatterings,
                   "Fog collisions per path before it is cut (default 100000; 1: single scattering)")
      ->transform(kDecimal);
  sensor_cmd->add_option(
      "--roulette", sensor.roulette,
      "Russian roulette below this fraction of a ray's emitted power, in [0, 1) (default 0.05; 0: off)");
  sensor_cmd->add_flag("--per-light", sensor.per_light,
                       "Also report each light's contribution (run.json and each sensor file's \"lights\"); "
                       "one process only");
  sensor_cmd->add_option(
      "--failure-threshold", sensor.failure_threshold,
      "Warn on stderr when numerical failures, or the path limits, carry more than this fraction of the emitted "
      "power, in [0, 1] (default 0.001)");
  sensor_cmd->add_option("--progress", sensor.progress, "auto (bar on a terminal, else lines), bar, lines or none")
      ->check(CLI::IsMember({"auto", "bar", "lines", "none"}));
  sensor_cmd
      ->add_option("--checkpoint", sensor.checkpoint_s,
                   "Seconds between saves of DIR/run_state.bin during the run (default 60; 0: only at the end)")
      ->check(CLI::Range(0.0, 1e9));
  sensor_cmd
      ->add_option("--text-map-limit", sensor.text_map_limit,
                   "Bins above which a sensor's maps go to .npy files instead of the JSON and CSV (default 1048576)")
      ->transform(kDecimal);
  sensor_cmd
      ->add_option("--at", sensor.at,
                   "Apply the scene's timed edits with time <= T (seconds) before the run (default: none)")
      ->check(CLI::Range(0.0, std::numeric_limits<double>::max()));
  sensor_cmd
      ->add_option("--batch-rays", sensor.batch_rays,
                   "Rays per batch: the unit of the ordered sums, of work dealt to MPI ranks, of checkpoints and "
                   "--target-error checks (default 65536; results depend on it, not on --threads or ranks)")
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 40));
  sensor_cmd->footer(
      "Files are described in docs/sensors.md; the run is bit-identical for any --threads, and for any number of "
      "ranks under mpirun (docs/distributed.md).");

  // duplex view
  duplex::cli::ViewOptions view;
  CLI::App* view_cmd = app.add_subcommand(
      "view",
      "Serve the scene to a browser: ray-traced view, picking, edits, timeline and sensor runs (docs/viewer.md). "
      "Prints {\"url\", \"port\", \"token\"} when ready; runs until Ctrl-C");
  view_cmd->add_option("scene", view.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  view_cmd->add_option("--port", view.port, "TCP port (0: a free port)")
      ->transform(kDecimal)
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  view_cmd
      ->add_option("--bind", view.bind,
                   "Address to listen on (other than 127.0.0.1: a warning; the token is still required)")
      ->capture_default_str();
  duplex::cli::addThreadsOption(*view_cmd, view.threads);

  // --max-memory of the commands that load scenes, meshes or ray files, or run (all of them).
  std::uint64_t max_memory = 0;
  for (CLI::App* cmd : {trace_cmd, rays_cmd, split_cmd, instances_cmd, robot_cmd, prepare_cmd, closest_cmd, update_cmd,
                        frame_cmd, deform_cmd, sensor_cmd, view_cmd})
    duplex::cli::addMaxMemoryOption(*cmd, max_memory);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);  // help to stdout with status 0; errors to stderr with a non-zero status
  }
  if (verbose) duplex::logger()->set_level(spdlog::level::info);
  if (max_memory != 0) duplex::setMemoryLimit(max_memory);

  const char* command = *trace_cmd       ? "duplex trace"
                        : *rays_cmd      ? "duplex rays"
                        : *split_cmd     ? "duplex scene split"
                        : *instances_cmd ? "duplex scene instances"
                        : *robot_cmd     ? "duplex scene robot"
                        : *sensor_cmd    ? "duplex sensor"
                        : *prepare_cmd   ? "duplex prepare"
                        : *closest_cmd   ? "duplex closest"
                        : *deform_cmd    ? "duplex bench deform"
                        : *frame_cmd     ? "duplex bench frame"
                        : *view_cmd      ? "duplex view"
                                         : "duplex bench update";
  try {
    nlohmann::ordered_json result;
    if (*trace_cmd) {
      result = duplex::cli::runTrace(trace);
    } else if (*split_cmd) {
      result = duplex::cli::runSceneSplit(split);
    } else if (*instances_cmd) {
      result = duplex::cli::runSceneInstances(scatter);
    } else if (*sensor_cmd) {
      result = duplex::cli::runSensor(sensor);
    } else if (*view_cmd) {
      duplex::cli::runView(view);  // prints its ready line itself and serves until stopped
    } else if (*prepare_cmd) {
      result = duplex::cli::runPrepare(prepare);
    } else if (*closest_cmd) {
      result = duplex::cli::runClosest(closest);
    } else if (*update_cmd) {
      result = duplex::cli::runBenchUpdate(bench_update);
    } else if (*frame_cmd) {
      result = duplex::cli::runBenchFrame(bench_frame);
    } else if (*deform_cmd) {
      result = duplex::cli::runBenchDeform(bench_deform);
    } else if (*robot_cmd) {
      if (*spacing_opt) robot.spacing = spacing;
      result = duplex::cli::runSceneRobot(robot);
    } else {
      if (*primary_opt) {
        rays.width = primary[0];
        rays.height = primary[1];
      }
      if (*random_opt) {
        rays.random_count = random_count;
        rays.seed = *seed_opt ? seed : kDefaultRaySeed;
        if (!*seed_opt) std::cerr << "duplex rays: no --seed given; using the default seed " << kDefaultRaySeed << "\n";
      }
      result = duplex::cli::runRays(rays);
    }
    // A shared sensor run reports on rank 0 only; the other ranks return null.
    if (!result.is_null()) std::cout << result.dump() << std::endl;
    // A run stopped by SIGINT / SIGTERM saved its state and wrote its files; the exit status still
    // says it was stopped, as a shell expects (128 + the signal).
    if (*sensor_cmd && result.contains("signal")) return 128 + result["signal"].get<int>();
    return 0;
  } catch (const duplex::cli::Interrupted& e) {
    std::cerr << command << ": " << e.what() << " (signal " << e.signal() << ")\n";
    return 128 + e.signal();
  } catch (const duplex::cli::AllRanksFailedReported&) {
    return kExitBadInput;  // written by every rank before any ended (runSensor)
  } catch (const duplex::Error& e) {
    std::cerr << command << ": error: " << e.what() << '\n';
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << command << ": internal error: " << e.what() << '\n';
    return kExitInternal;
  } catch (...) {
    std::cerr << command << ": internal error: unknown exception\n";
    return kExitInternal;
  }
}
