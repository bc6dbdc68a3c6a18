// The 4-wide watertight test of the mesh leaves (objects/mesh/src/WatertightTriangle4.h) must decide and
// compute exactly what the scalar intersectWatertight does, lane by lane: the watertightness argument
// (two triangles sharing an edge compute the same edge function) holds only if both paths do the
// same float operations in the same order. This test resolves each lane the way MeshObject's leaves
// do and compares hit or miss and the bits of t, u and v with the scalar test, on random triangles,
// triangles sharing edges and vertices with rays aimed at them, tiny and huge triangles, axis-aligned
// ones, and rays with zero (+0 / -0) direction components and every axis permutation.

#include "TestSupport.h"
#include "MeshRay.h"
#include "TriangleBlock4.h"
#include "WatertightTriangle4.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/WatertightTriangle.h"

#include <gtest/gtest.h>
#include <glm/vec3.hpp>

#include <array>
#include <bit>
#include <cstdint>
#include <limits>
#include <random>
#include <sstream>
#include <vector>

namespace duplex::test {
namespace {

constexpr int kLaneMask[5] = {0x0, 0x1, 0x3, 0x7, 0xF};

std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }

using Triangle = std::array<glm::vec3, 3>;

struct LaneResult {
  bool hit = false;
  float t = 0.0f, u = 0.0f, v = 0.0f;
};

// One block of up to four triangles, lanes resolved as MeshObject::intersect resolves them (the
// t_max of each lane is the caller's, not lowered by earlier lanes, to compare lane by lane).
std::array<LaneResult, 4> blockTest(const detail::MeshRay& ray, const std::vector<Triangle>& tris, float t_max) {
  detail::TriangleBlock4 block;
  for (int k = 0; k < 4; ++k) {
    const Triangle& t = tris[std::min<std::size_t>(k, tris.size() - 1)];
    block.set(k, t[0], t[1], t[2], static_cast<std::uint32_t>(k));
  }
  const int lanes = kLaneMask[std::min<std::size_t>(tris.size(), 4)];
  const detail::Watertight4 r = detail::intersectWatertight4(ray.wray4, block, lanes, t_max);
  EXPECT_EQ(r.fast & r.exact, 0) << "a lane is both decided in float and handed to the scalar test";
  EXPECT_EQ((r.fast | r.exact) & ~lanes, 0) << "a padding lane reported";
  std::array<LaneResult, 4> out{};
  for (int k = 0; k < 4; ++k) {
    LaneResult& o = out[k];
    if (r.exact >> k & 1) {
      o.hit = intersectWatertight(ray.wray, block.vertex(k, 0), block.vertex(k, 1), block.vertex(k, 2), t_max, o.t, o.u,
                                  o.v);
    } else if (r.fast >> k & 1) {
      if (r.sT[k] > t_max * r.abs_det[k]) continue;
      const float inv = 1.0f / r.det[k];
      o.hit = true;
      o.t = r.T[k] * inv;
      o.u = r.V[k] * inv;
      o.v = r.W[k] * inv;
    }
  }
  return out;
}

std::string describe(const Ray& r) {
  std::ostringstream os;
  os.precision(9);
  os << r;
  return os.str();
}

// Compares every lane of the block test with the scalar test for one ray; returns the hits.
int compareRay(const Ray& ray, const std::vector<Triangle>& tris, float t_max) {
  detail::MeshRay m;
  float tmin, tmax;
  // A huge box: only the per-ray constants matter here, not the clip.
  const Box box{glm::vec3(-1e30f), glm::vec3(1e30f)};
  if (!detail::setupMeshRay(ray, box, m, tmin, tmax)) return 0;
  const auto lanes = blockTest(m, tris, t_max);
  const WatertightRay scalar_ray(ray);
  int hits = 0;
  for (std::size_t k = 0; k < tris.size() && k < 4; ++k) {
    LaneResult ref;
    ref.hit = intersectWatertight(scalar_ray, tris[k][0], tris[k][1], tris[k][2], t_max, ref.t, ref.u, ref.v);
    SCOPED_TRACE(::testing::Message() << describe(ray) << " lane " << k);
    EXPECT_EQ(lanes[k].hit, ref.hit);
    if (lanes[k].hit && ref.hit) {
      EXPECT_EQ(bits(lanes[k].t), bits(ref.t)) << lanes[k].t << " vs " << ref.t;
      EXPECT_EQ(bits(lanes[k].u), bits(ref.u)) << lanes[k].u << " vs " << ref.u;
      EXPECT_EQ(bits(lanes[k].v), bits(ref.v)) << lanes[k].v << " vs " << ref.v;
      ++hits;
    }
  }
  return hits;
}

TEST(WatertightTriangle4, RandomTrianglesAndRaysEqualTheScalarTest) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  std::normal_distribution<float> n(0.0f, 1.0f);
  const float scales[] = {1.0f, 1e-4f, 1e4f};
  int hits = 0, rays = 0;
  for (int i = 0; i < 60000; ++i) {
    const float s = scales[i % 3];
    std::vector<Triangle> tris(1 + i % 4);
    for (Triangle& t : tris)
      for (glm::vec3& p : t) p = s * draw3(u, rng);
    Ray ray;
    ray.origin = s * (2.0f * draw3(u, rng));
    // Aim at a point of one triangle half the time, so that hits are common.
    if (i % 2 == 0) {
      const Triangle& t = tris[i % tris.size()];
      const float a = std::abs(u(rng)) / 2.0f, b = std::abs(u(rng)) / 2.0f;
      ray.dir = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]) - ray.origin;
    } else {
      ray.dir = draw3(n, rng);
    }
    ray.tnear = i % 5 == 0 ? 0.5f : 0.0f;
    const float t_max = i % 7 == 0 ? 1.0f : std::numeric_limits<float>::infinity();
    hits += compareRay(ray, tris, t_max);
    ++rays;
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(hits, rays / 5);  // not vacuous
}

