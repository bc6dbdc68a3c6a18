// The two-level structure: TopLevel over instances with rotations, non-uniform scales, mirrors and
// translations against a brute force over all triangles transformed to world space in double
// (same instance and primitive, or same t within 1e-5 relative), occlusion, world-space normals,
// the top-level tree invariants, counters, and invalid input.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "Reference.h"
#include "TestSupport.h"
#include "TwoLevelChecks.h"

#include "duplex/accel/Affine.h"
#include "duplex/accel/Error.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>
#include <glm/matrix.hpp>

#include <array>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr double kNaNd = std::numeric_limits<double>::quiet_NaN();

/// Instances, their world-space reference triangles, and a lookup (instance id, prim) -> triangle.
struct World {
  std::vector<InstanceDesc> instances;
  std::vector<RefTriangle> tris;
  std::map<std::pair<std::uint32_t, std::uint32_t>, RefTriangle> by_id;
  std::vector<bool> mirrored;  // by position in `instances`

  void add(const std::shared_ptr<const MeshObject>& object, const Affine& world_from_object, std::uint32_t id) {
    instances.push_back({object, world_from_object, id});
    mirrored.push_back(glm::determinant(world_from_object.linear) < 0.0);
    for (const RefTriangle& t : refTriangles(object->mesh(), world_from_object, id)) {
      tris.push_back(t);
      by_id.emplace(std::make_pair(id, t.prim), t);
    }
  }
  [[nodiscard]] bool isMirrored(std::uint32_t id) const {
    for (std::size_t i = 0; i < instances.size(); ++i)
      if (instances[i].id == id) return mirrored[i];
    return false;
  }
};

/// TopLevel::build followed by the tree checker over the instances' world boxes (every top-level
/// tree built in these tests is checked).
void buildTopChecked(TopLevel& top, std::span<const InstanceDesc> instances, const KdBuildConfig& config = {}) {
  top.build(instances, config);
  std::vector<Box> boxes;
  for (const InstanceDesc& d : instances) boxes.push_back(d.world_from_object.apply(d.object->bounds()));
  EXPECT_TRUE(checkBoxKdTree(top.tree(), boxes, config.max_depth));
}

/// Objects shared by the worlds below (each tree checked once, when built).
struct Library {
  std::shared_ptr<const MeshObject> sphere, box, grid, soup, spot;
  Library() {
    sphere = buildChecked(icosphere(3));
    box = buildChecked(boxMesh(glm::vec3(-1.0f), glm::vec3(1.0f), "unit-box"));
    grid = buildChecked(flatGrid(12, 2, 0.0f, 0.25f));
    soup = buildChecked(triangleSoup(300, 61));
    if (auto m = sharedMeshCached("spot.obj")) spot = buildChecked(m);
  }
};

/// Random rotations, non-uniform scales (some mirrored), translations in a cube of side `spread`
/// around `offset`; instance ids start at 100 so that they differ from positions.
World randomWorld(const Library& lib, int count, glm::dvec3 offset, double spread, std::uint64_t seed, bool mirrors) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0), s(0.3, 2.0);
  std::vector<std::shared_ptr<const MeshObject>> objects = {lib.sphere, lib.box, lib.grid, lib.soup};
  if (lib.spot) objects.push_back(lib.spot);
  World w;
  if (offset == glm::dvec3(0.0))
    w.add(lib.sphere, Affine::identity(), 100);  // placed as authored (the identity fast path)
  else w.add(lib.sphere, Affine::fromRowMajor3x4({1, 0, 0, offset.x, 0, 1, 0, offset.y, 0, 0, 1, offset.z}), 100);
  w.add(lib.box, Affine::fromRowMajor3x4({2, 0, 0, offset.x, 0, 2, 0, offset.y, 0, 0, 2, offset.z}), 101);
  for (int i = 2; i < count; ++i) {
    glm::dvec3 scale = draw3<glm::dvec3>(s, rng);
    if (i % 3 == 0) scale = glm::dvec3(scale.x);  // uniform
    if (mirrors && i % 4 == 1) scale.y = -scale.y;
    const glm::dvec3 axis = draw3<glm::dvec3>(u, rng) + glm::dvec3(0.0, 0.0, 1e-3);
    const double angle = 3.14159 * u(rng);
    const auto m = rotationScaleTranslation(axis, angle, scale, offset + 0.5 * spread * draw3<glm::dvec3>(u, rng));
    w.add(objects[static_cast<std::size_t>(i) % objects.size()], Affine::fromRowMajor3x4(m),
          100 + static_cast<std::uint32_t>(i));
  }
  return w;
}

