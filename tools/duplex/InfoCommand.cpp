#include "InfoCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "LoadScene.h"
#include "StructureOption.h"
#include "WorkerThreads.h"

#include <duplex/scenegraph/SceneGraph.h>

#include <memory>
#include <optional>

namespace duplex::cli {

nlohmann::ordered_json runInfo(const InfoOptions& options) {
  WorkerThreads workers(options.threads);
  std::optional<SceneDocument> doc;
  workers.arena.execute([&] { doc.emplace(loadDocumentNamed(options.scene, documentOptions(options.structure))); });

  std::size_t visible = 0;
  for (const NodeId node : doc->instances) visible += doc->graph->isVisibleInstance(node);
  const Box bounds = visibleWorldBounds(*doc);
  const SceneLoadFigures& figures = doc->figures;

  nlohmann::ordered_json report;
  report["format"] = doc->format;
  report["objects"] = figures.objects;
  report["instances"] = doc->instances.size();
  report["visible_instances"] = visible;
  report["triangles"] = figures.count("triangles");
  report["instanced_triangles"] = instancedTriangles(*doc);
  report["mesh_structures"] = meshStructureCounts(*doc);
  report["edits"] = doc->edits.size();
  if (bounds.empty()) report["world_bounds"] = nullptr;
  else
    report["world_bounds"] = {{"min", {bounds.lo.x, bounds.lo.y, bounds.lo.z}},
                              {"max", {bounds.hi.x, bounds.hi.y, bounds.hi.z}}};
  report["structures_loaded"] = figures.structures_loaded;
  report["threads"] = workers.count;
  report["load_ms"] = figures.load_ms;
  report["build_ms"] = figures.build_ms;
  report["graph_ms"] = figures.graph_ms;
  return report;
}

void addInfoCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<InfoOptions>();
  CLI::App* cmd = parent.add_subcommand(
      "info", "Load a scene and report what it holds (objects, instances, triangles, world bounds) and the load times");
  cmd->add_option("--scene", options->scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  addStructureOption(*cmd, options->structure);
  addThreadsOption(*cmd, options->threads);
  onParsed(*cmd, chosen, options, runInfo);
}

}  // namespace duplex::cli
