#pragma once
/// \file SceneWriter.h
/// Writing scene-json-v1 files (the interchange format, docs/cli.md) for the `duplex scene`
/// generators. Floats are written as the shortest decimal that reads back as the same float,
/// transforms as the shortest decimal that reads back as the same double.

#include <duplex/accel/Affine.h>

#include <glm/vec3.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace duplex::cli {

/// One entry of "objects": a mesh file (`file` non-empty, written as given) or inline arrays.
struct SceneObjectEntry {
  std::string name;
  std::string file;                    ///< relative paths are relative to the JSON file's folder
  std::vector<glm::vec3> positions;    ///< object space; used when `file` is empty
  std::vector<std::uint32_t> indices;  ///< three per triangle
};

/// One entry of "instances". `name` is written as an extra "name" key (readers ignore it) unless empty.
struct SceneInstanceEntry {
  std::string object;
  Affine world_from_object;
  std::string name;
};

/// Writes {"format": "scene-json-v1", "objects": [...], "instances": [...]} to `path`, one object
/// or instance per line. Throws FileError naming `path` when it cannot be written.
void writeSceneJson(const std::filesystem::path& path, const std::vector<SceneObjectEntry>& objects,
                    const std::vector<SceneInstanceEntry>& instances);

/// `target` relative to the folder that will hold `json_file` when both are on the same root
/// (so the scene can be moved with its meshes); otherwise `target` made absolute. Generic '/'
/// separators.
[[nodiscard]] std::string pathRelativeToFolderOf(const std::filesystem::path& json_file,
                                                 const std::filesystem::path& target);

}  // namespace duplex::cli
