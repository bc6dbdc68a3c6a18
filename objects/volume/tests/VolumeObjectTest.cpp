// VolumeObject (OpenVDB grids): level-set hits against the analytic sphere at two voxel sizes,
// rays from inside, instancing through the SceneTracer, 2 threads against 1, fog transmittance
// against exp(-sigma L) through a box, scene files, and the load errors.

#include "TestSupport.h"
#include "VolumeTestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/objects/VolumeObjectVdb.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/matrix.hpp>
#include <openvdb/io/File.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <random>
#include <thread>
#include <vector>

namespace duplex {
namespace {

using test::expectErrorNaming;
using test::randomUnit;
using test::registeredGrid;
using test::TempDir;
using test::writeGrids;

constexpr double kRadius = 1.0;
const glm::dvec3 kCentre(0.3, -0.2, 0.1);

openvdb::FloatGrid::Ptr sphereGrid(double voxel) {
  openvdb::initialize();
  auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      static_cast<float>(kRadius), openvdb::Vec3f(float(kCentre.x), float(kCentre.y), float(kCentre.z)),
      static_cast<float>(voxel), 3.0f);
  grid->setName("sphere");
  return grid;
}

// Analytic entry/exit times of origin + t dir with the sphere, if the line meets it.
std::optional<std::pair<double, double>> sphereTimes(const glm::dvec3& o, const glm::dvec3& d) {
  const glm::dvec3 oc = o - kCentre;
  const double a = glm::dot(d, d), b = glm::dot(oc, d), c = glm::dot(oc, oc) - kRadius * kRadius;
  const double disc = b * b - a * c;
  if (disc < 0.0) return std::nullopt;
  const double s = std::sqrt(disc);
  return std::make_pair((-b - s) / a, (-b + s) / a);
}

// Distance of the line from the centre (impact parameter).
double impact(const glm::dvec3& o, const glm::dvec3& d) {
  const glm::dvec3 oc = kCentre - o;
  const glm::dvec3 dn = glm::normalize(d);
  return glm::length(oc - glm::dot(oc, dn) * dn);
}

// Outside rays aimed near the sphere; the direction's length is random (t must not depend on it).
std::vector<Ray> outsideRays(std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Ray> rays;
  for (std::size_t k = 0; k < count; ++k) {
    const glm::dvec3 o = kCentre + 3.0 * randomUnit(rng);
    const double target_scale = u(rng);
    const glm::dvec3 target = kCentre + 1.4 * target_scale * randomUnit(rng);
    const glm::dvec3 d = (target - o) * (0.25 + 2.0 * u(rng));
    rays.push_back(Ray{glm::vec3(o), 0.0f, glm::vec3(d), std::numeric_limits<float>::infinity()});
  }
  return rays;
}

double angleDeg(const glm::dvec3& a, const glm::dvec3& b) {
  return std::acos(std::clamp(glm::dot(glm::normalize(a), glm::normalize(b)), -1.0, 1.0)) * 180.0 /
         3.14159265358979323846;
}

// ---- level sets ----

class LevelSetSphere : public ::testing::TestWithParam<double> {};

TEST_P(LevelSetSphere, HitsMatchTheAnalyticSphere) {
  const double voxel = GetParam();
  const auto object = makeVolumeObject(sphereGrid(voxel), VolumeKind::Auto, "sphere");
  ASSERT_EQ(object->kind(), VolumeKind::LevelSet);
  ASSERT_EQ(object->role(), ObjectRole::Surface);
  EXPECT_EQ(object->typeName(), "volume");
  // Bounds hold the sphere.
  const Box b = object->bounds();
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(b.lo[a], kCentre[a] - kRadius);
    EXPECT_GE(b.hi[a], kCentre[a] + kRadius);
    EXPECT_LE(b.hi[a] - b.lo[a], 2.0 * kRadius + 10.0 * voxel);
  }
  QueryContext ctx;
  double max_pos_err = 0.0, max_angle = 0.0;
  int hits = 0, misses = 0;
  for (const Ray& ray : outsideRays(4000, 7)) {
    const glm::dvec3 o(ray.origin), d(ray.dir);
    const double p = impact(o, d);
    Hit hit;
    const bool got = object->intersect(ray, hit, ctx);
    EXPECT_EQ(object->occluded(ray, ctx), got) << ray;
    if (p < kRadius - 2.0 * voxel) {  // clearly through the sphere (away from grazing)
      ASSERT_TRUE(got) << ray << " impact " << p;
      const auto times = sphereTimes(o, d);
      ASSERT_TRUE(times);
      const glm::dvec3 x = o + double(hit.t) * d;
      max_pos_err = std::max(max_pos_err, std::abs(glm::length(x - kCentre) - kRadius));
      max_pos_err = std::max(max_pos_err, std::abs(double(hit.t) - times->first) * glm::length(d));
      max_angle = std::max(max_angle, angleDeg(glm::dvec3(hit.ng), x - kCentre));
      EXPECT_EQ(hit.prim_id, 0u);
      EXPECT_EQ(hit.u, 0.0f);
      EXPECT_EQ(hit.v, 0.0f);
      ++hits;
    } else if (p > kRadius + 2.0 * voxel) {
      EXPECT_FALSE(got) << ray << " impact " << p;
      ++misses;
    }
  }
  std::cout << "[ figures  ] voxel " << voxel << ": " << hits << " hits, " << misses << " misses; max hit error "
            << max_pos_err << " (" << max_pos_err / voxel << " voxel), max normal error " << max_angle << " deg\n";
  EXPECT_GT(hits, 1000);
  EXPECT_GT(misses, 200);
  EXPECT_LT(max_pos_err, 0.25 * voxel);
  EXPECT_LT(max_angle, 3.0);
}

