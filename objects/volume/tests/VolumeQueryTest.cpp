// VolumeObject queries beyond level-set hits: the fog estimators against the exact
// integral (unbiased means within their confidence intervals, seeded), delta-tracking free flights
// against the analytic exponential and against the exact heterogeneous CDF, picking against a
// brute-force march, the top level's transmittance through several media and surfaces, 2 threads
// against 1 for every query, and the failure cases of section 4 (tangent and grazing rays, thin
// features, rays far outside the band, infinite rays, single voxels, huge sparse grids, non-float
// grids, damaged files). Includes OpenVDB (slow to compile), like VolumeObjectTest.

#include "TestSupport.h"
#include "VolumeTestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/VolumeObjectVdb.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <openvdb/io/File.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
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

constexpr float kInf = std::numeric_limits<float>::infinity();

// Density sigma over voxels [lo, hi]^3, stored as voxels (no tiles), voxel size `voxel`.
openvdb::FloatGrid::Ptr voxelBox(float sigma, int lo, int hi, double voxel) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->tree().fill(openvdb::CoordBBox(openvdb::Coord(lo), openvdb::Coord(hi)), sigma, true);
  grid->tree().voxelizeActiveTiles();
  grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setName("box");
  return grid;
}

// A linear ramp along x over voxels [0, n)^3: density (i + 0.5) * slope, with sparse holes (every
// 7th voxel inactive) so that leaves are neither empty nor homogeneous; rotated transform.
openvdb::FloatGrid::Ptr rampGrid(int n, float slope) {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  auto acc = grid->getAccessor();
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k)
        if ((i + 3 * j + 5 * k) % 7 != 0) acc.setValue(openvdb::Coord(i, j, k), (float(i) + 0.5f) * slope);
  openvdb::math::Mat4d m = openvdb::math::Mat4d::identity();
  m.preScale(openvdb::Vec3d(0.05));
  m.postRotate(openvdb::math::Y_AXIS, 0.3);
  m.postTranslate(openvdb::Vec3d(0.2, -0.1, 0.4));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(m));
  grid->setGridClass(openvdb::GRID_FOG_VOLUME);
  grid->setName("ramp");
  return grid;
}

// Rays through (or near) an object's bounds, some starting inside, some with finite segments.
std::vector<Ray> raysThrough(const Box& b, std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec3 c = 0.5 * (glm::dvec3(b.lo) + glm::dvec3(b.hi));
  const double r = 0.5 * glm::length(glm::dvec3(b.hi) - glm::dvec3(b.lo));
  std::vector<Ray> rays;
  for (std::size_t k = 0; k < count; ++k) {
    const double o_scale = u(rng);
    const glm::dvec3 o = c + (k % 4 == 0 ? 0.5 : 2.0) * r * o_scale * randomUnit(rng);
    const double target_scale = u(rng);
    const glm::dvec3 target = c + 0.6 * r * target_scale * randomUnit(rng);
    Ray ray{glm::vec3(o), 0.0f, glm::vec3((target - o) * (0.5 + u(rng))), kInf};
    if (k % 3 == 1) ray.tfar = static_cast<float>(0.5 + 2.0 * u(rng));
    rays.push_back(ray);
  }
  return rays;
}

// A query config with some fields changed: config([](VolumeQueryConfig& c) { c.samples = 4; }).
template <class F>
VolumeQueryConfig config(F&& change) {
  VolumeQueryConfig c;
  change(c);
  return c;
}

// [t0, t1] of the ray inside box b (slabs), if any.
std::optional<std::pair<double, double>> clipToBox(const Ray& r, const Box& b) {
  double t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    const double o = r.origin[a], d = r.dir[a];
    if (d == 0.0) {
      if (o < b.lo[a] || o > b.hi[a]) return std::nullopt;
      continue;
    }
    double ta = (b.lo[a] - o) / d, tb = (b.hi[a] - o) / d;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 <= t1)) return std::nullopt;
  return std::make_pair(t0, t1);
}

struct Stats {
  double mean = 0.0, stderr_mean = 0.0;
};

Stats estimate(const VolumeObject& v, const Ray& ray, FogMethod method, int n, std::uint64_t seed0) {
  QueryContext ctx;
  double sum = 0.0, sum2 = 0.0;
  for (int k = 0; k < n; ++k) {
    const double x = v.transmittance(ray, ctx, method, seed0 + std::uint64_t(k) * 0x9E3779B97F4A7C15ull);
    sum += x;
    sum2 += x * x;
  }
  Stats s;
  s.mean = sum / n;
  const double var = std::max(0.0, sum2 / n - s.mean * s.mean);
  s.stderr_mean = std::sqrt(var / (n - 1));
  return s;
}

// ---- estimators ----

struct EstimatorCase {
  FogMethod method;
  int majorant_level;
  bool residual;
};

class FogEstimators : public ::testing::TestWithParam<EstimatorCase> {};

TEST_P(FogEstimators, MeanIsTheExactTransmittanceWithinItsConfidenceInterval) {
  const EstimatorCase c = GetParam();
  const auto ramp = makeVolumeObject(rampGrid(40, 0.1f), VolumeKind::Fog, "ramp", config([&](VolumeQueryConfig& q) {
                                       q.majorant_level = c.majorant_level;
                                       q.residual = c.residual;
                                     }));
  QueryContext ctx;
  int checked = 0, tested = 0;
  double worst_z = 0.0;
  for (const Ray& ray : raysThrough(ramp->bounds(), 24, 17)) {
    const double exact = ramp->transmittance(ray, ctx, FogMethod::Exact, 0);
    const Stats s = estimate(*ramp, ray, c.method, 4000, 99);
    ++tested;
    if (exact == 1.0) {  // misses: every estimator gives exactly 1
      EXPECT_EQ(s.mean, 1.0) << ray;
      continue;
    }
    ++checked;
    // Deterministic (seeded); 4.5 standard errors: a false alarm has probability ~1e-5 per ray.
    const double z = std::abs(s.mean - exact) / std::max(s.stderr_mean, 1e-9);
    worst_z = std::max(worst_z, z);
    EXPECT_LT(std::abs(s.mean - exact), 4.5 * s.stderr_mean + 1e-6)
        << ray << " exact " << exact << " mean " << s.mean << " +- " << s.stderr_mean;
  }
  std::cout << "[ figures  ] " << c.method << " level " << c.majorant_level << (c.residual ? " residual" : "") << ": "
            << checked << " of " << tested << " rays attenuated, worst |mean - exact| = " << worst_z
            << " standard errors\n";
  EXPECT_GT(checked, 12);
}

INSTANTIATE_TEST_SUITE_P(Methods, FogEstimators,
                         ::testing::Values(EstimatorCase{FogMethod::RatioTracking, 0, true},
                                           EstimatorCase{FogMethod::RatioTracking, 0, false},
                                           EstimatorCase{FogMethod::RatioTracking, 1, true},
                                           EstimatorCase{FogMethod::RatioTracking, 2, false},
                                           EstimatorCase{FogMethod::DeltaTracking, 0, true},
                                           EstimatorCase{FogMethod::DeltaTracking, 2, true}));

