#include "duplex/scenegraph/SceneDocument.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/InputFile.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/scenegraph/SceneMemory.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

namespace duplex {

namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

constexpr const char* kV1 = "scene-json-v1";
constexpr const char* kOwn = "duplex-scene-v1";
constexpr int kMaxNesting = 256;  // node trees deeper than this are refused (recursion bound)

std::string at(const std::string& pointer, std::string_view key) { return pointer + "/" + std::string(key); }
std::string at(const std::string& pointer, std::size_t index) { return pointer + "/" + std::to_string(index); }

// Rotation about a unit axis by `radians` (Rodrigues), as a row-major 3x3 into an Affine.
Affine rotation(glm::dvec3 axis, double radians) {
  const double c = std::cos(radians), s = std::sin(radians), k = 1.0 - c;
  const double x = axis.x, y = axis.y, z = axis.z;
  return Affine::fromRowMajor3x4({c + x * x * k, x * y * k - z * s, x * z * k + y * s, 0.0,  //
                                  y * x * k + z * s, c + y * y * k, y * z * k - x * s, 0.0,  //
                                  z * x * k - y * s, z * y * k + x * s, c + z * z * k, 0.0});
}

/// Reads the JSON of one scene file into a graph. `ctx` carries the file, strictness and the JSON
/// helpers; every error goes through ctx.fail (file + pointer).
class DocumentReader {
 public:
  DocumentReader(const ObjectSpecContext& ctx, SceneGraph& graph, const ObjectTypeRegistry& registry)
      : ctx_(ctx), graph_(graph), registry_(registry) {}

  std::array<double, 12> twelveNumbers(const json& v, const std::string& p) const {
    if (!v.is_array()) ctx_.fail(p, "expected an array");
    if (v.size() != 12) ctx_.fail(p, "expected 12 numbers (row-major 3x4), got " + std::to_string(v.size()));
    std::array<double, 12> m{};
    for (std::size_t k = 0; k < 12; ++k) m[k] = ctx_.number(v[k], at(p, k));
    return m;
  }

  glm::dvec3 vec3(const json& v, const std::string& p) const {
    if (!v.is_array() || v.size() != 3) ctx_.fail(p, "expected an array of 3 numbers");
    return {ctx_.number(v[0], at(p, 0)), ctx_.number(v[1], at(p, 1)), ctx_.number(v[2], at(p, 2))};
  }

  Affine rotate(const json& v, const std::string& p) const {
    if (!v.is_object()) ctx_.fail(p, "expected {\"axis\": [x, y, z], \"degrees\": a} or {\"euler_xyz\": [a, b, c]}");
    ctx_.onlyKeys(v, p, {"axis", "degrees", "euler_xyz"});
    const double to_rad = std::numbers::pi / 180.0;
    if (v.contains("euler_xyz")) {
      if (v.contains("axis") || v.contains("degrees"))
        ctx_.fail(p, "\"euler_xyz\" cannot be combined with \"axis\"/\"degrees\"");
      const glm::dvec3 e = vec3(v["euler_xyz"], at(p, "euler_xyz")) * to_rad;
      // About x first, then y, then z (fixed axes): R = Rz * Ry * Rx.
      return rotation({0, 0, 1}, e.z) * rotation({0, 1, 0}, e.y) * rotation({1, 0, 0}, e.x);
    }
    const glm::dvec3 axis = vec3(ctx_.member(v, p, "axis"), at(p, "axis"));
    const double len = std::sqrt(axis.x * axis.x + axis.y * axis.y + axis.z * axis.z);
    if (!(len > 0.0) || !std::isfinite(len)) ctx_.fail(at(p, "axis"), "rotation axis must be a non-zero vector");
    return rotation(axis / len, ctx_.number(ctx_.member(v, p, "degrees"), at(p, "degrees")) * to_rad);
  }

  /// The keys "matrix" or "translate"/"rotate"/"scale" of `obj` (T * R * S: scale first); identity
  /// when none is present. `has` tells whether any was.
  Affine transformFields(const json& obj, const std::string& p, bool* has = nullptr) const {
    const bool matrix = obj.contains("matrix");
    const bool trs = obj.contains("translate") || obj.contains("rotate") || obj.contains("scale");
    if (has) *has = matrix || trs;
    Affine result;
    if (matrix) {
      if (trs) ctx_.fail(at(p, "matrix"), "\"matrix\" cannot be combined with \"translate\"/\"rotate\"/\"scale\"");
      result = Affine::fromRowMajor3x4(twelveNumbers(obj["matrix"], at(p, "matrix")));
    } else if (trs) {
      Affine t, r, s;
      if (obj.contains("translate")) t.translation = vec3(obj["translate"], at(p, "translate"));
      if (obj.contains("rotate")) r = rotate(obj["rotate"], at(p, "rotate"));
      if (obj.contains("scale")) {
        const auto sz = ctx_.positiveSizes(obj["scale"], at(p, "scale"), 3);
        s.linear = glm::dmat3(1.0);
        for (int k = 0; k < 3; ++k) s.linear[k][k] = sz[static_cast<std::size_t>(k)];
      }
      result = t * r * s;
    }
    if (result.isSingular()) ctx_.fail(matrix ? at(p, "matrix") : p, "singular transform");
    return result;
  }

