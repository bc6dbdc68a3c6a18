// The packet queries of the mesh BVH against its single-ray queries, bit for bit (t, u, v, prim id,
// normal), through the object's entry points: run once per SIMD path (ctest's ISA variants, packets
// of 4, 8 and 16 rays), with packets of other sizes too; coherent and random rays, rays aimed at shared edges and
// vertices (ties between triangles), packets whose rays span several octants, partial lane masks, tfar limits and hits
// found before the query, and rays that are not queryable (NaN, zero direction, tnear > tfar).

#include "MeshChecks.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/SimdIsa.h"
#include "duplex/objects/MeshObject.h"
#include "MeshBvh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

/// Rays through vertices and edge midpoints of the mesh's triangles from random origins around it:
/// a ray through a shared edge hits both triangles at the same t.
std::vector<Ray> edgeAndVertexRays(const TriangleMesh& mesh, std::size_t count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const Box b = enlarged(mesh.bounds(), 1.0f);
  std::uniform_real_distribution<float> ux(b.lo.x, b.hi.x), uy(b.lo.y, b.hi.y), uz(b.lo.z, b.hi.z);
  std::uniform_int_distribution<std::size_t> tri(0, mesh.triangleCount() - 1);
  std::vector<Ray> rays;
  for (std::size_t i = 0; i < count; ++i) {
    const auto& t = mesh.triangles()[tri(rng)];
    const glm::vec3 a = mesh.positions()[t[i % 3]], c = mesh.positions()[t[(i + 1) % 3]];
    const glm::vec3 target = i % 2 == 0 ? a : 0.5f * (a + c);
    Ray r;
    r.origin = {ux(rng), uy(rng), uz(rng)};
    r.dir = target - r.origin;
    rays.push_back(r);
  }
  return rays;
}

/// Unqueryable and awkward rays mixed among good ones: NaN origin, zero direction, tnear > tfar,
/// infinite direction, axis-parallel rays, a short tfar.
std::vector<Ray> awkwardRays(const Box& bounds) {
  const glm::vec3 c = bounds.center();
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  std::vector<Ray> rays;
  const glm::vec3 outside = c + 2.0f * (bounds.hi - c);
  for (int k = 0; k < 4; ++k) {
    Ray r;
    r.origin = outside;
    r.dir = c - outside;
    rays.push_back(r);  // good
    r.origin.x = nan;
    rays.push_back(r);
    r.origin = outside;
    r.dir = glm::vec3(0.0f);
    rays.push_back(r);
    r.dir = c - outside;
    r.tnear = 2.0f;
    r.tfar = 1.0f;
    rays.push_back(r);
    r.tnear = 0.0f;
    r.tfar = 0.45f + 0.05f * static_cast<float>(k);  // ends near the surface
    rays.push_back(r);
    r.tfar = inf;
    r.dir = glm::vec3(inf, 0.0f, 0.0f);
    rays.push_back(r);
    Ray axis;
    axis.origin = glm::vec3(c.x, c.y, bounds.hi.z + 1.0f);
    axis.dir = glm::vec3(0.0f, 0.0f, k % 2 == 0 ? -1.0f : -0.0f);
    if (k % 2 == 1) axis.dir = glm::vec3(-0.0f, 0.0f, -2.0f);
    rays.push_back(axis);
    axis.origin = glm::vec3(c.x, bounds.hi.y + 1.0f, c.z);
    axis.dir = glm::vec3(0.0f, -1.0f, 0.0f);
    rays.push_back(axis);
  }
  return rays;
}

struct Tally {
  std::size_t rays = 0, hits = 0, occluded = 0;
};