TEST_P(LevelSetSphere, RangeLimitsAndRaysFromInside) {
  const double voxel = GetParam();
  const auto object = makeVolumeObject(sphereGrid(voxel), VolumeKind::LevelSet, "sphere");
  QueryContext ctx;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double max_err = 0.0;
  for (int k = 0; k < 1000; ++k) {
    const double o_scale = u(rng);
    const glm::dvec3 o = kCentre + 0.8 * o_scale * randomUnit(rng);
    const glm::dvec3 dir = randomUnit(rng);
    const glm::dvec3 d = dir * (0.5 + u(rng));
    const Ray ray{glm::vec3(o), 0.0f, glm::vec3(d), std::numeric_limits<float>::infinity()};
    Hit hit;
    ASSERT_TRUE(object->intersect(ray, hit, ctx)) << ray;
    const auto times = sphereTimes(o, d);
    max_err = std::max(max_err, std::abs(double(hit.t) - times->second) * glm::length(d));
    // Leaving: the normal points along the ray.
    EXPECT_GT(glm::dot(glm::dvec3(hit.ng), d), 0.0);
    // tfar short of the exit: no hit; the hit limit is honoured too.
    Ray short_ray = ray;
    short_ray.tfar = static_cast<float>(times->second * 0.9);
    Hit none;
    EXPECT_FALSE(object->intersect(short_ray, none, ctx));
    EXPECT_FALSE(object->occluded(short_ray, ctx));
    Hit closer;
    closer.t = static_cast<float>(times->second * 0.5);
    EXPECT_FALSE(object->intersect(ray, closer, ctx));
    EXPECT_EQ(closer.t, static_cast<float>(times->second * 0.5));
  }
  EXPECT_LT(max_err, 0.25 * voxel);
  // intersectAll: a ray through the centre crosses twice, an entry and an exit.
  const Ray through{glm::vec3(kCentre - glm::dvec3(3, 0, 0)), 0.0f, glm::vec3(1, 0, 0), 100.0f};
  std::vector<Hit> all;
  object->intersectAll(through, all, ctx);
  ASSERT_EQ(all.size(), 2u);
  EXPECT_NEAR(all[0].t, 2.0, 0.25 * voxel);
  EXPECT_NEAR(all[1].t, 4.0, 0.25 * voxel);
  // tnear past the entry starts inside.
  Ray inside = through;
  inside.tnear = 3.0f;
  Hit exit_hit;
  ASSERT_TRUE(object->intersect(inside, exit_hit, ctx));
  EXPECT_NEAR(exit_hit.t, 4.0, 0.25 * voxel);
}

INSTANTIATE_TEST_SUITE_P(VoxelSizes, LevelSetSphere, ::testing::Values(0.05, 0.02));