  /// An instance's "transform" or an edit's "set_transform": 12 numbers, or an object of
  /// "matrix" | "translate"/"rotate"/"scale".
  Affine transformValue(const json& v, const std::string& p) const {
    if (v.is_array()) {
      const Affine a = Affine::fromRowMajor3x4(twelveNumbers(v, p));
      if (a.isSingular()) ctx_.fail(p, "singular transform");
      return a;
    }
    if (!v.is_object())
      ctx_.fail(
          p, "expected 12 numbers (row-major 3x4) or an object with \"matrix\" or \"translate\"/\"rotate\"/\"scale\"");
    ctx_.onlyKeys(v, p, {"matrix", "translate", "rotate", "scale"});
    return transformFields(v, p);
  }

  ObjectId object(const json& v, const std::string& p) const {
    const std::string name = ctx_.string(v, p);
    const auto id = graph_.library().find(name);
    if (!id) ctx_.fail(p, "no object named \"" + name + "\"");
    return *id;
  }

  bool boolean(const json& v, const std::string& p) const {
    if (!v.is_boolean()) ctx_.fail(p, "expected true or false");
    return v.get<bool>();
  }

  std::uint32_t mask(const json& v, const std::string& p) const {
    const double d = ctx_.number(v, p);
    if (d < 0.0 || d > 4294967295.0 || d != std::floor(d)) ctx_.fail(p, "expected a mask (integer in [0, 2^32 - 1])");
    return static_cast<std::uint32_t>(d);
  }

  SceneNodeSpec node(const json& v, const std::string& p, int depth) const {
    if (depth > kMaxNesting) ctx_.fail(p, "nodes nested deeper than " + std::to_string(kMaxNesting));
    if (!v.is_object()) ctx_.fail(p, "expected a node (an object with \"group\" or \"instance\")");
    const bool group = v.contains("group"), instance = v.contains("instance");
    if (group == instance)
      ctx_.fail(p, group ? "a node is either a \"group\" or an \"instance\", not both"
                         : "expected a node (an object with \"group\" or \"instance\")");
    SceneNodeSpec spec;
    spec.pointer = p;
    if (v.contains("visible")) spec.visible = boolean(v["visible"], at(p, "visible"));
    if (instance) {
      // "material" belongs to duplex::sensors, which reads it (an instance's own material).
      ctx_.onlyKeys(v, p, {"instance", "object", "transform", "mask", "visible", "material"});
      spec.kind = NodeKind::Instance;
      spec.name = ctx_.string(v["instance"], at(p, "instance"));
      spec.object = object(ctx_.member(v, p, "object"), at(p, "object"));
      if (v.contains("transform")) spec.local = transformValue(v["transform"], at(p, "transform"));
      if (v.contains("mask")) spec.mask = mask(v["mask"], at(p, "mask"));
      return spec;
    }
    ctx_.onlyKeys(v, p, {"group", "children", "visible", "matrix", "translate", "rotate", "scale"});
    spec.name = ctx_.string(v["group"], at(p, "group"));
    bool has_transform = false;
    spec.local = transformFields(v, p, &has_transform);
    spec.kind = has_transform ? NodeKind::Transform : NodeKind::Group;
    if (v.contains("children")) {
      const json& children = v["children"];
      if (!children.is_array()) ctx_.fail(at(p, "children"), "expected an array of nodes");
      for (std::size_t i = 0; i < children.size(); ++i)
        spec.children.push_back(node(children[i], at(at(p, "children"), i), depth + 1));
    }
    return spec;
  }