/// Traces `rays` in packets of `packet` rays (lanes selected by `lane_mask` per packet, which is
/// rotated from packet to packet), and compares every lane with the single-ray queries; the hits start at `preset_t` (a
/// hit found before the query). Returns counts so that the caller can check the comparison was not vacuous.
Tally expectPacketsEqualSingle(const MeshObject& object, const std::vector<Ray>& rays, int packet,
                               std::uint32_t lane_mask, float preset_t, const std::string& label) {
  Tally tally;
  QueryContext ctx;
  int mismatches = 0;
  for (std::size_t first = 0; first < rays.size(); first += static_cast<std::size_t>(packet)) {
    const int n = static_cast<int>(std::min<std::size_t>(static_cast<std::size_t>(packet), rays.size() - first));
    const std::uint32_t full = (1u << n) - 1u;
    const int rot = static_cast<int>(first / static_cast<std::size_t>(packet)) % 16;
    const std::uint32_t active = std::rotl(lane_mask, rot) & full;
    Hit hits[kMaxPacketRays], expected[kMaxPacketRays];
    for (int j = 0; j < n; ++j) hits[j].t = expected[j].t = preset_t;
    const std::span<const Ray> span(rays.data() + first, static_cast<std::size_t>(n));
    const unsigned found = object.intersectPacket(span, std::span<Hit>(hits, static_cast<std::size_t>(n)), active, ctx);
    const unsigned blocked = object.occludedPacket(span, active, ctx);
    for (int j = 0; j < n; ++j) {
      const Ray& r = rays[first + static_cast<std::size_t>(j)];
      const bool on = (active >> j & 1u) != 0;
      const bool expect_found = on && object.intersect(r, expected[j], ctx);
      const bool expect_blocked = on && object.occluded(r, ctx);
      tally.rays += on ? 1 : 0;
      tally.hits += expect_found ? 1 : 0;
      tally.occluded += expect_blocked ? 1 : 0;
      const bool ok = expect_found == ((found >> j & 1u) != 0) && sameHitBits(hits[j], expected[j]) &&
                      expect_blocked == ((blocked >> j & 1u) != 0);
      if (!ok && ++mismatches <= 5) {
        ADD_FAILURE() << label << ": lane " << j << " of packet at " << first << ", " << r << ": packet " << hits[j]
                      << " (found " << (found >> j & 1u) << ", occluded " << (blocked >> j & 1u) << "), single "
                      << expected[j] << " (found " << expect_found << ", occluded " << expect_blocked << ")";
      }
    }
    EXPECT_EQ(found & ~active, 0u) << label;
    EXPECT_EQ(blocked & ~active, 0u) << label;
  }
  EXPECT_EQ(mismatches, 0) << label;
  return tally;
}

class MeshPacket : public ::testing::Test {
 protected:
  static void runAll(const std::shared_ptr<const MeshObject>& object, const std::vector<Ray>& rays,
                     const std::string& name, bool expect_hits = true) {
    const std::string isa(toString(widestSimdIsa()));
    {
      for (int packet : {1, 3, detail::meshBvhKernels().packet_width, kMaxPacketRays}) {
        for (std::uint32_t mask : {0xFFFFFFFFu, 0x5A5A5A5Au, 0x00010001u}) {
          for (float preset : {std::numeric_limits<float>::infinity(), 2.5f}) {
            const std::string label = name + " / " + isa + " / packet " + std::to_string(packet) + " / mask " +
                                      std::to_string(mask) + " / t " + std::to_string(preset);
            const Tally t = expectPacketsEqualSingle(*object, rays, packet, mask, preset, label);
            EXPECT_GT(t.rays, 0u) << label;
            if (expect_hits && mask == 0xFFFFFFFFu && preset > 1e30f) {
              EXPECT_GT(t.hits, t.rays / 20) << label;
              EXPECT_LT(t.hits, t.rays) << label;
              EXPECT_GT(t.occluded, 0u) << label;
            }
          }
        }
      }
    }
  }
};

TEST_F(MeshPacket, CoherentPrimaryRaysEqualSingleRays) {
  const auto object = buildChecked(icosphere(4), BvhBuildConfig{});
  runAll(object, primaryRays(enlarged(object->bounds(), 0.5f), 48, 48), "icosphere primary");
  const auto soup = buildChecked(triangleSoup(4000, 7), BvhBuildConfig{});
  runAll(soup, primaryRays(soup->bounds(), 40, 40), "soup primary");
}