TEST(VolumeObject, InstanceMovedByTheTopLevelHitsAlike) {
  const auto object = makeVolumeObject(sphereGrid(0.05), VolumeKind::Auto, "sphere");
  auto library = std::make_shared<ObjectLibrary>();
  const ObjectId id = library->add("sphere", object);
  SceneGraph graph(library);
  const Affine world_from_object = Affine::fromRowMajor3x4(
      test::rotationScaleTranslation(glm::dvec3(1, 2, 3), 0.7, glm::dvec3(2.0), glm::dvec3(5, -4, 9)));
  const NodeId node = graph.addInstance(kRootNode, id, world_from_object, "moved");
  graph.commit();
  SceneTracer tracer(graph);
  QueryContext ctx;
  int hits = 0;
  for (const Ray& ray_os : outsideRays(500, 3)) {
    Hit local;
    const bool got = object->intersect(ray_os, local, ctx);
    Ray ray_ws = ray_os;
    ray_ws.origin = glm::vec3(world_from_object.point(glm::dvec3(ray_os.origin)));
    ray_ws.dir = glm::vec3(world_from_object.linear * glm::dvec3(ray_os.dir));
    const Hit world = tracer.intersect(ray_ws, ctx);
    ASSERT_EQ(world.valid(), got) << ray_os;
    if (!got) continue;
    ++hits;
    EXPECT_NEAR(world.t, local.t, 2e-4 * local.t) << ray_os;
    EXPECT_EQ(world.instance_id, node);
    const glm::dvec3 n_ws = glm::transpose(glm::inverse(world_from_object.linear)) * glm::dvec3(local.ng);
    EXPECT_LT(angleDeg(glm::dvec3(world.ng), n_ws), 0.5);
  }
  EXPECT_GT(hits, 100);
  // Moving the instance only touches the top level: the same object answers at the new place.
  graph.setTransform(node, Affine{world_from_object.linear, world_from_object.translation + glm::dvec3(10, 0, 0)});
  graph.commit();
  const glm::dvec3 c_ws = world_from_object.point(kCentre) + glm::dvec3(10, 0, 0);
  const Ray down{glm::vec3(c_ws + glm::dvec3(0, 0, 10)), 0.0f, glm::vec3(0, 0, -1), 100.0f};
  const Hit h = tracer.intersect(down, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 10.0 - 2.0 * kRadius, 2.0 * 0.25 * 0.05);
}

TEST(VolumeObject, TwoThreadsGiveTheResultsOfOne) {
  const auto object = makeVolumeObject(sphereGrid(0.05), VolumeKind::Auto, "sphere");
  const auto rays = outsideRays(3000, 5);
  auto trace = [&](std::size_t begin, std::size_t end, std::vector<Hit>& out) {
    QueryContext ctx;  // one per thread
    for (std::size_t k = begin; k < end; ++k) (void)object->intersect(rays[k], out[k], ctx);
  };
  std::vector<Hit> one(rays.size()), two(rays.size());
  trace(0, rays.size(), one);
  // Both threads trace interleaved halves (so that both walk the same nodes at once).
  std::thread a([&] { trace(0, rays.size() / 2, two); });
  std::thread b([&] { trace(rays.size() / 2, rays.size(), two); });
  a.join();
  b.join();
  for (std::size_t k = 0; k < rays.size(); ++k) {
    ASSERT_EQ(one[k].t, two[k].t) << k;
    ASSERT_EQ(one[k].ng, two[k].ng) << k;
    ASSERT_EQ(one[k].prim_id, two[k].prim_id) << k;
  }
}

TEST(VolumeObject, QueryContextCacheIsPerObjectAndSurvivesTheObject) {
  QueryContext ctx;
  Hit hit;
  const Ray ray{glm::vec3(kCentre - glm::dvec3(3, 0, 0)), 0.0f, glm::vec3(1, 0, 0), 100.0f};
  {
    const auto a = makeVolumeObject(sphereGrid(0.05), VolumeKind::Auto, "a");
    ASSERT_TRUE(a->intersect(ray, hit, ctx));
  }
  // The first object is gone; its slot (which holds its grid) stays valid; a new one works.
  const auto b = makeVolumeObject(sphereGrid(0.1), VolumeKind::Auto, "b");
  Hit hit_b;
  ASSERT_TRUE(b->intersect(ray, hit_b, ctx));
  EXPECT_NEAR(hit_b.t, 2.0, 0.025);
  EXPECT_GE(ctx.cachedSlots(), 1u);
  QueryContext copy = ctx;  // copies counters only
  EXPECT_EQ(copy.cachedSlots(), 0u);
}

// ---- fog ----

// A homogeneous box of density sigma over voxels [lo, hi]^3 (filled with tiles where whole nodes
// fit, voxels elsewhere), under a rotated, scaled, translated linear transform.
openvdb::FloatGrid::Ptr fogBox(float sigma, int lo, int hi) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(lo), openvdb::Coord(hi)), sigma, true);
  openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
  m.preScale(openvdb::Vec3d(0.1, 0.1, 0.1));
  m.postRotate(openvdb::math::Z_AXIS, 0.4);
  m.postRotate(openvdb::math::X_AXIS, -0.3);
  m.postTranslate(openvdb::Vec3d(1.0, 2.0, -0.5));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setName("density");
  return grid;
}

