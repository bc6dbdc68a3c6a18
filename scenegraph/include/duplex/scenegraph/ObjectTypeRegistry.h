#pragma once
/// \file ObjectTypeRegistry.h
/// Object types by the name a scene file uses for them. An object entry of a scene file is
/// `{"name": N, "<type>": SPEC, "structure": S?}`, S a prepared structure's PATH or, for types that
/// offer several structures, a choice "<name>" or "<name>:<parameters>"; the reader finds the type by which registered
/// key the entry has (exactly one) and hands SPEC to that type's reader, which returns the object
/// built, or a factory that ObjectLibrary calls later (in parallel, ObjectLibrary::buildAll).
///
/// The scene graph knows no object type: each type's folder registers its own
/// (`registerMeshTypes`, `registerShapeTypes`, `registerVolumeTypes` in duplex::objects,
/// `registerSensorTypes` in duplex::sensors), and duplex::builtinObjectTypes() holds the types of
/// duplex::objects. docs/object-types.md shows how a new type plugs in.

#include "duplex/accel/Error.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/Object.h"
#include "duplex/scenegraph/ObjectLibrary.h"
#include "duplex/scenegraph/SceneLoadCache.h"

#include <nlohmann/json_fwd.hpp>

#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace duplex {

/// What a type's reader is given besides its spec.
struct ObjectSpecContext {
  std::filesystem::path scene_file;  ///< for messages; relative paths resolve against its folder
  std::string pointer;               ///< JSON pointer of the spec, e.g. "/objects/3/mesh"
  std::string entry_pointer;         ///< JSON pointer of the object entry, e.g. "/objects/3"
  std::string object_name;           ///< the entry's "name"
  KdBuildConfig build;               ///< bottom-level build parameters
  /// A prepared bottom-level structure (resolved path) to load instead of building, when the entry
  /// names one ("structure") and the type accepts it.
  std::optional<std::filesystem::path> structure;
  /// The bottom-level structure to build, one of the type's ObjectTypeInfo::structure_names: the
  /// entry's choice ("structure": "<name>[:<parameters>]"), else the load's default
  /// (SceneDocumentOptions::structure) when the type offers that name; empty: the type's own default.
  std::string structure_name;
  /// The text after "<name>:" (empty without one), for the type to parse (its errors go through
  /// fail(structure_pointer, ...)).
  std::string structure_params;
  /// Where the choice came from, for messages: "/objects/3/structure", or the entry's pointer when
  /// it is the load's default.
  std::string structure_pointer;
  /// Own format: unknown keys are errors. scene-json-v1: unknown keys are ignored.
  bool strict = false;
  std::shared_ptr<SceneLoadCache> cache;  ///< never null

  /// Throws FileError "<scene file>: <pointer>: <problem>".
  [[noreturn]] void fail(const std::string& pointer, const std::string& problem) const;
  /// `path` relative to the scene file's folder (absolute paths unchanged).
  [[nodiscard]] std::filesystem::path resolve(const std::string& path) const;

  // JSON helpers with errors naming the file and pointer (`at` is the value's pointer).
  /// obj[key]; fails when `obj` is not an object or has no `key`.
  [[nodiscard]] const nlohmann::json& member(const nlohmann::json& obj, const std::string& at, const char* key) const;
  /// `v` as a finite number; fails otherwise.
  [[nodiscard]] double number(const nlohmann::json& v, const std::string& at) const;
  /// `v` as a finite number > 0; fails otherwise.
  [[nodiscard]] double positiveNumber(const nlohmann::json& v, const std::string& at) const;
  /// `v` as a string; fails otherwise.
  [[nodiscard]] std::string string(const nlohmann::json& v, const std::string& at) const;
  /// A number or an array of `n` numbers (a number s means n copies of s), each > 0.
  [[nodiscard]] std::vector<double> positiveSizes(const nlohmann::json& v, const std::string& at, std::size_t n) const;
  /// In strict mode, fails on the first key of `obj` not in `allowed`.
  void onlyKeys(const nlohmann::json& obj, const std::string& at,
                std::initializer_list<std::string_view> allowed) const;
};

/// A reader's answer: the object, built now, or a factory for ObjectLibrary::addDeferred.
using ObjectSpecResult = std::variant<std::shared_ptr<const Object>, ObjectLibrary::Factory>;
/// Reads a type's spec. Called serially while the scene file is read; errors must throw (ctx.fail).
/// A returned factory may run on any thread, after the scene file is closed; it captures what it
/// needs (the context by value) and throws on failure (the scene reader adds file and pointer).
using ObjectTypeReader = std::function<ObjectSpecResult(const nlohmann::json& spec, const ObjectSpecContext& ctx)>;

/// One object type as the scene reader sees it: its key and its reader.
struct ObjectTypeInfo {
  std::string name;         ///< the key in an object entry ("mesh")
  ObjectTypeReader reader;  ///< reads the type's spec; not null
  /// The key belongs to the scene-json-v1 interchange format (read in v1 files; other keys are
  /// ignored there, as v1 requires).
  bool in_scene_json_v1 = false;
  /// The type loads prepared bottom-level structures ("structure" in the entry); for other types
  /// the key is an error.
  bool accepts_structure = false;
  /// The structures an entry may choose by name ("structure": "<name>" or "<name>:<parameters>",
  /// handed to the reader as ObjectSpecContext::structure_name and structure_params), e.g. {"bvh",
  /// "kdtree"}. A name some registered type offers is a choice, never a path: an entry of a type
  /// that does not offer it is an error. Empty: the type has no choice.
  std::vector<std::string> structure_names = {};
  /// Reads the target geometry of a timed "deform" edit's "file": a file of the type's format with
  /// the topology of `current` (the object as it is when the edit is applied). Returns its
  /// object-space positions, current.deformableVertexCount() of them. Throws FileError naming the
  /// file when it cannot be read or its topology differs. Null (the default): objects of the type
  /// cannot be deformed from a file (inline "positions" still work for deformable ones).
  std::function<std::vector<glm::vec3>(const std::filesystem::path& file, const Object& current)> deform_file_reader =
      {};
};

/// A set of object types. Start from duplex::builtinObjectTypes() (or an empty registry) and add()
/// your own. Not thread-safe for add().
class ObjectTypeRegistry {
 public:
  /// Registers a type; throws InvalidArgument for an empty or taken name or a null reader.
  void add(ObjectTypeInfo info);
  /// The type registered under `name`, or nullptr.
  [[nodiscard]] const ObjectTypeInfo* find(std::string_view name) const;
  /// Registered names, in registration order.
  [[nodiscard]] std::vector<std::string> names() const;

 private:
  std::vector<ObjectTypeInfo> types_;
};

}  // namespace duplex