/// Every ray: TopLevel::intersect (instance, primitive, t), the hit's geometry in world space,
/// TopLevel::occluded and the ray counter, against the world-space brute force.
DiffStats expectTopLevelAgrees(const TopLevel& top, const World& w, std::span<const Ray> rays, bool check_normal,
                               const std::string& label) {
  const RefScene ref(w.tris);
  HitTolerance tol;
  tol.abs_scale = 1e-6 * coordinateScale(top.bounds());
  DiffStats s;
  QueryContext ctx;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    ++s.rays;
    auto fail = [&](const auto& what) {
      if (s.failures++ < 8) ADD_FAILURE() << label << ", ray " << i << ": " << what;
    };
    const std::uint64_t before = ctx.stats.rays;
    const Hit hit = top.intersect(ray, ctx);
    const bool occ = top.occluded(ray, ctx);
    if (ctx.stats.rays != before + 2) fail("QueryContext::stats.rays does not count one per query");
    const auto match = agreesWithReference(hit, ray, ref, tol, true);
    if (!match) fail(match.message());
    const auto occ_match = occlusionAgrees(occ, ray, ref, tol);
    if (!occ_match) fail(occ_match.message());
    if (!hit.valid()) continue;
    ++s.hits;
    const auto it = w.by_id.find({hit.instance_id, hit.prim_id});
    if (it == w.by_id.end()) {
      fail(::testing::Message() << hit << " names no instance/triangle of the world");
      continue;
    }
    const RefTriangle& tri = it->second;
    // Barycentrics are invariant under affine maps: they give the hit point on the world triangle.
    const glm::dvec3 pb = (1.0 - double(hit.u) - double(hit.v)) * tri.a + double(hit.u) * tri.b + double(hit.v) * tri.c;
    const glm::dvec3 pr = glm::dvec3(ray.origin) + double(hit.t) * glm::dvec3(ray.dir);
    const double allowed = 1e-5 * (coordinateScale(top.bounds()) + double(hit.t) * glm::length(glm::dvec3(ray.dir)));
    if (!(glm::length(pb - pr) <= allowed))
      fail(::testing::Message() << hit << ": barycentric point " << glm::length(pb - pr) << " from origin + t dir");
    if (check_normal && !w.isMirrored(hit.instance_id)) {
      const double c = glm::dot(glm::normalize(glm::dvec3(hit.ng)), glm::normalize(tri.n));
      if (!(c > 1.0 - 1e-4))
        fail(::testing::Message() << hit << ": ng not along the world triangle normal (cos " << c << ")");
    }
  }
  EXPECT_EQ(s.failures, 0u) << label << ": " << s.failures << " of " << s.rays << " rays disagree";
  return s;
}

std::vector<Ray> worldRays(const Box& bounds, std::uint64_t seed) {
  std::vector<Ray> rays = randomRays(bounds, 2500, seed);
  const auto outer = randomRays(enlarged(bounds, 0.5f), 1000, seed + 1);
  rays.insert(rays.end(), outer.begin(), outer.end());
  const auto primary = primaryRays(bounds, 40, 40);
  rays.insert(rays.end(), primary.begin(), primary.end());
  // Limited intervals and scaled (non-unit) directions.
  for (std::size_t i = 0; i < 600; ++i) {
    Ray r = rays[i];
    r.dir *= 0.37f + static_cast<float>(i % 5);
    r.tnear = 0.1f * static_cast<float>(i % 4);
    r.tfar = 0.5f + static_cast<float>(i % 7);
    rays.push_back(r);
  }
  return rays;
}

// ---------------------------------------------------------------------------------------------

TEST(TopLevel, AgreesWithWorldSpaceBruteForce) {
  const Library lib;
  const World w = randomWorld(lib, 14, glm::dvec3(0.0), 8.0, 71, true);
  TopLevel top;
  buildTopChecked(top, w.instances);
  EXPECT_EQ(top.size(), w.instances.size());
  const auto s = expectTopLevelAgrees(top, w, worldRays(top.bounds(), 72), true, "random world");
  EXPECT_GT(s.hits, s.rays / 8);  // the rays meet the instances (about a fifth hit them)
}

