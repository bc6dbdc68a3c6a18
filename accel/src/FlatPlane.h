#pragma once
// Private to accel/src: a float record of a flat instance's plane (Object::flatCrossings), by slot
// of the sensors' level, and the test that drops the instances a ray plainly misses before the
// crossing query asks them (TopLevelCrossings.cpp).
//
// Why: with many small sensors, most boxes a ray meets belong to sensors it misses (the benchmark's
// 10,000 sensors: 1.4 boxes met per segment, 0.5 crossed). The exact crossing (SensorObject::cross,
// reached by intersectAll) needs the instance's record, the ray transformed in double and a
// virtual call; this test reads one 64-byte record and does some 60 float operations.
//
// Exactness: the test only says "misses" when the exact path could not find a crossing. It
// computes the same quantities as the exact path (the object-space ray, t = -o.z / d.z, the local
// x and y), in float from a float copy of the transform, with bounds on how far each may be from
// the exact path's value (that path rounds the object-space ray to float, then works in double):
// a value is decided only when it lies beyond its bound. Anything else (grazing rays, crossings
// near the border or near the ends of the segment, NaN) goes to the exact path, so the crossings,
// their bins, t, u, v and order are those of SensorObject::cross whether or not this test runs.

#include "duplex/accel/Affine.h"
#include "duplex/accel/Object.h"

#include <cmath>
#include <cstdint>
#include <limits>

namespace duplex::toplevel_detail {

struct alignas(64) FlatPlane {
  // Object-space x, y, z of a world point p: row[k][0..2] . p + row[k][3] (object_from_world,
  // rounded to float).
  float row[3][4] = {};
  float half_width = 0.0f, half_height = 0.0f;  // Object::flatCrossings, rounded outwards
  // The slot's query mask, 0 when the slot is not a sensor (no crossing query asks it), so that a
  // met grid entry is filtered without reading the slot's filter: one cache line per entry met.
  std::uint32_t mask = 0;
  // slot | front_only << 30 | valid << 31. Not valid: not flat, a free slot, or a slot number too
  // large to pack: always take the general path (filter, object).
  std::uint32_t bits = 0;

  static constexpr std::uint32_t kFrontOnly = 1u << 30, kValid = 1u << 31, kSlotMask = kFrontOnly - 1u;

  FlatPlane() = default;
  FlatPlane(const Affine& object_from_world, const FlatCrossings& f, std::uint32_t slot = 0,
            std::uint32_t query_mask = 0)
      : half_width(f.half_width),
        half_height(f.half_height),
        mask(query_mask),
        bits(slot <= kSlotMask ? slot | (f.front_only ? kFrontOnly : 0u) | kValid : 0u) {
    for (int k = 0; k < 3; ++k) {
      // glm matrices are column-major: linear[column][row].
      for (int j = 0; j < 3; ++j) row[k][j] = static_cast<float>(object_from_world.linear[j][k]);
      row[k][3] = static_cast<float>(object_from_world.translation[k]);
    }
  }
  [[nodiscard]] bool valid() const { return (bits & kValid) != 0; }
  [[nodiscard]] bool frontOnly() const { return (bits & kFrontOnly) != 0; }
  [[nodiscard]] std::uint32_t slot() const { return bits & kSlotMask; }
};
static_assert(sizeof(FlatPlane) == 64, "one cache line per plane record");

// The world ray as the plane test reads it: float origin and direction and the largest magnitude
// of each (once per ray).
struct PlaneRay {
  float o[3], d[3];
  float o_max, d_max;
  float tnear;
  explicit PlaneRay(const Ray& r)
      : o{r.origin.x, r.origin.y, r.origin.z},
        d{r.dir.x, r.dir.y, r.dir.z},
        o_max(std::fmax(std::fabs(r.origin.x), std::fmax(std::fabs(r.origin.y), std::fabs(r.origin.z)))),
        d_max(std::fmax(std::fabs(r.dir.x), std::fmax(std::fabs(r.dir.y), std::fabs(r.dir.z)))),
        tnear(r.tnear) {}
};

// Whether the ray plainly misses flat instance `f` within [ray.tnear, t_reach] (world t): true only
// when the exact path (object-space ray rounded to float, t = -o.z / d.z in double, the closed
// rectangle |x| <= w/2, |y| <= h/2, a one-sided instance's rays towards -z only) finds no crossing.
//
// Error bounds (eps = float epsilon): a component a . v + c computed in float from the float row
// is within 8 eps (|a|_1 max|v| + |c|) of the exact path's (which rounds the double product to
// float: eps/2 of the value, no more than that sum); t = -oz / dz is within
// (E_oz + |t| E_dz) / (|dz| - E_dz) + 8 eps |t| when |dz| > 2 E_dz, and x = ox + t dx within
// E_ox + |t| E_dx + E_t (|dx| + E_dx) + 8 eps (|ox| + |t dx|). Every comparison that decides is
// false for NaN, so NaN and infinities go to the exact path.
inline bool plainlyMisses(const FlatPlane& f, const PlaneRay& r, float t_reach) {
  // All conditions are evaluated and combined bitwise: one branch per instance at the caller
  // instead of one per condition (which one decides is unpredictable).
  constexpr float kErr = 8.0f * std::numeric_limits<float>::epsilon();
  auto at = [&](int k, const float v[3]) { return f.row[k][0] * v[0] + f.row[k][1] * v[1] + f.row[k][2] * v[2]; };
  auto norm1 = [&](int k) { return std::fabs(f.row[k][0]) + std::fabs(f.row[k][1]) + std::fabs(f.row[k][2]); };
  const float n2 = norm1(2);
  const float dz = at(2, r.d), e_dz = kErr * n2 * r.d_max;
  const bool back = f.frontOnly() & (dz > e_dz);  // the exact d.z > 0: it arrives at the back
  const float adz = std::fabs(dz);
  const bool steep = adz > 2.0f * e_dz;  // else (nearly) parallel: only the exact path decides
  const float oz = at(2, r.o) + f.row[2][3], e_oz = kErr * (n2 * r.o_max + std::fabs(f.row[2][3]));
  const float t = -oz / dz, abs_t = std::fabs(t);
  const float e_t = (e_oz + abs_t * e_dz) / (adz - e_dz) + kErr * abs_t;
  bool outside = (t + e_t < r.tnear) | (t - e_t > t_reach);
  for (int k = 0; k < 2; ++k) {
    const float n = norm1(k);
    const float dk = at(k, r.d), e_dk = kErr * n * r.d_max;
    const float ok = at(k, r.o) + f.row[k][3], e_ok = kErr * (n * r.o_max + std::fabs(f.row[k][3]));
    const float x = ok + t * dk;
    const float e_x = e_ok + abs_t * e_dk + e_t * (std::fabs(dk) + e_dk) + kErr * (std::fabs(ok) + std::fabs(t * dk));
    outside |= std::fabs(x) - e_x > (k == 0 ? f.half_width : f.half_height);
  }
  return back | (steep & outside);
}

}  // namespace duplex::toplevel_detail
