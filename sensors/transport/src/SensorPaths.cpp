// The light paths of a sensor run: each chunk's rays are emitted from the lights, traced through
// the scene's surfaces, materials and media, and their deposits on the sensors recorded per ray
// (merged per bin within the path, so that a bin's sum of squares is over emitted rays).

#include "duplex/objects/MeshObject.h"
#include "duplex/sensors/CounterRng.h"
#include "duplex/sensors/HenyeyGreenstein.h"
#include "duplex/sensors/SensorRun.h"

#include "OrthonormalBasis.h"
#include "Polarisation.h"
#include "SurfaceEvent.h"
#include "SensorRunChunk.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <variant>
#include <vector>

namespace duplex {

using detail::BinEvent;
using detail::SensorEvent;

namespace {

// A direction scattered from unit propagation direction d by phase function hg.
glm::dvec3 phaseDirection(const glm::dvec3& d, const HenyeyGreenstein& hg, double u0, double u1) {
  const double c = hg.sampleCos(u0), sn = std::sqrt(std::max(0.0, 1.0 - c * c)), phi = 2.0 * std::numbers::pi * u1;
  glm::dvec3 t, b;
  detail::orthonormalBasis(d, t, b);
  return glm::normalize(sn * std::cos(phi) * t + sn * std::sin(phi) * b + c * d);
}

// Whether the segment origin + t dir, t in [0, t_max], meets the box [lo, hi] (slab test; an
// infinite t_max is a ray).
bool segmentMeetsBox(const glm::dvec3& origin, const glm::dvec3& dir, double t_max, const glm::dvec3& lo,
                     const glm::dvec3& hi) {
  double t0 = 0.0, t1 = t_max;
  for (int a = 0; a < 3; ++a) {
    const double inv = 1.0 / dir[a];
    double ta = (lo[a] - origin[a]) * inv, tb = (hi[a] - origin[a]) * inv;
    if (ta > tb) std::swap(ta, tb);
    if (!(ta <= t1 && tb >= t0)) {
      if (std::isnan(ta) || std::isnan(tb)) continue;  // dir[a] == 0 with the origin on a face: keep
      return false;
    }
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1;
}

bool isFinite(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// The meters' next-event connection from the emission of `light`, picked with probability
// power_w / P (`scale` = P / power_w undoes it): `connect(from_of, radiance)` as in traceChunk.
// Point-like lights send their radiant intensity towards the meter; an area light's sampled point
// (uniform over its area A, so the estimate of the integral of L cos_l dA is L A cos_l) sends
// power_w cos_l / (pi sides); a directional light lights a point inside its beam's cylinder
// (downstream of its disk, the light coming from the disk along the beam) with the irradiance
// power_w / (pi r^2) on a plane across the beam, whichever ray was emitted.
// A beam of parallel rays along unit `b` from the disk of `radius` about `centre` (across b),
// with the irradiance e across it: a point inside its cylinder, downstream of the disk, receives it
// from the disk's point upstream of it; elsewhere nothing.
template <class Connect>
void connectBeam(const glm::dvec3& centre, const glm::dvec3& b, double radius, double e, Connect&& connect) {
  connect(
      [&](const glm::dvec3& x) {
        const double along = glm::dot(x - centre, b);
        const glm::dvec3 across = x - centre - along * b;
        const bool lit = along > 0.0 && glm::dot(across, across) <= radius * radius;
        return lit ? x - along * b : x;  // x itself: distance 0, no connection
      },
      [&](const glm::dvec3&, double d) {
        return d > 0.0 ? e * d * d : 0.0;  // irradiance e across the beam: radiance e d^2 / cos
      });
}

template <class Connect>
void connectLight(const Light& light, const EmittedRay& emitted, double scale, Connect&& connect) {
  switch (light.type) {
    case LightType::Point:
    case LightType::Spot:
    case LightType::Goniometric:
      connect([&](const glm::dvec3&) { return light.position; },
              [&](const glm::dvec3& v, double) { return scale * light.intensity(v); });
      break;
    case LightType::Area: {
      // The face sampleLight emits from: the cross product of the mapped local axes.
      // (An emissive mesh: the sampled triangle's front face.)
      const glm::dvec3 n = !light.triangles.empty()
                               ? emitted.normal
                               : glm::normalize(glm::cross(light.world_from_light.vector(glm::dvec3(1, 0, 0)),
                                                           light.world_from_light.vector(glm::dvec3(0, 1, 0))));
      const double sides = light.two_sided ? 2.0 : 1.0;
      connect([&](const glm::dvec3&) { return emitted.origin; },
              [&](const glm::dvec3& v, double) {
                const double c = glm::dot(v, n);
                return scale * light.power_w * (light.two_sided ? std::abs(c) : std::max(0.0, c)) /
                       (std::numbers::pi * sides);
              });
      break;
    }
    case LightType::Directional:
      connectBeam(light.position, glm::normalize(light.direction), light.radius,
                  scale * light.power_w / (std::numbers::pi * light.radius * light.radius), connect);
      break;
    case LightType::Sky:
      // The emitted direction is a sample of the sky's radiance (pdf ~ L, weight of mean 1): along
      // it, a point of the lit sphere receives the irradiance power_w / (pi r^2) weight across the
      // beam, an unbiased estimate of the integral of L over the sky, as for the beam of a
      // directional light from the ray's disk (centred one radius upstream of the sphere's centre).
      connectBeam(light.position - light.radius * emitted.dir, emitted.dir, light.radius,
                  scale * emitted.weight * light.power_w / (std::numbers::pi * light.radius * light.radius), connect);
      break;
  }
}

}  // namespace

detail::RestartPoint detail::restartFromTriangle(const std::array<glm::vec3, 3>& tri, float u, float v,
                                                 const SurfaceInstance& si, const glm::dvec3& n_ws) {
  constexpr double kUnit = 0x1p-24;  // float's unit roundoff
  auto gamma = [](double k) { return k * kUnit / (1.0 - k * kUnit); };
  const glm::dvec3 v0(tri[0]), v1(tri[1]), v2(tri[2]);
  const double b1 = u, b2 = v, b0 = 1.0 - b1 - b2;
  const glm::dvec3 p_os = b0 * v0 + b1 * v1 + b2 * v2;
  RestartPoint out;
  out.p_ws = si.identity ? p_os : si.world_from_object.point(p_os);
  const glm::dvec3 n_os = glm::normalize(glm::cross(v1 - v0, v2 - v0));
  // The next ray's origin per object-space axis: rounded to float in world space, and for a
  // transformed instance mapped through object_from_world (whose absolute entries spread each
  // world error over the object axes) and rounded to float again.
  const glm::dvec3 world_err = kUnit * glm::abs(out.p_ws);
  glm::dvec3 err = world_err;
  double per_unit = std::abs(glm::dot(n_os, n_ws));  // object-space distance per world distance along n_ws
  if (!si.identity) {
    const glm::dmat3& m = si.object_from_world.linear;
    glm::dmat3 abs_m;
    for (int c = 0; c < 3; ++c) abs_m[c] = glm::abs(m[c]);
    err = abs_m * world_err + kUnit * glm::abs(p_os);
    per_unit = std::abs(glm::dot(n_os, m * n_ws));
  }
  // The watertight test works on the vertices minus the origin; those differences (and all that
  // follows from them) are rounded relative to the triangle's extent about the hit.
  double extent = 0.0;
  for (const glm::dvec3& w : {v0, v1, v2}) {
    const glm::dvec3 d = glm::abs(w - p_os);
    extent = std::max({extent, d.x, d.y, d.z});
  }
  const double across = glm::dot(glm::abs(n_os), err) + gamma(12) * extent;
  // Twice the bound; a plane seen edge-on by the transform (per_unit ~ 0) cannot occur for a
  // non-singular transform, but is kept finite.
  out.offset = 2.0 * across / std::max(per_unit, 1e-6);
  return out;
}

bool detail::leavesSurface(const glm::dvec3& next, const glm::dvec3& n_in, bool transmits) {
  const double side = glm::dot(next, n_in);
  return std::isfinite(next.x) && std::isfinite(next.y) && std::isfinite(next.z) &&
         (transmits ? side < 0.0 : side > 0.0);
}

namespace {

// Sorts a path's deposits by bin, keeping the path order within a bin. Most paths deposit in a
// handful of bins: a stable insertion sort, where std::stable_sort would allocate a buffer per path.
void sortByBin(std::vector<BinEvent>& events) {
  if (events.size() > 32) {
    std::stable_sort(events.begin(), events.end(), [](const BinEvent& a, const BinEvent& b) { return a.bin < b.bin; });
    return;
  }
  for (std::size_t i = 1; i < events.size(); ++i) {
    const BinEvent e = events[i];
    std::size_t j = i;
    for (; j > 0 && events[j - 1].bin > e.bin; --j) events[j] = events[j - 1];
    events[j] = e;
  }
}

}  // namespace

void SensorRun::traceChunk(Chunk& chunk) const {
  const TopLevel& top = scene_.tracer().topLevel();
  const auto& lights = scene_.lights();
  const auto& sensors = scene_.sensors();
  const double power = scene_.totalPower();
  const double rr_level = config_.roulette_threshold * power;
  const std::uint32_t bands = scene_.bandCount();
  const std::uint32_t angle_base = scene_.binCount();  // angular bins follow the spatial ones
  // In a scene whose fogs scatter, every fog acts through sampled free flights, not through the
  // crossing query's transmittance.
  const bool scatter = scene_.scatters();
  CrossingQuery query = config_.query;
  if (scatter) query.medium_mask = 0;
  // Far-field sensors (after the graph's sensors) record the direction of every ray that escapes.
  std::vector<std::uint32_t> far_field;
  if (!config_.closest_hit_only)
    for (std::size_t s = 0; s < sensors.size(); ++s)
      if (sensors[s].object->spec().shape == SensorShape::FarField) far_field.push_back(static_cast<std::uint32_t>(s));
  QueryContext ctx;
  std::vector<Crossing> crossings, no_crossings;
  std::vector<BinEvent> path_bins;  // this path's deposits before merging
  // Meters: next-event connections from every emission and diffuse reflection to every meter point
  // (their bins follow the angular ones). For each meter point x, `from_of(x)` is where the event
  // sends light to it from and `radiance(u, d)` the power per unit solid angle it sends along unit
  // direction u to a point at distance d (W/sr of the ray's estimate): its irradiance at x, if
  // visible, is radiance cos_meter / d^2, times the media's transmittance between.
  const std::vector<PointMeter>& meters = scene_.meters();
  const std::uint32_t meter_base = scene_.binCount() + scene_.angleBinCount();
  CrossingQuery shadow_query = query;
  shadow_query.crossing_mask = 0;
  // Whether the segment from `from` along unit u to the meter point at distance d is free of
  // blocking surfaces, and the media's transmittance along it. It stops short of the point by more
  // than float's rounding of t, so that a meter lying on a surface is not hidden by that surface.
  const auto unblocked = [&](const glm::dvec3& from, const glm::dvec3& u, double d, double& transmittance) {
    Ray shadow;
    shadow.origin = glm::vec3(from);
    shadow.dir = glm::vec3(u);
    shadow.tfar = static_cast<float>(d * (1.0 - 1e-5));
    const SegmentEnd end = top.intersectWithCrossings(shadow, no_crossings, ctx, shadow_query);
    transmittance = end.transmittance;
    return !end.hit.valid();
  };
  // The pixel of camera `mt` (its bins from `first`) that the connection from `from_of(eye)` falls
  // in, if any: its radiance over the pixel's solid angle.
  const auto connectCamera = [&](const PointMeter& mt, std::uint32_t first, auto&& from_of, auto&& radiance) {
    const glm::dvec3 eye = mt.points[0];
    const glm::dvec3 from = from_of(eye);
    const glm::dvec3 to = eye - from;
    const double d = glm::length(to);
    if (!(d > 0.0)) return;
    const glm::dvec3 u = to / d, v = -u;  // v: from the eye towards the source
    const double z = glm::dot(v, mt.image_forward);
    if (!(z > 0.0)) return;
    const double sx = glm::dot(v, mt.image_right) / z, sy = glm::dot(v, mt.image_up) / z;
    if (!(std::abs(sx) < mt.image_tan_x && std::abs(sy) < mt.image_tan_y)) return;
    const auto px =
        std::min(mt.image_width - 1, static_cast<std::uint32_t>((sx / mt.image_tan_x + 1.0) * 0.5 * mt.image_width));
    const auto py =
        std::min(mt.image_height - 1, static_cast<std::uint32_t>((1.0 - sy / mt.image_tan_y) * 0.5 * mt.image_height));
    const double value = radiance(u, d);
    if (!(value > 0.0)) return;
    double transmittance = 0.0;
    if (!unblocked(from, u, d, transmittance)) return;
    const std::uint32_t pixel = py * mt.image_width + px;
    path_bins.push_back({first + pixel, kInvalidId, value / (d * d) / mt.pixel_solid_angle[pixel] * transmittance});
  };
  const auto connect = [&](auto&& from_of, auto&& radiance) {
    std::uint32_t bin = meter_base;
    for (const PointMeter& mt : meters) {
      if (mt.image_width != 0) {  // a pinhole camera: one connection to the eye, into one pixel
        connectCamera(mt, bin, from_of, radiance);
        bin += static_cast<std::uint32_t>(mt.points.size());
        continue;
      }
      // A luminance meter counts the connections arriving within its cone, without the cosine,
      // over the cone's solid angle.
      const bool cone = mt.half_angle > 0.0;
      const double cos_cone = std::cos(mt.half_angle),
                   per_sr = cone ? 1.0 / (2.0 * std::numbers::pi * (1.0 - cos_cone)) : 0.0;
      for (std::size_t i = 0; i < mt.points.size(); ++i, ++bin) {
        const glm::dvec3 from = from_of(mt.points[i]);
        const glm::dvec3 to = mt.points[i] - from;
        const double d = glm::length(to);
        if (!(d > 0.0)) continue;
        const glm::dvec3 u = to / d;
        const double cos_m = -glm::dot(u, mt.normals[i]);
        if (cos_m <= 0.0 || (cone && cos_m < cos_cone)) continue;
        const double value = radiance(u, d);
        if (!(value > 0.0)) continue;
        double transmittance = 0.0;
        if (!unblocked(from, u, d, transmittance)) continue;
        path_bins.push_back({bin, kInvalidId, value * (cone ? per_sr : cos_m) / (d * d) * transmittance});
      }
    }
  };
  chunk.bins.clear();
  chunk.bin_end.clear();
  chunk.sensors.clear();
  chunk.sensor_end.clear();
  chunk.band.assign(bands > 1 ? chunk.count : 0, 0);
  chunk.light.assign(config_.per_light ? chunk.count : 0, 0);
  chunk.energy.assign(chunk.count, EnergyBalance{});
  chunk.counters = {};

  for (std::uint64_t k = 0; k < chunk.count; ++k) {
    if (cancel_.load(std::memory_order_relaxed)) return;  // chunk stays not done
    CounterRng rng(config_.seed, chunk.first + k);
    EnergyBalance& e = chunk.energy[k];
    // Light by power, then a ray of it.
    const double pick = rng.uniform() * power;
    const std::size_t li = std::min<std::size_t>(
        lights.size() - 1,
        static_cast<std::size_t>(std::upper_bound(light_cdf_.begin(), light_cdf_.end(), pick) - light_cdf_.begin()));
    // The band by the light's spectrum, from where `pick` fell inside the light's share: the path's
    // other random numbers stay those of a single-band run (equal reflectances: equal paths).
    std::uint32_t band = 0;
    if (bands > 1) {
      const double lo = li ? light_cdf_[li - 1] : 0.0;
      const double ub = std::clamp((pick - lo) / lights[li].power_w, 0.0, 1.0);
      const std::vector<double>& cdf = scene_.bandCdf(li);
      band =
          std::min(bands - 1, static_cast<std::uint32_t>(std::upper_bound(cdf.begin(), cdf.end(), ub) - cdf.begin()));
      // ub rounded up to 1 lands past the end: never in a band of zero share.
      while (band > 0 && cdf[band] == cdf[band - 1]) --band;
      chunk.band[k] = static_cast<std::uint16_t>(band);
    }
    double u[4] = {rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform()};
    if (config_.per_light) chunk.light[k] = static_cast<std::uint32_t>(li);
    const EmittedRay emitted = sampleLight(lights[li], u);
    glm::dvec3 origin = emitted.origin, dir = emitted.dir;
    double w = power * emitted.weight;
    detail::Polarisation pol;  // the lights emit unpolarised light
    path_bins.clear();
    if (!meters.empty()) connectLight(lights[li], emitted, power / lights[li].power_w, connect);

    std::uint32_t depth = 0, scatterings = 0;
    for (;;) {
      Ray ray;
      ray.origin = glm::vec3(origin);
      ray.dir = glm::vec3(dir);
      ++chunk.counters.segments;
      SegmentEnd end;
      if (config_.closest_hit_only) end.hit = top.intersect(ray, ctx, config_.query.surface_mask);
      else end = top.intersectWithCrossings(ray, crossings, ctx, query);
      // A collision in a scattering fog before the blocking hit ends the segment there.
      const MediumInstance* collided = nullptr;
      double t_collision = std::numeric_limits<double>::infinity();
      if (scatter) {
        collided = sampleCollision(origin, dir, end.hit.valid() ? end.hit.t : std::numeric_limits<float>::infinity(),
                                   rng, ctx, t_collision);
      }
      if (!config_.closest_hit_only) {
        for (const Crossing& c : crossings) {
          if (c.hit.t > t_collision) break;  // sorted by t
          if (c.hit.instance_id >= deposit_targets_.size()) continue;
          const DepositTarget target = deposit_targets_[c.hit.instance_id];
          const int s = target.sensor;
          if (s < 0) continue;
          const double value = w * c.transmittance;
          path_bins.push_back({target.first_bin + c.hit.prim_id, static_cast<std::uint32_t>(s), value});
          if (target.angular) {  // the incoming direction, in the sensor's world frame
            const SensorInstance& si = sensors[static_cast<std::size_t>(s)];
            const glm::dvec3 in = -dir;
            const std::uint32_t ab = si.object->angleBinAt(
                glm::dot(in, si.normal), std::atan2(glm::dot(in, si.frame_y), glm::dot(in, si.frame_x)));
            path_bins.push_back({angle_base + si.first_angle_bin + ab, kInvalidId, value});
          }
          ++chunk.counters.crossings;
        }
      }
      if (collided) {
        ++chunk.counters.scatterings;
        if (scatterings == config_.max_scatterings) {
          e.depth_limited_w += w;
          ++e.depth_limited_rays;
          break;
        }
        ++scatterings;
        // A fog without a medium material absorbs at every collision.
        const Medium* medium = collided->material.as<Medium>();
        const double albedo = medium ? medium->albedo.in(band) : 0.0;
        if (!(rng.uniform() < albedo)) {
          e.medium_absorbed_w += w;
          ++e.medium_absorbed_rays;
          break;
        }
        const glm::dvec3 d = glm::normalize(dir);
        origin = origin + t_collision * dir;
        // Random numbers are drawn in statements of their own: a call's arguments are evaluated in
        // an order each compiler picks, and a run must give the same paths whichever built it.
        const double u1 = rng.uniform(), u2 = rng.uniform();
        dir = phaseDirection(d, HenyeyGreenstein{medium->g}, u1, u2);
        pol = {};  // the scalar phase function: scattered light is taken as unpolarised
        if (!isFinite(dir)) {
          e.failed_w += w;
          ++e.failed_rays;
          break;
        }
        continue;
      }
      const double w_after = w * end.transmittance;
      e.medium_absorbed_w += w - w_after;
      w = w_after;
      if (!end.hit.valid()) {
        e.escaped_w += w;
        ++e.escaped_rays;
        for (const std::uint32_t s : far_field) {  // the direction in the sensor's frame
          const SensorInstance& si = sensors[s];
          const std::uint32_t b = si.object->farFieldBinAt(
              {glm::dot(dir, si.frame_x), glm::dot(dir, si.frame_y), glm::dot(dir, si.normal)});
          if (b != kInvalidId) path_bins.push_back({si.first_bin + b, s, w});
        }
        break;
      }
      if (depth == config_.max_depth) {
        e.depth_limited_w += w;
        ++e.depth_limited_rays;
        break;
      }
      ++depth;
      // The material's step, dispatched once per surface event: the path ends (absorbed) or goes on.
      const Material& m = scene_.materialOf(end.hit.instance_id);
      const glm::dvec3 p = origin + static_cast<double>(end.hit.t) * dir;
      glm::dvec3 n = glm::normalize(glm::dvec3(end.hit.ng));
      const glm::dvec3 d = glm::normalize(dir);
      const bool front = glm::dot(d, n) < 0.0;
      const glm::dvec3 nf = front ? n : -n;  // faces the incoming ray
      detail::SurfaceEvent event{d, n, nf, front, band, static_cast<double>(end.hit.t), w, pol, rng, e};
      const SurfaceStep step = std::visit([&event](const auto& material) { return material.step(event); }, m.model);
      if (step.absorbed) {
        e.absorbed_w += w;
        ++e.absorbed_rays;
        break;
      }
      const glm::dvec3 next = step.next;
      const bool transmits = step.transmits;  // whether `next` must cross to the far side of the surface
      if (step.diffuse && !meters.empty()) {  // the reflected power w leaves with radiant intensity w cos / pi
        const SurfaceInstance* si = scene_.surfaceOf(end.hit.instance_id);
        const glm::dvec3 from =
            si ? detail::restartFromTriangle(si->mesh->mesh().vertices(end.hit.prim_id), end.hit.u, end.hit.v, *si, n)
                     .p_ws
               : p;
        const double offset = 1e-5 * std::max({1.0, std::abs(from.x), std::abs(from.y), std::abs(from.z)});
        const glm::dvec3 start = from + nf * offset;
        connect([&](const glm::dvec3&) { return start; },
                [&](const glm::dvec3& v, double) { return w * std::max(0.0, glm::dot(v, nf)) / std::numbers::pi; });
      }
      // A direction that does not leave the surface to the side the material sends it (tangent,
      // on the wrong side, not finite) would be traced from the wrong side of the offset: the
      // path is a numerical failure, counted as such rather than hidden in another term.
      if (!detail::leavesSurface(next, nf, transmits) || !std::isfinite(w)) {
        e.failed_w += w;
        ++e.failed_rays;
        break;
      }
      // Deep paths: roulette at every interaction, so that paths that lose nothing end too.
      if (depth > config_.roulette_depth) {
        if (rng.uniform() >= kDeepSurvival) {
          e.roulette_w += w;
          ++e.roulette_rays;
          break;
        }
        e.roulette_w -= w * (1.0 / kDeepSurvival - 1.0);
        w /= kDeepSurvival;
      }
      // Russian roulette on power lost to media (materials keep a surviving path's power).
      if (w < rr_level) {
        if (rng.uniform() * rr_level >= w) {
          e.roulette_w += w;
          ++e.roulette_rays;
          break;
        }
        e.roulette_w -= rr_level - w;
        w = rr_level;
      }
      // Leave the surface on the side the new direction points to, by no more than the hit's
      // rounding error: on a mesh, the point rebuilt from its triangle and the error bound of the
      // next ray across that triangle's plane (restartFromTriangle). Other types report a float t
      // only: the offset then follows the magnitudes of the point and of the instance's box.
      const glm::dvec3 side = glm::dot(next, n) >= 0.0 ? n : -n;
      if (const SurfaceInstance* si = scene_.surfaceOf(end.hit.instance_id)) {
        const detail::RestartPoint rp =
            detail::restartFromTriangle(si->mesh->mesh().vertices(end.hit.prim_id), end.hit.u, end.hit.v, *si, n);
        origin = rp.p_ws + side * rp.offset;
      } else {
        const Box box = top.instanceBounds(end.hit.instance_id);
        const double scale =
            std::max({1.0, std::abs(p.x), std::abs(p.y), std::abs(p.z), std::abs(double(box.lo.x)),
                      std::abs(double(box.lo.y)), std::abs(double(box.lo.z)), std::abs(double(box.hi.x)),
                      std::abs(double(box.hi.y)), std::abs(double(box.hi.z))});
        origin = p + side * (1e-5 * scale);
      }
      dir = glm::normalize(next);
    }

    // Merge this path's deposits per bin (in path order within a bin) and per sensor.
    sortByBin(path_bins);
    const std::size_t sensor_first = chunk.sensors.size();
    for (std::size_t i = 0; i < path_bins.size();) {
      BinEvent merged = path_bins[i];
      for (++i; i < path_bins.size() && path_bins[i].bin == merged.bin; ++i) merged.value += path_bins[i].value;
      chunk.bins.push_back(merged);
    }
    // Sensor totals: bins are sorted, and a sensor's spatial bins are contiguous, so its sum follows.
    for (std::size_t i = chunk.bin_end.empty() ? 0 : chunk.bin_end.back(); i < chunk.bins.size(); ++i) {
      const BinEvent& b = chunk.bins[i];
      if (b.bin >= angle_base) break;  // angular bins (sorted after the spatial ones) repeat the same power
      const std::uint32_t s = b.sensor;
      if (chunk.sensors.size() > sensor_first && chunk.sensors.back().sensor == s)
        chunk.sensors.back().value += b.value;
      else chunk.sensors.push_back({s, b.value});
    }
    chunk.bin_end.push_back(static_cast<std::uint32_t>(chunk.bins.size()));
    chunk.sensor_end.push_back(static_cast<std::uint32_t>(chunk.sensors.size()));
  }
  chunk.done = true;
}

const MediumInstance* SensorRun::sampleCollision(const glm::dvec3& origin, const glm::dvec3& dir, float t_max,
                                                 CounterRng& rng, QueryContext& ctx, double& t_collision) const {
  // The first collision among independent free flights is a free flight through the summed
  // density; each later medium only needs to be sampled up to the best collision so far.
  const MediumInstance* found = nullptr;
  float t_best = t_max;
  for (const MediumInstance& m : scene_.scatteringMedia()) {
    const std::uint64_t seed = rng.next();  // drawn for every medium: the stream does not depend on the geometry
    if ((m.mask & config_.query.medium_mask) == 0) continue;
    if (!segmentMeetsBox(origin, dir, t_best, m.world_lo, m.world_hi)) continue;
    Ray ray_os;  // object space, direction not renormalised: t is the world t
    ray_os.origin = glm::vec3(m.object_from_world.point(origin));
    ray_os.dir = glm::vec3(m.object_from_world.vector(dir));
    ray_os.tnear = 0.0f;
    ray_os.tfar = t_best;
    if (const std::optional<float> t = m.volume->sampleFreeFlight(ray_os, ctx, seed); t && *t < t_best) {
      t_best = *t;
      found = &m;
    }
  }
  t_collision = found ? static_cast<double>(t_best) : std::numeric_limits<double>::infinity();
  return found;
}

}  // namespace duplex