TEST(TopLevel, AgreesForEveryHeuristic) {
  const Library lib;
  const World w = randomWorld(lib, 10, glm::dvec3(1.0, 2.0, 3.0), 5.0, 73, true);
  for (const ConfigCase& c : allConfigCases()) {
    SCOPED_TRACE(c.name);
    TopLevel top;
    buildTopChecked(top, w.instances, c.config);
    auto rays = worldRays(top.bounds(), 74);
    rays.resize(1200);
    expectTopLevelAgrees(top, w, rays, true, c.name);
  }
}

TEST(TopLevel, InstancesFarFromTheOrigin) {
  const Library lib;
  const World w = randomWorld(lib, 10, glm::dvec3(1.0e5, -2.0e5, 5.0e4), 10.0, 75, true);
  TopLevel top;
  buildTopChecked(top, w.instances);
  const auto s = expectTopLevelAgrees(top, w, worldRays(top.bounds(), 76), true, "far world");
  EXPECT_GT(s.hits, s.rays / 8);
}

// The wide traversal form (the default) and the kd-tree walk give the same hits bit for bit, single
// and packet, closest and any hit, with the brute force as the reference; axis-aligned rays (zero
// direction components) and rays starting on instance box faces included.
TEST(TopLevel, WideAndKdTraversalsAgree) {
  const Library lib;
  const World w = randomWorld(lib, 40, glm::dvec3(0.5, -1.0, 2.0), 6.0, 91, true);
  TopLevelConfig kd_config;
  kd_config.wide_traversal = false;
  TopLevel wide, kd(kd_config);
  buildTopChecked(wide, w.instances);
  buildTopChecked(kd, w.instances);
  std::vector<Ray> rays = worldRays(wide.bounds(), 92);
  rays.resize(1200);
  for (std::size_t i = 0; i < 400; ++i) {  // axis-aligned, some from an instance's origin
    Ray r = rays[i];
    r.dir = glm::vec3(0.0f);
    r.dir[i % 3] = i % 2 ? 1.0f : -1.0f;
    if (i % 3 == 0) r.origin = glm::vec3(w.instances[i % w.instances.size()].world_from_object.translation);
    rays.push_back(r);
  }
  expectTopLevelAgrees(wide, w, rays, true, "wide");
  QueryContext ctx;
  std::size_t hits = 0;
  for (std::size_t start = 0; start + kMaxPacketRays <= rays.size(); start += kMaxPacketRays) {
    const std::span<const Ray> packet(rays.data() + start, kMaxPacketRays);
    std::array<Hit, kMaxPacketRays> a{}, b{};
    const std::uint32_t found_a = wide.intersectPacket(packet, a, ctx);
    const std::uint32_t found_b = kd.intersectPacket(packet, b, ctx);
    EXPECT_EQ(found_a, found_b) << "packet at " << start;
    EXPECT_EQ(wide.occludedPacket(packet, ctx), kd.occludedPacket(packet, ctx)) << "packet at " << start;
    for (int j = 0; j < kMaxPacketRays; ++j) {
      const Ray& r = packet[static_cast<std::size_t>(j)];
      const Hit single_wide = wide.intersect(r, ctx), single_kd = kd.intersect(r, ctx);
      EXPECT_TRUE(sameHitBits(single_wide, single_kd))
          << "ray " << start + j << ": " << sameHit(single_wide, single_kd).message();
      EXPECT_TRUE(sameHitBits(a[static_cast<std::size_t>(j)], single_wide)) << "ray " << start + j;
      EXPECT_TRUE(sameHitBits(b[static_cast<std::size_t>(j)], single_kd)) << "ray " << start + j;
      EXPECT_EQ(wide.occluded(r, ctx), kd.occluded(r, ctx)) << "ray " << start + j;
      hits += single_wide.valid();
    }
  }
  EXPECT_GT(hits, rays.size() / 10);
  // Switching the form off and on through setConfig takes effect at once, with the same hits.
  TopLevelConfig c = wide.config();
  c.wide_traversal = false;
  wide.setConfig(c);
  c.wide_traversal = true;
  wide.setConfig(c);
  for (std::size_t i = 0; i < 300; ++i)
    EXPECT_TRUE(sameHitBits(wide.intersect(rays[i], ctx), kd.intersect(rays[i], ctx)));
}

