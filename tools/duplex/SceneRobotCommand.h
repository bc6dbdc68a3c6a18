#pragma once
/// \file SceneRobotCommand.h
/// `duplex scene robot`: the links of a URDF robot (the ABB IRB 6640 of the paper-style robot
/// scene) placed by forward kinematics, in several copies side by side, as scene-json-v1.

#include "Command.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <optional>
#include <vector>

namespace duplex::cli {

struct SceneRobotOptions {
  std::filesystem::path urdf;
  int copies = 1;                 ///< >= 1 robots, side by side along +y
  std::vector<double> joints;     ///< radians (metres for prismatic joints), one per movable
                                  ///< joint in file order; empty: all zero
  std::optional<double> spacing;  ///< distance between copies; default 1.25 x the larger
                                  ///< horizontal (x, y) extent of one posed robot
  std::filesystem::path out;
};

/// Reads the URDF's links (visual mesh, else collision mesh; mesh scale and visual origin honoured)
/// and joints (origin xyz/rpy, axis; revolute, continuous, prismatic and fixed), and places every
/// link with a mesh by forward kinematics from the root link:
///   world_from_child = world_from_parent * T(origin xyz) * R(origin rpy) * motion(axis, q)
/// with R(rpy) = Rz(yaw) Ry(pitch) Rx(roll) (the URDF convention). Copy c is shifted by
/// c * spacing along +y. One object per distinct mesh file (named after its first link), one
/// instance per link and copy (extra key "name": "robot<c>/<link>"), in copy order then link order
/// of the file. Mesh paths "package://PKG/REST" resolve to ANCESTOR/REST for an ancestor folder of
/// the URDF named PKG, else URDF_FOLDER/REST, else URDF_FOLDER/<file name>; relative paths are
/// relative to the URDF's folder. Joint values outside the URDF limits are refused. Returns
/// {"copies", "links", "objects", "instances", "movable_joints", "spacing", "out"}.
/// Throws duplex::Error naming the file for bad input.
[[nodiscard]] nlohmann::ordered_json runSceneRobot(const SceneRobotOptions& options);

/// Adds `duplex scene robot` to `parent` (the tool, or its command group) with its options; when it is the
/// command given, its callback sets `chosen` to run it (Command.h).
void addSceneRobotCommand(CLI::App& parent, ChosenCommand& chosen);

}  // namespace duplex::cli