TEST(FogEstimators, RatioTrackingIsExactInHomogeneousNodesAndMarchingConverges) {
  // A homogeneous voxel box of whole leaves: residual ratio tracking takes each leaf's constant out
  // analytically (zero variance).
  const auto box = makeVolumeObject(voxelBox(3.0f, 0, 31, 0.05));
  QueryContext ctx;
  for (const Ray& ray : raysThrough(box->bounds(), 200, 5)) {
    const double exact = box->transmittance(ray, ctx, FogMethod::Exact, 0);
    EXPECT_NEAR(box->transmittance(ray, ctx, FogMethod::RatioTracking, 7), exact, 2e-5 + 2e-5 * exact) << ray;
  }
  // Marching converges to the exact value on a field that varies per voxel.
  const auto ramp = makeVolumeObject(rampGrid(40, 0.1f));
  const auto coarse = ramp->withConfig(config([](VolumeQueryConfig& c) { c.march_step = 1.0; }));
  const auto fine = ramp->withConfig(config([](VolumeQueryConfig& c) { c.march_step = 0.05; }));
  double err_coarse = 0.0, err_fine = 0.0;
  for (const Ray& ray : raysThrough(ramp->bounds(), 200, 5)) {
    const double exact = ramp->transmittance(ray, ctx, FogMethod::Exact, 0);
    err_coarse = std::max(err_coarse, std::abs(coarse->transmittance(ray, ctx, FogMethod::RayMarching, 0) - exact));
    err_fine = std::max(err_fine, std::abs(fine->transmittance(ray, ctx, FogMethod::RayMarching, 0) - exact));
  }
  std::cout << "[ figures  ] marching, ramp: max error " << err_coarse << " (1 voxel steps), " << err_fine
            << " (0.05 voxel)\n";
  EXPECT_LT(err_fine, 0.5 * err_coarse);
  EXPECT_LT(err_fine, 0.01);
}

TEST(FogEstimators, TransmittanceIsDeterministicPerRayAndAveragesSamples) {
  const auto ramp = makeVolumeObject(rampGrid(24, 0.2f), VolumeKind::Fog, "ramp", config([](VolumeQueryConfig& c) {
                                       c.transmittance = FogMethod::RatioTracking;
                                       c.samples = 16;
                                     }));
  QueryContext a, b;
  for (const Ray& ray : raysThrough(ramp->bounds(), 50, 3)) {
    const float x = ramp->transmittance(ray, a);
    EXPECT_EQ(x, ramp->transmittance(ray, b)) << ray;  // same ray, same estimate, any context
    EXPECT_GE(x, 0.0f);
    EXPECT_LE(x, 1.0f);
  }
}

// ---- free flights ----

TEST(FreeFlight, HomogeneousDistancesFollowTheExponential) {
  const float sigma = 2.0f;
  const double voxel = 0.05;
  for (const int level : {0, 1, 2}) {
    const auto box = makeVolumeObject(voxelBox(sigma, 0, 63, voxel), VolumeKind::Fog, "box",
                                      config([&](VolumeQueryConfig& c) { c.majorant_level = level; }));
    // Along x through the middle; the box spans index x in [-0.5, 63.5]: object x in [-0.025, 3.175].
    const double x0 = -0.5 * voxel, length = 64 * voxel;
    const Ray ray{glm::vec3(-1.0f, 1.6f, 1.6f), 0.0f, glm::vec3(2.0f, 0.0f, 0.0f), kInf};  // |dir| = 2
    QueryContext ctx;
    const int n = 20000;
    std::vector<double> s;  // object-space distance into the box
    int escaped = 0;
    for (int k = 0; k < n; ++k) {
      const auto t = box->sampleFreeFlight(ray, ctx, 1000 + k);
      if (!t) {
        ++escaped;
        continue;
      }
      s.push_back(double(ray.origin.x) + 2.0 * double(*t) - x0);
    }
    // Escape probability exp(-sigma L) within 4.5 binomial standard errors.
    const double p = std::exp(-sigma * length);
    EXPECT_NEAR(double(escaped) / n, p, 4.5 * std::sqrt(p * (1 - p) / n) + 1e-9) << "level " << level;
    // Kolmogorov-Smirnov against the truncated exponential.
    std::sort(s.begin(), s.end());
    const double norm = 1.0 - p;
    double d = 0.0;
    for (std::size_t k = 0; k < s.size(); ++k) {
      ASSERT_GE(s[k], -1e-6);
      ASSERT_LE(s[k], length + 1e-6);
      const double f = (1.0 - std::exp(-sigma * s[k])) / norm;
      d = std::max({d, std::abs(f - double(k) / s.size()), std::abs(f - double(k + 1) / s.size())});
    }
    // 1.95 / sqrt(n): the KS critical value at significance 0.001.
    EXPECT_LT(d, 1.95 / std::sqrt(double(s.size()))) << "level " << level;
    std::cout << "[ figures  ] free flight, majorant level " << level << ": KS distance " << d << " (" << s.size()
              << " collisions), escaped " << escaped << " of " << n << "\n";
  }
}

TEST(FreeFlight, HeterogeneousDistancesFollowTheExactCdf) {
  // P(collision before t) = 1 - T(tnear, t), T from the exact integral on the truncated ray.
  const auto ramp = makeVolumeObject(rampGrid(40, 0.1f));
  const Box b = ramp->bounds();
  const glm::vec3 c = 0.5f * (b.lo + b.hi);
  const Ray ray{c - glm::vec3(2.0f, 0.3f, 0.1f), 0.0f, glm::vec3(1.0f, 0.15f, 0.05f), kInf};
  QueryContext ctx;
  const int n = 8000;
  std::vector<double> t;
  for (int k = 0; k < n; ++k)
    if (const auto x = ramp->sampleFreeFlight(ray, ctx, 7 + k)) t.push_back(*x);
  ASSERT_GT(t.size(), 1000u);
  std::sort(t.begin(), t.end());
  const double collide = 1.0 - ramp->transmittance(ray, ctx, FogMethod::Exact, 0);
  EXPECT_NEAR(double(t.size()) / n, collide, 4.5 * std::sqrt(collide * (1 - collide) / n));
  double d = 0.0;
  for (std::size_t k = 0; k < t.size(); k += 7) {  // every 7th point: the CDF costs a query each
    Ray part = ray;
    part.tfar = static_cast<float>(t[k]);
    const double f = (1.0 - ramp->transmittance(part, ctx, FogMethod::Exact, 0)) / collide;
    d = std::max(d, std::abs(f - (double(k) + 0.5) / t.size()));
  }
  EXPECT_LT(d, 1.95 / std::sqrt(double(t.size())) + 1.0 / t.size());
}

// ---- picking ----