TEST_F(MeshPacket, RandomRaysEqualSingleRays) {
  const auto object = buildChecked(triangleSoup(3000, 99), BvhBuildConfig{});
  runAll(object, randomRays(enlarged(object->bounds(), 1.0f), 3000, 11), "soup random");
}

TEST_F(MeshPacket, RaysThroughSharedEdgesAndVerticesEqualSingleRays) {
  for (const auto& mesh : {icosphere(3), flatGrid(24), uvSphere(32, 16)}) {
    const auto object = buildChecked(mesh, BvhBuildConfig{});
    runAll(object, edgeAndVertexRays(mesh, 1600, 5), mesh.name() + " edges", false);
    // The same rays in coherent order: sorted by direction, so that packets hold neighbours.
    auto rays = edgeAndVertexRays(mesh, 1600, 6);
    std::sort(rays.begin(), rays.end(), [](const Ray& a, const Ray& b) { return a.dir.x < b.dir.x; });
    runAll(object, rays, mesh.name() + " edges sorted", false);
  }
}

TEST_F(MeshPacket, CoherentRaysThroughGridVerticesAndEdgesEqualSingleRays) {
  // Parallel rays down onto a grid (z = 0.25, cells of 0.125), on a lattice of half cells: every
  // ray passes through a vertex or an edge, where edge functions are exactly zero, and whole
  // packets stay together down to the leaves, where many rays take the exact path at once; also
  // tilted (exact shears 1/8 and 1/4).
  const auto object = buildChecked(flatGrid(16), BvhBuildConfig{});
  std::vector<Ray> rays;
  for (const glm::vec3 dir : {glm::vec3(0.0f, 0.0f, -1.0f), glm::vec3(0.125f, 0.25f, -1.0f)})
    for (int ty = 0; ty < 32; ty += 4)
      for (int tx = 0; tx < 32; tx += 4)
        for (int y = ty; y < ty + 4; ++y)
          for (int x = tx; x < tx + 4; ++x) {
            Ray r;
            r.origin = glm::vec3(0.0625f * static_cast<float>(x), 0.0625f * static_cast<float>(y), 1.25f) - dir;
            r.dir = dir;
            rays.push_back(r);
          }
  runAll(object, rays, "grid lattice", false);
  QueryContext ctx;
  std::size_t hits = 0;
  for (const Ray& r : rays) {
    Hit h;
    hits += object->intersect(r, h, ctx) ? 1 : 0;
  }
  EXPECT_GT(hits, rays.size() / 2);
}

TEST_F(MeshPacket, PacketsOfSpreadOriginsAndDirectionsEqualSingleRays) {
  // The packet walk drops a node's children by one test against bounds of all its rays (origins,
  // inverse directions, tnear): packets here spread their origins over up to a third of the mesh,
  // their directions by up to 0.3 (still mostly one octant), start some rays inside the mesh
  // (tnear > 0) and zero some direction components (+0 and -0: infinite inverses), so that a bound
  // that is not conservative shows as a lane that misses its own single-ray hit.
  const auto object = buildChecked(triangleSoup(5000, 31), BvhBuildConfig{});
  const Box b = object->bounds();
  const glm::vec3 size = b.hi - b.lo;
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f), sym(-1.0f, 1.0f);
  std::vector<Ray> rays;
  for (int packet = 0; packet < 400; ++packet) {
    const float spread = packet % 4 == 0 ? 0.0f : 0.33f * u01(rng);
    const float turn = packet % 3 == 0 ? 0.0f : 0.3f * u01(rng);
    const glm::vec3 centre = b.lo + glm::vec3(u01(rng), u01(rng), u01(rng)) * size;
    glm::vec3 axis(sym(rng), sym(rng), sym(rng));
    if (packet % 5 == 1) axis = glm::vec3(0.0f, 0.0f, packet % 10 == 1 ? -1.0f : 1.0f);
    const glm::vec3 origin = centre - 1.5f * glm::length(size) * glm::normalize(axis);
    for (int j = 0; j < kMaxPacketRays; ++j) {
      Ray r;
      r.origin = origin + spread * glm::vec3(sym(rng), sym(rng), sym(rng)) * size;
      r.dir = axis + turn * glm::vec3(sym(rng), sym(rng), sym(rng));
      if (packet % 5 == 1 && j % 3 != 0) r.dir = glm::vec3(j % 2 == 0 ? 0.0f : -0.0f, 0.0f, axis.z);
      if (packet % 7 == 3) r.tnear = 0.5f * glm::length(size) * u01(rng) + glm::length(size);
      rays.push_back(r);
    }
  }
  runAll(object, rays, "spread packets");
}

