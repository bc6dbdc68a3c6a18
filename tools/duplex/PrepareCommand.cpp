#include "PrepareCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "Elapsed.h"
#include "StructureOption.h"
#include "LoadScene.h"
#include "WorkerThreads.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/InputFile.h>
#include <duplex/scenegraph/ObjectTypeRegistry.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/sensors/SensorTypes.h>

#include <tbb/task_arena.h>

#include <chrono>
#include <cstddef>
#include <fstream>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

namespace duplex::cli {

namespace {

namespace fs = std::filesystem;
using OrderedJson = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

OrderedJson readJson(const fs::path& path) {
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError(path.string() + ": cannot open: " + problem);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(path.string() + ": cannot open");
  try {
    return OrderedJson::parse(in);
  } catch (const OrderedJson::exception& e) {
    throw FileError(path.string() + ": " + e.what());
  }
}

/// `file` as named in the source scene, as it must be named in a scene file in `out_dir`.
std::string rebasePath(const std::string& file, const fs::path& source_dir, const fs::path& out_dir) {
  const fs::path named(file);
  const fs::path target = (named.is_absolute() ? named : fs::absolute(source_dir / named)).lexically_normal();
  const fs::path relative = target.lexically_relative(fs::absolute(out_dir).lexically_normal());
  return relative.empty() ? target.string() : relative.generic_string();
}

/// A type's spec for the copy: a "file" key rebased to `out_dir`. A v1 mesh keeps only what v1
/// reads ("file" wins over the inline arrays); the own format's specs are copied as they are.
OrderedJson specForCopy(const std::string& type, const OrderedJson& spec, bool v1, const fs::path& source_dir,
                        const fs::path& out_dir) {
  OrderedJson out = spec;
  if (v1 && type == "mesh") {
    out = OrderedJson::object();
    if (spec.contains("file")) {
      out["file"] = spec["file"];
    } else {
      out["positions"] = spec["positions"];
      out["indices"] = spec["indices"];
    }
  }
  if (out.is_object() && out.contains("file") && out["file"].is_string())
    out["file"] = rebasePath(out["file"].get<std::string>(), source_dir, out_dir);
  return out;
}

/// Compact JSON with one line per top-level key and per element of its arrays (objects, nodes,
/// edits): small for inline meshes, readable in a diff.
std::string layout(const OrderedJson& doc) {
  std::string text = "{";
  bool first_key = true;
  for (const auto& [key, value] : doc.items()) {
    text += (first_key ? "" : ",\n ") + OrderedJson(key).dump() + ": ";
    first_key = false;
    if (!value.is_array() || value.empty()) {
      text += value.dump();
      continue;
    }
    for (std::size_t i = 0; i < value.size(); ++i) text += (i == 0 ? "[\n  " : ",\n  ") + value[i].dump();
    text += "]";
  }
  return text + "}\n";
}

void writeReplacing(const fs::path& path, const std::string& text) {
  const fs::path temporary = fs::path(path.string() + ".tmp");
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) throw FileError(path.string() + ": cannot write");
  }
  std::error_code ec;
  fs::rename(temporary, path, ec);
  if (ec) throw FileError(path.string() + ": cannot write (" + ec.message() + ")");
}

}  // namespace

nlohmann::ordered_json runPrepare(const PrepareOptions& options) {
  const fs::path scene_out = options.out / (options.scene.stem().string() + ".json");
  std::error_code ec;
  if (fs::exists(scene_out, ec) && fs::equivalent(scene_out, options.scene, ec))
    throw InvalidArgument(scene_out.string() + ": would overwrite the source scene; choose another --out");

  WorkerThreads workers(options.threads);
  tbb::task_arena& arena = workers.arena;
  const int threads = workers.count;

  // Load (and so check) the scene the way `duplex trace` does; prepared entries are rebuilt, so a
  // stale structure named by the source is replaced rather than copied.
  SceneDocumentOptions load_options = documentOptions(options.structure);
  load_options.use_structures = false;
  std::optional<SceneDocument> doc;
  arena.execute([&] { doc.emplace(loadDocumentNamed(options.scene, load_options)); });

  const auto t_save = Clock::now();
  const std::vector<fs::path> saved = saveStructures(*doc, options.out);
  const double save_ms = msSince(t_save);

  // The copy: the loader accepted the file, so its shape is known to be valid here.
  const OrderedJson source = readJson(options.scene);
  const bool v1 = doc->format == "scene-json-v1";
  const fs::path source_dir = options.scene.parent_path();
  OrderedJson copy = OrderedJson::object();
  copy["format"] = "duplex-scene-v1";
  copy["objects"] = OrderedJson::array();
  std::size_t mesh_objects = 0, structures = 0;
  const ObjectLibrary& library = doc->graph->library();
  const ObjectTypeRegistry& registry = sensorTypeRegistry();  // the types loadDocumentNamed reads
  const OrderedJson& objects = source["objects"];
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const OrderedJson& entry = objects[k];
    const ObjectId id = doc->objects.at(k);
    const fs::path& structure = saved.at(id);
    // The entry's type is the registered key the loader found in it.
    const std::string type(library.typeName(id));
    const ObjectTypeInfo* info = registry.find(type);
    OrderedJson out_entry = v1 ? OrderedJson{{"name", entry["name"]}} : entry;
    out_entry[type] = specForCopy(type, entry[type], v1, source_dir, options.out);
    if (info && info->accepts_structure) {
      if (structure.empty())
        throw InvalidArgument(options.scene.string() + ": /objects/" + std::to_string(k) + ": " + type +
                              " object without a saved structure");
      out_entry["structure"] = structure.filename().string();
      ++structures;
    } else if (!structure.empty()) {
      fs::remove(structure, ec);  // types without structure files (procedural shapes) rebuild from their spec
    }
    if (type == "mesh") ++mesh_objects;
    copy["objects"].push_back(std::move(out_entry));
  }
  if (v1) {
    copy["nodes"] = OrderedJson::array();
    const OrderedJson& instances = source["instances"];
    for (std::size_t k = 0; k < instances.size(); ++k)
      copy["nodes"].push_back({{"instance", "instance" + std::to_string(k)},
                               {"object", instances[k]["object"]},
                               {"transform", instances[k]["transform"]}});
  } else {
    for (const char* key : {"nodes", "edits"})
      if (source.contains(key)) copy[key] = source[key];
  }
  writeReplacing(scene_out, layout(copy));

  OrderedJson report;
  report["scene"] = scene_out.string();
  report["format_in"] = doc->format;
  report["objects"] = objects.size();
  report["mesh_objects"] = mesh_objects;
  report["structures"] = structures;
  report["load_ms"] = doc->figures.load_ms + doc->figures.graph_ms;
  report["build_ms"] = doc->figures.build_ms;
  report["save_ms"] = save_ms;
  report["threads"] = threads;
  report["mesh_structures"] = meshStructureCounts(*doc);
  return report;
}

void addPrepareCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<PrepareOptions>();
  PrepareOptions& prepare = *options;
  CLI::App* cmd = parent.add_subcommand(
      "prepare", "Save the bottom-level structure of every mesh object and a duplex-scene-v1 copy that names them");
  cmd->add_option("--scene", prepare.scene, "scene-json-v1 or duplex-scene-v1 file")->required();
  cmd->add_option("--out", prepare.out, "Folder for <scene stem>.json and the .dbvh / .dkdt structure files")
      ->required();
  addStructureOption(*cmd, prepare.structure);
  addThreadsOption(*cmd, prepare.threads);
  onParsed(*cmd, chosen, options, runPrepare);
}

}  // namespace duplex::cli