TEST(FogPicking, FirstVoxelAboveTheThresholdMatchesABruteForceMarch) {
  // Properties against a fine march of the nearest-voxel density: just after the picked t the
  // density exceeds the threshold; nothing before it does; with no pick, nothing on the ray does.
  const auto grid = rampGrid(40, 0.1f);
  const auto ramp = makeVolumeObject(grid);
  QueryContext ctx;
  auto acc = grid->getConstAccessor();
  const openvdb::math::Transform& xf = grid->transform();
  auto density = [&](const Ray& r, double t) {
    const glm::dvec3 p = glm::dvec3(r.origin) + t * glm::dvec3(r.dir);
    float v = 0.0f;
    return acc.probeValue(openvdb::Coord::round(xf.worldToIndex(openvdb::Vec3d(p.x, p.y, p.z))), v) ? v : 0.0f;
  };
  int found = 0;
  for (const float threshold : {0.5f, 2.0f, 3.5f, 100.0f}) {
    for (const Ray& ray : raysThrough(ramp->bounds(), 150, 21)) {
      const auto t = ramp->firstDensityAbove(ray, threshold, ctx);
      const auto span = clipToBox(ray, ramp->bounds());
      const double dt = 0.02 * 0.05 / glm::length(glm::dvec3(ray.dir));  // 1/50 voxel
      const double end = t ? double(*t) - dt : span ? span->second : 0.0;
      if (span) {
        for (double s = span->first; s < end; s += dt)
          ASSERT_LE(density(ray, s), threshold)
              << ray << " threshold " << threshold << " at t " << s << ", pick " << (t ? *t : -1.0f);
      }
      if (!t) continue;
      ++found;
      EXPECT_GE(*t, ray.tnear);
      EXPECT_LE(*t, ray.tfar);
      EXPECT_GT(density(ray, *t + 0.02 * dt), threshold) << ray << " threshold " << threshold;
    }
  }
  EXPECT_GT(found, 150);
}

// ---- the top level ----

TEST(TopLevelTransmittance, MultipliesMediaOnceEachAndIsZeroBehindSurfaces) {
  openvdb::initialize();
  const auto fog = makeVolumeObject(voxelBox(1.5f, 0, 15, 0.1));  // object box [-0.05, 1.55]^3
  auto sphere_grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.5f, openvdb::Vec3f(0.0f), 0.05f);
  const auto sphere = makeVolumeObject(sphere_grid);
  std::vector<InstanceDesc> instances;
  // 12 fog boxes in a row along x (overlapping pairs), rotated and scaled; a sphere further on.
  for (std::uint32_t k = 0; k < 12; ++k) {
    const Affine m = Affine::fromRowMajor3x4(test::rotationScaleTranslation(
        glm::dvec3(0.3, 1, 0.2), 0.1 * k, glm::dvec3(0.8 + 0.05 * k), glm::dvec3(1.2 * k, 0, 0)));
    instances.push_back({fog, m, k});
  }
  instances.push_back({sphere,
                       Affine::fromRowMajor3x4(test::rotationScaleTranslation(glm::dvec3(0, 0, 1), 0.0, glm::dvec3(1.0),
                                                                              glm::dvec3(20, 0.6, 0.6))),
                       100});
  TopLevel top;
  top.build(instances);
  QueryContext ctx;
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int blocked = 0, attenuated = 0;
  for (int r = 0; r < 300; ++r) {
    const double oy = u(rng), oz = u(rng), ty = u(rng), tz = u(rng);
    const glm::dvec3 o(-2.0, 0.2 + 0.8 * oy, 0.2 + 0.8 * oz);
    const glm::dvec3 target(22.0, 0.6 + 0.6 * (ty - 0.5), 0.6 + 0.6 * (tz - 0.5));
    Ray ray{glm::vec3(o), 0.0f, glm::vec3(target - o), r % 2 ? 1.0f : 0.8f};
    // Reference: the product over instances of the object's own transmittance of the object-space
    // ray, and the sphere's occlusion.
    double expected = 1.0;
    for (const InstanceDesc& d : instances) {
      const Affine inv = d.world_from_object.inverse();
      const Ray ray_os{glm::vec3(inv.point(glm::dvec3(ray.origin))), ray.tnear,
                       glm::vec3(inv.vector(glm::dvec3(ray.dir))), ray.tfar};
      expected *= d.object->transmittance(ray_os, ctx);
    }
    const float got = top.transmittance(ray, ctx);
    EXPECT_NEAR(got, expected, 1e-5 + 1e-4 * expected) << ray;
    blocked += expected == 0.0;
    attenuated += expected > 0.0 && expected < 0.5;
  }
  EXPECT_GT(blocked, 50);
  EXPECT_GT(attenuated, 50);
  // A ray that meets nothing, infinite: 1; a NaN ray: 1 (cannot be queried).
  EXPECT_EQ(top.transmittance(Ray{glm::vec3(0, 50, 0), 0.0f, glm::vec3(1, 0, 0), kInf}, ctx), 1.0f);
  EXPECT_EQ(top.transmittance(Ray{glm::vec3(NAN, 0, 0), 0.0f, glm::vec3(1, 0, 0), kInf}, ctx), 1.0f);
  // Masks select instances.
  const Ray through{glm::vec3(-2, 0.6f, 0.6f), 0.0f, glm::vec3(1, 0, 0), 30.0f};
  EXPECT_EQ(top.transmittance(through, ctx), 0.0f);
  EXPECT_EQ(top.transmittance(through, ctx, 0u), 1.0f);
}

// ---- threads ----

TEST(VolumeQueries, TwoThreadsGiveTheResultsOfOne) {
  const auto ramp = makeVolumeObject(rampGrid(40, 0.1f));
  const auto rays = raysThrough(ramp->bounds(), 2000, 8);
  struct Out {
    std::vector<float> exact, ratio, delta, march, pick;
    std::vector<float> flight;
    explicit Out(std::size_t n) : exact(n), ratio(n), delta(n), march(n), pick(n), flight(n) {}
  };
  auto run = [&](std::size_t begin, std::size_t end, Out& out) {
    QueryContext ctx;  // one per thread
    for (std::size_t k = begin; k < end; ++k) {
      out.exact[k] = ramp->transmittance(rays[k], ctx, FogMethod::Exact, k);
      out.ratio[k] = ramp->transmittance(rays[k], ctx, FogMethod::RatioTracking, k);
      out.delta[k] = ramp->transmittance(rays[k], ctx, FogMethod::DeltaTracking, k);
      out.march[k] = ramp->transmittance(rays[k], ctx, FogMethod::RayMarching, k);
      out.pick[k] = ramp->firstDensityAbove(rays[k], 2.0f, ctx).value_or(-1.0f);
      out.flight[k] = ramp->sampleFreeFlight(rays[k], ctx, k).value_or(-1.0f);
    }
  };
  Out one(rays.size()), two(rays.size());
  run(0, rays.size(), one);
  std::thread a([&] { run(0, rays.size() / 2, two); });
  std::thread b([&] { run(rays.size() / 2, rays.size(), two); });
  a.join();
  b.join();
  EXPECT_EQ(one.exact, two.exact);
  EXPECT_EQ(one.ratio, two.ratio);
  EXPECT_EQ(one.delta, two.delta);
  EXPECT_EQ(one.march, two.march);
  EXPECT_EQ(one.pick, two.pick);
  EXPECT_EQ(one.flight, two.flight);
  // And through the top level.
  TopLevel top;
  const std::vector<InstanceDesc> inst = {{ramp, Affine{}, 0},
                                          {ramp,
                                           Affine::fromRowMajor3x4(test::rotationScaleTranslation(
                                               glm::dvec3(1, 0, 0), 0.5, glm::dvec3(1.0), glm::dvec3(0.3, 0, 0))),
                                           1}};
  top.build(inst);
  std::vector<float> t1(rays.size()), t2(rays.size());
  {
    QueryContext ctx;
    for (std::size_t k = 0; k < rays.size(); ++k) t1[k] = top.transmittance(rays[k], ctx);
  }
  auto half = [&](std::size_t begin, std::size_t end) {
    QueryContext ctx;
    for (std::size_t k = begin; k < end; ++k) t2[k] = top.transmittance(rays[k], ctx);
  };
  std::thread c([&] { half(0, rays.size() / 2); });
  std::thread d([&] { half(rays.size() / 2, rays.size()); });
  c.join();
  d.join();
  EXPECT_EQ(t1, t2);
}

