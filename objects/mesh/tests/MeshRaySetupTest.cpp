// MeshObject's per-ray setup (objects/mesh/src/MeshRay.h) computes with SSE, in one pass, what KdRay,
// WatertightRay, clipRayToBox and isQueryable compute separately (and prepareBvhRay the part of it
// the BVH's single-ray walks read). The traversal and the exactness
// arguments (docs/design/kdtree.md) rely on those values, so the setup must equal them bit for bit: this
// test compares them on random rays and on the awkward ones (zero and negative-zero direction
// components, denormal components, origins on the box faces and outside, directions that overflow
// 1/d, non-finite and non-queryable rays).

#include "TestSupport.h"
#include "MeshRay.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/WatertightTriangle.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }

// Equal as bit patterns, except that +0 and -0 count as equal (min / max of equal zeros may
// return either; the traversal only compares these values).
bool same(float a, float b) { return bits(a) == bits(b) || (a == 0.0f && b == 0.0f); }

std::string describe(const Ray& r) {
  std::ostringstream os;
  os.precision(9);
  os << r;
  return os.str();
}

// Compares setupMeshRay with the separate reference computations for one ray.
void checkRay(const Ray& ray, const Box& box) {
  SCOPED_TRACE(describe(ray));
  detail::MeshRay m;
  float tmin = kNaN, tmax = kNaN;
  const bool hit = detail::setupMeshRay(ray, box, m, tmin, tmax);
  detail::MeshRay b;
  int octant = -1;
  const bool bvh_ok = detail::prepareBvhRay(ray, b, octant);
  if (!isQueryable(ray)) {
    EXPECT_FALSE(hit);
    EXPECT_FALSE(bvh_ok);
    return;
  }
  const KdRay kd(ray);
  // The BVH walks' box part: the values the BVH's box test reads, and the octant of the sign masks.
  ASSERT_TRUE(bvh_ok);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(bits(b.kd.origin[k]), bits(kd.origin[k])) << "axis " << k;
    EXPECT_EQ(bits(b.kd.inv_dir[k]), bits(kd.inv_dir[k])) << "axis " << k;
  }
  EXPECT_EQ(bits(b.kd.tnear), bits(kd.tnear));
  EXPECT_EQ(octant, static_cast<int>((kd.neg_mask[0] & 1u) | (kd.neg_mask[1] & 2u) | (kd.neg_mask[2] & 4u)));
  float ref_min = kNaN, ref_max = kNaN;
  const bool ref_hit = clipRayToBox(kd, box, ref_min, ref_max);
  ASSERT_EQ(hit, ref_hit);
  if (!hit) return;
  EXPECT_TRUE(same(tmin, ref_min)) << tmin << " vs " << ref_min;
  EXPECT_TRUE(same(tmax, ref_max)) << tmax << " vs " << ref_max;
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(bits(m.kd.origin[k]), bits(kd.origin[k])) << "axis " << k;
    EXPECT_EQ(bits(m.kd.inv_dir[k]), bits(kd.inv_dir[k])) << "axis " << k;
    EXPECT_EQ(m.kd.neg_mask[k], kd.neg_mask[k]) << "axis " << k;
    EXPECT_EQ(m.kd.zero[k], kd.zero[k]) << "axis " << k;
  }
  EXPECT_EQ(bits(m.kd.tnear), bits(kd.tnear));
  EXPECT_EQ(bits(m.kd.tfar), bits(kd.tfar));
  const WatertightRay w(ray);
  EXPECT_EQ(m.wray.kx, w.kx);
  EXPECT_EQ(m.wray.ky, w.ky);
  EXPECT_EQ(m.wray.kz, w.kz);
  EXPECT_EQ(bits(m.wray.sx), bits(w.sx));
  EXPECT_EQ(bits(m.wray.sy), bits(w.sy));
  EXPECT_EQ(bits(m.wray.sz), bits(w.sz));
  EXPECT_EQ(bits(m.wray.tnear), bits(w.tnear));
  for (int k = 0; k < 3; ++k) EXPECT_EQ(bits(m.wray.origin[k]), bits(w.origin[k]));
  // The 4-wide constants: permuted origin and shear in every lane.
  const detail::WatertightRay4& w4 = m.wray4;
  EXPECT_EQ(w4.kx, w.kx);
  EXPECT_EQ(w4.ky, w.ky);
  EXPECT_EQ(w4.kz, w.kz);
  alignas(16) float lanes[4];
  const int axes[3] = {w.kx, w.ky, w.kz};
  for (int j = 0; j < 3; ++j) {
    _mm_store_ps(lanes, w4.o[j]);
    for (float f : lanes) EXPECT_EQ(bits(f), bits(w.origin[axes[j]])) << "permuted origin " << j;
  }
  const __m128 shear[3] = {w4.sx, w4.sy, w4.sz};
  const float ref_shear[3] = {w.sx, w.sy, w.sz};
  for (int j = 0; j < 3; ++j) {
    _mm_store_ps(lanes, shear[j]);
    for (float f : lanes) EXPECT_EQ(bits(f), bits(ref_shear[j])) << "shear " << j;
  }
}

