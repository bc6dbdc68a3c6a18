#include "LoadScene.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/Hit.h>
#include <duplex/objects/MeshObject.h>
#include <duplex/sensors/SensorTypes.h>

#include <algorithm>
#include <exception>
#include <new>
#include <string>
#include <unordered_set>

namespace duplex::cli {

SceneDocument loadDocumentNamed(const std::filesystem::path& path, const SceneDocumentOptions& options) {
  try {
    // Every command reads sensor objects of duplex-scene-v1 files (they never block a ray).
    return loadSceneDocument(path, sensorTypeRegistry(), options);
  } catch (const Error&) {
    throw;  // already names the file
  } catch (const std::bad_alloc&) {
    throw;
  } catch (const std::exception& e) {
    throw FileError(path.string() + ": " + e.what());
  }
}

InstanceIds::InstanceIds(const SceneDocument& doc) {
  NodeId largest = 0;
  for (const NodeId node : doc.instances) largest = std::max(largest, node);
  by_node_.assign(doc.instances.empty() ? 0 : std::size_t{largest} + 1, kInvalidId);
  for (std::size_t i = 0; i < doc.instances.size(); ++i) by_node_[doc.instances[i]] = static_cast<std::uint32_t>(i);
}

Box visibleWorldBounds(const SceneDocument& doc) { return doc.graph->worldBounds(doc.instances); }

std::vector<NodeId> visibleInstances(const SceneDocument& doc, const std::filesystem::path& scene) {
  std::vector<NodeId> visible;
  for (const NodeId node : doc.instances)
    if (doc.graph->isVisibleInstance(node)) visible.push_back(node);
  if (visible.empty()) throw InvalidArgument(scene.string() + ": no visible instances to move");
  return visible;
}

std::map<std::string, std::size_t> meshStructureCounts(const SceneDocument& doc) {
  const ObjectLibrary& library = doc.graph->library();
  std::map<std::string, std::size_t> counts;
  std::unordered_set<const Object*> seen;
  for (ObjectId id = 0; id < library.size(); ++id) {
    if (!library.contains(id)) continue;  // removed
    const auto object = library.get(id);
    if (!seen.insert(object.get()).second) continue;
    if (const auto* mesh = dynamic_cast<const MeshObject*>(object.get()))
      ++counts[std::string(toString(mesh->structure()))];
  }
  return counts;
}

std::size_t instancedTriangles(const SceneDocument& doc) {
  const SceneGraph& graph = *doc.graph;
  std::size_t n = 0;
  for (const NodeId node : doc.instances) {
    for (const ObjectFigure& figure : graph.library().get(graph.node(node).object)->figures())
      if (figure.name == "triangles") n += figure.value;
  }
  return n;
}

}  // namespace duplex::cli