// ---- where methods fail (docs/design/volumes.md) ----

openvdb::FloatGrid::Ptr sphereLevelSet(float radius, float voxel, float half_width = 3.0f) {
  openvdb::initialize();
  auto g = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, openvdb::Vec3f(0.0f), voxel, half_width);
  g->setName("sphere");
  return g;
}

TEST(VolumeFailureCases, TangentRaysHitOnTheSurfaceOrMiss) {
  const float voxel = 0.05f;
  const auto sphere = makeVolumeObject(sphereLevelSet(1.0f, voxel));
  QueryContext ctx;
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int hits = 0;
  for (int k = 0; k < 2000; ++k) {
    // Impact parameter within +-0.2 voxel of the radius, in a random direction.
    std::mt19937 r2(k);
    const glm::dvec3 d = randomUnit(r2);
    glm::dvec3 side = glm::normalize(glm::cross(d, randomUnit(r2)));
    const double b = 1.0 + 0.2 * voxel * u(rng);
    const glm::dvec3 o = b * side - 3.0 * d;
    Hit hit;
    if (!sphere->intersect(Ray{glm::vec3(o), 0.0f, glm::vec3(d), kInf}, hit, ctx)) continue;
    ++hits;
    const glm::dvec3 p = o + double(hit.t) * d;
    EXPECT_NEAR(glm::length(p), 1.0, 0.5 * voxel) << "impact " << b;
  }
  std::cout << "[ figures  ] tangent rays (impact 1 +- 0.2 voxel): " << hits << " of 2000 hit\n";
}

TEST(VolumeFailureCases, ThinFeaturesAreFoundWhenTheirNegativeRunIsAStepLong) {
  // A slab of the interpolated distance field thinner than a voxel: |z| - 0.2 voxels (narrow band
  // of 3 voxels). Reference: a march at 1/200 voxel of the same interpolated field. Every reported
  // hit must be a real crossing, and every crossing whose negative run is at least one sampling
  // step (0.5 voxel) long must be found; shorter runs (grazing rays) may be missed.
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(3.0f);
  auto acc = grid->getAccessor();
  for (int i = -120; i <= 120; ++i)
    for (int j = -120; j <= 120; ++j)
      for (int k = -3; k <= 3; ++k) acc.setValue(openvdb::Coord(i, j, k), std::abs(float(k)) - 0.2f);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->setName("slab");
  const auto slab = makeVolumeObject(grid);
  auto cacc = grid->getConstAccessor();
  auto field = [&](const glm::dvec3& p) {
    return openvdb::tools::BoxSampler::sample(cacc, openvdb::Vec3d(p.x, p.y, p.z));
  };
  QueryContext ctx;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  int found = 0, long_runs = 0, short_missed = 0;
  for (int r = 0; r < 1000; ++r) {
    // Directions from steep to grazing (elevation down to 0.5 degrees), crossing z = 0 inside
    // [-40, 40]^2 and running from z = 0.6 to z = -0.6 (at most 69 voxels sideways).
    const double elev = (0.5 + 60.0 * std::pow(u(rng), 3.0)) * 3.14159265358979 / 180.0;
    const double az = 6.283185307 * u(rng);
    const glm::dvec3 d(std::cos(elev) * std::cos(az), std::cos(elev) * std::sin(az), -std::sin(elev));
    const double ox = u(rng), oy = u(rng);
    const glm::dvec3 o = glm::dvec3(80.0 * (ox - 0.5), 80.0 * (oy - 0.5), 0.0) - d * (0.6 / std::sin(elev));
    const double t_end = 1.2 / std::sin(elev);
    Ray ray{glm::vec3(o), 0.0f, glm::vec3(d), static_cast<float>(t_end)};
    // Reference negative runs.
    double run_start = -1.0, first_long = -1.0, first_any = -1.0;
    const double dt = 0.01;
    for (double t = 0.0; t <= t_end + dt; t += dt) {
      const bool neg = field(o + t * d) < 0.0;
      if (neg && run_start < 0.0) run_start = t;
      if (neg && first_any < 0.0) first_any = t;
      if (!neg && run_start >= 0.0) {
        if (first_long < 0.0 && t - run_start >= 0.55) first_long = run_start;
        run_start = -1.0;
      }
    }
    Hit hit;
    const bool got = slab->intersect(ray, hit, ctx);
    if (got) {
      ++found;
      ASSERT_GE(first_any, 0.0) << "spurious hit " << ray;
      EXPECT_NEAR(std::abs(field(o + double(hit.t) * d)), 0.0, 0.02) << ray;
      EXPECT_GE(double(hit.t), first_any - 0.01) << ray;
    }
    if (first_long >= 0.0) {
      ++long_runs;
      EXPECT_TRUE(got) << "missed a crossing with a negative run of >= 0.5 voxel: " << ray;
      if (got) {
        EXPECT_LE(double(hit.t), first_long + 0.01) << ray;
      }
    } else if (first_any >= 0.0 && !got) {
      ++short_missed;
    }
  }
  std::cout << "[ figures  ] thin slab (0.4 voxel): " << found << " hits, " << long_runs
            << " rays with a run >= 0.5 voxel (all found), " << short_missed << " grazing rays missed\n";
  EXPECT_GT(long_runs, 300);
}

TEST(VolumeFailureCases, RaysFarOutsideTheBandAndDeepInside) {
  const float voxel = 0.05f;
  // Radius 4: the interior holds inactive tiles of negative background far from the band.
  const auto sphere = makeVolumeObject(sphereLevelSet(4.0f, voxel));
  QueryContext ctx;
  std::mt19937 rng(9);
  double worst = 0.0;
  for (int k = 0; k < 500; ++k) {
    const glm::dvec3 dir = randomUnit(rng);
    // From 1e4 units away (float origin), aimed at the centre: one hit at distance - 4.
    const glm::dvec3 o = -1.0e4 * dir;
    Hit hit;
    ASSERT_TRUE(sphere->intersect(Ray{glm::vec3(o), 0.0f, glm::vec3(dir), kInf}, hit, ctx));
    const glm::dvec3 p = glm::dvec3(glm::vec3(o)) + double(hit.t) * dir;
    worst = std::max(worst, std::abs(glm::length(p) - 4.0));
    // Aimed 6 units off the centre: a miss, with no spurious crossing in the far background.
    const glm::dvec3 off = glm::normalize(glm::cross(dir, randomUnit(rng))) * 6.0;
    Hit none;
    EXPECT_FALSE(sphere->intersect(Ray{glm::vec3(o + off), 0.0f, glm::vec3(dir), kInf}, none, ctx));
    // From the centre (deep inside, far from the band): the exit at radius 4.
    Hit exit_hit;
    ASSERT_TRUE(sphere->intersect(Ray{glm::vec3(0.0f), 0.0f, glm::vec3(dir), kInf}, exit_hit, ctx));
    EXPECT_NEAR(exit_hit.t, 4.0, 0.25 * voxel);
  }
  // From 1e4 units the float origin itself is only good to ~1e-3: the hit error stays within it.
  EXPECT_LT(worst, 2e-3 + 0.25 * voxel);
}

