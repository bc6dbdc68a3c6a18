#include "ClosestCommand.h"

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

#include <chrono>
#include <memory>
#include <optional>
#include <sstream>
#include <vector>

namespace duplex::cli {

namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

nlohmann::ordered_json runClosest(const ClosestOptions& options) {
  WorkerThreads workers(options.threads);
  // The point file first: a bad one fails before the (longer) scene load.
  if (sameFile(options.points, options.out))
    throw InvalidArgument("--out " + options.out.string() +
                          " names the point file given as --points: it would be overwritten");
  {
    // Per point: its record, the query, the answer and the record written.
    const RecordFileReader<PointRecord> probe(options.points, "point");
    std::ostringstream what;
    what << "point file '" << options.points.string() << "' (" << probe.count() << " points)";
    requireMemory(arrayBytes(probe.count(), sizeof(PointRecord) + sizeof(ClosestPointRequest) + sizeof(ClosestPoint) +
                                                sizeof(ClosestRecord)),
                  what.str());
  }
  const std::vector<PointRecord> points = readPointFile(options.points);
  std::optional<SceneDocument> doc;
  std::unique_ptr<SceneTracer> tracer;
  double top_build_ms = 0.0;
  workers.arena.execute([&] {
    doc.emplace(loadDocumentNamed(options.scene, documentOptions(options.structure)));
    const auto t0 = Clock::now();
    tracer = std::make_unique<SceneTracer>(*doc->graph);
    top_build_ms = msSince(t0);
  });
  std::vector<ClosestPointRequest> requests(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    requests[i] = {glm::dvec3(points[i].x, points[i].y, points[i].z), static_cast<double>(points[i].max_distance)};
  std::vector<ClosestPoint> answers(points.size());
  const auto t0 = Clock::now();
  workers.arena.execute([&] { tracer->closestPoints(requests, answers); });
  const double query_ms = msSince(t0);

  // The tracer names instances by node id, the file by position in the document.
  const InstanceIds ids(*doc);
  std::vector<ClosestRecord> records(points.size(), ClosestRecord::none());
  std::size_t found = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const ClosestPoint& a = answers[i];
    if (!a.valid()) continue;
    ++found;
    records[i] = {static_cast<float>(a.point_ws.x),
                  static_cast<float>(a.point_ws.y),
                  static_cast<float>(a.point_ws.z),
                  static_cast<float>(a.distance),
                  ids.of(a.instance_id),
                  a.prim_id};
  }
  writeClosestFile(options.out, records);

  const SceneLoadFigures& figures = doc->figures;
  nlohmann::ordered_json report;
  report["points"] = points.size();
  report["found"] = found;
  report["threads"] = workers.count;
  report["load_ms"] = figures.load_ms + figures.graph_ms;
  report["build_ms"] = figures.build_ms + top_build_ms;
  report["query_ms"] = query_ms;
  report["objects"] = figures.objects;
  report["instances"] = figures.instances;
  report["format"] = doc->format;
  return report;
}

void addClosestCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<ClosestOptions>();
  ClosestOptions& closest = *options;
  CLI::App* cmd = parent.add_subcommand(
      "closest", "Nearest surface point to each point of a point file (16-byte records in, 24-byte records out)");
  cmd->add_option("--scene", closest.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  cmd->add_option("--points", closest.points, "Point file: float x, y, z, max_distance per record")->required();
  cmd->add_option("--out", closest.out,
                  "Closest file to write: float x, y, z, distance; uint32 instance_id, prim_id per point")
      ->required();
  addStructureOption(*cmd, closest.structure);
  addThreadsOption(*cmd, closest.threads);
  onParsed(*cmd, chosen, options, runClosest);
}

}  // namespace duplex::cli
