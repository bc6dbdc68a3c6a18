#include "SceneSplitCommand.h"

#include "Command.h"
#include "DecimalOption.h"
#include "SceneWriter.h"

#include <duplex/accel/Error.h>
#include <duplex/objects/MeshLoader.h>

#include <glm/vec3.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <span>
#include <string>

namespace duplex::cli {

namespace {

// One recursion step of the rule on `tris` (reordered in place), appending objects to `out`.
void splitRecursive(std::span<std::uint32_t> tris, std::uint32_t k, const std::vector<glm::dvec3>& centroids,
                    std::vector<std::vector<std::uint32_t>>& out) {
  if (k == 1) {
    std::vector<std::uint32_t> object(tris.begin(), tris.end());
    std::sort(object.begin(), object.end());
    out.push_back(std::move(object));
    return;
  }
  // Longest axis of the centroid box; a later axis wins only when strictly longer.
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
  for (const std::uint32_t t : tris) {
    lo = glm::min(lo, centroids[t]);
    hi = glm::max(hi, centroids[t]);
  }
  const glm::dvec3 extent = hi - lo;
  int axis = 0;
  if (extent[1] > extent[axis]) axis = 1;
  if (extent[2] > extent[axis]) axis = 2;

  std::sort(tris.begin(), tris.end(), [&](std::uint32_t a, std::uint32_t b) {
    const double ca = centroids[a][axis], cb = centroids[b][axis];
    return ca < cb || (ca == cb && a < b);
  });
  const std::uint64_t n = tris.size(), kk = k, kl = k / 2;
  const std::size_t left = static_cast<std::size_t>((2 * n * kl + kk) / (2 * kk));
  splitRecursive(tris.first(left), static_cast<std::uint32_t>(kl), centroids, out);
  splitRecursive(tris.subspan(left), static_cast<std::uint32_t>(kk - kl), centroids, out);
}

}  // namespace

std::vector<std::vector<std::uint32_t>> splitTriangles(const TriangleMesh& mesh, std::uint32_t objects) {
  const std::size_t n = mesh.triangleCount();
  if (objects == 0) throw InvalidArgument(mesh.name() + ": cannot split into 0 objects");
  if (objects > n)
    throw InvalidArgument(mesh.name() + ": cannot split " + std::to_string(n) + " triangles into " +
                          std::to_string(objects) + " objects (at most one object per triangle)");
  if (n > std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument(mesh.name() + ": more than 2^32 - 1 triangles");

  std::vector<glm::dvec3> centroids(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& tri = mesh.triangles()[i];
    const glm::dvec3 a(mesh.positions()[tri[0]]), b(mesh.positions()[tri[1]]), c(mesh.positions()[tri[2]]);
    centroids[i] = (a + b + c) / 3.0;
    if (!std::isfinite(centroids[i].x) || !std::isfinite(centroids[i].y) || !std::isfinite(centroids[i].z))
      throw InvalidArgument(mesh.name() + ": triangle " + std::to_string(i) +
                            " has a non-finite vertex; the split rule needs finite centroids");
  }
  std::vector<std::uint32_t> ids(n);
  for (std::size_t i = 0; i < n; ++i) ids[i] = static_cast<std::uint32_t>(i);
  std::vector<std::vector<std::uint32_t>> out;
  out.reserve(objects);
  splitRecursive(ids, objects, centroids, out);
  return out;
}

nlohmann::ordered_json runSceneSplit(const SceneSplitOptions& options) {
  if (options.loop < 0) throw InvalidArgument("--loop must not be negative");
  TriangleMesh mesh = loadMesh(options.mesh);
  if (options.loop > 0) mesh = loopSubdivide(mesh, options.loop);
  const std::vector<std::vector<std::uint32_t>> parts = splitTriangles(mesh, options.objects);

  // Per object: the triangles in id order, vertices re-indexed in order of first use.
  constexpr std::uint32_t kUnused = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> local_index(mesh.positions().size(), kUnused);
  std::vector<SceneObjectEntry> objects(parts.size());
  std::vector<SceneInstanceEntry> instances(parts.size());
  std::size_t min_triangles = std::numeric_limits<std::size_t>::max(), max_triangles = 0, without_valid = 0;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    SceneObjectEntry& object = objects[k];
    object.name = "part" + std::to_string(k);
    object.indices.reserve(3 * parts[k].size());
    bool any_valid = false;
    for (const std::uint32_t t : parts[k]) {
      any_valid |= mesh.isValid(t);
      for (const std::uint32_t v : mesh.triangles()[t]) {
        if (local_index[v] == kUnused) {
          local_index[v] = static_cast<std::uint32_t>(object.positions.size());
          object.positions.push_back(mesh.positions()[v]);
        }
        object.indices.push_back(local_index[v]);
      }
    }
    for (const std::uint32_t t : parts[k])
      for (const std::uint32_t v : mesh.triangles()[t]) local_index[v] = kUnused;
    if (!any_valid) {
      ++without_valid;
      std::cerr << "duplex scene split: warning: " << object.name
                << " holds only degenerate triangles; scene-json-v1 readers refuse such an object\n";
    }
    min_triangles = std::min(min_triangles, parts[k].size());
    max_triangles = std::max(max_triangles, parts[k].size());
    instances[k].object = object.name;
  }
  writeSceneJson(options.out, objects, instances);

  nlohmann::ordered_json summary;
  summary["objects"] = parts.size();
  summary["triangles"] = mesh.triangleCount();
  summary["degenerate_triangles"] = mesh.degenerateCount();
  summary["min_triangles"] = min_triangles;
  summary["max_triangles"] = max_triangles;
  summary["objects_without_valid_triangle"] = without_valid;
  summary["out"] = options.out.string();
  return summary;
}

void addSceneSplitCommand(CLI::App& parent, ChosenCommand& chosen) {
  auto options = std::make_shared<SceneSplitOptions>();
  SceneSplitOptions& split = *options;
  CLI::App* cmd =
      parent.add_subcommand("split", "Split a mesh into K objects (the paper's scenes), one identity instance each");
  cmd->footer(
      "Rule: split(tris, k): k == 1 gives one object; else kl = k div 2, order the\n"
      "triangles by (centroid on the longest axis of their centroid box, ties x, y, z; triangle index),\n"
      "the first (2 n kl + k) div 2k go left with kl, the rest right with k - kl. Objects part0..part<K-1>\n"
      "(depth-first, left to right) hold inline arrays: triangles in their original order, vertices\n"
      "re-indexed in order of first use. Every triangle the loader returns counts, degenerate (zero-area)\n"
      "ones included; they stay in their object (an object of degenerate triangles only is reported).");
  cmd->add_option("--mesh", split.mesh, "Mesh file (OBJ, PLY, OFF, STL, OM)")->required();
  cmd->add_option("--objects", split.objects, "K: number of objects (1 to the triangle count)")
      ->required()
      ->transform(kDecimal)
      ->check(CLI::Range(1u, 0xFFFFFFFFu));
  cmd->add_option("--loop", split.loop, "Loop-subdivide the mesh N times before splitting (default 0)")
      ->transform(kDecimal)
      ->check(CLI::Range(0, 6));
  cmd->add_option("--out", split.out, "scene-json-v1 file to write")->required();
  onParsed(*cmd, chosen, options, runSceneSplit);
}

}  // namespace duplex::cli