// The packet walk drops a node's children by one test against bounds of all the packet's rays:
// packets whose origins spread over up to a third of the scene (shadow rays from surface points),
// whose directions differ by up to 0.3 (still mostly one octant), some starting inside the scene
// (tnear > 0), some with zero direction components (+0 and -0), against single rays bit for bit.
// Packets and batches against single rays, in a world with instances placed as authored (offset
// zero: the identity path, which asks objects with the caller's rays) and in one without.
void expectPacketsAndBatchesEqualSingleRays(glm::dvec3 offset, std::uint64_t seed) {
  const Library lib;
  const World w = randomWorld(lib, 60, offset, 6.0, seed, true);
  TopLevel top;
  buildTopChecked(top, w.instances);
  const Box b = top.bounds();
  const glm::vec3 size = b.hi - b.lo;
  const float diagonal = glm::length(size);
  std::mt19937_64 rng(seed + 1);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f), sym(-1.0f, 1.0f);
  QueryContext ctx;
  std::size_t hits = 0, blocked = 0, mismatches = 0, rays = 0;
  for (int packet = 0; packet < 300; ++packet) {
    const float spread = packet % 4 == 0 ? 0.0f : 0.33f * u01(rng);
    const float turn = packet % 3 == 0 ? 0.0f : 0.3f * u01(rng);
    const glm::vec3 centre = b.lo + glm::vec3(u01(rng), u01(rng), u01(rng)) * size;
    glm::vec3 axis(sym(rng), sym(rng), sym(rng));
    if (packet % 5 == 1) axis = glm::vec3(0.0f, 0.0f, packet % 10 == 1 ? -1.0f : 1.0f);
    const glm::vec3 origin = centre - 1.5f * diagonal * glm::normalize(axis);
    std::array<Ray, kMaxPacketRays> rs;
    for (int j = 0; j < kMaxPacketRays; ++j) {
      Ray& r = rs[static_cast<std::size_t>(j)];
      r.origin = origin + spread * glm::vec3(sym(rng), sym(rng), sym(rng)) * size;
      r.dir = axis + turn * glm::vec3(sym(rng), sym(rng), sym(rng));
      if (packet % 5 == 1 && j % 3 != 0) r.dir = glm::vec3(j % 2 == 0 ? 0.0f : -0.0f, 0.0f, axis.z);
      if (packet % 7 == 3) r.tnear = (1.0f + 0.5f * u01(rng)) * diagonal / glm::length(r.dir);
      if (packet % 11 == 5) r.tfar = (0.8f + 0.6f * u01(rng)) * diagonal / glm::length(r.dir);
    }
    std::array<Hit, kMaxPacketRays> got{}, batch{};
    std::array<std::uint8_t, kMaxPacketRays> batch_blocked{};
    const std::uint32_t found = top.intersectPacket(rs, got, ctx);
    const std::uint32_t occluded = top.occludedPacket(rs, ctx);
    top.intersectBatch(rs, batch, ctx);
    top.occludedBatch(rs, batch_blocked, ctx);
    for (int j = 0; j < kMaxPacketRays; ++j) {
      const auto i = static_cast<std::size_t>(j);
      const Ray& r = rs[i];
      const Hit want = top.intersect(r, ctx);
      const bool want_blocked = top.occluded(r, ctx);
      ++rays;
      hits += want.valid() ? 1 : 0;
      blocked += want_blocked ? 1 : 0;
      const bool ok = sameHitBits(got[i], want) && ((found >> j & 1u) != 0) == want.valid() &&
                      ((occluded >> j & 1u) != 0) == want_blocked && sameHitBits(batch[i], want) &&
                      (batch_blocked[i] != 0) == want_blocked;
      if (!ok && ++mismatches <= 5)
        ADD_FAILURE() << "packet " << packet << ", lane " << j << ", " << r << ": packet " << got[i] << ", batch "
                      << batch[i] << ", single " << want;
    }
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_GT(hits, rays / 10);
  EXPECT_LT(hits, rays);
  EXPECT_GT(blocked, rays / 10);
}

TEST(TopLevel, PacketsOfSpreadOriginsAndDirectionsEqualSingleRays) {
  expectPacketsAndBatchesEqualSingleRays(glm::dvec3(0.5, -1.0, 2.0), 93);
}

TEST(TopLevel, PacketsThroughInstancesPlacedAsAuthoredEqualSingleRays) {
  expectPacketsAndBatchesEqualSingleRays(glm::dvec3(0.0), 193);
}