TEST(VolumeFailureCases, InfiniteRaysThatMissTerminateForEveryMethod) {
  const auto sphere = makeVolumeObject(sphereLevelSet(1.0f, 0.05f));
  const auto ramp = makeVolumeObject(rampGrid(24, 0.2f));
  QueryContext ctx;
  std::mt19937 rng(2);
  for (int k = 0; k < 300; ++k) {
    const glm::dvec3 d = randomUnit(rng);
    const glm::dvec3 o = 50.0 * randomUnit(rng);
    const Ray ray{glm::vec3(o), 0.0f, glm::vec3(d), kInf};
    // Whatever the ray does, the answer is one of the two: and it comes back.
    const glm::dvec3 to_c = -o;
    const bool aims_at_sphere = glm::length(to_c - glm::dot(to_c, d) * d) < 0.9 && glm::dot(to_c, d) > 0.0;
    Hit hit;
    EXPECT_EQ(sphere->intersect(ray, hit, ctx), aims_at_sphere) << ray;
    for (const FogMethod m :
         {FogMethod::Exact, FogMethod::RatioTracking, FogMethod::DeltaTracking, FogMethod::RayMarching}) {
      const float t = ramp->transmittance(ray, ctx, m, k);
      EXPECT_GE(t, 0.0f);
      EXPECT_LE(t, 1.0f);
    }
  }
  // Rays pointing away from the volume along each axis, infinite: 1 / no hit.
  for (int a = 0; a < 3; ++a) {
    glm::vec3 d(0.0f);
    d[a] = 1.0f;
    const Ray away{glm::vec3(10.0f), 0.0f, d, kInf};
    Hit hit;
    EXPECT_FALSE(sphere->intersect(away, hit, ctx));
    EXPECT_EQ(ramp->transmittance(away, ctx, FogMethod::RayMarching, 0), 1.0f);
    EXPECT_FALSE(ramp->sampleFreeFlight(away, ctx, 0).has_value());
    EXPECT_FALSE(ramp->firstDensityAbove(away, 0.0f, ctx).has_value());
  }
}

TEST(VolumeFailureCases, RaysWhoseParameterCannotResolveAVoxelMissAndReturn) {
  // An origin at -1e20 with a direction of 1e20 reaches the grid at t ~ 1, where one voxel is a
  // step of t far below its rounding: every query answers at once, as a miss.
  const auto sphere = makeVolumeObject(sphereLevelSet(1.0f, 0.05f));
  const auto ramp = makeVolumeObject(rampGrid(24, 0.2f));
  QueryContext ctx;
  const std::vector<Ray> rays = {
      Ray{glm::vec3(-1e20f, 0.1f, 0.1f), 0.0f, glm::vec3(1e20f, 0.0f, 0.0f), kInf},
      Ray{glm::vec3(-1e20f, -1e20f, 0.2f), 0.0f, glm::vec3(1e20f, 1e20f, 0.0f), kInf},
      Ray{glm::vec3(0.3f, 0.2f, -1e18f), 0.0f, glm::vec3(0.0f, 0.0f, 1.0f), kInf},  // far, slow
  };
  for (const Ray& ray : rays) {
    Hit hit;
    EXPECT_FALSE(sphere->intersect(ray, hit, ctx)) << ray;
    EXPECT_FALSE(sphere->occluded(ray, ctx)) << ray;
    for (const FogMethod m :
         {FogMethod::Exact, FogMethod::RatioTracking, FogMethod::DeltaTracking, FogMethod::RayMarching})
      EXPECT_EQ(ramp->transmittance(ray, ctx, m, 1), 1.0f) << ray;
    EXPECT_FALSE(ramp->sampleFreeFlight(ray, ctx, 0).has_value()) << ray;
    EXPECT_FALSE(ramp->firstDensityAbove(ray, 0.0f, ctx).has_value()) << ray;
  }
  // The same rays brought near (origin a few units away) are traced as usual.
  const Ray near{glm::vec3(-5.0f, 0.1f, 0.1f), 0.0f, glm::vec3(1.0f, 0.0f, 0.0f), kInf};
  Hit hit;
  EXPECT_TRUE(sphere->intersect(near, hit, ctx));
  EXPECT_LT(ramp->transmittance(near, ctx, FogMethod::Exact, 1), 1.0f);
}

TEST(VolumeFailureCases, SingleActiveVoxel) {
  openvdb::initialize();
  const double voxel = 0.1;
  auto fog = openvdb::FloatGrid::create(0.0f);
  fog->tree().setValue(openvdb::Coord(3, -2, 5), 4.0f);
  fog->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
  const auto v = makeVolumeObject(fog, VolumeKind::Fog);
  EXPECT_EQ(v->activeVoxelCount(), 1u);
  EXPECT_FLOAT_EQ(v->maxDensity(), 4.0f);
  QueryContext ctx;
  const Ray ray{glm::vec3(-1.0f, -0.2f, 0.5f), 0.0f, glm::vec3(1.0f, 0.0f, 0.0f), kInf};  // through its centre
  const double expected = std::exp(-4.0 * voxel);
  EXPECT_NEAR(v->transmittance(ray, ctx, FogMethod::Exact, 0), expected, 1e-6);
  EXPECT_NEAR(v->transmittance(ray, ctx, FogMethod::RayMarching, 0), expected, 1e-6);
  const Stats s = estimate(*v, ray, FogMethod::RatioTracking, 4000, 5);
  EXPECT_NEAR(s.mean, expected, 4.5 * s.stderr_mean + 1e-6);
  const auto pick = v->firstDensityAbove(ray, 1.0f, ctx);
  ASSERT_TRUE(pick);
  EXPECT_NEAR(*pick, 1.0 + 2.5 * voxel, 1e-5);         // enters the voxel at x = 0.25
  EXPECT_FALSE(v->firstDensityAbove(ray, 4.0f, ctx));  // strictly above
  // A single negative voxel as a level set (background +3 voxels): the interpolated distance
  // crosses zero 0.5 / 3.5 voxel either side of its centre.
  auto ls = openvdb::FloatGrid::create(float(3 * voxel));
  ls->tree().setValue(openvdb::Coord(3, -2, 5), float(-0.5 * voxel));
  ls->setTransform(openvdb::math::Transform::createLinearTransform(voxel));
  ls->setGridClass(openvdb::GRID_LEVEL_SET);
  const auto dot = makeVolumeObject(ls);
  Hit hit;
  ASSERT_TRUE(dot->intersect(ray, hit, ctx));
  EXPECT_NEAR(hit.t, 1.0 + 3.0 * voxel - (0.5 / 3.5) * voxel, 1e-4);
}