// Object-space length of ray [tnear, tfar] inside the box of voxels [lo, hi]^3 (cells around the
// voxel centres), computed in index space by slabs.
double lengthInBox(const openvdb::math::Transform& xf, const Ray& r, int lo, int hi) {
  const openvdb::Vec3d o = xf.worldToIndex(openvdb::Vec3d(r.origin.x, r.origin.y, r.origin.z));
  const openvdb::Vec3d d = xf.baseMap()->applyInverseJacobian(openvdb::Vec3d(r.dir.x, r.dir.y, r.dir.z));
  double t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    double ta = (lo - 0.5 - o[a]) / d[a], tb = (hi + 0.5 - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t1 > t0 ? (t1 - t0) * glm::length(glm::dvec3(r.dir)) : 0.0;
}

TEST(VolumeObject, GridTransformsThatGiveNoFiniteBoundsAreRefused) {
  // Without the check a NaN or huge voxel size gave NaN or infinite bounds: a volume never hit.
  // OpenVDB's own constructors refuse a NaN map, but its reader takes one from a damaged file: the
  // voxel size 0.15625 (exact in binary, so its 8 bytes are found as written) patched to NaN / inf.
  TempDir dir;
  openvdb::initialize();
  auto grid = fogBox(1.0f, 0, 3);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(0.15625));
  const auto clean = dir / "scaled.vdb";
  {
    openvdb::io::File out(clean.string());
    out.write({grid});
    out.close();
  }
  ASSERT_NO_THROW((void)VolumeObject::load(clean));
  const std::vector<char> bytes = test::readBinaryFile(clean);
  const auto patched = [&](double value) {
    std::vector<char> b = bytes;
    const double size = 0.15625;
    int found = 0;
    for (std::size_t o = 0; o + 8 <= b.size(); ++o)
      if (std::memcmp(b.data() + o, &size, 8) == 0) {
        std::memcpy(b.data() + o, &value, 8);
        ++found;
      }
    EXPECT_GT(found, 0) << "voxel size not found in the file";
    const auto path = dir / "patched.vdb";
    test::writeBinaryFile(path, b);
    return path;
  };
  for (const double bad : {std::nan(""), double(INFINITY), 0.0}) {
    SCOPED_TRACE(bad);
    const auto path = patched(bad);
    expectErrorNaming<Error>([&] { (void)VolumeObject::load(path); },
                             "patched.vdb: grid \"density\": grid transform is not finite and invertible");
  }
  // In memory: a voxel size that takes the active voxels beyond float range.
  grid->setTransform(openvdb::math::Transform::createLinearTransform(1e38));
  expectErrorNaming<InvalidArgument>([&] { (void)makeVolumeObject(grid, VolumeKind::Fog, "v"); }, "float range");
}

TEST(VolumeObject, FogTransmittanceThroughABoxIsExact) {
  const float sigma = 2.0f;
  const int lo = -3, hi = 16;  // 20 voxels: full 8^3 tiles and partial leaves
  const auto grid = fogBox(sigma, lo, hi);
  const auto object = makeVolumeObject(grid);
  ASSERT_EQ(object->kind(), VolumeKind::Fog);
  ASSERT_EQ(object->role(), ObjectRole::Medium);
  EXPECT_EQ(object->activeVoxelCount(), 8000u);
  const Box b = object->bounds();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  QueryContext ctx;
  double max_err = 0.0;
  int crossing = 0;
  const glm::dvec3 centre = 0.5 * (glm::dvec3(b.lo) + glm::dvec3(b.hi));
  for (int k = 0; k < 5000; ++k) {
    const double o_scale = u(rng);
    const glm::dvec3 o = centre + 3.0 * o_scale * randomUnit(rng);
    const double target_scale = u(rng);
    const glm::dvec3 target = centre + 1.5 * target_scale * randomUnit(rng);
    Ray ray{glm::vec3(o), 0.0f, glm::vec3((target - o) * (0.3 + u(rng))), std::numeric_limits<float>::infinity()};
    if (k % 2) {  // finite segments, some starting inside
      ray.tnear = static_cast<float>(u(rng) * 1.5);
      ray.tfar = ray.tnear + static_cast<float>(u(rng) * 2.0);
    }
    const double L = lengthInBox(grid->transform(), ray, lo, hi);
    const double expected = std::exp(-double(sigma) * L);
    const double got = object->transmittance(ray, ctx);
    max_err = std::max(max_err, std::abs(got - expected));
    ASSERT_NEAR(got, expected, 1e-5) << ray << " L=" << L;
    crossing += L > 0.0;
    // Fog never blocks.
    Hit hit;
    EXPECT_FALSE(object->intersect(ray, hit, ctx));
    EXPECT_FALSE(object->occluded(ray, ctx));
  }
  std::cout << "[ figures  ] fog box: " << crossing << " of 5000 rays cross it; max |T - exp(-sigma L)| = " << max_err
            << "\n";
  EXPECT_GT(crossing, 2000);
}

