// libFuzzer target of the prepared bottom-level structure files (loadMeshObject: ".dbvh" wide BVH
// and ".dkdt" kd-tree, MeshObjectFile.h) for one fixed mesh. The input is the file; it is loaded
// as it is and again with its trailing checksum repaired, so that mutations reach the header,
// size and tree checks behind the checksum. A FileError is the expected refusal; a structure that
// loads must answer queries safely: every hit inside the ray's segment on one of the mesh's
// triangles, occluded() agreeing with intersect(), every crossing of intersectAll() inside the
// segment. Anything else (a crash, a sanitizer report, another exception) is a finding.
//
// The seeds (tests/fuzz/corpus/structure) are this mesh's structures as the library writes them:
// DUPLEX_FUZZ_WRITE_SEEDS=DIR duplex_fuzz_structure writes them to DIR and exits.

#include "FuzzInputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/Log.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <vector>

namespace {

[[noreturn]] void violated(const char* what) {
  std::fprintf(stderr, "loadMeshObject property violated: %s\n", what);
  std::abort();
}

// A bumpy 8 x 8 grid (128 triangles) with a few sliver and repeated-corner triangles: enough nodes
// for a BVH of several levels and kd-tree leaves holding straddling triangles.
std::shared_ptr<const duplex::TriangleMesh> fixedMesh() {
  std::vector<glm::vec3> p;
  constexpr int n = 9;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i)
      p.emplace_back(static_cast<float>(i), static_cast<float>(j), 0.3f * std::sin(1.7f * i) * std::cos(1.1f * j));
  std::vector<duplex::TriangleMesh::Triangle> t;
  for (std::uint32_t j = 0; j + 1 < n; ++j)
    for (std::uint32_t i = 0; i + 1 < n; ++i) {
      const std::uint32_t a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      t.push_back({a, b, d});
      t.push_back({a, d, c});
    }
  t.push_back({0, 40, 80});  // a sliver along the diagonal
  t.push_back({5, 5, 6});    // no area
  return std::make_shared<const duplex::TriangleMesh>(duplex::TriangleMesh::fromTriangles(p, t, "fuzz-grid"));
}

const std::shared_ptr<const duplex::TriangleMesh>& mesh() {
  static const std::shared_ptr<const duplex::TriangleMesh> m = fixedMesh();
  return m;
}

void query(const duplex::MeshObject& object) {
  const std::size_t triangles = mesh()->triangleCount();
  duplex::QueryContext ctx;
  std::vector<duplex::Hit> all;
  for (int k = 0; k < 24; ++k) {
    duplex::Ray ray;
    ray.origin = glm::vec3(0.37f * k - 1.0f, 0.29f * k - 0.5f, 2.0f);
    ray.dir = glm::vec3(0.1f * (k % 5) - 0.2f, 0.07f * (k % 7) - 0.2f, -1.0f);
    if (k % 6 == 5) ray.dir = glm::vec3(1.0f, 0.8f, 0.0f);  // grazing, along the grid
    ray.tnear = 0.0f;
    ray.tfar = k % 4 == 3 ? 1.5f : INFINITY;
    duplex::Hit hit;
    const bool hit_any = object.intersect(ray, hit, ctx);
    if (hit_any && !(hit.prim_id < triangles && hit.t >= ray.tnear && hit.t <= ray.tfar))
      violated("intersect() reported a hit outside the segment or the mesh");
    if (object.occluded(ray, ctx) != hit_any) violated("occluded() disagrees with intersect()");
    all.clear();
    object.intersectAll(ray, all, ctx);
    for (const duplex::Hit& h : all)
      if (!(h.prim_id < triangles && h.t >= ray.tnear && h.t <= ray.tfar))
        violated("intersectAll() reported a crossing outside the segment or the mesh");
  }
}

void load(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& file = duplex::fuzz::writeInputFile(data, size, ".structure");
  try {
    const std::shared_ptr<const duplex::MeshObject> object = duplex::loadMeshObject(file, mesh());
    if (!object) violated("loadMeshObject returned null");
    query(*object);
  } catch (const duplex::FileError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  duplex::logger()->set_level(spdlog::level::off);
  duplex::fuzz::writeSeedsIfAsked([](const std::filesystem::path& out) {
    duplex::saveMeshObject(duplex::MeshObject(mesh(), duplex::BvhBuildConfig{}), out / "grid.dbvh");
    duplex::saveMeshObject(duplex::MeshObject(mesh(), duplex::KdBuildConfig{}), out / "grid.dkdt");
  });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  duplex::fuzz::loadAsIsAndRepaired(data, size, load);
  return 0;
}