TEST(TopLevel, BatchesOnATopLevelNeverBuiltMissEveryRay) {
  const TopLevel top;
  QueryContext ctx;
  std::array<Ray, 5> rs{};
  for (Ray& r : rs) r.dir = glm::vec3(0.0f, 1.0f, 0.0f);
  std::array<Hit, 5> hits{};
  for (Hit& h : hits) h.prim_id = 7;  // overwritten by a miss
  std::array<std::uint8_t, 5> blocked{};
  blocked.fill(1);
  top.intersectBatch(rs, hits, ctx);
  top.occludedBatch(rs, blocked, ctx);
  for (std::size_t i = 0; i < rs.size(); ++i) {
    EXPECT_FALSE(hits[i].valid()) << i;
    EXPECT_EQ(blocked[i], 0) << i;
  }
  EXPECT_EQ(ctx.stats.rays, 2 * rs.size());
}

TEST(TopLevel, BatchesRefuseShortResultSpans) {
  const Library lib;
  const World w = randomWorld(lib, 8, glm::dvec3(0.0), 3.0, 5, false);
  TopLevel top;
  buildTopChecked(top, w.instances);
  QueryContext ctx;
  std::array<Ray, 3> rs{};
  for (Ray& r : rs) r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  std::array<Hit, 2> hits{};
  std::array<std::uint8_t, 2> blocked{};
  const auto expect_refused = [](auto&& call, const std::string& needle) {
    try {
      call();
      ADD_FAILURE() << "no InvalidArgument (" << needle << ")";
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_refused([&] { top.intersectBatch(rs, hits, ctx); }, "2 hits for 3 rays");
  expect_refused([&] { top.occludedBatch(rs, blocked, ctx); }, "2 results for 3 rays");
}

TEST(TopLevel, ManyOverlappingInstancesOfOneObject) {
  // 60 instances of one sphere around one spot: the top-level leaves hold many instances and the
  // traversal's mailbox (8 entries) overflows.
  const Library lib;
  World w;
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::uint32_t i = 0; i < 60; ++i) {
    const double ax = u(rng), ay = u(rng), angle = u(rng), scale = 0.5 + 0.3 * u(rng);
    const glm::dvec3 at = draw3<glm::dvec3>(u, rng);
    w.add(lib.sphere,
          Affine::fromRowMajor3x4(rotationScaleTranslation(glm::dvec3(ax, ay, 1.0), angle, glm::dvec3(scale), at)), i);
  }
  TopLevel top;
  buildTopChecked(top, w.instances);
  auto rays = worldRays(top.bounds(), 78);
  rays.resize(2000);
  const auto s = expectTopLevelAgrees(top, w, rays, true, "overlapping");
  EXPECT_GT(s.hits, s.rays / 5);
}

TEST(TopLevel, TiesBetweenInstancesGoToTheLowestId) {
  // Coincident copies of one sphere (the same transform: every ray meets all of them at the same t)
  // beside two others: whatever the insertion order, tree shape, single or packet walk, the hit is
  // the lowest id's, with the t and triangle of a scene holding that copy alone.
  const Library lib;
  const Affine at = Affine::fromRowMajor3x4(
      rotationScaleTranslation(glm::dvec3(0.3, 0.2, 1.0), 0.7, glm::dvec3(1.3), {0.5, -0.2, 0.1}));
  const std::uint32_t copies[] = {41, 7, 19, 3, 25, 12};
  std::vector<InstanceDesc> instances;
  for (const std::uint32_t id : copies) instances.push_back({lib.sphere, at, id});
  instances.push_back({lib.box, Affine::fromRowMajor3x4({1, 0, 0, 4, 0, 1, 0, 0, 0, 0, 1, 0}), 1});
  instances.push_back({lib.soup, Affine::fromRowMajor3x4({1, 0, 0, -4, 0, 1, 0, 0, 0, 0, 1, 0}), 2});
  std::vector<InstanceDesc> alone(1, InstanceDesc{lib.sphere, at, 3});
  TopLevel top, single;
  buildTopChecked(top, instances);
  buildTopChecked(single, alone);
  std::vector<Ray> rays = primaryRays(top.bounds(), 48, 48);
  const auto random = randomRays(top.bounds(), 2000, 5);
  rays.insert(rays.end(), random.begin(), random.end());
  QueryContext ctx;
  auto check = [&](std::uint32_t lowest, const std::string& label) {
    std::size_t on_copies = 0, failures = 0;
    for (std::size_t i = 0; i < rays.size(); i += kMaxPacketRays) {
      const std::size_t n = std::min<std::size_t>(kMaxPacketRays, rays.size() - i);
      const std::span<const Ray> packet(rays.data() + i, n);
      Hit packet_hits[kMaxPacketRays];
      top.intersectPacket(packet, std::span<Hit>(packet_hits, n), ctx);
      for (std::size_t j = 0; j < n; ++j) {
        const Ray& ray = packet[j];
        const Hit h = top.intersect(ray, ctx);
        const Hit ref = single.intersect(ray, ctx);
        const RayD ray_d{glm::dvec3(ray.origin), glm::dvec3(ray.dir), ray.tnear, ray.tfar};
        const Hit hd = top.intersect(ray_d, ctx);
        const bool copy_hit = h.valid() && h.instance_id != 1 && h.instance_id != 2;
        if (copy_hit) ++on_copies;
        const bool ok =
            (!copy_hit || (h.instance_id == lowest && ref.valid() && h.t == ref.t && h.prim_id == ref.prim_id)) &&
            packet_hits[j].instance_id == h.instance_id && packet_hits[j].t == h.t &&
            packet_hits[j].prim_id == h.prim_id &&
            (!hd.valid() || hd.instance_id == 1 || hd.instance_id == 2 || hd.instance_id == lowest);
        if (!ok && failures++ < 5)
          ADD_FAILURE() << label << ", ray " << i + j << ": " << h << " (packet " << packet_hits[j] << ", alone " << ref
                        << ", double " << hd << "), expected instance " << lowest;
      }
    }
    EXPECT_EQ(failures, 0u) << label;
    EXPECT_GT(on_copies, rays.size() / 10) << label << ": too few rays reach the copies to test the rule";
  };
  check(3, "built");
  // Incremental edits change the tree and the slots; the rule does not depend on them.
  top.remove(3);
  top.set({lib.sphere, at, 3});
  top.remove(7);
  top.commit();
  check(3, "after re-adding 3 and removing 7");
  top.remove(3);
  top.commit();
  check(12, "after removing 3");
}

TEST(TopLevel, AnalyticScaledBox) {
  // Unit box [-1, 1]^3 scaled by 2 around (0, 0, 0): the face z = -2 is hit at t = 8 from z = -10,
  // t is in units of the (unnormalised) world direction, and ng points along -z.
  const Library lib;
  TopLevel top;
  const std::vector<InstanceDesc> inst = {{lib.box, Affine::fromRowMajor3x4({2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0}), 7}};
  buildTopChecked(top, inst);
  EXPECT_LE(top.bounds().lo.z, -2.0f);  // world box rounded outward, but tight
  EXPECT_GE(top.bounds().lo.z, -2.00001f);
  QueryContext ctx;
  Ray r;
  r.origin = glm::vec3(0.1f, 0.2f, -10.0f);
  r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  Hit h = top.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, 7u);
  EXPECT_NEAR(h.t, 8.0f, 1e-5f);
  EXPECT_GT(glm::dot(glm::dvec3(h.ng), glm::dvec3(0, 0, -1)), 0.999 * glm::length(glm::dvec3(h.ng)));
  r.dir = glm::vec3(0.0f, 0.0f, 0.5f);
  h = top.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 16.0f, 2e-5f);
  r.tfar = 15.9f;
  EXPECT_FALSE(top.intersect(r, ctx).valid());
  EXPECT_FALSE(top.occluded(r, ctx));
  r.tfar = 16.1f;
  EXPECT_TRUE(top.occluded(r, ctx));
  // Rotated 90 degrees about z and moved: the face x = +2 (object +y face) is hit from +x.
  buildTopChecked(
      top, std::vector<InstanceDesc>{{lib.box, Affine::fromRowMajor3x4({0, -2, 0, 5, 2, 0, 0, 0, 0, 0, 2, 0}), 9}});
  Ray s;
  s.origin = glm::vec3(20.0f, 0.25f, 0.5f);
  s.dir = glm::vec3(-1.0f, 0.0f, 0.0f);
  h = top.intersect(s, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, 9u);
  EXPECT_NEAR(h.t, 13.0f, 1e-5f);  // face at x = 5 + 2 = 7
  EXPECT_GT(glm::dot(glm::dvec3(h.ng), glm::dvec3(1, 0, 0)), 0.999 * glm::length(glm::dvec3(h.ng)));
  EXPECT_EQ(top.size(), 1u);  // a rebuild replaces the instances
}