  /// An edit; `added_object` is the library id of an "add_object" edit's entry (read before).
  /// `timed`: a file's edit, which needs a "time"; else an edit given at run time
  /// (parseLiveEdits), which has none and may not read files.
  SceneEdit edit(const json& v, const std::string& p, ObjectId added_object, bool timed = true) const {
    if (!v.is_object()) ctx_.fail(p, "expected an edit (an object)");
    SceneEdit e;
    e.pointer = p;
    if (timed) {
      e.time = ctx_.number(ctx_.member(v, p, "time"), at(p, "time"));
      if (e.time < 0.0) ctx_.fail(at(p, "time"), "expected a time >= 0 (seconds)");
    } else {
      if (v.contains("time")) ctx_.fail(at(p, "time"), "an edit applied now has no \"time\"");
      // Reading files is the scene file's privilege: an edit from outside (a browser) never
      // reaches the file system.
      if (v.contains("add_object")) ctx_.fail(at(p, "add_object"), "\"add_object\" reads files: not accepted here");
      if (v.contains("deform") && v.contains("file"))
        ctx_.fail(at(p, "file"), "a \"deform\" edit from a file reads files: not accepted here (give \"positions\")");
    }
    static constexpr std::array<std::pair<const char*, SceneEditKind>, 8> kinds = {{
        {"set_transform", SceneEditKind::SetTransform},
        {"add", SceneEditKind::Add},
        {"remove", SceneEditKind::Remove},
        {"visible", SceneEditKind::SetVisible},
        {"object", SceneEditKind::SetObject},
        {"mask", SceneEditKind::SetMask},
        {"deform", SceneEditKind::Deform},
        {"add_object", SceneEditKind::AddObject},
    }};
    const char* key = nullptr;
    for (const auto& [k, kind] : kinds) {
      if (!v.contains(k)) continue;
      if (key) ctx_.fail(p, std::string("an edit does one thing: both \"") + key + "\" and \"" + k + "\"");
      key = k;
      e.kind = kind;
    }
    if (!key)
      ctx_.fail(p,
                "expected one of \"set_transform\", \"add\", \"remove\", \"visible\", \"object\", \"mask\", "
                "\"deform\", \"add_object\"");
    const std::string kp = at(p, key);
    auto target = [&] { return ctx_.string(ctx_.member(v, p, "node"), at(p, "node")); };
    switch (e.kind) {
      case SceneEditKind::SetTransform:
        ctx_.onlyKeys(v, p, {"time", "node", "set_transform"});
        e.node = target();
        e.transform = transformValue(v[key], kp);
        break;
      case SceneEditKind::Add:
        ctx_.onlyKeys(v, p, {"time", "add", "parent"});
        e.node = v.contains("parent") ? ctx_.string(v["parent"], at(p, "parent")) : "/";
        e.added = std::make_shared<const SceneNodeSpec>(node(v[key], kp, 0));
        break;
      case SceneEditKind::Remove:
        ctx_.onlyKeys(v, p, {"time", "remove"});
        e.node = ctx_.string(v[key], kp);
        break;
      case SceneEditKind::SetVisible:
        ctx_.onlyKeys(v, p, {"time", "node", "visible"});
        e.node = target();
        e.visible = boolean(v[key], kp);
        break;
      case SceneEditKind::SetObject:
        ctx_.onlyKeys(v, p, {"time", "node", "object"});
        e.node = target();
        e.object = object(v[key], kp);
        break;
      case SceneEditKind::SetMask:
        ctx_.onlyKeys(v, p, {"time", "node", "mask"});
        e.node = target();
        e.mask = mask(v[key], kp);
        break;
      case SceneEditKind::Deform: deform(v, p, e); break;
      case SceneEditKind::AddObject:
        ctx_.onlyKeys(v, p, {"time", "add_object"});
        e.object = added_object;
        break;
    }
    return e;
  }

  /// A "deform" edit: the object, and "positions" (inline, x y z per vertex) or "file" (read by
  /// the object's type when the edit is applied).
  void deform(const json& v, const std::string& p, SceneEdit& e) const {
    ctx_.onlyKeys(v, p, {"time", "deform", "positions", "file"});
    e.object = object(v["deform"], at(p, "deform"));
    if (v.contains("positions") == v.contains("file"))
      ctx_.fail(p, "a \"deform\" edit takes exactly one of \"positions\" and \"file\"");
    if (v.contains("positions")) {
      const std::string pp = at(p, "positions");
      const json& list = v["positions"];
      if (!list.is_array() || list.empty() || list.size() % 3 != 0)
        ctx_.fail(pp, "expected x, y, z numbers for each vertex (a non-empty array of 3n numbers)");
      auto positions = std::make_shared<std::vector<glm::vec3>>(list.size() / 3);
      for (std::size_t i = 0; i < list.size(); ++i)
        (*positions)[i / 3][static_cast<int>(i % 3)] = static_cast<float>(ctx_.number(list[i], at(pp, i)));
      e.positions = [positions](const Object&) { return *positions; };
      return;
    }
    const std::string& type_name = graph_.library().typeName(e.object);
    const ObjectTypeInfo* type = registry_.find(type_name);
    if (!type || !type->deform_file_reader)
      ctx_.fail(at(p, "file"), "objects of type \"" + type_name + "\" cannot be deformed from a file");
    const std::filesystem::path file = ctx_.resolve(ctx_.string(v["file"], at(p, "file")));
    e.positions = [reader = type->deform_file_reader, file](const Object& current) { return reader(file, current); };
  }

