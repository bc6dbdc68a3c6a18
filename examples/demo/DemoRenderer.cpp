#include "DemoRenderer.h"

#include <duplex/accel/QueryContext.h>
#include <duplex/accel/RayGenerator.h>

#include <glm/common.hpp>
#include <glm/exponential.hpp>
#include <glm/geometric.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <limits>
#include <vector>

namespace duplex::demo {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

constexpr std::size_t kRaysPerTask = 1024;

// Calls body(i, ctx) for every i in [0, n) on the current arena, one QueryContext per task.
template <class Body>
void forEachRay(std::size_t n, Body&& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kRaysPerTask), [&](const tbb::blocked_range<std::size_t>& r) {
    QueryContext ctx;
    for (std::size_t i = r.begin(); i != r.end(); ++i) body(i, ctx);
  });
}

// Base colour: by library object, varied slightly per instance so that copies stay apart.
glm::vec3 albedo(const Scene& scene, std::uint32_t instance_id) {
  static constexpr std::array<glm::vec3, 6> kPalette = {
      glm::vec3(0.78f, 0.76f, 0.72f), glm::vec3(0.85f, 0.33f, 0.24f), glm::vec3(0.25f, 0.52f, 0.85f),
      glm::vec3(0.95f, 0.74f, 0.22f), glm::vec3(0.33f, 0.72f, 0.42f), glm::vec3(0.68f, 0.42f, 0.80f)};
  const std::uint32_t object = scene.instances()[instance_id].object;
  const std::uint32_t hash = instance_id * 2654435761u;
  const float tint = 0.82f + 0.18f * static_cast<float>(hash >> 24) / 255.0f;
  return kPalette[object % kPalette.size()] * tint;
}

glm::vec3 sky(const glm::vec3& dir) {
  const float a = glm::clamp(glm::normalize(dir).y, 0.0f, 1.0f);
  return glm::mix(glm::vec3(0.92f, 0.94f, 1.0f), glm::vec3(0.42f, 0.58f, 0.88f), a);
}

std::uint8_t toSrgb8(float linear) {
  const float encoded = std::pow(glm::clamp(linear, 0.0f, 1.0f), 1.0f / 2.2f);
  return static_cast<std::uint8_t>(encoded * 255.0f + 0.5f);
}

}  // namespace

RgbImage render(const Scene& scene, const TopLevel& top, const RenderSettings& settings, RenderStats& stats) {
  const Box bounds = scene.worldBounds();
  const std::vector<Ray> rays = primaryRays(bounds, settings.width, settings.height);
  const std::size_t n = rays.size();
  const glm::vec3 to_light = glm::normalize(settings.to_light);
  // Shadow rays start this far off the surface (world units), so they do not hit their own triangle.
  const float offset = 1e-4f * glm::length(bounds.extent());

  // Primary rays: closest hits.
  std::vector<Hit> hits(n);
  auto t0 = Clock::now();
  forEachRay(n, [&](std::size_t i, QueryContext& ctx) { hits[i] = top.intersect(rays[i], ctx); });
  stats.primary_ms = msSince(t0);
  stats.primary_rays = n;

  // Facing normals and the shadow rays of the surfaces that face the light.
  std::vector<glm::vec3> normals(n, glm::vec3(0.0f));
  std::vector<Ray> shadow_rays(n);
  std::vector<std::uint8_t> needs_shadow(n, 0);
  forEachRay(n, [&](std::size_t i, QueryContext&) {
    const Hit& h = hits[i];
    if (!h.valid()) return;
    glm::vec3 nrm = glm::normalize(h.ng);
    if (glm::dot(nrm, rays[i].dir) > 0.0f) nrm = -nrm;  // two-sided: face the viewer
    normals[i] = nrm;
    if (glm::dot(nrm, to_light) <= 0.0f) return;
    const glm::vec3 p = rays[i].origin + h.t * rays[i].dir;
    shadow_rays[i] = Ray{p + offset * nrm, 0.0f, to_light, std::numeric_limits<float>::infinity()};
    needs_shadow[i] = 1;
  });

  // Shadow rays: occlusion only.
  std::vector<std::uint8_t> in_shadow(n, 0);
  t0 = Clock::now();
  forEachRay(n, [&](std::size_t i, QueryContext& ctx) {
    if (needs_shadow[i]) in_shadow[i] = top.occluded(shadow_rays[i], ctx) ? 1 : 0;
  });
  stats.shadow_ms = msSince(t0);

  // Shade: sky for misses, ambient plus Lambert (n.l on the facing normal) where the light arrives.
  RgbImage image{settings.width, settings.height, std::vector<std::uint8_t>(n * 3)};
  forEachRay(n, [&](std::size_t i, QueryContext&) {
    glm::vec3 colour;
    if (!hits[i].valid()) {
      colour = sky(rays[i].dir);
    } else {
      const glm::vec3& nrm = normals[i];
      const float ambient = 0.10f + 0.12f * (0.5f + 0.5f * nrm.y);
      const float direct = (needs_shadow[i] && !in_shadow[i]) ? glm::dot(nrm, to_light) : 0.0f;
      colour = albedo(scene, hits[i].instance_id) * (ambient + 0.85f * direct);
    }
    for (int c = 0; c < 3; ++c) image.pixels[i * 3 + c] = toSrgb8(colour[c]);
  });

  stats.primary_hits = static_cast<std::size_t>(std::count_if(hits.begin(), hits.end(), [](const Hit& h) { return h.valid(); }));
  stats.shadow_rays = static_cast<std::size_t>(std::count(needs_shadow.begin(), needs_shadow.end(), 1));
  stats.shadowed = static_cast<std::size_t>(std::count(in_shadow.begin(), in_shadow.end(), 1));
  return image;
}

}  // namespace duplex::demo