// Hit::ng is documented as cross(v1 - v0, v2 - v0) of the hit triangle in the space of the query.
// For a mirroring instance (det < 0) the transformed triangle's cross product flips with the
// winding, so ng must still point along the world triangle's normal.
TEST(TopLevel, NormalOfMirroredInstancesFollowsTheWorldTriangle) {
  const Library lib;
  World w;
  w.add(lib.box, Affine::fromRowMajor3x4({-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}), 0);     // mirror x
  w.add(lib.sphere, Affine::fromRowMajor3x4({1, 0, 0, 4, 0, -2, 0, 0, 0, 0, 1, 0}), 1);  // mirror y, scaled
  w.add(lib.soup,
        Affine::fromRowMajor3x4(
            rotationScaleTranslation(glm::dvec3(1, 2, 3), 0.7, glm::dvec3(1.5, 0.5, -1.0), glm::dvec3(0, 4, 0))),
        2);
  TopLevel top;
  buildTopChecked(top, w.instances);
  QueryContext ctx;
  std::size_t checked = 0, wrong = 0;
  for (const Ray& r : worldRays(top.bounds(), 79)) {
    const Hit h = top.intersect(r, ctx);
    if (!h.valid()) continue;
    const RefTriangle& tri = w.by_id.at({h.instance_id, h.prim_id});
    ++checked;
    const double c = glm::dot(glm::normalize(glm::dvec3(h.ng)), glm::normalize(tri.n));
    if (!(c > 1.0 - 1e-4) && wrong++ < 5)
      ADD_FAILURE() << r << " hits mirrored instance " << h.instance_id << " prim " << h.prim_id << ": ng (" << h.ng.x
                    << ", " << h.ng.y << ", " << h.ng.z << ") vs world cross(v1 - v0, v2 - v0) (" << tri.n.x << ", "
                    << tri.n.y << ", " << tri.n.z << "), cos " << c;
  }
  EXPECT_GT(checked, 500u);
  EXPECT_EQ(wrong, 0u) << "hits whose ng points against the world triangle's normal";
}