TEST(VolumeFailureCases, HugeSparseGridsStayBoundedInMemoryAndTime) {
  openvdb::initialize();
  // Two voxels 2e8 voxels apart: a 2e8^3 index box, two leaves in memory.
  auto fog = openvdb::FloatGrid::create(0.0f);
  fog->tree().setValue(openvdb::Coord(-100000000, 0, 0), 2.0f);
  fog->tree().setValue(openvdb::Coord(100000000, 0, 0), 3.0f);
  const auto v = makeVolumeObject(fog);
  std::cout << "[ figures  ] two voxels 2e8 voxels apart: " << v->memoryBytes() << " bytes\n";
  EXPECT_LT(v->memoryBytes(), 4u << 20);
  QueryContext ctx;
  // Along the line through both voxels: the HDDA steps over ~5e4 empty upper-node cells.
  const Ray ray{glm::vec3(-2.0e8f, 0.0f, 0.0f), 0.0f, glm::vec3(1.0f, 0.0f, 0.0f), kInf};
  for (const FogMethod m : {FogMethod::Exact, FogMethod::RayMarching})
    EXPECT_NEAR(v->transmittance(ray, ctx, m, 0), std::exp(-5.0), 1e-5) << m;
  const Stats s = estimate(*v, ray, FogMethod::RatioTracking, 200, 1);
  EXPECT_NEAR(s.mean, std::exp(-5.0), 4.5 * s.stderr_mean + 1e-6);
  const auto pick = v->firstDensityAbove(ray, 2.5f, ctx);
  ASSERT_TRUE(pick);
  EXPECT_NEAR(*pick, 3.0e8 - 0.5, 64.0);  // float t: ulp 32 at 3e8
}

TEST(VolumeFailureCases, NonFloatGridsAndBadConfigsGiveClearErrors) {
  TempDir dir;
  openvdb::initialize();
  const auto dbl = registeredGrid("Tree_double_5_4_3", "density");
  const auto mask = registeredGrid("Tree_mask_5_4_3", "mask");
  writeGrids(dir / "other.vdb", {dbl, mask});
  expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "other.vdb"); },
                               "no float grid (grids: \"density\" (double)");
  expectErrorNaming<FileError>(
      [&] { (void)VolumeObject::load(dir / "other.vdb", {.grid = "density", .kind = {}, .name = {}, .query = {}}); },
      "holds double values, not float");
  const auto ramp = makeVolumeObject(rampGrid(8, 1.0f));
  using C = VolumeQueryConfig;
  expectErrorNaming<InvalidArgument>([&] { (void)ramp->withConfig(config([](C& c) { c.samples = 0; })); }, "samples");
  expectErrorNaming<InvalidArgument>([&] { (void)ramp->withConfig(config([](C& c) { c.march_step = 0.0; })); },
                                     "march_step");
  expectErrorNaming<InvalidArgument>([&] { (void)ramp->withConfig(config([](C& c) { c.majorant_level = 3; })); },
                                     "majorant_level");
  expectErrorNaming<InvalidArgument>([&] { (void)ramp->withConfig(config([](C& c) { c.levelset_step = 2.0; })); },
                                     "levelset_step");
  expectErrorNaming<InvalidArgument>(
      [&] {
        (void)makeVolumeObject(rampGrid(8, 1.0f), VolumeKind::Fog, "r", config([](C& c) { c.refine_steps = -1; }));
      },
      "refine_steps");
}

// Truncations anywhere, including inside the (blosc-compressed) grid data, and damaged descriptor
// offsets: refused by the structure check before OpenVDB reads a block. Runs under ASan too.
TEST(VolumeFailureCases, TruncatedAndDamagedFilesAreRefusedBeforeOpenVdbReadsThem) {
  TempDir dir;
  const auto fog = voxelBox(1.0f, 0, 40, 0.1);
  writeGrids(dir / "two.vdb", {sphereLevelSet(1.0f, 0.05f), fog});
  const auto bytes = test::readBinaryFile(dir / "two.vdb");
  ASSERT_GT(bytes.size(), 10000u);
  ASSERT_EQ(
      VolumeObject::load(dir / "two.vdb", {.grid = "box", .kind = {}, .name = {}, .query = {}})->activeVoxelCount(),
      41u * 41u * 41u);
  // Every 1/40 of the file, and a few bytes before the end.
  std::vector<std::size_t> cuts;
  for (int k = 0; k < 40; ++k) cuts.push_back(bytes.size() * k / 40);
  for (const std::size_t back : {1, 2, 9, 100}) cuts.push_back(bytes.size() - back);
  for (const std::size_t n : cuts) {
    test::writeBinaryFile(dir / "cut.vdb", std::vector<char>(bytes.begin(), bytes.begin() + std::ptrdiff_t(n)));
    for (const char* grid : {"", "box", "sphere"})
      expectErrorNaming<FileError>(
          [&] { (void)VolumeObject::load(dir / "cut.vdb", {.grid = grid, .kind = {}, .name = {}, .query = {}}); },
          "cut.vdb");
  }
  // The first grid descriptor: after the 57-byte header, the file metadata (none: a count of 0)
  // and the grid count; name, type and instance parent strings, then grid, block and end offsets.
  std::uint32_t meta_count = 1;
  std::memcpy(&meta_count, &bytes[57], 4);
  ASSERT_EQ(meta_count, 0u);
  std::size_t p = 57 + 4 + 4;
  for (int k = 0; k < 3; ++k) {
    std::uint32_t len = 0;
    std::memcpy(&len, &bytes[p], 4);
    p += 4 + len;
  }
  std::int64_t grid_pos = 0;
  std::memcpy(&grid_pos, &bytes[p], 8);
  ASSERT_EQ(grid_pos, std::int64_t(p + 24));  // what OpenVDB wrote: the grid follows its descriptor
  for (const std::int64_t bad : {std::int64_t(bytes.size()) + 1000, std::int64_t(1) << 60, std::int64_t(3)}) {
    auto damaged = bytes;
    std::memcpy(&damaged[p + 16], &bad, 8);
    test::writeBinaryFile(dir / "damaged.vdb", damaged);
    expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "damaged.vdb"); }, "damaged.vdb");
  }
  // A huge metadata count, then a huge grid count.
  for (const std::size_t at : {std::size_t(57), std::size_t(61)}) {
    auto damaged = bytes;
    const std::uint32_t huge = 0x7FFFFFF0u;
    std::memcpy(&damaged[at], &huge, 4);
    test::writeBinaryFile(dir / "counts.vdb", damaged);
    expectErrorNaming<FileError>([&] { (void)VolumeObject::load(dir / "counts.vdb"); }, "counts.vdb");
  }
}