TEST(VolumeObject, FogMissesGiveOneAndInfiniteRaysTerminate) {
  const auto object = makeVolumeObject(fogBox(1.5f, 0, 9));
  QueryContext ctx;
  const float inf = std::numeric_limits<float>::infinity();
  // Away from the box, with an infinite tfar: 1 at once.
  EXPECT_EQ(object->transmittance(Ray{glm::vec3(100, 100, 100), 0.0f, glm::vec3(1, 0, 0), inf}, ctx), 1.0f);
  EXPECT_EQ(object->transmittance(Ray{glm::vec3(100, 100, 100), 0.0f, glm::vec3(0, 0, 0), inf}, ctx), 1.0f);
  // Through the box with an infinite tfar: finite optical depth.
  const Box b = object->bounds();
  const glm::vec3 c = 0.5f * (b.lo + b.hi);
  const float t = object->transmittance(Ray{c - glm::vec3(5, 0, 0), 0.0f, glm::vec3(1, 0, 0), inf}, ctx);
  EXPECT_GT(t, 0.0f);
  EXPECT_LT(t, 1.0f);
  // An empty segment: 1.
  EXPECT_EQ(object->transmittance(Ray{c, 0.5f, glm::vec3(1, 0, 0), 0.5f}, ctx), 1.0f);
}

// ---- files and errors ----

TEST(VolumeObject, LoadsFilesByGridNameOrFirstFloatGrid) {
  TempDir dir;
  const auto vec = registeredGrid("Tree_vec3s_5_4_3", "velocity");
  auto fog = fogBox(1.0f, 0, 3);
  writeGrids(dir / "two.vdb", {vec, sphereGrid(0.1), fog});
  // "First" is in OpenVDB's listing order (by grid name): "density" before "sphere", whatever the
  // order they were written in.
  const auto first = VolumeObject::load(dir / "two.vdb");
  EXPECT_EQ(first->gridName(), "density");
  EXPECT_EQ(first->kind(), VolumeKind::Fog);
  EXPECT_EQ(first->name(), "two:density");
  const auto sphere =
      VolumeObject::load(dir / "two.vdb", {.grid = "sphere", .kind = VolumeKind::Auto, .name = {}, .query = {}});
  EXPECT_EQ(sphere->kind(), VolumeKind::LevelSet);
  const auto named =
      VolumeObject::load(dir / "two.vdb", {.grid = "density", .kind = VolumeKind::Auto, .name = "d", .query = {}});
  EXPECT_EQ(named->kind(), VolumeKind::Fog);
  EXPECT_EQ(named->name(), "d");
  EXPECT_GT(named->memoryBytes(), 0u);
  const auto forced =
      VolumeObject::load(dir / "two.vdb", {.grid = "sphere", .kind = VolumeKind::Fog, .name = {}, .query = {}});
  EXPECT_EQ(forced->role(), ObjectRole::Medium);
}

// contentHash (a sensor run state's fingerprint of volumes): the same grid read twice hashes equal;
// another query option, one changed active voxel, and one changed *inactive* value of a level set
// (read by interpolation and by the sign of inactive tiles) each change it.
TEST(VolumeObject, ContentHashSeesEveryValueAndTheQueryOptions) {
  TempDir dir;
  writeGrids(dir / "sphere.vdb", {sphereGrid(0.1)});
  const VolumeLoadOptions options{.grid = "sphere", .kind = VolumeKind::Auto, .name = {}, .query = {}};
  const auto a = VolumeObject::load(dir / "sphere.vdb", options);
  const auto b = VolumeObject::load(dir / "sphere.vdb", options);
  const std::uint64_t h = a->contentHash();
  EXPECT_NE(h, 0u);
  EXPECT_EQ(h, b->contentHash());
  VolumeQueryConfig coarse;
  coarse.levelset_step = 0.75;
  EXPECT_NE(h, a->withConfig(coarse)->contentHash());

  const auto changed = [&](bool active) {
    openvdb::FloatGrid::Ptr grid = sphereGrid(0.1);
    // A voxel of the narrow band (active) or one just outside it in a leaf that holds band voxels
    // (inactive, but stored: interpolation reads it).
    for (auto leaf = grid->tree().beginLeaf(); leaf; ++leaf) {
      for (openvdb::Index i = 0; i < leaf->SIZE; ++i)
        if (leaf->isValueOn(i) == active) {
          leaf->setValueOnly(i, leaf->getValue(i) + 0.01f);
          return makeVolumeObject(grid, VolumeKind::Auto, "sphere")->contentHash();
        }
    }
    ADD_FAILURE() << "no " << (active ? "active" : "inactive") << " voxel in a leaf";
    return std::uint64_t{0};
  };
  const std::uint64_t same_in_memory = makeVolumeObject(sphereGrid(0.1), VolumeKind::Auto, "sphere")->contentHash();
  EXPECT_EQ(h, same_in_memory);
  EXPECT_NE(h, changed(true));
  EXPECT_NE(h, changed(false));
}

