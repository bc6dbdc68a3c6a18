// Fog media: transmittance by exact integration, ratio tracking, delta tracking or fixed-step
// marching; free-flight sampling; picking by a density threshold.
//
// All methods see one density field: an active voxel's value (negatives clamped to 0) over the
// unit cube around its centre, 0 elsewhere. The ray is shifted by half a voxel so that voxel ijk is
// the integer cell [ijk, ijk + 1) that OpenVDB's DDA walks.
//
// Tracking walks the VDB tree with a hierarchical DDA of our own (Museth 2014): the upper
// internal nodes along the ray, inside each the lower nodes, inside each the leaves, skipping
// empty children at every level. Each node at the configured majorant level is one segment with
// the node's (min, max) density, precomputed at construction (VolumeObject::Grid::ranges); an
// active tile is a segment of constant density. Delta tracking (Woodcock et al. 1965) and ratio
// tracking (Cramer 1978; residual form: Novak, Selle and Jarosz, "Residual ratio tracking for
// estimating attenuation in participating media", SIGGRAPH Asia 2014) draw tentative collisions
// per segment with rate max x |dir| (memoryless, so restarting at each segment is exact).

#include "VolumeGrid.h"

#include "duplex/accel/Error.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace duplex {

using namespace volume_detail;

std::string_view toString(FogMethod method) {
  switch (method) {
    case FogMethod::Exact: return "exact";
    case FogMethod::RatioTracking: return "ratio";
    case FogMethod::DeltaTracking: return "delta";
    case FogMethod::RayMarching: return "march";
  }
  return "?";
}

std::ostream& operator<<(std::ostream& os, FogMethod method) { return os << toString(method); }