TEST(VolumeFailureCases, RealVolumesAnswerEveryMethod) {
  const std::filesystem::path dir = test::sharedDataDir() / "volumes";
  const auto file = dir / "cortex_smoke.vdb";
  if (!std::filesystem::exists(file))
    GTEST_SKIP() << "no " << file << " (the shared data folder is absent on this machine)";
  // Lower-node majorants: ratio tracking with tight (leaf) majorants has heavy-tailed estimates
  // on this smoke (factors near 0), whose sample variance is unreliable at a few thousand samples;
  // the looser majorant gives many factors near 1 and a well-behaved interval.
  const auto smoke = VolumeObject::load(
      file, {.grid = {}, .kind = VolumeKind::Fog, .name = {}, .query = config([](VolumeQueryConfig& c) {
                                                                c.majorant_level = 1;
                                                              })});
  QueryContext ctx;
  int attenuated = 0;
  for (const Ray& ray : raysThrough(smoke->bounds(), 20, 6)) {
    const double exact = smoke->transmittance(ray, ctx, FogMethod::Exact, 0);
    attenuated += exact < 0.999;
    const Stats s = estimate(*smoke, ray, FogMethod::RatioTracking, 2000, 3);
    EXPECT_NEAR(s.mean, exact, 4.5 * s.stderr_mean + 1e-5) << ray;
  }
  std::cout << "[ figures  ] cortex_smoke.vdb: " << attenuated << " of 20 rays attenuated\n";
}

// ---- closest points on level sets ----

namespace closest {

using duplex::test::rotationScaleTranslation;

// The interpolated distance at an object-space point (object units).
double distanceAt(const openvdb::FloatGrid& grid, const glm::dvec3& p_os) {
  return openvdb::tools::BoxSampler::sample(grid.tree(),
                                            grid.transform().worldToIndex(openvdb::Vec3d(p_os.x, p_os.y, p_os.z)));
}

ClosestPoint query(const Object& object, const glm::dvec3& p_ws, const Affine& world_from_object, QueryContext& ctx,
                   double max_distance = kInf) {
  ClosestPoint best;
  best.distance = max_distance;
  (void)object.closestPoint(PointQuery::make(p_ws, world_from_object, world_from_object.inverse()), best, ctx);
  return best;
}

TEST(LevelSetClosestPoint, SphereDistancesAreAnalyticNearFarAndInside) {
  const float voxel = 0.02f, radius = 0.5f;
  const auto grid = sphereLevelSet(radius, voxel);
  const auto sphere = makeVolumeObject(grid);
  const std::size_t bytes_before = sphere->memoryBytes();
  QueryContext ctx;
  std::mt19937 rng(31);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    // Points at distances from 0.05 to 4 radii from the centre: inside (far below the narrow
    // band), on the band, far outside.
    const glm::dvec3 dir = randomUnit(rng);
    const double r = radius * (k % 4 == 0 ? 0.1 + 0.8 * std::abs(u(rng))
                                          : (k % 4 == 1 ? 1.0 + 0.1 * u(rng) : 1.5 + 2.5 * std::abs(u(rng))));
    const glm::dvec3 p = r * dir;
    const ClosestPoint c = query(*sphere, p, Affine::identity(), ctx);
    ASSERT_TRUE(c.valid()) << "point " << k;
    // The trilinear surface of a sampled sphere lies within a small fraction of a voxel of it.
    EXPECT_NEAR(c.distance, std::abs(r - radius), 0.02 * voxel) << "point " << k << " at " << r;
    EXPECT_NEAR(glm::length(c.point_ws), radius, 0.02 * voxel);
    // Tangentially the distance is flat to second order, and the trilinear surface departs from
    // the sphere by a small fraction of a voxel: the nearest point of that surface may lie a part of
    // a voxel aside from the radial foot.
    EXPECT_LT(glm::length(c.point_ws - double{radius} * dir), voxel) << "point " << k;
    EXPECT_NEAR(std::abs(distanceAt(*grid, c.point_ws)), 0.0, 1e-3 * voxel) << "on the zero crossing";
    EXPECT_NEAR(glm::length(c.point_ws - p), c.distance, 1e-9);
    EXPECT_GT(glm::dot(c.normal_ws, dir), 0.999);  // outward
  }
  EXPECT_GT(sphere->memoryBytes(), bytes_before) << "the surface points count once made";
  // The maximum distance: nothing within it is nothing found, best left alone.
  const ClosestPoint none = query(*sphere, glm::dvec3(2.0, 0, 0), Affine::identity(), ctx, 1.0);
  EXPECT_FALSE(none.valid());
  EXPECT_EQ(none.distance, 1.0);
  // Fog has no surface.
  const auto fog = makeVolumeObject(voxelBox(1.0f, 0, 7, 0.1));
  EXPECT_FALSE(query(*fog, glm::dvec3(0.0), Affine::identity(), ctx).valid());
}

TEST(LevelSetClosestPoint, InstancesOfAnyAffineTransformGetTheWorldNearestPoint) {
  const float voxel = 0.02f, radius = 0.5f;
  const auto grid = sphereLevelSet(radius, voxel);
  const auto sphere = makeVolumeObject(grid);
  QueryContext ctx;
  std::mt19937 rng(32);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  // A rotated sphere scaled by 2: distances double, analytically.
  const Affine similar = Affine::fromRowMajor3x4(
      rotationScaleTranslation(glm::dvec3(0.2, 1.0, 0.4), 0.7, glm::dvec3(2.0), glm::dvec3(3.0, -1.0, 5.0)));
  for (int k = 0; k < 100; ++k) {
    const glm::dvec3 p = glm::dvec3(3.0, -1.0, 5.0) + 2.5 * test::draw3<glm::dvec3>(u, rng);
    const ClosestPoint c = query(*sphere, p, similar, ctx);
    ASSERT_TRUE(c.valid());
    EXPECT_NEAR(c.distance, std::abs(glm::length(p - glm::dvec3(3.0, -1.0, 5.0)) - 2.0 * radius), 0.05 * voxel);
  }
  // An ellipsoid (scale 1, 2.5, 0.6, rotated): no closed form, so the conditions of a nearest
  // point: on the surface, and no surface point closer (a dense sampling of the ellipsoid in world
  // space).
  const Affine uneven = Affine::fromRowMajor3x4(
      rotationScaleTranslation(glm::dvec3(1.0, 0.3, -0.2), 1.1, glm::dvec3(1.0, 2.5, 0.6), glm::dvec3(-4.0, 2.0, 1.0)));
  const Affine to_object = uneven.inverse();
  std::vector<glm::dvec3> dense;  // world points of the object-space sphere of radius 0.5
  for (int i = 0; i < 400; ++i)
    for (int j = 0; j < 200; ++j) {
      const double th = std::numbers::pi * (j + 0.5) / 200, ph = 2.0 * std::numbers::pi * i / 400;
      dense.push_back(uneven.point(double{radius} *
                                   glm::dvec3(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th))));
    }
  for (int k = 0; k < 60; ++k) {
    const glm::dvec3 p = glm::dvec3(-4.0, 2.0, 1.0) + 2.0 * test::draw3<glm::dvec3>(u, rng);
    const ClosestPoint c = query(*sphere, p, uneven, ctx);
    ASSERT_TRUE(c.valid());
    EXPECT_NEAR(distanceAt(*grid, to_object.point(c.point_ws)), 0.0, 1e-3 * voxel) << "on the zero crossing";
    // The normal (the interpolant's gradient, a few degrees off) roughly along the offset.
    EXPECT_GT(std::abs(glm::dot(glm::normalize(p - c.point_ws), c.normal_ws)), 0.99) << "point " << k;
    double sampled = kInf;
    for (const glm::dvec3& s : dense) sampled = std::min(sampled, glm::length(s - p));
    // The dense points are on the true ellipsoid, the level set within a tiny fraction of a voxel
    // (in world units, at most 2.5 x) of it.
    EXPECT_LE(c.distance, sampled + 0.05 * voxel) << "point " << k;
    EXPECT_GE(c.distance, sampled - 0.05 * voxel - 0.01) << "point " << k;  // sampling spacing ~ 0.01
  }
}