TEST(VolumeObject, ErrorsNameTheFileGridAndProblem) {
  TempDir dir;
  openvdb::initialize();
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "absent.vdb"); }, "absent.vdb: no such file");
  const auto vec = registeredGrid("Tree_vec3s_5_4_3", "velocity");
  writeGrids(dir / "vec.vdb", {vec});
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "vec.vdb"); }, "no float grid");
  expectErrorNaming<FileError>(
      [&] { (void)VolumeObject::load(dir / "vec.vdb", {.grid = "velocity", .kind = {}, .name = {}, .query = {}}); },
      "not float");
  writeGrids(dir / "sphere.vdb", {sphereGrid(0.1)});
  expectErrorNaming<FileError>(
      [&] { (void)VolumeObject::load(dir / "sphere.vdb", {.grid = "smoke", .kind = {}, .name = {}, .query = {}}); },
      "no grid named \"smoke\"");
  // Truncated at several lengths, and not a VDB file at all: errors, never a crash.
  const auto bytes = test::readBinaryFile(dir / "sphere.vdb");
  // Cuts inside the header and inside the (blosc-compressed) grid data, sanitizer builds included:
  // VolumeObject::load checks every grid's extent against the file size before OpenVDB reads it
  // (OpenVDB 10 itself would allocate an unchecked block length from a short stream).
  std::vector<std::size_t> cuts;
  for (const double fraction : {0.0, 0.01, 0.1, 0.5, 0.99})
    cuts.push_back(static_cast<std::size_t>(fraction * double(bytes.size())));
  for (const std::size_t n : {std::size_t(16), std::size_t(40), bytes.size() - 1}) cuts.push_back(n);
  for (const std::size_t n : cuts) {
    test::writeBinaryFile(dir / "cut.vdb", std::vector<char>(bytes.begin(), bytes.begin() + std::ptrdiff_t(n)));
    expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "cut.vdb"); }, "cut.vdb");
  }
  // A whitespace byte inside the UUID: OpenVDB's formatted UUID read skips it and would read the
  // rest of the file one byte later than the file walk, with lengths nobody checked.
  for (const char c : {'\v', ' ', 'g'}) {
    std::vector<char> b = bytes;
    b[8 + 4 + 4 + 4 + 1 + 35] = c;  // the UUID's last character
    test::writeBinaryFile(dir / "uuid.vdb", b);
    expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "uuid.vdb"); },
                                 "uuid.vdb: not a readable .vdb file: the UUID");
  }
  test::writeTextFile(dir / "text.vdb", "this is not a vdb file\n");
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "text.vdb"); }, "text.vdb");
  // Empty grids, in memory and in a file.
  auto empty = openvdb::FloatGrid::create(0.0f);
  empty->setName("nothing");
  expectErrorNaming<InvalidArgument>([&] { (void)makeVolumeObject(empty); }, "grid \"nothing\": empty grid");
  writeGrids(dir / "empty.vdb", {empty});
  expectErrorNaming<InvalidArgument>([&] { (void)VolumeObject::load(dir / "empty.vdb"); },
                                     "empty.vdb: grid \"nothing\": empty");
  // A frustum transform.
  auto frustum = fogBox(1.0f, 0, 3);
  frustum->setName("frustum");
  frustum->setTransform(openvdb::math::Transform::createFrustumTransform(
      openvdb::BBoxd(openvdb::Vec3d(0), openvdb::Vec3d(10)), 0.5, 2.0, 0.1));
  expectErrorNaming<InvalidArgument>([&] { (void)makeVolumeObject(frustum); }, "non-linear");
  writeGrids(dir / "frustum.vdb", {frustum});
  expectErrorNaming<InvalidArgument>([&] { (void)VolumeObject::load(dir / "frustum.vdb"); },
                                     "frustum.vdb: grid \"frustum\"");
  expectErrorNaming<InvalidArgument>([&] { (void)makeVolumeObject(nullptr); }, "null grid");
}

