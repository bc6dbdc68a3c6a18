#pragma once
/// \file SceneDocument.h
/// Scene files read into a SceneGraph: scene-json-v1 (the interchange format, to the letter) and
/// the project's own format "duplex-scene-v1" (groups, transform nodes, instances, objects through
/// the ObjectTypeRegistry, prepared bottom-level structures, timed edits). docs/scene-format.md
/// describes both with a complete example.
///
/// Errors throw FileError naming the file and the JSON pointer of the bad value
/// ("scene.json: /instances/3/transform/5: expected a number").

#include "duplex/accel/Affine.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/WorkControl.h"
#include "duplex/scenegraph/NodeId.h"
#include "duplex/scenegraph/ObjectTypeRegistry.h"
#include "duplex/scenegraph/SceneGraph.h"

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace duplex {

/// A node of the file's tree, or of an "add" edit, as read (objects resolved to library ids).
struct SceneNodeSpec {
  NodeKind kind = NodeKind::Group;      ///< group, transform node or instance
  std::string name;                     ///< may be empty: the graph names it "<kind><id>"
  Affine local;                         ///< parent_from_local (transform nodes and instances)
  bool visible = true;                  ///< the node's own visibility flag
  ObjectId object = kInvalidObject;     ///< instances
  std::uint32_t mask = 0xFFFFFFFFu;     ///< instances
  std::vector<SceneNodeSpec> children;  ///< groups and transform nodes
  std::string pointer;                  ///< JSON pointer, for messages
};

/// What a timed edit does (the key of the edit in the file).
enum class SceneEditKind : std::uint8_t {
  SetTransform,  ///< "set_transform": replace the node's local transform
  Add,           ///< "add": add a subtree under the node
  Remove,        ///< "remove": remove the node and its subtree
  SetVisible,    ///< "visible": hide or show the node
  SetObject,     ///< "object": give the instance another library object
  SetMask,       ///< "mask": set the instance's mask
  Deform,        ///< "deform": move a library object's vertices (SceneGraph::deformObject)
  AddObject      ///< "add_object": load an object not declared in "objects" (read now, built then)
};

/// One timed edit of the file's "edits" list; applied (by the demo, a player) with applyEdit().
struct SceneEdit {
  double time = 0.0;                                 ///< seconds from the start of the animation, >= 0
  SceneEditKind kind = SceneEditKind::SetTransform;  ///< what the edit does (the other fields it uses are marked)
  std::string node;                                  ///< path of the edited node; for Add, of the parent ("/" = root)
  Affine transform;                                  ///< SetTransform: the node's new local transform
  bool visible = true;                               ///< SetVisible
  ObjectId object = kInvalidObject;                  ///< SetObject; Deform, AddObject: the library object
  std::uint32_t mask = 0xFFFFFFFFu;                  ///< SetMask
  std::shared_ptr<const SceneNodeSpec> added;        ///< Add: the subtree to add
  /// Deform (with `object`, the library object deformed): the new object-space positions, given
  /// the object as it is when the edit is applied (inline "positions", or read from "file").
  std::function<std::vector<glm::vec3>(const Object& current)> positions;
  std::string pointer;  ///< "/edits/3", for messages
};

/// Figures of a load (milliseconds of wall time).
struct SceneLoadFigures {
  double load_ms = 0.0;               ///< reading and parsing the JSON, the object specs, and the files they name
  double build_ms = 0.0;              ///< bottom-level structures (built, or loaded from prepared files), in parallel
  double graph_ms = 0.0;              ///< adding the nodes to the graph and the first commit
  std::size_t objects = 0;            ///< library objects (the "objects" entries)
  std::size_t structures_loaded = 0;  ///< prepared bottom-level structures read instead of built
  std::size_t instances = 0;          ///< instance nodes
  std::size_t nodes = 0;              ///< graph nodes, root included
  /// What the object types report, summed: each object's Object::figures() over the distinct
  /// objects ("triangles", "degenerate_triangles", ...), the counts their readers added while
  /// reading files ("repeated_corner_faces", "complex_edge_warnings"), and "<kind>_files", the distinct files read per
  /// kind
  /// ("mesh_files").
  std::map<std::string, std::size_t, std::less<>> counts;

  /// counts[name], 0 when absent.
  [[nodiscard]] std::size_t count(std::string_view name) const {
    const auto it = counts.find(name);
    return it == counts.end() ? 0 : it->second;
  }
};

/// Options of loadSceneDocument().
struct SceneDocumentOptions {
  KdBuildConfig build;  ///< kd-tree build parameters of the types that build kd-trees
  /// Progress of the bottom-level builds (objects built or read from prepared structures, out of
  /// the "objects" entries to build) and cancellation: a cancelled load throws Cancelled and
  /// returns nothing (the caller's scene, if any, is untouched).
  WorkControl control;
  /// Honour "structure" keys that name prepared bottom-level structures; false builds every object
  /// (structure choices such as "kdtree" still apply).
  bool use_structures = true;
  /// The structure choice for the entries that make none, in the syntax of the "structure" key
  /// ("bvh", "kdtree", "bvh:fast", "bvh:medium,leaf=4"): used by every type that offers the name
  /// (ObjectTypeInfo::structure_names), ignored by the others. Empty: each type's own default. A
  /// name no registered type offers is refused (FileError naming the scene file).
  std::string structure;
};

/// A loaded scene file: the graph (committed once, so a SceneTracer sees every instance), with its
/// library, and what the file says beyond the graph.
struct SceneDocument {
  std::filesystem::path file;         ///< the scene file, as given (messages name it)
  std::string format;                 ///< "scene-json-v1" or "duplex-scene-v1"
  std::unique_ptr<SceneGraph> graph;  ///< the scene, committed once; never null
  std::vector<ObjectId> objects;      ///< the "objects" entries, in file order
  /// Instance nodes in file order (depth first in the own format). For scene-json-v1 the position is
  /// the instance id of the hit file: instances[id] is its node. v1 instances are children of the
  /// root named "instance<k>".
  std::vector<NodeId> instances;
  std::vector<SceneEdit> edits;  ///< sorted by time (stable: equal times keep file order)
  SceneLoadFigures figures;      ///< what the load took and counted
  /// The parsed file, for the layers above the graph: the top-level "lights" and "sensors" keys and
  /// the objects' "material" keys are read by duplex::sensors (SensorScene), not here.
  std::shared_ptr<const nlohmann::json> parsed;
};

/// Reads `path` (either format, by its "format" key). Objects are read through `registry` (e.g.
/// duplex::builtinObjectTypes(), or duplex::sensorTypeRegistry() with sensors); their
/// bottom-level structures are built (or loaded) in parallel, each file a type requests read once and objects of
/// the same source built once, before the instances are added; then the graph is committed. Throws
/// FileError naming the file and the JSON pointer of the first problem (objects: the first in file
/// order whose build failed).
[[nodiscard]] SceneDocument loadSceneDocument(const std::filesystem::path& path, const ObjectTypeRegistry& registry,
                                              const SceneDocumentOptions& options = {});

/// Reads edits given at run time (an editor, a viewer's requests) in the vocabulary of the file's
/// "edits" (duplex-scene-v1, docs/scene-format.md), without "time": `edits` is a JSON array; node
/// paths and object names are resolved when applied (applyEdit) and at parse time against doc's
/// library respectively. Edits that read files ("add_object", "deform" with "file") and edits with a
/// "time" are refused. Throws FileError naming `source` (e.g. "request body") and the JSON pointer
/// of the first problem ("request body: /2/set_transform/3: expected a number"), NaN and infinite
/// numbers included; nothing is applied.
[[nodiscard]] std::vector<SceneEdit> parseLiveEdits(const SceneDocument& doc, const nlohmann::json& edits,
                                                    const std::string& source, const ObjectTypeRegistry& registry);

/// Applies `edit` to doc.graph (without committing). Returns the nodes an Add created (its subtree,
/// depth first), else nothing. Throws FileError naming doc.file and edit.pointer when the node path
/// does not exist (now) or the graph refuses the edit; the graph is then unchanged.
std::vector<NodeId> applyEdit(SceneDocument& doc, const SceneEdit& edit);

/// Applies the edits of one step of the animation, doc.edits[first, end) that share
/// doc.edits[first].time, in file order, without committing; returns end (first when first >=
/// doc.edits.size()). Throws as applyEdit; the group's earlier edits then stay pending (commit or
/// roll them back).
std::size_t applyEditGroup(SceneDocument& doc, std::size_t first);

/// Plays the timed edits up to `time` (seconds): every edit with time <= `time`, one group of equal
/// times after another, committing the graph after each group as a player does (an edit's node
/// path is resolved against the graph the earlier groups left). Returns the number of edits
/// applied. A failing edit or commit rolls its group back (the earlier groups stay committed) and
/// throws FileError naming doc.file and the edit's pointer. A NaN `time` applies nothing.
std::size_t applyEditsUntil(SceneDocument& doc, double time);

/// Writes the prepared bottom-level structure of every object of doc's library whose type has a
/// prepared format (Object::preparedExtension(); meshes: ".dbvh" or ".dkdt"), built now if deferred, to `dir`
/// (created if needed) as "<object id>_<name><extension>" (characters other than [A-Za-z0-9._-]
/// replaced by '_'), for use as "structure" in a scene file. Returns the path per library object id
/// (empty for objects of types without one and for removed objects). An object shared by several entries is written
/// once per entry. Throws FileError naming the folder or file that cannot be created or written.
std::vector<std::filesystem::path> saveStructures(const SceneDocument& doc, const std::filesystem::path& dir);

}  // namespace duplex
