#include "SceneRobotCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "SceneWriter.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/InputFile.h>
#include <duplex/objects/MeshLoader.h>

#include <tinyxml2.h>

#include <glm/geometric.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>

namespace duplex::cli {

namespace {

// ---- XML access (tinyxml2). ----

using tinyxml2::XMLElement;

// The attribute `key` of `element`, or nullopt when it has none.
std::optional<std::string> attribute(const XMLElement& element, const char* key) {
  const char* value = element.Attribute(key);
  return value ? std::optional<std::string>(value) : std::nullopt;
}

// ---- The URDF structure this command needs. ----

struct UrdfLink {
  std::string name;
  std::string mesh_uri;  ///< empty: nothing to place
  glm::dvec3 mesh_scale{1.0};
  Affine link_from_visual;  ///< the visual's <origin>
};

enum class JointKind { Fixed, Revolute, Prismatic };

struct UrdfJoint {
  std::string name;
  JointKind kind = JointKind::Fixed;
  Affine parent_from_joint;        ///< <origin xyz rpy>
  glm::dvec3 axis{1.0, 0.0, 0.0};  ///< unit, joint frame
  std::string parent, child;
  std::optional<std::pair<double, double>> limits;  ///< lower, upper (revolute, prismatic)
};

std::vector<double> parseNumbers(const std::string& text, std::size_t count, const std::string& where) {
  std::vector<double> values;
  std::size_t p = 0;
  while (true) {
    while (p < text.size() && std::isspace(static_cast<unsigned char>(text[p]))) ++p;
    if (p >= text.size()) break;
    if (text[p] == '+') ++p;
    double v = 0.0;
    const auto [end, ec] = std::from_chars(text.data() + p, text.data() + text.size(), v);
    if (ec != std::errc() || !std::isfinite(v)) throw FileError(where + ": '" + text + "' is not a list of numbers");
    values.push_back(v);
    p = static_cast<std::size_t>(end - text.data());
  }
  if (values.size() != count)
    throw FileError(where + ": expected " + std::to_string(count) + " numbers, got '" + text + "'");
  return values;
}

glm::dvec3 vec3Attribute(const XMLElement* element, const char* key, glm::dvec3 fallback, const std::string& where) {
  if (!element) return fallback;
  const std::optional<std::string> text = attribute(*element, key);
  if (!text) return fallback;
  const std::vector<double> v = parseNumbers(*text, 3, where + " " + key);
  return {v[0], v[1], v[2]};
}

// Rotation by `angle` radians about the unit vector `axis` (Rodrigues), column-major.
glm::dmat3 axisAngle(const glm::dvec3& axis, double angle) {
  const double c = std::cos(angle), s = std::sin(angle), t = 1.0 - c;
  const double x = axis.x, y = axis.y, z = axis.z;
  glm::dmat3 m;
  m[0] = {t * x * x + c, t * x * y + s * z, t * x * z - s * y};
  m[1] = {t * x * y - s * z, t * y * y + c, t * y * z + s * x};
  m[2] = {t * x * z + s * y, t * y * z - s * x, t * z * z + c};
  return m;
}

// URDF <origin>: translate(xyz) * Rz(yaw) * Ry(pitch) * Rx(roll).
Affine originTransform(const XMLElement* origin, const std::string& where) {
  const glm::dvec3 xyz = vec3Attribute(origin, "xyz", glm::dvec3(0.0), where + " <origin>");
  const glm::dvec3 rpy = vec3Attribute(origin, "rpy", glm::dvec3(0.0), where + " <origin>");
  Affine a;
  a.linear = axisAngle({0, 0, 1}, rpy.z) * axisAngle({0, 1, 0}, rpy.y) * axisAngle({1, 0, 0}, rpy.x);
  a.translation = xyz;
  return a;
}

struct Urdf {
  std::vector<UrdfLink> links;
  std::vector<UrdfJoint> joints;
};

// The URDF's <robot> element in `doc`, loaded from `path`. Malformed XML is refused with the file,
// the line tinyxml2 reports and its description of the problem.
const XMLElement& loadRobotElement(tinyxml2::XMLDocument& doc, const std::filesystem::path& path) {
  const std::string file = path.string();
  if (const std::string problem = notRegularFile(path); !problem.empty())
    throw FileError(file + ": cannot open the URDF file: " + problem);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FileError(file + ": cannot open the URDF file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  if (doc.Parse(text.data(), text.size()) != tinyxml2::XML_SUCCESS) {
    // ErrorStr() is "Error=<name> ErrorID=<n> (0x..) Line number=<line>[: <detail>]": keep the detail.
    const std::string str = doc.ErrorStr() ? doc.ErrorStr() : "";
    const std::size_t colon = str.find(": ");
    const std::string detail = colon == std::string::npos ? "" : ", " + str.substr(colon + 2);
    const std::string line = doc.ErrorLineNum() > 0 ? ": line " + std::to_string(doc.ErrorLineNum()) : "";
    throw FileError(file + line + ": malformed XML (tinyxml2: " + doc.ErrorName() + detail + ")");
  }
  const XMLElement* root = doc.RootElement();
  if (!root) throw FileError(file + ": no XML element");
  if (const XMLElement* second = root->NextSiblingElement())
    throw FileError(file + ": line " + std::to_string(second->GetLineNum()) + ": more than one top-level element");
  if (std::string_view(root->Name()) != "robot")
    throw FileError(file + ": the top-level element is <" + root->Name() + ">, not <robot>");
  return *root;
}

Urdf readUrdf(const std::filesystem::path& path) {
  const std::string file = path.string();
  tinyxml2::XMLDocument doc;
  const XMLElement& root = loadRobotElement(doc, path);

  Urdf urdf;
  for (const XMLElement* e = root.FirstChildElement(); e; e = e->NextSiblingElement()) {
    const std::string element = e->Name();
    const std::optional<std::string> name = attribute(*e, "name");
    const std::string where = file + ": line " + std::to_string(e->GetLineNum()) + ": <" + element +
                              (name ? " name=\"" + *name + "\"" : "") + ">";
    if (element == "link") {
      if (!name) throw FileError(where + " has no name");
      UrdfLink link;
      link.name = *name;
      // The visual mesh, else the collision mesh.
      for (const char* kind : {"visual", "collision"}) {
        const XMLElement* shape = e->FirstChildElement(kind);
        const XMLElement* geometry = shape ? shape->FirstChildElement("geometry") : nullptr;
        const XMLElement* mesh = geometry ? geometry->FirstChildElement("mesh") : nullptr;
        if (!mesh) continue;
        const std::optional<std::string> filename = attribute(*mesh, "filename");
        if (!filename || filename->empty()) throw FileError(where + ": <mesh> without a filename");
        link.mesh_uri = *filename;
        link.mesh_scale = vec3Attribute(mesh, "scale", glm::dvec3(1.0), where + " <mesh>");
        link.link_from_visual = originTransform(shape->FirstChildElement("origin"), where + " <" + kind + ">");
        break;
      }
      urdf.links.push_back(std::move(link));
    } else if (element == "joint") {
      if (!name) throw FileError(where + " has no name");
      UrdfJoint joint;
      joint.name = *name;
      const std::optional<std::string> type = attribute(*e, "type");
      if (!type) throw FileError(where + " has no type");
      if (*type == "fixed") joint.kind = JointKind::Fixed;
      else if (*type == "revolute" || *type == "continuous") joint.kind = JointKind::Revolute;
      else if (*type == "prismatic") joint.kind = JointKind::Prismatic;
      else
        throw FileError(where + ": joint type '" + *type +
                        "' is not supported (fixed, revolute, continuous, prismatic)");
      joint.parent_from_joint = originTransform(e->FirstChildElement("origin"), where);
      const glm::dvec3 axis = vec3Attribute(e->FirstChildElement("axis"), "xyz", {1.0, 0.0, 0.0}, where + " <axis>");
      if (!(glm::length(axis) > 0.0)) throw FileError(where + ": <axis xyz> is the zero vector");
      joint.axis = glm::normalize(axis);
      const XMLElement* parent = e->FirstChildElement("parent");
      const XMLElement* child = e->FirstChildElement("child");
      const std::optional<std::string> parent_link = parent ? attribute(*parent, "link") : std::nullopt;
      const std::optional<std::string> child_link = child ? attribute(*child, "link") : std::nullopt;
      if (!parent_link || !child_link) throw FileError(where + ": needs <parent link=...> and <child link=...>");
      joint.parent = *parent_link;
      joint.child = *child_link;
      if (*type == "revolute" || *type == "prismatic") {
        const XMLElement* limit = e->FirstChildElement("limit");
        const std::optional<std::string> lower = limit ? attribute(*limit, "lower") : std::nullopt;
        const std::optional<std::string> upper = limit ? attribute(*limit, "upper") : std::nullopt;
        if (lower && upper)
          joint.limits = std::make_pair(parseNumbers(*lower, 1, where + " <limit lower>")[0],
                                        parseNumbers(*upper, 1, where + " <limit upper>")[0]);
      }
      urdf.joints.push_back(std::move(joint));
    }
  }
  if (urdf.links.empty()) throw FileError(file + ": no <link>");
  return urdf;
}

// Where a URDF mesh reference points, as an existing file (see SceneRobotOptions).
std::filesystem::path resolveMesh(const std::string& uri, const std::filesystem::path& urdf, const std::string& link) {
  const std::filesystem::path folder = std::filesystem::absolute(urdf).parent_path();
  std::vector<std::filesystem::path> candidates;
  if (uri.starts_with("package://")) {
    const std::string rest = uri.substr(10);
    const std::size_t slash = rest.find('/');
    const std::string package = rest.substr(0, slash);
    const std::string inside = slash == std::string::npos ? std::string() : rest.substr(slash + 1);
    for (std::filesystem::path p = folder; !p.empty(); p = p.parent_path()) {
      if (p.filename() == package) candidates.push_back(p / inside);
      if (p == p.parent_path()) break;
    }
    candidates.push_back(folder / inside);
    candidates.push_back(folder / std::filesystem::path(inside).filename());
  } else if (uri.starts_with("file://")) {
    candidates.push_back(uri.substr(7));
  } else {
    const std::filesystem::path p(uri);
    candidates.push_back(p.is_absolute() ? p : folder / p);
  }
  std::string tried;
  for (const std::filesystem::path& c : candidates) {
    std::error_code ec;
    if (std::filesystem::is_regular_file(c, ec)) return c;
    tried += (tried.empty() ? "" : ", ") + c.string();
  }
  throw FileError(urdf.string() + ": link '" + link + "': mesh '" + uri + "' not found (tried " + tried + ")");
}

}  // namespace

nlohmann::ordered_json runSceneRobot(const SceneRobotOptions& options) {
  if (options.copies < 1) throw InvalidArgument("--copies must be at least 1");
  if (options.spacing && !(std::isfinite(*options.spacing) && *options.spacing >= 0.0))
    throw InvalidArgument("--spacing must be a finite number >= 0");
  const Urdf urdf = readUrdf(options.urdf);
  const std::string file = options.urdf.string();

  // The tree: each link is the child of at most one joint; exactly one root.
  std::map<std::string, std::size_t> link_index;
  for (std::size_t i = 0; i < urdf.links.size(); ++i)
    if (!link_index.emplace(urdf.links[i].name, i).second)
      throw FileError(file + ": link '" + urdf.links[i].name + "' is defined twice");
  std::vector<int> parent_joint(urdf.links.size(), -1);
  std::vector<std::size_t> movable;  // joint indices, file order
  for (std::size_t j = 0; j < urdf.joints.size(); ++j) {
    const UrdfJoint& joint = urdf.joints[j];
    for (const std::string* l : {&joint.parent, &joint.child})
      if (!link_index.contains(*l))
        throw FileError(file + ": joint '" + joint.name + "' names unknown link '" + *l + "'");
    int& pj = parent_joint[link_index[joint.child]];
    if (pj >= 0)
      throw FileError(file + ": link '" + joint.child + "' is the child of two joints ('" +
                      urdf.joints[static_cast<std::size_t>(pj)].name + "' and '" + joint.name + "')");
    pj = static_cast<int>(j);
    if (joint.kind != JointKind::Fixed) movable.push_back(j);
  }
  std::vector<std::size_t> roots;
  for (std::size_t i = 0; i < urdf.links.size(); ++i)
    if (parent_joint[i] < 0) roots.push_back(i);
  if (roots.size() != 1)
    throw FileError(file + ": expected one root link (a link no joint has as child), found " +
                    std::to_string(roots.size()));

  // Joint values.
  std::vector<double> q(urdf.joints.size(), 0.0);
  if (!options.joints.empty()) {
    if (options.joints.size() != movable.size()) {
      std::string names;
      for (const std::size_t j : movable) names += (names.empty() ? "" : ", ") + urdf.joints[j].name;
      throw InvalidArgument("--joints gives " + std::to_string(options.joints.size()) + " values but " + file +
                            " has " + std::to_string(movable.size()) + " movable joints (" + names + ")");
    }
    for (std::size_t m = 0; m < movable.size(); ++m) {
      const UrdfJoint& joint = urdf.joints[movable[m]];
      const double v = options.joints[m];
      if (!std::isfinite(v)) throw InvalidArgument("--joints: value for '" + joint.name + "' is not finite");
      if (joint.limits && (v < joint.limits->first || v > joint.limits->second))
        throw InvalidArgument("--joints: " + std::to_string(v) + " for joint '" + joint.name +
                              "' is outside its limits [" + std::to_string(joint.limits->first) + ", " +
                              std::to_string(joint.limits->second) + "] in " + file);
      q[movable[m]] = v;
    }
  }

  // Forward kinematics, parents before children (repeat until every reachable link is placed).
  std::vector<std::optional<Affine>> world_from_link(urdf.links.size());
  world_from_link[roots[0]] = Affine::identity();
  for (bool progress = true; progress;) {
    progress = false;
    for (std::size_t j = 0; j < urdf.joints.size(); ++j) {
      const UrdfJoint& joint = urdf.joints[j];
      const std::size_t p = link_index[joint.parent], c = link_index[joint.child];
      if (!world_from_link[p] || world_from_link[c]) continue;
      Affine joint_from_child;
      if (joint.kind == JointKind::Revolute) joint_from_child.linear = axisAngle(joint.axis, q[j]);
      if (joint.kind == JointKind::Prismatic) joint_from_child.translation = joint.axis * q[j];
      world_from_link[c] = *world_from_link[p] * joint.parent_from_joint * joint_from_child;
      progress = true;
    }
  }
  for (std::size_t i = 0; i < urdf.links.size(); ++i)
    if (!world_from_link[i])
      throw FileError(file + ": link '" + urdf.links[i].name + "' is not connected to the root (a joint cycle?)");

  // Objects: one per distinct mesh file; the posed robot's bounds for the spacing.
  std::vector<SceneObjectEntry> objects;
  std::map<std::filesystem::path, std::size_t> object_of_file;
  struct Placed {
    std::string link;
    std::size_t object;
    Affine robot_from_object;
  };
  std::vector<Placed> placed;
  Box robot_bounds;
  for (std::size_t i = 0; i < urdf.links.size(); ++i) {
    const UrdfLink& link = urdf.links[i];
    if (link.mesh_uri.empty()) continue;
    const std::filesystem::path mesh_path =
        std::filesystem::weakly_canonical(resolveMesh(link.mesh_uri, options.urdf, link.name));
    auto [it, inserted] = object_of_file.emplace(mesh_path, objects.size());
    if (inserted) objects.push_back({link.name, pathRelativeToFolderOf(options.out, mesh_path), {}, {}});
    Affine scale;
    scale.linear = glm::dmat3(glm::dvec3(link.mesh_scale.x, 0, 0), glm::dvec3(0, link.mesh_scale.y, 0),
                              glm::dvec3(0, 0, link.mesh_scale.z));
    const Affine robot_from_object = *world_from_link[i] * link.link_from_visual * scale;
    if (robot_from_object.isSingular())
      throw FileError(file + ": link '" + link.name + "': singular mesh transform (zero scale?)");
    placed.push_back({link.name, it->second, robot_from_object});
    if (!options.spacing) robot_bounds.extend(robot_from_object.apply(loadMesh(mesh_path).bounds()));
  }
  if (placed.empty()) throw FileError(file + ": no link has a mesh");
  const double spacing =
      options.spacing ? *options.spacing : 1.25 * std::max(robot_bounds.extent().x, robot_bounds.extent().y);

  std::vector<SceneInstanceEntry> instances;
  for (int c = 0; c < options.copies; ++c)
    for (const Placed& p : placed) {
      Affine world_from_object = p.robot_from_object;
      world_from_object.translation.y += spacing * c;
      instances.push_back({objects[p.object].name, world_from_object, "robot" + std::to_string(c) + "/" + p.link});
    }
  writeSceneJson(options.out, objects, instances);

  nlohmann::ordered_json summary;
  summary["copies"] = options.copies;
  summary["links"] = placed.size();
  summary["objects"] = objects.size();
  summary["instances"] = instances.size();
  summary["movable_joints"] = movable.size();
  summary["spacing"] = spacing;
  summary["out"] = options.out.string();
  return summary;
}

void addSceneRobotCommand(CLI::App& parent, ChosenCommand& chosen) {
  // The options as given: --spacing is optional in SceneRobotOptions, set only when given.
  struct Given {
    SceneRobotOptions robot;
    double spacing = 0.0;
  };
  auto given = std::make_shared<Given>();
  SceneRobotOptions& robot = given->robot;
  CLI::App* cmd = parent.add_subcommand(
      "robot", "A URDF robot's link meshes placed by forward kinematics, in copies side by side along +y");
  cmd->add_option("--urdf", robot.urdf, "URDF file (package:// mesh paths resolved near it)")->required();
  cmd->add_option("--copies", robot.copies, "Number of robots (default 1)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--joints", robot.joints,
                  "Joint values a1,a2,... in radians (metres for prismatic), one per movable joint in file "
                  "order (default: all zero)")
      ->delimiter(',');
  CLI::Option* spacing_opt =
      cmd->add_option("--spacing", given->spacing,
                      "Distance between copies (default 1.25 x the larger horizontal extent of one robot)");
  cmd->add_option("--out", robot.out, "scene-json-v1 file to write")->required();
  onParsed(*cmd, chosen, given, [spacing_opt](const Given& g) {
    SceneRobotOptions options = g.robot;
    if (*spacing_opt) options.spacing = g.spacing;
    return runSceneRobot(options);
  });
}

}  // namespace duplex::cli