// Damage inside the grid data (not a cut: lengths, masks and values overwritten at random) is
// refused by the file walk or read as some other valid grid, never a crash or a memory error (in
// the sanitizer build OpenVDB 10 itself would write past its buffers for a damaged raw-chunk
// length). Each compression OpenVDB writes, and half floats; the walk must be what refuses some.
TEST(VolumeObject, DamagedGridDataIsRefusedNeverACrash) {
  TempDir dir;
  openvdb::initialize();
  struct Variant {
    const char* name;
    std::uint32_t compression;
    bool half;
  };
  for (const Variant v :
       {Variant{"blosc", openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK, false},
        Variant{"zip", openvdb::io::COMPRESS_ZIP | openvdb::io::COMPRESS_ACTIVE_MASK, false},
        Variant{"none", openvdb::io::COMPRESS_NONE, false},
        Variant{"blosc_half", openvdb::io::COMPRESS_BLOSC | openvdb::io::COMPRESS_ACTIVE_MASK, true}}) {
    openvdb::FloatGrid::Ptr grid = sphereGrid(0.1);
    grid->setSaveFloatAsHalf(v.half);
    // OpenVDB never zips level sets or fog volumes.
    if (v.compression & openvdb::io::COMPRESS_ZIP) grid->setGridClass(openvdb::GRID_UNKNOWN);
    const auto clean = dir / (std::string(v.name) + ".vdb");
    {
      openvdb::io::File out(clean.string());
      out.setCompression(v.compression);
      out.write({grid});
      out.close();
    }
    ASSERT_NO_THROW((void)VolumeObject::load(clean)) << v.name;
    const std::vector<char> bytes = test::readBinaryFile(clean);
    std::mt19937 rng(7);
    int refused_by_walk = 0;
    const auto damaged = dir / (std::string(v.name) + "_damaged.vdb");
    for (int trial = 0; trial < 150; ++trial) {
      std::vector<char> b = bytes;
      // Past the header and descriptor (about the first 250 bytes): the grid's own data.
      std::uniform_int_distribution<std::size_t> at(250, b.size() - 8);
      for (int k = 0, n = 1 + trial % 4; k < n; ++k) {
        const std::size_t o = at(rng);
        if (trial % 2 == 0) {
          b[o] = static_cast<char>(rng());
        } else {  // a plausible length or count: small, negative, huge
          const std::int64_t values[] = {-static_cast<std::int64_t>(rng() % 100000),
                                         static_cast<std::int64_t>(rng() % 100000), std::int64_t{1} << 40, -1};
          std::memcpy(b.data() + o, &values[rng() % 4], 8);
        }
      }
      test::writeBinaryFile(damaged, b);
      try {
        (void)VolumeObject::load(damaged);
      } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(damaged.filename().string()), std::string::npos) << what;
        if (what.find("not a readable .vdb file: grid") != std::string::npos) ++refused_by_walk;
      }
    }
    EXPECT_GT(refused_by_walk, 0) << v.name << ": the file walk refused none of the damaged files";
  }
}

// An internal node's chunk whose lengths are right but whose data does not inflate to its values is
// refused by the file walk: OpenVDB 10 would throw from RootNode::readTopology after allocating the
// node, and leak it (the sanitizer build reports that leak).
TEST(VolumeObject, InternalNodeChunksThatDoNotInflateAreRefused) {
  TempDir dir;
  openvdb::initialize();
  const auto clean = dir / "zip.vdb";
  {
    openvdb::io::File out(clean.string());
    // OpenVDB never zips level sets or fog volumes: a grid of no class. Zip alone: every internal
    // node stores all its values (with the active mask a level set's internal nodes store none).
    openvdb::FloatGrid::Ptr grid = sphereGrid(0.1);
    grid->setGridClass(openvdb::GRID_UNKNOWN);
    out.setCompression(openvdb::io::COMPRESS_ZIP);
    out.write({grid});
    out.close();
  }
  const std::vector<char> bytes = test::readBinaryFile(clean);
  // The grid's first zlib stream (an int64 length, then zlib's 0x78 header byte) is the values of
  // the root's first child, which OpenVDB reads with the topology.
  std::size_t at = 0;
  std::int64_t length = 0;
  for (std::size_t p = 250; p + 10 < bytes.size() && at == 0; ++p) {
    std::memcpy(&length, bytes.data() + p, 8);
    if (length > 16 && length < std::int64_t(bytes.size() - p - 8) && std::uint8_t(bytes[p + 8]) == 0x78 &&
        (std::uint8_t(bytes[p + 8]) * 256 + std::uint8_t(bytes[p + 9])) % 31 == 0)
      at = p;
  }
  ASSERT_NE(at, 0u) << "no zlib stream found in " << clean;
  std::vector<char> b = bytes;
  for (std::int64_t k = length / 3; k < 2 * length / 3; ++k) b[at + 8 + std::size_t(k)] ^= 0x5a;
  test::writeBinaryFile(dir / "damaged.vdb", b);
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "damaged.vdb"); },
                               "damaged.vdb: not a readable .vdb file: grid");
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "damaged.vdb"); }, "decompress");
}