TEST(MeshRaySetup, RandomRaysEqualTheSeparateComputations) {
  const Box box{glm::vec3(-1.5f, 0.25f, -3.0f), glm::vec3(2.0f, 1.75f, 0.5f)};
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<float> u(-4.0f, 4.0f);
  std::normal_distribution<float> n(0.0f, 1.0f);
  for (int i = 0; i < 200000; ++i) {
    Ray r;
    r.origin = draw3(u, rng);
    r.dir = draw3(n, rng);
    if (i % 3 == 0) r.tnear = std::abs(u(rng));
    if (i % 5 == 0) r.tfar = r.tnear + std::abs(u(rng));
    checkRay(r, box);
    if (::testing::Test::HasFailure()) return;
  }
}

TEST(MeshRaySetup, AwkwardRaysEqualTheSeparateComputations) {
  const Box box{glm::vec3(-1.0f, -2.0f, 0.0f), glm::vec3(1.0f, 0.0f, 3.0f)};
  const float denormal = std::numeric_limits<float>::denorm_min() * 3.0f;
  const float components[] = {0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -2.0f, denormal, -denormal, 1e-30f, -1e-30f, 1e30f};
  // Origins inside, on each face and edge, and outside of the box, per axis.
  const float xs[] = {-1.0f, 0.0f, 1.0f, -1.5f, 2.0f};
  const float ys[] = {-2.0f, -1.0f, 0.0f, 0.5f, -3.0f};
  const float zs[] = {0.0f, 1.0f, 3.0f, -1.0f, 4.0f};
  int rays = 0;
  for (float dx : components)
    for (float dy : components)
      for (float dz : components)
        for (float ox : xs)
          for (float oy : ys)
            for (float oz : zs) {
              Ray r;
              r.origin = glm::vec3(ox, oy, oz);
              r.dir = glm::vec3(dx, dy, dz);
              checkRay(r, box);
              ++rays;
              if (::testing::Test::HasFailure()) return;
            }
  EXPECT_EQ(rays, 11 * 11 * 11 * 125);
}

TEST(MeshRaySetup, NonQueryableRaysAreRefused) {
  const Box box{glm::vec3(-1.0f), glm::vec3(1.0f)};
  std::vector<Ray> rays;
  for (int k = 0; k < 3; ++k)
    for (float bad : {kNaN, kInf, -kInf}) {
      Ray r;
      r.origin[k] = bad;
      rays.push_back(r);
      Ray s;
      s.dir[k] = bad;
      rays.push_back(s);
    }
  Ray zero_dir;
  zero_dir.dir = glm::vec3(0.0f, -0.0f, 0.0f);
  rays.push_back(zero_dir);
  Ray reversed;
  reversed.tnear = 2.0f;
  reversed.tfar = 1.0f;
  rays.push_back(reversed);
  Ray nan_near;
  nan_near.tnear = kNaN;
  rays.push_back(nan_near);
  for (const Ray& r : rays) {
    ASSERT_FALSE(isQueryable(r)) << r;
    detail::MeshRay m;
    float tmin, tmax;
    EXPECT_FALSE(detail::setupMeshRay(r, box, m, tmin, tmax)) << r;
    int octant;
    EXPECT_FALSE(detail::prepareBvhRay(r, m, octant)) << r;
  }
  // And a queryable ray through the box is accepted (the refusals above are not a stuck false).
  detail::MeshRay m;
  float tmin, tmax;
  EXPECT_TRUE(detail::setupMeshRay(Ray{}, box, m, tmin, tmax));
}

}  // namespace
}  // namespace duplex::test