 private:
  const ObjectSpecContext& ctx_;
  SceneGraph& graph_;
  const ObjectTypeRegistry& registry_;
};

/// A structure choice split at its first ':' into name and parameters.
std::pair<std::string, std::string> splitChoice(const std::string& text) {
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos) return {text, ""};
  return {text.substr(0, colon), text.substr(colon + 1)};
}

bool offers(const ObjectTypeInfo& type, const std::string& name) {
  return std::find(type.structure_names.begin(), type.structure_names.end(), name) != type.structure_names.end();
}

[[noreturn]] void failAt(const std::filesystem::path& file, const std::string& pointer, const std::string& problem) {
  throw FileError(file.string() + ": " + (pointer.empty() ? "/" : pointer) + ": " + problem);
}

/// Adds `spec` and its subtree under `parent`; appends instance ids to `instances` and every new id
/// to `added`. Graph errors become FileErrors at the node's pointer.
void addNode(SceneGraph& graph, const std::filesystem::path& file, NodeId parent, const SceneNodeSpec& spec,
             std::vector<NodeId>* instances, std::vector<NodeId>& added) {
  NodeId id = kInvalidNode;
  try {
    switch (spec.kind) {
      case NodeKind::Group: id = graph.addGroup(parent, spec.name); break;
      case NodeKind::Transform: id = graph.addTransform(parent, spec.local, spec.name); break;
      case NodeKind::Instance: id = graph.addInstance(parent, spec.object, spec.local, spec.name, spec.mask); break;
    }
    added.push_back(id);
    if (!spec.visible) graph.setVisible(id, false);
  } catch (const InvalidArgument& e) {
    failAt(file, spec.pointer, e.what());
  }
  if (spec.kind == NodeKind::Instance && instances) instances->push_back(id);
  for (const SceneNodeSpec& child : spec.children) addNode(graph, file, id, child, instances, added);
}

// Counts what nlohmann::json will allocate for a document (without building it): 16 bytes per
// value, an array's vector (24 bytes) and its elements with the parser's geometric growth, an
// object's map (48 bytes) and a tree node per member (links, key, value), strings past the short
// buffer, and the allocator's header of each allocation.
class JsonFootprint : public nlohmann::json_sax<json> {
 public:
  std::uint64_t bytes = 0;
  std::uint64_t values = 0;