TEST(VolumeObject, SceneFilesReadVolumes) {
  TempDir dir;
  writeGrids(dir / "vol.vdb", {fogBox(1.0f, 0, 7), sphereGrid(0.05)});
  test::writeTextFile(dir / "scene.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "ball", "volume": {"file": "vol.vdb", "grid": "sphere"}},
                {"name": "smoke", "volume": {"file": "vol.vdb", "kind": "fog"}},
                {"name": "ball2", "volume": {"file": "vol.vdb", "grid": "sphere", "kind": "levelset"}}],
    "instances": [{"object": "ball", "transform": [1,0,0,10, 0,1,0,0, 0,0,1,0]},
                  {"object": "smoke", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}]})");
  const SceneDocument doc = loadSceneDocument(dir / "scene.json", builtinObjectTypes());
  const ObjectLibrary& lib = doc.graph->library();
  ASSERT_EQ(doc.objects.size(), 3u);
  const auto ball = std::dynamic_pointer_cast<const VolumeObject>(lib.get(doc.objects[0]));
  const auto smoke = std::dynamic_pointer_cast<const VolumeObject>(lib.get(doc.objects[1]));
  ASSERT_TRUE(ball && smoke);
  EXPECT_EQ(ball->kind(), VolumeKind::LevelSet);
  EXPECT_EQ(smoke->kind(), VolumeKind::Fog);
  EXPECT_EQ(smoke->gridName(), "density");
  SceneTracer tracer(*doc.graph);
  QueryContext ctx;
  const glm::vec3 c = glm::vec3(kCentre) + glm::vec3(10, 0, 0);
  const Hit h = tracer.intersect(Ray{c - glm::vec3(0, 5, 0), 0.0f, glm::vec3(0, 1, 0), 100.0f}, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 4.0, 0.0125);
  EXPECT_EQ(h.instance_id, doc.instances[0]);
  // Bad specs name the file and pointer.
  test::writeTextFile(dir / "bad.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "v", "volume": {"file": "vol.vdb", "kind": "smoke"}}], "instances": []})");
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(dir / "bad.json", builtinObjectTypes()); },
                               "/objects/0/volume/kind");
  test::writeTextFile(dir / "missing.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "v", "volume": {"file": "nope.vdb"}}], "instances": []})");
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(dir / "missing.json", builtinObjectTypes()); },
                               "nope.vdb");
}

TEST(VolumeObject, RealFilesLoad) {
  const std::filesystem::path dir = test::sharedDataDir() / "volumes";
  int loaded = 0;
  for (const char* name : {"cortex_sphere.vdb", "oiio_sphere.vdb", "cortex_smoke.vdb"}) {
    const auto file = dir / name;
    if (!std::filesystem::exists(file)) continue;
    const auto object = VolumeObject::load(file);
    ++loaded;
    const Box b = object->bounds();
    ASSERT_TRUE(b.lo.x <= b.hi.x) << name;
    const glm::vec3 c = 0.5f * (b.lo + b.hi);
    const glm::vec3 size = b.hi - b.lo;
    const Ray ray{c - glm::vec3(2.0f * size.x, 0, 0), 0.0f, glm::vec3(1, 0, 0), std::numeric_limits<float>::infinity()};
    QueryContext ctx;
    std::cout << "[ figures  ] " << name << ": grid \"" << object->gridName() << "\", " << object->kind() << ", "
              << object->activeVoxelCount() << " active voxels, voxel " << object->voxelSize() << ", "
              << object->memoryBytes() << " bytes";
    if (object->kind() == VolumeKind::LevelSet) {
      Hit hit;
      EXPECT_TRUE(object->intersect(ray, hit, ctx)) << name;
      std::cout << ", hit t " << hit.t;
    } else {
      const float t = object->transmittance(ray, ctx);
      EXPECT_GE(t, 0.0f);
      EXPECT_LE(t, 1.0f);
      std::cout << ", transmittance through the middle " << t;
    }
    std::cout << "\n";
  }
  if (loaded == 0)
    GTEST_SKIP() << "no real volumes under " << dir << " (the shared data folder is absent on this machine)";
}

}  // namespace
}  // namespace duplex