// The same contract for length: ng = cross(v1 - v0, v2 - v0) of the world-space triangle, for
// scaled (not mirrored) instances.
TEST(TopLevel, NormalIsTheWorldCrossProduct) {
  const Library lib;
  World w;
  w.add(lib.box, Affine::fromRowMajor3x4({3, 0, 0, 0, 0, 3, 0, 0, 0, 0, 3, 0}), 0);  // uniform scale 3
  w.add(lib.sphere,
        Affine::fromRowMajor3x4(
            rotationScaleTranslation(glm::dvec3(0, 1, 1), 0.4, glm::dvec3(0.5, 2.0, 1.0), glm::dvec3(8, 0, 0))),
        1);
  TopLevel top;
  buildTopChecked(top, w.instances);
  QueryContext ctx;
  std::size_t checked = 0, wrong = 0;
  for (const Ray& r : worldRays(top.bounds(), 80)) {
    const Hit h = top.intersect(r, ctx);
    if (!h.valid()) continue;
    ++checked;
    const glm::dvec3 n = w.by_id.at({h.instance_id, h.prim_id}).n;
    if (!(glm::length(glm::dvec3(h.ng) - n) <= 1e-4 * glm::length(n)) && wrong++ < 5)
      ADD_FAILURE() << r << " instance " << h.instance_id << ": ng (" << h.ng.x << ", " << h.ng.y << ", " << h.ng.z
                    << ") but world cross(v1 - v0, v2 - v0) = (" << n.x << ", " << n.y << ", " << n.z << ")";
  }
  EXPECT_GT(checked, 500u);
  EXPECT_EQ(wrong, 0u);
}

TEST(TopLevel, EmptyTopLevelMissesEverything) {
  TopLevel top;
  buildTopChecked(top, {});
  EXPECT_EQ(top.size(), 0u);
  EXPECT_TRUE(top.bounds().empty());
  EXPECT_TRUE(top.tree().empty());
  QueryContext ctx;
  Ray r;
  EXPECT_FALSE(top.intersect(r, ctx).valid());
  EXPECT_FALSE(top.occluded(r, ctx));
  EXPECT_EQ(ctx.stats.rays, 2u);
  EXPECT_EQ(ctx.stats.instance_visits, 0u);
  TopLevel never_built;
  EXPECT_FALSE(never_built.intersect(r, ctx).valid());
  EXPECT_FALSE(never_built.occluded(r, ctx));
}