  bool null() override { return value(); }
  bool boolean(bool) override { return value(); }
  bool number_integer(number_integer_t) override { return value(); }
  bool number_unsigned(number_unsigned_t) override { return value(); }
  bool number_float(number_float_t, const string_t&) override { return value(); }
  bool string(string_t& s) override {
    add(sizeof(string_t) + kAllocation + longString(s));
    return value();
  }
  bool binary(binary_t& b) override {
    add(sizeof(binary_t) + kAllocation + b.size());
    return value();
  }
  bool start_object(std::size_t) override {
    (void)value();
    add(sizeof(json::object_t) + kAllocation);
    open_.push_back(0);
    return true;
  }
  bool key(string_t& k) override {
    add(kMapNode + kAllocation + longString(k));
    return true;
  }
  bool end_object() override {
    open_.pop_back();
    return true;
  }
  bool start_array(std::size_t) override {
    (void)value();
    add(sizeof(json::array_t) + kAllocation);
    open_.push_back(1);  // element count + 1: 0 marks an object
    return true;
  }
  bool end_array() override {
    const std::uint64_t n = open_.back() - 1;
    open_.pop_back();
    if (n) add(arrayBytes(std::bit_ceil(n), sizeof(json)) + kAllocation);
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override { return false; }

 private:
  // A std::map node: three links and the colour (32 bytes), the key and the value.
  static constexpr std::uint64_t kMapNode = 32 + sizeof(string_t) + sizeof(json);
  static constexpr std::uint64_t kAllocation = 16;  // glibc's chunk header and rounding
  static std::uint64_t longString(const string_t& s) { return s.size() > 15 ? s.size() + 1 + kAllocation : 0; }
  void add(std::uint64_t b) { bytes = saturatingAdd(bytes, b); }
  // A value inside an array counts as an element (its 16 bytes are the array's); elsewhere
  // (a member's value, the root) they are inside the map node or the document.
  bool value() {
    ++values;
    if (!open_.empty() && open_.back() != 0) ++open_.back();
    return true;
  }
  std::vector<std::uint64_t> open_;  // per open container: 0 for an object, 1 + elements for an array
};

json parseFile(const std::filesystem::path& path) {
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError(path.string() + ": cannot open scene file: " + problem);
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) throw FileError(path.string() + ": cannot open scene file");
  const std::streamoff size = in.tellg();
  if (size < 0) throw FileError(path.string() + ": cannot read scene file");
  // The text, then the document nlohmann::json builds from it, against the memory limit.
  requireMemory(static_cast<std::uint64_t>(size), "scene file '" + path.string() + "' (its text)");
  std::string text(static_cast<std::size_t>(size), '\0');
  in.seekg(0);
  if (!in.read(text.data(), size)) throw FileError(path.string() + ": cannot read scene file");
  // A document takes at most about 40 bytes per byte of text (an empty object in an array while the
  // array grows: its element twice and its map, for the three bytes "{},"): the counting pass is
  // only needed for a text that large against the limit.
  constexpr std::uint64_t kMostBytesPerTextByte = 48;
  JsonFootprint footprint;
  if (arrayBytes(text.size(), kMostBytesPerTextByte + 1) > memoryLimit() && json::sax_parse(text, &footprint)) {
    std::ostringstream what;
    what << "scene file '" << path.string() << "' (its text and its " << footprint.values << " JSON values)";
    requireMemory(saturatingAdd(footprint.bytes, text.size()), what.str());
  }
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    // parse_error, and out_of_range for numbers such as 1e999
    throw FileError(path.string() + ": not valid JSON (" + e.what() + ")");
  }
}

// The nodes of a duplex-scene-v1 "nodes" list and their "children", at any depth (iteratively:
// the depth is checked when they are read).
std::uint64_t countNodes(const json& nodes) {
  std::uint64_t n = 0;
  std::vector<const json*> stack = {&nodes};
  while (!stack.empty()) {
    const json* list = stack.back();
    stack.pop_back();
    if (!list->is_array()) continue;
    for (const json& node : *list) {
      ++n;
      if (node.is_object() && node.contains("children")) stack.push_back(&node["children"]);
    }
  }
  return n;
}

}  // namespace

