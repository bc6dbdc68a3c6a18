#include "SceneWriter.h"

#include <duplex/accel/Error.h>

#include <nlohmann/json.hpp>

#include <array>
#include <charconv>
#include <fstream>
#include <system_error>

namespace duplex::cli {

namespace {

// Shortest round-trip decimal of a float or double (std::to_chars without a format).
template <typename T>
void writeNumber(std::ostream& out, T value) {
  std::array<char, 32> buffer{};
  const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
  out.write(buffer.data(), result.ptr - buffer.data());
}

void writeObject(std::ostream& out, const SceneObjectEntry& object) {
  out << "{\"name\": " << nlohmann::json(object.name).dump() << ", \"mesh\": {";
  if (!object.file.empty()) {
    out << "\"file\": " << nlohmann::json(object.file).dump() << "}}";
    return;
  }
  out << "\"positions\": [";
  for (std::size_t i = 0; i < object.positions.size(); ++i) {
    const glm::vec3& p = object.positions[i];
    if (i > 0) out << ',';
    writeNumber(out, p.x);
    out << ',';
    writeNumber(out, p.y);
    out << ',';
    writeNumber(out, p.z);
  }
  out << "], \"indices\": [";
  for (std::size_t i = 0; i < object.indices.size(); ++i) {
    if (i > 0) out << ',';
    out << object.indices[i];
  }
  out << "]}}";
}

void writeInstance(std::ostream& out, const SceneInstanceEntry& instance) {
  out << "{\"object\": " << nlohmann::json(instance.object).dump();
  if (!instance.name.empty()) out << ", \"name\": " << nlohmann::json(instance.name).dump();
  out << ", \"transform\": [";
  const std::array<double, 12> m = instance.world_from_object.toRowMajor3x4();
  for (std::size_t k = 0; k < m.size(); ++k) {
    if (k > 0) out << (k % 4 == 0 ? ", " : ",");
    writeNumber(out, m[k] == 0.0 ? 0.0 : m[k]);  // no "-0"
  }
  out << "]}";
}

}  // namespace

void writeSceneJson(const std::filesystem::path& path, const std::vector<SceneObjectEntry>& objects,
                    const std::vector<SceneInstanceEntry>& instances) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw FileError(path.string() + ": cannot open for writing");
  out << "{\"format\": \"scene-json-v1\",\n\"objects\": [";
  for (std::size_t i = 0; i < objects.size(); ++i) {
    out << (i > 0 ? ",\n  " : "\n  ");
    writeObject(out, objects[i]);
  }
  out << "],\n\"instances\": [";
  for (std::size_t i = 0; i < instances.size(); ++i) {
    out << (i > 0 ? ",\n  " : "\n  ");
    writeInstance(out, instances[i]);
  }
  out << "]}\n";
  out.close();
  if (!out) throw FileError(path.string() + ": write failed (disk full?)");
}

std::string pathRelativeToFolderOf(const std::filesystem::path& json_file, const std::filesystem::path& target) {
  // Canonical paths (symlinks resolved), because the reader joins "folder/../x" and the system
  // resolves ".." after following the links.
  std::error_code ec;
  const std::filesystem::path real_target = std::filesystem::weakly_canonical(std::filesystem::absolute(target), ec);
  if (ec) return std::filesystem::absolute(target).generic_string();
  const std::filesystem::path folder =
      std::filesystem::weakly_canonical(std::filesystem::absolute(json_file), ec).parent_path();
  if (ec || folder.root_path() != real_target.root_path()) return real_target.generic_string();
  const std::filesystem::path relative = real_target.lexically_relative(folder);
  return relative.empty() ? real_target.generic_string() : relative.generic_string();
}

}  // namespace duplex::cli
