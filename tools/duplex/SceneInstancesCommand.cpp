#include "SceneInstancesCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "SceneWriter.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/MemoryLimit.h>
#include <duplex/objects/MeshLoader.h>

#include <glm/geometric.hpp>

#include <cmath>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::cli {

namespace {

// Uniform in [0, 1) from the top 53 bits: the same numbers on every standard library, unlike
// std::uniform_real_distribution.
double unitInterval(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// Shoemake, "Uniform random rotations" (Graphics Gems III, 1992): a unit quaternion uniform on S^3.
glm::dmat3 randomRotation(std::mt19937_64& rng) {
  const double u1 = unitInterval(rng), u2 = unitInterval(rng), u3 = unitInterval(rng);
  const double r1 = std::sqrt(1.0 - u1), r2 = std::sqrt(u1);
  const double a = 2.0 * std::numbers::pi * u2, b = 2.0 * std::numbers::pi * u3;
  const double w = r2 * std::cos(b), x = r1 * std::sin(a), y = r1 * std::cos(a), z = r2 * std::sin(b);
  // Rotation matrix of (w, x, y, z), column-major.
  glm::dmat3 m;
  m[0] = {1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)};
  m[1] = {2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)};
  m[2] = {2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)};
  return m;
}

// Smallest s with s^3 >= n.
std::uint64_t gridSide(std::uint64_t n) {
  std::uint64_t s = static_cast<std::uint64_t>(std::cbrt(static_cast<double>(n)));
  while (s * s * s < n) ++s;
  while (s > 1 && (s - 1) * (s - 1) * (s - 1) >= n) --s;
  return s;
}

}  // namespace

nlohmann::ordered_json runSceneInstances(const SceneInstancesOptions& options) {
  if (options.count == 0) throw InvalidArgument("--count must be at least 1");
  if (options.count > (std::uint64_t{1} << 32))
    throw InvalidArgument("--count " + std::to_string(options.count) + " exceeds 2^32 instances");
  {
    // The instances are held until the file is written.
    std::ostringstream what;
    what << "--count " << options.count << " (the instances of '" << options.mesh.string() << "')";
    requireMemory(arrayBytes(options.count, sizeof(SceneInstanceEntry)), what.str());
  }
  const TriangleMesh mesh = loadMesh(options.mesh);
  const Box bounds = mesh.bounds();
  const glm::dvec3 centre = 0.5 * (glm::dvec3(bounds.lo) + glm::dvec3(bounds.hi));
  const double cell = glm::length(glm::dvec3(bounds.hi) - glm::dvec3(bounds.lo));
  if (!(cell > 0.0) || !std::isfinite(cell))
    throw InvalidArgument(options.mesh.string() + ": the mesh's bounds have no extent; cannot size the grid");

  std::vector<SceneObjectEntry> objects(1);
  const std::string object_name = options.mesh.stem().string().empty() ? "mesh" : options.mesh.stem().string();
  objects[0].name = object_name;
  objects[0].file = pathRelativeToFolderOf(options.out, options.mesh);

  const std::uint64_t s = gridSide(options.count);
  std::mt19937_64 rng(options.seed);
  std::vector<SceneInstanceEntry> instances(options.count);
  for (std::uint64_t i = 0; i < options.count; ++i) {
    const glm::dvec3 cell_index(static_cast<double>(i % s), static_cast<double>((i / s) % s),
                                static_cast<double>(i / (s * s)));
    Affine world_from_object;
    world_from_object.linear = randomRotation(rng);
    world_from_object.translation = cell * cell_index - world_from_object.linear * centre;
    instances[i] = {object_name, world_from_object, {}};
  }
  writeSceneJson(options.out, objects, instances);

  nlohmann::ordered_json summary;
  summary["instances"] = options.count;
  summary["grid"] = s;
  summary["cell"] = cell;
  summary["mesh"] = objects[0].file;
  summary["out"] = options.out.string();
  return summary;
}

void addSceneInstancesCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<SceneInstancesOptions>();
  SceneInstancesOptions& scatter = *options;
  CLI::App* cmd = parent.add_subcommand(
      "instances", "N randomly rotated instances of one mesh on a grid (cells of the mesh's bounding diagonal)");
  cmd->add_option("--mesh", scatter.mesh, "Mesh file (written relative to the output's folder when possible)")
      ->required();
  cmd->add_option("--count", scatter.count, "N: number of instances")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1} << 32));
  cmd->add_option("--seed", scatter.seed, "Seed of the rotations (std::mt19937_64, 0 to 2^64-1)")
      ->required()
      ->transform(kDecimal);
  cmd->add_option("--out", scatter.out, "scene-json-v1 file to write")->required();
  onParsed(*cmd, chosen, options, runSceneInstances);
}

}  // namespace duplex::cli