SceneDocument loadSceneDocument(const std::filesystem::path& path, const ObjectTypeRegistry& registry,
                                const SceneDocumentOptions& options) {
  const auto t_load = Clock::now();
  SceneDocument doc;
  doc.file = path;
  doc.graph = std::make_unique<SceneGraph>();
  SceneGraph& graph = *doc.graph;
  ObjectLibrary& library = graph.library();

  ObjectSpecContext ctx;
  ctx.scene_file = path;
  ctx.build = options.build;
  ctx.cache = std::make_shared<SceneLoadCache>();

  const auto parsed = std::make_shared<const json>(parseFile(path));
  const json& root = *parsed;
  doc.parsed = parsed;
  if (!root.is_object()) ctx.fail("", "expected a JSON object at the top level");
  doc.format = ctx.string(ctx.member(root, "", "format"), "/format");
  if (doc.format != kV1 && doc.format != kOwn)
    ctx.fail("/format",
             "unknown format \"" + doc.format + "\" (this version reads \"" + kV1 + "\" and \"" + kOwn + "\")");
  const bool v1 = doc.format == kV1;
  ctx.strict = !v1;  // v1: unknown keys are ignored; own format: they are errors (typos)
  // "lights", "sensors", "bands", "meters" (and an object's "material") belong to duplex::sensors, which reads them
  // from doc.parsed.
  ctx.onlyKeys(root, "", {"format", "objects", "nodes", "edits", "lights", "sensors", "bands", "meters"});
  DocumentReader reader(ctx, graph, registry);
  // The instances (scene-json-v1) or nodes (duplex-scene-v1) against the memory limit, before any
  // object is read or built.
  {
    const char* key = v1 ? "instances" : "nodes";
    const std::uint64_t count = !root.contains(key) ? 0 : v1 ? root[key].size() : countNodes(root[key]);
    std::ostringstream what;
    what << "scene file '" << path.string() << "' (" << count << (v1 ? " instances" : " nodes") << ")";
    requireMemory(arrayBytes(count, sceneBytesPerInstance()), what.str());
  }

  // Objects: each entry's type is the one registered key it has (v1: among the v1 keys only).
  const json& objects = ctx.member(root, "", "objects");
  if (!objects.is_array()) ctx.fail("/objects", "expected an array");
  // Per entry, set by its failing factory; `resource`: the build needed more than the memory limit.
  struct BuildError {
    std::string message;
    bool resource = false;
  };
  std::vector<std::shared_ptr<BuildError>> build_errors;
  const std::vector<std::string> type_names = registry.names();
  std::vector<std::string_view> entry_keys = {"name", "structure", "material"};  // allowed in an entry (own format)
  entry_keys.insert(entry_keys.end(), type_names.begin(), type_names.end());
  // Structure names some type offers: such a "structure" value is a choice, not a path.
  std::vector<std::string> choice_names;
  for (const std::string& t : type_names)
    for (const std::string& n : registry.find(t)->structure_names)
      if (std::find(choice_names.begin(), choice_names.end(), n) == choice_names.end()) choice_names.push_back(n);
  const auto isChoice = [&](const std::string& name) {
    return std::find(choice_names.begin(), choice_names.end(), name) != choice_names.end();
  };
  const std::pair<std::string, std::string> default_choice = splitChoice(options.structure);
  const std::string& default_name = default_choice.first;
  const std::string& default_params = default_choice.second;
  if (!options.structure.empty() && !isChoice(default_name))
    throw FileError(path.string() + ": default structure \"" + options.structure +
                    "\": no object type offers a structure named \"" + default_name + "\"");
  // One object entry (of "objects" or of an "add_object" edit) read into the library.
  const auto addEntry = [&](const json& entry, const std::string& p) -> ObjectId {
    if (!entry.is_object()) ctx.fail(p, "expected an object");
    const std::string name = ctx.string(ctx.member(entry, p, "name"), at(p, "name"));
    if (library.find(name)) ctx.fail(at(p, "name"), "duplicate object name \"" + name + "\"");
    const ObjectTypeInfo* type = nullptr;
    std::string known;
    for (const std::string& t : type_names) {
      const ObjectTypeInfo* info = registry.find(t);
      if (v1 && !info->in_scene_json_v1) continue;
      known += (known.empty() ? "\"" : ", \"") + t + "\"";
      if (!entry.contains(t)) continue;
      if (type) ctx.fail(p, "two object types, \"" + type->name + "\" and \"" + t + "\" (expected exactly one)");
      type = info;
    }
    if (!type) ctx.fail(p, "no object type (expected exactly one of the keys " + known + ")");
    if (ctx.strict)
      for (const auto& [key, value] : entry.items())
        if (std::find(entry_keys.begin(), entry_keys.end(), key) == entry_keys.end())
          ctx.fail(at(p, key), "unknown key \"" + key + "\"");

    ObjectSpecContext object_ctx = ctx;
    object_ctx.pointer = at(p, type->name);
    object_ctx.entry_pointer = p;
    object_ctx.object_name = name;
    bool chosen = false;
    if (entry.contains("structure")) {
      const std::string sp = at(p, "structure");
      const std::string text = ctx.string(entry["structure"], sp);
      auto [choice, params] = splitChoice(text);
      if (isChoice(choice)) {
        if (!offers(*type, choice)) {
          std::string offered;
          for (const std::string& n : type->structure_names) offered += (offered.empty() ? "\"" : ", \"") + n + "\"";
          ctx.fail(sp, "objects of type \"" + type->name + "\" offer no structure \"" + choice + "\"" +
                           (offered.empty() ? std::string(" (they have no structure choice)")
                                            : " (they offer " + offered + ")"));
        }
        object_ctx.structure_name = std::move(choice);
        object_ctx.structure_params = std::move(params);
        object_ctx.structure_pointer = sp;
        chosen = true;
      } else if (options.use_structures) {
        if (!type->accepts_structure) ctx.fail(sp, "objects of type \"" + type->name + "\" have no prepared structure");
        object_ctx.structure = ctx.resolve(text);
      }
    }
    if (!chosen && !object_ctx.structure && !options.structure.empty() && offers(*type, default_name)) {
      object_ctx.structure_name = default_name;
      object_ctx.structure_params = default_params;
      object_ctx.structure_pointer = p;
    }
    ObjectSpecResult result = type->reader(entry[type->name], object_ctx);
    try {
      if (auto* built = std::get_if<std::shared_ptr<const Object>>(&result)) {
        if (!*built) ctx.fail(object_ctx.pointer, "type \"" + type->name + "\" returned no object");
        return library.add(name, *built);
      }
      auto factory = std::get<ObjectLibrary::Factory>(std::move(result));
      if (!factory) ctx.fail(object_ctx.pointer, "type \"" + type->name + "\" returned no object");
      auto error = std::make_shared<BuildError>();
      build_errors.push_back(error);
      // Errors of the build name the file and the entry; the first in file order is reported.
      const std::string prefix = path.string() + ": ";
      return library.addDeferred(name, type->name,
                                 [factory = std::move(factory), error, prefix, pointer = object_ctx.pointer] {
                                   try {
                                     return factory();
                                   } catch (const std::exception& e) {
                                     std::string message = e.what();
                                     if (message.rfind(prefix, 0) != 0) message = prefix + pointer + ": " + message;
                                     error->message = message;
                                     error->resource = dynamic_cast<const ResourceError*>(&e) != nullptr;
                                     if (error->resource) throw ResourceError(message);
                                     throw FileError(message);
                                   }
                                 });
    } catch (const InvalidArgument& e) {
      ctx.fail(at(p, "name"), e.what());
    }
  };
  for (std::size_t i = 0; i < objects.size(); ++i) doc.objects.push_back(addEntry(objects[i], at("/objects", i)));
  ctx.cache->readRequested();
  doc.figures.load_ms = msSince(t_load);

  // Bottom-level structures, all in parallel, before any instance is added.
  const auto t_build = Clock::now();
  if (options.control.cancelled()) throw Cancelled(path.string() + ": load cancelled before the builds");
  try {
    library.buildAll(options.control);
  } catch (const Cancelled&) {
    throw;  // nothing of the load is kept: the document is never returned
  } catch (const std::exception& e) {
    for (const auto& error : build_errors) {
      if (error->message.empty()) continue;
      if (error->resource) throw ResourceError(error->message);
      throw FileError(error->message);
    }
    throw FileError(path.string() + ": " + e.what());
  }
  doc.figures.build_ms = msSince(t_build);

  // Nodes.
  const auto t_graph = Clock::now();
  std::vector<NodeId> added;
  if (v1) {
    const json& instances = ctx.member(root, "", "instances");
    if (!instances.is_array()) ctx.fail("/instances", "expected an array");
    for (std::size_t i = 0; i < instances.size(); ++i) {
      const std::string p = at("/instances", i);
      if (!instances[i].is_object()) ctx.fail(p, "expected an object");
      const ObjectId object = reader.object(ctx.member(instances[i], p, "object"), at(p, "object"));
      const std::string tp = at(p, "transform");
      const Affine transform =
          Affine::fromRowMajor3x4(reader.twelveNumbers(ctx.member(instances[i], p, "transform"), tp));
      try {
        doc.instances.push_back(graph.addInstance(kRootNode, object, transform, "instance" + std::to_string(i)));
      } catch (const InvalidArgument& e) {
        ctx.fail(tp, e.what());
      }
    }
  } else {
    if (root.contains("nodes")) {
      const json& nodes = root["nodes"];
      if (!nodes.is_array()) ctx.fail("/nodes", "expected an array of nodes");
      for (std::size_t i = 0; i < nodes.size(); ++i)
        addNode(graph, path, kRootNode, reader.node(nodes[i], at("/nodes", i), 0), &doc.instances, added);
    }
    if (root.contains("edits")) {
      const json& edits = root["edits"];
      if (!edits.is_array()) ctx.fail("/edits", "expected an array of edits");
      // Objects of "add_object" edits first, so that any edit can name them. They join the library
      // deferred: read (or built) when the edit is applied or an instance first uses them.
      std::vector<ObjectId> added_objects(edits.size(), kInvalidObject);
      for (std::size_t i = 0; i < edits.size(); ++i)
        if (edits[i].is_object() && edits[i].contains("add_object"))
          added_objects[i] = addEntry(edits[i]["add_object"], at(at("/edits", i), "add_object"));
      for (std::size_t i = 0; i < edits.size(); ++i)
        doc.edits.push_back(reader.edit(edits[i], at("/edits", i), added_objects[i]));
      std::stable_sort(doc.edits.begin(), doc.edits.end(),
                       [](const SceneEdit& a, const SceneEdit& b) { return a.time < b.time; });
    }
  }
  (void)graph.commit();
  doc.figures.graph_ms = msSince(t_graph);

  SceneLoadFigures& f = doc.figures;
  f.objects = doc.objects.size();
  f.structures_loaded = ctx.cache->structures_loaded.load();
  std::unordered_set<const Object*> seen;
  for (ObjectId id = 0; id < library.size(); ++id) {
    if (!library.isBuilt(id)) continue;  // an "add_object" edit's, read when it is applied
    const auto object = library.get(id);
    if (!seen.insert(object.get()).second) continue;
    for (const ObjectFigure& figure : object->figures()) ctx.cache->addCount(figure.name, figure.value);
  }
  f.counts = ctx.cache->counts();
  f.instances = doc.instances.size();
  f.nodes = graph.nodeCount();
  return doc;
}