TEST(LevelSetClosestPoint, AcrossAGapTheNearerWallWins) {
  // Two spheres 0.2 (4 voxels) apart, their union, along a diagonal of the lattice: from points near
  // the middle of the gap the nearest crossing may lie on the farther wall (crossings lie up to a
  // cell from the foot), and refining it alone would end there.
  openvdb::initialize();
  const float voxel = 0.05f;
  const glm::dvec3 axis = glm::normalize(glm::dvec3(1.0, 0.7, 0.4));
  const glm::dvec3 ca = -0.6 * axis, cb = 0.6 * axis;
  auto a = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      0.5f, openvdb::Vec3f(static_cast<float>(ca.x), static_cast<float>(ca.y), static_cast<float>(ca.z)), voxel);
  auto b = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      0.5f, openvdb::Vec3f(static_cast<float>(cb.x), static_cast<float>(cb.y), static_cast<float>(cb.z)), voxel);
  openvdb::tools::csgUnion(*a, *b);
  const auto pair = makeVolumeObject(a, VolumeKind::LevelSet, "pair");
  QueryContext ctx;
  std::mt19937 rng(33);
  std::uniform_real_distribution<double> ut(-0.01, 0.01), us(-0.1, 0.1);
  const glm::dvec3 side1 = glm::normalize(glm::cross(axis, glm::dvec3(0, 0, 1))), side2 = glm::cross(axis, side1);
  int decided = 0;
  for (int k = 0; k < 300; ++k) {
    const double t = ut(rng);
    const double s1 = us(rng), s2 = us(rng);
    const glm::dvec3 p = t * axis + s1 * side1 + s2 * side2;
    const double da = glm::length(p - ca) - 0.5, db = glm::length(p - cb) - 0.5;
    const ClosestPoint c = query(*pair, p, Affine::identity(), ctx);
    ASSERT_TRUE(c.valid());
    // The trilinear surface of this coarse grid departs from the spheres by up to ~0.04 voxel.
    EXPECT_NEAR(c.distance, std::min(da, db), 0.05 * voxel) << "point " << k << " at t = " << t;
    if (std::abs(da - db) > 0.1 * voxel) {
      ++decided;
      EXPECT_EQ(glm::dot(c.point_ws, axis) > 0, db < da) << "point " << k << ": the foot is on the nearer sphere";
    }
  }
  EXPECT_GT(decided, 100);
}

TEST(LevelSetClosestPoint, TopLevelFindsTheNearestAmongMeshesAndLevelSets) {
  const auto sphere = makeVolumeObject(sphereLevelSet(0.5f, 0.02f));
  // A mesh box [1.8, 2.2] x [-0.2, 0.2] x [-0.2, 0.2] between the level sets at x = 0 and x = 4.
  const auto box = std::make_shared<const MeshObject>(
      std::make_shared<const TriangleMesh>(test::boxMesh(glm::vec3(1.8f, -0.2f, -0.2f), glm::vec3(2.2f, 0.2f, 0.2f))));
  TopLevel top;
  std::vector<InstanceDesc> instances;
  for (std::uint32_t k = 0; k < 3; ++k)
    instances.push_back({sphere, Affine::fromRowMajor3x4({1, 0, 0, 4.0 * k, 0, 1, 0, 0, 0, 0, 1, 0}), k});
  instances.push_back({box, Affine::identity(), 10});
  top.build(instances);
  QueryContext ctx;
  std::mt19937 rng(34);
  std::uniform_real_distribution<double> ux(-0.5, 8.5), uy(-1.0, 1.0);
  int mesh_nearest = 0, level_set_nearest = 0;
  for (int k = 0; k < 300; ++k) {
    const double x = ux(rng), y = uy(rng), z = uy(rng);
    const glm::dvec3 p(x, y, z);
    double want = kInf;
    std::uint32_t owner = kInvalidId;
    for (std::uint32_t i = 0; i < 3; ++i) {
      const double d = std::abs(glm::length(p - glm::dvec3(4.0 * i, 0, 0)) - 0.5);
      if (d < want) want = d, owner = i;
    }
    // Outside the box: the distance to the box (the query points never fall inside it here).
    const glm::dvec3 lo(1.8, -0.2, -0.2), hi(2.2, 0.2, 0.2);
    const glm::dvec3 e = glm::max(glm::max(lo - p, p - hi), glm::dvec3(0.0));
    if (glm::length(e) > 0.0 && glm::length(e) < want) want = glm::length(e), owner = 10;
    if (glm::length(e) == 0.0) continue;
    const ClosestPoint c = top.closestPoint(p, kInf, ctx);
    ASSERT_TRUE(c.valid());
    EXPECT_EQ(c.instance_id, owner) << "point " << k;
    EXPECT_NEAR(c.distance, want, 1e-3) << "point " << k;
    (owner == 10 ? mesh_nearest : level_set_nearest) += 1;
  }
  EXPECT_GT(mesh_nearest, 20);
  EXPECT_GT(level_set_nearest, 100);
}

TEST(LevelSetClosestPoint, FirstQueriesFromManyThreadsAtOnceAgree) {
  // The surface points are made by the first query, in parallel, while other threads of the same
  // parallel loop wait for them or ask too (a fresh object each round).
  std::vector<glm::dvec3> points;
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int k = 0; k < 150; ++k) points.push_back(test::draw3<glm::dvec3>(u, rng));
  std::vector<double> reference;
  {
    const auto sphere = makeVolumeObject(sphereLevelSet(0.5f, 0.02f));
    QueryContext ctx;
    for (const glm::dvec3& p : points) reference.push_back(query(*sphere, p, Affine::identity(), ctx).distance);
  }
  for (int round = 0; round < 2; ++round) {
    const auto sphere = makeVolumeObject(sphereLevelSet(0.5f, 0.02f));
    std::vector<double> got(points.size());
    tbb::parallel_for(std::size_t{0}, points.size(), [&](std::size_t i) {
      QueryContext ctx;
      got[i] = query(*sphere, points[i], Affine::identity(), ctx).distance;
    });
    EXPECT_EQ(got, reference) << "round " << round;
  }
}

}  // namespace closest

}  // namespace
}  // namespace duplex