namespace {

// SplitMix64 (Steele, Lea and Flood 2014): a tiny, well-mixed generator whose state is a seed.
struct Random {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  // Exponential with rate 1 (1 - u lies in (0, 1]: never log(0)).
  double exponential() { return -std::log1p(-uniform()); }
};

// A seed from the ray's 32 bytes and a user seed: the same ray gets the same random stream.
std::uint64_t hashRay(const Ray& r, std::uint64_t seed) {
  std::uint32_t words[8];
  static_assert(sizeof(words) == sizeof(Ray));
  std::memcpy(words, &r, sizeof(Ray));
  Random h{seed};
  std::uint64_t acc = h.next();
  for (std::uint32_t w : words) {
    h.state ^= w + acc;
    acc = h.next();
  }
  return acc;
}

double density(ThreadState& s, const RayI& ray, double t) {
  float v = 0.0f;
  return s.acc.probeValue(vdb::Coord::floor(ray(t)), v) ? effectiveDensity(v) : 0.0;
}

// One piece of the ray with a density bound: [t0, t1], density in [lo, hi]; `constant` for an
// active tile (density exactly hi everywhere on the piece).
struct Segment {
  double t0, t1;
  float lo, hi;
  bool constant;
};

vdb::Coord rangeKey(const vdb::Coord& origin, int level) {
  const int s = kLog2Size[level];
  return vdb::Coord(origin.x() >> s, origin.y() >> s, origin.z() >> s);
}

// Calls on(Segment) for the non-empty nodes at majorant level `level` and the active tiles along
// [t0, t1] of the (shifted) ray, front to back, until it returns true; returns whether it stopped.
// ChildLevel: the level of the cells this DDA steps over (2: upper nodes, 1: lower, 0: leaves).
template <int ChildLevel, class On>
bool walkLevel(const RayI& ray, double t0, double t1, int level, ThreadState& s, On& on) {
  using ChildT = std::conditional_t<ChildLevel == 2, Upper, std::conditional_t<ChildLevel == 1, Lower, LeafT>>;
  vdb::math::DDA<RayI, ChildT::TOTAL> dda(ray, t0, t1);
  do {
    const double a = std::max(dda.time(), t0), b = std::min(dda.next(), t1);
    if (a < b) {
      const vdb::Coord ijk = dda.voxel();
      if (const ChildT* node = s.acc.template probeConstNode<ChildT>(ijk)) {
        if (ChildLevel == level) {
          const vdb::Vec2s r = s.range_acc[ChildLevel]->getValue(rangeKey(node->origin(), ChildLevel));
          if (r.y() > 0.0f && on(Segment{a, b, r.x(), r.y(), false})) return true;
        } else if constexpr (ChildLevel > 0) {
          if (walkLevel<ChildLevel - 1>(ray, a, b, level, s, on)) return true;
        }
      } else {
        float v = 0.0f;
        if (s.acc.probeValue(ijk, v) && effectiveDensity(v) > 0.0f) {  // an active tile
          const float d = effectiveDensity(v);
          if (on(Segment{a, b, d, d, true})) return true;
        }
      }
    }
  } while (dda.step());
  return false;
}

// All segments of [ray.t0, ray.t1] with majorants of nodes at `level` (0..2).
template <class On>
bool walkSegments(const RayI& ray, int level, ThreadState& s, On on) {
  return walkLevel<2>(ray, ray.t0(), ray.t1(), level, s, on);
}

// Exact optical depth (in t units): density x time in each voxel of each non-empty leaf, and
// density x time across each active tile (constant: no voxel walk).
double exactDepth(const RayI& ray, ThreadState& s) {
  double depth_t = 0.0;
  walkSegments(ray, 0, s, [&](const Segment& seg) {
    if (seg.constant) {
      depth_t += double(seg.hi) * (seg.t1 - seg.t0);
      return false;
    }
    vdb::math::DDA<RayI, 0> dda(ray, seg.t0, seg.t1);
    do {
      float v = 0.0f;
      if (s.acc.probeValue(dda.voxel(), v) && v > 0.0f)
        depth_t += double(v) * (std::min(dda.next(), seg.t1) - std::max(dda.time(), seg.t0));
    } while (dda.step());
    return false;
  });
  return depth_t;
}

// Midpoint-rule optical depth over the active spans, steps of `step_vox` voxels (the last step of
// a span shortened so that the steps tile it exactly).
double marchedDepth(const RayI& ray, ThreadState& s, double step_vox) {
  const double dt = step_vox / ray.dir().length();
  double depth_t = 0.0;
  for (const TimeSpan& span : activeSpans(ray, s)) {
    const double a = std::max(span.t0, ray.t0()), b = std::min(span.t1, ray.t1());
    if (!(a < b)) continue;
    for (double t = a; t < b; t += dt) {
      const double e = std::min(t + dt, b);
      depth_t += density(s, ray, 0.5 * (t + e)) * (e - t);
    }
  }
  return depth_t;
}

// One ratio-tracking estimate of exp(-depth); len_per_t converts t to object-space length.
double ratioTracking(const RayI& ray, ThreadState& s, const VolumeQueryConfig& c, double len_per_t, Random& rng) {
  double tr = 1.0;
  walkSegments(ray, c.majorant_level, s, [&](const Segment& seg) {
    if (seg.constant) {
      tr *= std::exp(-double(seg.hi) * (seg.t1 - seg.t0) * len_per_t);
      return tr == 0.0;
    }
    const double control = c.residual ? seg.lo : 0.0;
    const double residual_max = seg.hi - control;
    tr *= std::exp(-control * (seg.t1 - seg.t0) * len_per_t);
    if (residual_max <= 0.0) return tr == 0.0;
    const double rate = residual_max * len_per_t;  // tentative collisions per unit t
    for (double t = seg.t0 + rng.exponential() / rate; t < seg.t1; t += rng.exponential() / rate) {
      tr *= 1.0 - (density(s, ray, t) - control) / residual_max;
      if (tr <= 0.0) return true;
    }
    return false;
  });
  return std::max(tr, 0.0);
}

// Delta tracking: the t of the first real collision, or NaN when the flight escapes.
double deltaTracking(const RayI& ray, ThreadState& s, int level, double len_per_t, Random& rng) {
  double hit = std::numeric_limits<double>::quiet_NaN();
  walkSegments(ray, level, s, [&](const Segment& seg) {
    const double rate = double(seg.hi) * len_per_t;
    for (double t = seg.t0 + rng.exponential() / rate; t < seg.t1; t += rng.exponential() / rate) {
      if (seg.constant || rng.uniform() * seg.hi < density(s, ray, t)) {
        hit = t;
        return true;
      }
    }
    return false;
  });
  return hit;
}

}  // namespace