std::vector<SceneEdit> parseLiveEdits(const SceneDocument& doc, const nlohmann::json& edits, const std::string& source,
                                      const ObjectTypeRegistry& registry) {
  ObjectSpecContext ctx;
  ctx.scene_file = source;
  ctx.strict = true;
  ctx.cache = std::make_shared<SceneLoadCache>();
  if (!edits.is_array()) ctx.fail("", "expected an array of edits");
  DocumentReader reader(ctx, *doc.graph, registry);
  std::vector<SceneEdit> out;
  out.reserve(edits.size());
  for (std::size_t i = 0; i < edits.size(); ++i)
    out.push_back(reader.edit(edits[i], at("", i), kInvalidObject, /*timed=*/false));
  return out;
}

std::vector<NodeId> applyEdit(SceneDocument& doc, const SceneEdit& edit) {
  SceneGraph& graph = *doc.graph;
  if (edit.kind == SceneEditKind::Deform || edit.kind == SceneEditKind::AddObject) {
    try {
      if (edit.kind == SceneEditKind::Deform)
        graph.deformObject(edit.object, edit.positions(*graph.pendingObject(edit.object)));
      else (void)graph.library().get(edit.object);
    } catch (const Error& e) {
      failAt(doc.file, edit.pointer, e.what());
    }
    return {};
  }
  const auto target = graph.find(edit.node);
  if (!target) failAt(doc.file, edit.pointer, "no node at path \"" + edit.node + "\"");
  std::vector<NodeId> added;
  try {
    switch (edit.kind) {
      case SceneEditKind::SetTransform: graph.setTransform(*target, edit.transform); break;
      case SceneEditKind::Remove: graph.remove(*target); break;
      case SceneEditKind::SetVisible: graph.setVisible(*target, edit.visible); break;
      case SceneEditKind::SetObject: graph.setObject(*target, edit.object); break;
      case SceneEditKind::SetMask: graph.setMask(*target, edit.mask); break;
      case SceneEditKind::Deform:
      case SceneEditKind::AddObject: break;  // handled above
      case SceneEditKind::Add:
        if (!edit.added) failAt(doc.file, edit.pointer, "no node to add");
        try {
          addNode(graph, doc.file, *target, *edit.added, nullptr, added);
        } catch (...) {
          if (!added.empty()) graph.remove(added.front());  // the partial subtree goes again
          throw;
        }
        break;
    }
  } catch (const InvalidArgument& e) {
    failAt(doc.file, edit.pointer, e.what());
  }
  return added;
}