TEST(TopLevel, BadRaysMissAndInstanceVisitsAreCounted) {
  const Library lib;
  TopLevel top;
  const std::vector<InstanceDesc> inst = {{lib.sphere, Affine::identity(), 0},
                                          {lib.box, Affine::fromRowMajor3x4({1, 0, 0, 10, 0, 1, 0, 0, 0, 0, 1, 0}), 1}};
  buildTopChecked(top, inst);
  QueryContext ctx;
  Ray r;
  r.origin = glm::vec3(0.0f, 0.0f, -5.0f);
  r.dir = glm::vec3(0.0f, 0.0f, 1.0f);
  const Hit h = top.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, 0u);
  EXPECT_GE(ctx.stats.instance_visits, 1u);
  // A ray pointing away from everything visits no instance.
  QueryContext away;
  Ray a;
  a.origin = glm::vec3(0.0f, 0.0f, -5.0f);
  a.dir = glm::vec3(0.0f, 0.0f, -1.0f);
  EXPECT_FALSE(top.intersect(a, away).valid());
  EXPECT_FALSE(top.occluded(a, away));
  EXPECT_EQ(away.stats.instance_visits, 0u);
  EXPECT_EQ(away.stats.rays, 2u);
  for (int k = 0; k < 4; ++k) {
    Ray bad = r;
    if (k == 0) bad.dir = glm::vec3(0.0f);
    if (k == 1) bad.dir.z = std::numeric_limits<float>::quiet_NaN();
    if (k == 2) bad.origin.x = std::numeric_limits<float>::infinity();
    if (k == 3) {
      bad.tnear = 10.0f;
      bad.tfar = 1.0f;
    }
    EXPECT_FALSE(top.intersect(bad, ctx).valid()) << bad;
    EXPECT_FALSE(top.occluded(bad, ctx)) << bad;
  }
}

TEST(TopLevel, InvalidInstancesThrowNamingTheInstance) {
  const Library lib;
  auto expect_throw = [&](const InstanceDesc& bad, const std::string& needle) {
    const std::vector<InstanceDesc> inst = {{lib.sphere, Affine::identity(), 0}, bad};
    TopLevel top;
    try {
      top.build(inst);  // must throw: no tree to check
      ADD_FAILURE() << "no InvalidArgument for instance " << bad.id << " " << bad.world_from_object;
    } catch (const InvalidArgument& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_throw({lib.box, Affine::fromRowMajor3x4({kNaNd, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}), 41}, "41");
  expect_throw({lib.box, Affine::fromRowMajor3x4({1, 0, 0, kNaNd, 0, 1, 0, 0, 0, 0, 1, 0}), 42}, "42");
  expect_throw({lib.box, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, INFINITY, 0, 0, 1, 0}), 43}, "43");
  expect_throw({lib.box, Affine::fromRowMajor3x4({0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}), 44}, "44");  // zero
  expect_throw({lib.box, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 5}), 45}, "45");  // flat
  expect_throw({lib.box, Affine::fromRowMajor3x4({1, 2, 3, 0, 2, 4, 6, 0, 1, 0, 1, 0}), 46}, "46");  // rank 2
  expect_throw({nullptr, Affine::identity(), 47}, "47");
  // Finite in double, but the world box leaves float range: refused by the full build and by set(),
  // which leaves the top level as it was.
  const Affine huge = Affine::fromRowMajor3x4({1e39, 0, 0, 0, 0, 1e39, 0, 0, 0, 0, 1e39, 0});
  expect_throw({lib.box, huge, 48}, "float range");
  TopLevel top;
  top.build(std::vector<InstanceDesc>{{lib.sphere, Affine::identity(), 0}});
  EXPECT_THROW(top.set({lib.box, huge, 49}), InvalidArgument);
  top.commit();
  EXPECT_FALSE(top.contains(49));
  EXPECT_EQ(top.size(), 1u);
  EXPECT_TRUE(std::isfinite(top.bounds().hi.x)) << "the root grew to infinity";
}

}  // namespace
}  // namespace duplex::test