TEST_F(MeshPacket, AwkwardRaysEqualSingleRays) {
  const auto object = buildChecked(icosphere(3), BvhBuildConfig{});
  const auto rays = awkwardRays(object->bounds());
  runAll(object, rays, "awkward", false);
  // Not vacuous: some of them hit, the unqueryable ones never.
  Hit h[kMaxPacketRays];
  QueryContext ctx;
  const unsigned found = object->intersectPacket(std::span<const Ray>(rays.data(), kMaxPacketRays), h, 0xFFFFu, ctx);
  EXPECT_NE(found & 1u, 0u);
  EXPECT_EQ(found & 0b1110u, 0u);
}

TEST_F(MeshPacket, SmallMeshesWhoseRootIsALeaf) {
  const auto object = buildChecked(boxMesh({0, 0, 0}, {1, 1, 1}), BvhBuildConfig{});
  runAll(object, primaryRays(enlarged(object->bounds(), 0.5f), 24, 24), "box");
}

TEST_F(MeshPacket, ObjectEntryPointsEqualSingleRaysForBothStructures) {
  const auto mesh = std::make_shared<const TriangleMesh>(icosphere(4));
  const std::vector<std::shared_ptr<const MeshObject>> objects = {buildChecked(mesh, BvhBuildConfig{}),
                                                                  buildChecked(mesh, KdBuildConfig{})};
  const auto rays = primaryRays(mesh->bounds(), 32, 32);
  QueryContext ctx;
  for (const auto& object : objects) {
    std::size_t hits = 0;
    for (std::size_t first = 0; first < rays.size(); first += kMaxPacketRays) {
      const std::span<const Ray> packet(rays.data() + first, kMaxPacketRays);
      Hit got[kMaxPacketRays], want[kMaxPacketRays];
      const std::uint32_t found = object->intersectPacket(packet, got, 0xFFFFu, ctx);
      const std::uint32_t blocked = object->occludedPacket(packet, 0xFFFFu, ctx);
      for (int j = 0; j < kMaxPacketRays; ++j) {
        const bool f = object->intersect(packet[j], want[j], ctx);
        hits += f ? 1 : 0;
        EXPECT_EQ(f, (found >> j & 1u) != 0);
        EXPECT_TRUE(sameHitBits(got[j], want[j])) << got[j] << " vs " << want[j];
        EXPECT_EQ(object->occluded(packet[j], ctx), (blocked >> j & 1u) != 0);
      }
    }
    EXPECT_GT(hits, rays.size() / 10);
  }
}

TEST_F(MeshPacket, BadPacketsAreRefusedNamingTheProblem) {
  const auto object = buildChecked(icosphere(2), BvhBuildConfig{});
  std::vector<Ray> rays(kMaxPacketRays + 1);
  std::vector<Hit> hits(kMaxPacketRays + 1);
  QueryContext ctx;
  expectErrorNaming<InvalidArgument>([&] { (void)object->intersectPacket(rays, hits, ~0u, ctx); }, "at most 16");
  expectErrorNaming<InvalidArgument>([&] { (void)object->occludedPacket(rays, ~0u, ctx); }, "at most 16");
  expectErrorNaming<InvalidArgument>(
      [&] {
        (void)object->intersectPacket(std::span<const Ray>(rays.data(), 4), std::span<Hit>(hits.data(), 3), ~0u, ctx);
      },
      "3 hits for 4 rays");
}

}  // namespace
}  // namespace duplex::test