std::size_t applyEditGroup(SceneDocument& doc, std::size_t first) {
  std::size_t end = first;
  while (end < doc.edits.size() && doc.edits[end].time == doc.edits[first].time) (void)applyEdit(doc, doc.edits[end++]);
  return end;
}

std::size_t applyEditsUntil(SceneDocument& doc, double time) {
  std::size_t done = 0;
  while (done < doc.edits.size() && doc.edits[done].time <= time) {
    try {
      const std::size_t end = applyEditGroup(doc, done);
      try {
        (void)doc.graph->commit();
      } catch (const InvalidArgument& e) {
        failAt(doc.file, doc.edits[done].pointer, e.what());
      }
      done = end;
    } catch (...) {
      doc.graph->rollback();
      throw;
    }
  }
  return done;
}

std::vector<std::filesystem::path> saveStructures(const SceneDocument& doc, const std::filesystem::path& dir) {
  const ObjectLibrary& library = doc.graph->library();
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw FileError(dir.string() + ": cannot create directory (" + ec.message() + ")");
  std::vector<std::filesystem::path> written(library.size());
  for (ObjectId id = 0; id < library.size(); ++id) {
    if (!library.contains(id)) continue;  // removed
    const auto object = library.get(id);
    const std::string_view extension = object->preparedExtension();
    if (extension.empty()) continue;
    std::string name = library.name(id);
    for (char& c : name)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) c = '_';
    written[id] = dir / (std::to_string(id) + "_" + name + std::string(extension));
    object->savePrepared(written[id]);
  }
  return written;
}

}  // namespace duplex