TEST(WatertightTriangle4, SharedEdgesAndVerticesEqualTheScalarTest) {
  // A fan of four triangles around a centre vertex; rays aimed exactly at the centre, at the shared
  // edges' midpoints and at the outer vertices, from all around (every axis permutation, both signs),
  // hit exactly as the scalar test says: these are the lanes with zero edge functions.
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  int hits = 0;
  for (int i = 0; i < 20000; ++i) {
    const glm::vec3 c = draw3(u, rng);
    const glm::vec3 ring[4] = {c + glm::vec3(1.0f, 0.1f * u(rng), 0.0f), c + glm::vec3(0.0f, 1.0f, 0.1f * u(rng)),
                               c + glm::vec3(-1.0f, 0.1f * u(rng), 0.0f), c + glm::vec3(0.0f, -1.0f, 0.1f * u(rng))};
    std::vector<Triangle> fan;
    for (int k = 0; k < 4; ++k) fan.push_back({c, ring[k], ring[(k + 1) % 4]});
    const glm::vec3 targets[3] = {c, 0.5f * (c + ring[i % 4]), ring[i % 4]};
    Ray ray;
    ray.origin = c + 3.0f * draw3(u, rng);
    ray.dir = targets[i % 3] - ray.origin;
    hits += compareRay(ray, fan, std::numeric_limits<float>::infinity());
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(hits, 20000);  // rays through edges and vertices hit several triangles of the fan
}

TEST(WatertightTriangle4, AxisParallelRaysAndFlatTrianglesEqualTheScalarTest) {
  // Directions with zero and negative-zero components, and triangles lying in axis planes (also the
  // plane of the ray): the shear and the permutation take their special values here.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  const float zeros[2] = {0.0f, -0.0f};
  int hits = 0;
  for (int i = 0; i < 30000; ++i) {
    std::vector<Triangle> tris(4);
    for (int k = 0; k < 4; ++k) {
      for (glm::vec3& p : tris[k]) p = draw3(u, rng);
      const int flat_axis = (i + k) % 4;  // 3: not flat
      if (flat_axis < 3)
        for (glm::vec3& p : tris[k]) p[flat_axis] = 0.25f;
    }
    Ray ray;
    ray.origin = draw3(u, rng);
    const int axis = i % 3;
    ray.dir = glm::vec3(zeros[(i / 3) & 1], zeros[(i / 6) & 1], zeros[(i / 12) & 1]);
    ray.dir[axis] = (i / 24) & 1 ? 1.0f : -1.0f;
    if (i % 5 == 0) ray.dir[(axis + 1) % 3] = 0.5f * u(rng);  // one more non-zero component
    if (i % 11 == 0) ray.origin[(axis + 2) % 3] = 0.25f;      // in the flat triangles' plane
    hits += compareRay(ray, tris, std::numeric_limits<float>::infinity());
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(hits, 1000);  // not vacuous
}

}  // namespace
}  // namespace duplex::test