float VolumeObject::transmittance(const Ray& ray_os, QueryContext& ctx) const {
  return transmittance(ray_os, ctx, config_.transmittance, hashRay(ray_os, config_.seed));
}

float VolumeObject::transmittance(const Ray& ray_os, QueryContext& ctx, FogMethod method, std::uint64_t seed) const {
  if (grid_->kind != VolumeKind::Fog) return Object::transmittance(ray_os, ctx);
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, ray_os.tfar, 0.5, ray)) return 1.0f;
  ThreadState& s = threadState(this, grid_, ctx);
  const double len_per_t = vdb::Vec3d(ray_os.dir.x, ray_os.dir.y, ray_os.dir.z).length();
  Random rng{seed};
  double tr = 1.0;
  switch (method) {
    case FogMethod::Exact: tr = std::exp(-exactDepth(ray, s) * len_per_t); break;
    case FogMethod::RayMarching: tr = std::exp(-marchedDepth(ray, s, config_.march_step) * len_per_t); break;
    case FogMethod::RatioTracking: {
      double sum = 0.0;
      for (std::uint32_t k = 0; k < config_.samples; ++k) sum += ratioTracking(ray, s, config_, len_per_t, rng);
      tr = sum / config_.samples;
      break;
    }
    case FogMethod::DeltaTracking: {
      std::uint32_t escaped = 0;
      for (std::uint32_t k = 0; k < config_.samples; ++k)
        escaped += std::isnan(deltaTracking(ray, s, config_.majorant_level, len_per_t, rng)) ? 1u : 0u;
      tr = double(escaped) / config_.samples;
      break;
    }
  }
  return static_cast<float>(tr);
}

std::optional<float> VolumeObject::sampleFreeFlight(const Ray& ray_os, QueryContext& ctx, std::uint64_t seed) const {
  if (grid_->kind != VolumeKind::Fog) return std::nullopt;
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, ray_os.tfar, 0.5, ray)) return std::nullopt;
  ThreadState& s = threadState(this, grid_, ctx);
  const double len_per_t = vdb::Vec3d(ray_os.dir.x, ray_os.dir.y, ray_os.dir.z).length();
  Random rng{seed};
  const double t = deltaTracking(ray, s, config_.majorant_level, len_per_t, rng);
  if (std::isnan(t)) return std::nullopt;
  return static_cast<float>(t);
}

std::optional<float> VolumeObject::firstDensityAbove(const Ray& ray_os, float threshold, QueryContext& ctx) const {
  if (grid_->kind != VolumeKind::Fog) {
    Hit hit;
    hit.t = ray_os.tfar;
    if (!intersect(ray_os, hit, ctx)) return std::nullopt;
    return hit.t;
  }
  RayI ray;
  if (!indexRay(*grid_, ray_os, ray_os.tnear, ray_os.tfar, 0.5, ray)) return std::nullopt;
  ThreadState& s = threadState(this, grid_, ctx);
  double found = std::numeric_limits<double>::quiet_NaN();
  // Leaves whose maximum is at most the threshold are skipped whole; inside the others, voxels.
  walkSegments(ray, 0, s, [&](const Segment& seg) {
    if (seg.hi <= threshold) return false;
    if (seg.constant) {
      found = seg.t0;
      return true;
    }
    vdb::math::DDA<RayI, 0> dda(ray, seg.t0, seg.t1);
    do {
      float v = 0.0f;
      if (s.acc.probeValue(dda.voxel(), v) && effectiveDensity(v) > threshold) {
        found = std::max(dda.time(), seg.t0);
        return true;
      }
    } while (dda.step());
    return false;
  });
  if (std::isnan(found)) return std::nullopt;
  // The clipped start is in double; never report a t before tnear after rounding to float.
  return std::max(static_cast<float>(found), ray_os.tnear);
}

}  // namespace duplex
