#include "TraceCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "Elapsed.h"
#include "StructureOption.h"
#include "LoadScene.h"
#include "WorkerThreads.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/InputFile.h>
#include <duplex/accel/MemoryLimit.h>
#include <duplex/accel/RayFile.h>
#include <duplex/scenegraph/SceneTracer.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <optional>
#include <sstream>
#include <span>
#include <vector>

namespace duplex::cli {

namespace {

using Clock = std::chrono::steady_clock;

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

}  // namespace

nlohmann::ordered_json runTrace(const TraceOptions& options) {
  if (options.repeat < 1) throw InvalidArgument("--repeat must be at least 1");
  const bool want_transmittance = !options.transmittance.empty();
  if (want_transmittance == !options.hits.empty())
    throw InvalidArgument("give exactly one of --hits and --transmittance");
  if (want_transmittance && options.any_hit) throw InvalidArgument("--transmittance cannot be combined with --any-hit");
  const std::filesystem::path& output = want_transmittance ? options.transmittance : options.hits;
  if (sameFile(options.rays, output))
    throw InvalidArgument((want_transmittance ? "--transmittance " : "--hits ") + output.string() +
                          " names the ray file given as --rays: it would be overwritten");
  if (options.block_rays < 1) throw InvalidArgument("--block-rays must be at least 1");
  WorkerThreads workers(options.threads);
  tbb::task_arena& arena = workers.arena;
  const int threads = workers.count;

  // The ray file first: a bad one fails before the (longer) scene load. It is read in blocks, so
  // that memory is bounded by the scene and the block, not by the ray count.
  RayFileReader ray_file(options.rays, "ray");
  const std::size_t ray_count = ray_file.count();
  // What a block holds (its rays, the query's answers and the records written), checked before the
  // scene is loaded.
  const std::size_t block =
      std::min<std::size_t>(static_cast<std::size_t>(options.block_rays), std::max<std::size_t>(ray_count, 1));
  {
    const std::uint64_t per_ray = sizeof(Ray) + (want_transmittance ? sizeof(float)
                                                 : options.any_hit  ? sizeof(std::uint8_t) + sizeof(HitRecord)
                                                                    : sizeof(Hit) + sizeof(HitRecord));
    std::ostringstream what;
    what << "--block-rays " << block << " (blocks of the ray file '" << options.rays.string() << "')";
    requireMemory(arrayBytes(block, per_ray), what.str());
  }

  // Load (bottom levels built or read in parallel inside the arena), then the tracer's top level.
  std::optional<SceneDocument> doc;
  std::unique_ptr<SceneTracer> tracer;
  double top_build_ms = 0.0;
  arena.execute([&] {
    doc.emplace(loadDocumentNamed(options.scene, documentOptions(options.structure)));
    const auto t0 = Clock::now();
    tracer = std::make_unique<SceneTracer>(*doc->graph);
    top_build_ms = msSince(t0);
    tracer->setBatchPackets(!options.single);
  });

  // Block by block: read, trace `repeat` times (each run's time summed over the blocks, reading
  // and writing excluded), store the last run's results. The output appears only when complete.
  std::vector<Ray> rays(block);
  std::vector<Hit> hits(options.any_hit || want_transmittance ? 0 : block);
  std::vector<std::uint8_t> blocked(options.any_hit ? block : 0);
  std::vector<float> transmittance(want_transmittance ? block : 0);
  std::vector<HitRecord> records(want_transmittance ? 0 : block);
  std::optional<RecordFileWriter<float>> transmittance_file;
  std::optional<HitFileWriter> hit_file;
  if (want_transmittance) transmittance_file.emplace(options.transmittance, "transmittance");
  else hit_file.emplace(options.hits, "hit");
  const InstanceIds ids(*doc);  // the tracer names instances by node id, the hit file by position
  std::vector<double> trace_ms(static_cast<std::size_t>(options.repeat), 0.0);
  std::size_t hit_count = 0;
  double transmittance_sum = 0.0;
  for (std::size_t first = 0; first < ray_count; first += block) {
    const std::size_t n = std::min(block, ray_count - first);
    const std::span<Ray> in(rays.data(), n);
    ray_file.read(first, in);
    for (int run = 0; run < options.repeat; ++run) {
      const auto t0 = Clock::now();
      arena.execute([&] {
        if (want_transmittance) tracer->transmittance(in, std::span<float>(transmittance.data(), n));
        else if (options.any_hit) tracer->occluded(in, std::span<std::uint8_t>(blocked.data(), n));
        else tracer->intersect(in, std::span<Hit>(hits.data(), n));
      });
      trace_ms[static_cast<std::size_t>(run)] += msSince(t0);
    }
    if (want_transmittance) {
      for (std::size_t i = 0; i < n; ++i) {
        hit_count += transmittance[i] == 0.0f ? 1u : 0u;
        transmittance_sum += transmittance[i];
      }
      transmittance_file->write(std::span<const float>(transmittance.data(), n));
      continue;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (options.any_hit) {
        records[i] = occlusionRecord(blocked[i] != 0);
      } else {
        Hit h = hits[i];
        if (h.valid()) h.instance_id = ids.of(h.instance_id);
        records[i] = HitRecord::from(h);
      }
      hit_count += records[i].instance_id != kInvalidId ? 1u : 0u;
    }
    hit_file->write(std::span<const HitRecord>(records.data(), n));
  }
  if (transmittance_file) transmittance_file->commit();
  if (hit_file) hit_file->commit();

  const double trace_median = median(trace_ms);
  const double mrays_per_s = trace_median > 0.0 ? static_cast<double>(ray_count) / (trace_median * 1e3) : 0.0;
  const SceneLoadFigures& figures = doc->figures;

  nlohmann::ordered_json report;
  report["rays"] = ray_count;
  report["hits"] = hit_count;
  report["threads"] = threads;
  report["load_ms"] = figures.load_ms + figures.graph_ms;
  report["build_ms"] = figures.build_ms + top_build_ms;
  report["trace_ms"] = trace_median;
  report["mrays_per_s"] = mrays_per_s;
  report["repeat"] = options.repeat;
  report["any_hit"] = options.any_hit;
  report["objects"] = figures.objects;
  report["instances"] = doc->instances.size();
  report["triangles"] = figures.count("triangles");
  report["instanced_triangles"] = instancedTriangles(*doc);
  report["bottom_build_ms"] = figures.build_ms;
  report["top_build_ms"] = top_build_ms;
  report["trace_ms_all"] = trace_ms;
  report["format"] = doc->format;
  report["structures_loaded"] = figures.structures_loaded;
  report["packets"] = !options.single;
  report["graph_ms"] = figures.graph_ms;
  report["mesh_structures"] = meshStructureCounts(*doc);
  report["block_rays"] = block;
  if (want_transmittance) {
    report["transmittance"] = true;
    report["mean_transmittance"] = ray_count == 0 ? 0.0 : transmittance_sum / static_cast<double>(ray_count);
  }
  return report;
}

void addTraceCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<TraceOptions>();
  TraceOptions& trace = *options;
  CLI::App* cmd = parent.add_subcommand("trace", "Trace a ray file against a scene and write a hit file");
  cmd->add_option("--scene", trace.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  addStructureOption(*cmd, trace.structure);
  cmd->add_option("--rays", trace.rays, "Ray file: 32-byte records ox oy oz tnear dx dy dz tfar")->required();
  CLI::Option* hits_opt =
      cmd->add_option("--hits", trace.hits, "Hit file to write: 20-byte records t u v instance_id prim_id");
  CLI::Option* transmittance_opt = cmd->add_option(
      "--transmittance", trace.transmittance,
      "Instead of hits: one float32 per ray, the transmittance along [tnear, tfar] through all fog volumes "
      "(0 where a surface blocks the ray)");
  hits_opt->excludes(transmittance_opt);
  addThreadsOption(*cmd, trace.threads);
  cmd->add_flag("--any-hit", trace.any_hit,
                "Occlusion queries: blocked -> {0, 0, 0, instance 0, prim 0xFFFFFFFF}, free -> miss");
  cmd->add_flag("--single", trace.single,
                "Trace one ray at a time instead of in packets (same hits; for speed comparisons)");
  cmd->add_option("--repeat", trace.repeat, "Trace R times and report the median time")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--block-rays", trace.block_rays,
                  "Rays read, traced and written per block (memory: about 100 bytes per ray of a block)")
      ->transform(kDecimal)
      ->check(CLI::Range(std::int64_t{1}, std::int64_t{1} << 32))
      ->capture_default_str();
  cmd->footer(
      "A hit's instance_id is the instance's position in the scene: in \"instances\" for scene-json-v1; in\n"
      "depth-first file order of the node tree for duplex-scene-v1 (hidden instances keep their place).\n"
      "The timed edits of a duplex-scene-v1 file are not applied.");
  onParsed(*cmd, chosen, options, runTrace);
}

}  // namespace duplex::cli
