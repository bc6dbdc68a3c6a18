#pragma once
/// \file LoadScene.h
/// Scene files for the tool's commands: duplex::loadSceneDocument (scene-json-v1 and
/// duplex-scene-v1) with every failure reported as a duplex::FileError naming the scene file, and
/// the hit-file view of a loaded document (instance ids, world bounds, triangle counts).

#include <duplex/accel/Box.h>
#include <duplex/scenegraph/SceneDocument.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace duplex::cli {

/// Same as duplex::loadSceneDocument with duplex::sensorTypeRegistry() (the built-in object types and
/// the sensor type). Some failures reach callers as other exceptions (e.g.
/// nlohmann's out_of_range for a number such as 1e999); they are rethrown as
/// FileError("<file>: <what>") so that the tool's message always names the file.
[[nodiscard]] SceneDocument loadDocumentNamed(const std::filesystem::path& path,
                                              const SceneDocumentOptions& options = {});

/// The options of a command's load with --structure `structure` (empty: the types' defaults).
[[nodiscard]] inline SceneDocumentOptions documentOptions(const std::string& structure) {
  SceneDocumentOptions options;
  options.structure = structure;
  return options;
}

/// Distinct mesh objects of doc's library per structure ("bvh", "kdtree"; prepared ones included).
[[nodiscard]] std::map<std::string, std::size_t> meshStructureCounts(const SceneDocument& doc);

/// The hit file's instance ids of a document's instance nodes. The id of an instance is its
/// position in SceneDocument::instances: for scene-json-v1 the position in "instances" (the
/// interchange contract); for duplex-scene-v1 the position in depth-first file order of the node
/// tree, hidden instances included (they are never hit, but keep their place).
class InstanceIds {
 public:
  explicit InstanceIds(const SceneDocument& doc);
  /// The hit-file id of node `node`; kInvalidId for kInvalidId (a miss) and for nodes that are not
  /// instances of the document (none is hit while the graph is not edited).
  [[nodiscard]] std::uint32_t of(std::uint32_t node) const {
    return node < by_node_.size() ? by_node_[node] : 0xFFFFFFFFu;
  }

 private:
  std::vector<std::uint32_t> by_node_;
};

/// Union of the world boxes of the visible instances as of the last commit (each object's box
/// mapped by its world_from_object), in the order of SceneDocument::instances. Empty without any.
[[nodiscard]] Box visibleWorldBounds(const SceneDocument& doc);

/// The visible instances of `doc` as of the last commit, in the order of SceneDocument::instances:
/// what the benchmarks move. Throws InvalidArgument naming `scene` (the document's file) when there
/// is none.
[[nodiscard]] std::vector<NodeId> visibleInstances(const SceneDocument& doc, const std::filesystem::path& scene);

/// Triangles as the rays see them: the mesh triangles of every instance (hidden ones included),
/// summed over instances.
[[nodiscard]] std::size_t instancedTriangles(const SceneDocument& doc);

}  // namespace duplex::cli
