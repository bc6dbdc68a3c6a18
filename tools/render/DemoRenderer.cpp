#include "DemoRenderer.h"

#include <glm/common.hpp>
#include <glm/exponential.hpp>
#include <glm/geometric.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>

namespace duplex::demo {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Base colour by library object (file order), varied slightly per instance so that copies stay apart.
glm::vec3 baseColour(ObjectId object, NodeId instance) {
  static constexpr std::array<glm::vec3, 12> kPalette = {
      glm::vec3(0.55f, 0.55f, 0.52f), glm::vec3(0.80f, 0.12f, 0.10f), glm::vec3(0.50f, 0.66f, 0.82f),
      glm::vec3(0.95f, 0.62f, 0.12f), glm::vec3(0.08f, 0.08f, 0.09f), glm::vec3(0.05f, 0.05f, 0.05f),
      glm::vec3(0.62f, 0.48f, 0.32f), glm::vec3(1.00f, 0.95f, 0.75f), glm::vec3(0.95f, 0.85f, 0.15f),
      glm::vec3(0.15f, 0.35f, 0.95f), glm::vec3(0.98f, 0.40f, 0.05f), glm::vec3(0.90f, 0.70f, 0.58f)};
  const std::uint32_t hash = instance * 2654435761u;
  const float tint = 0.88f + 0.12f * static_cast<float>(hash >> 24) / 255.0f;
  return kPalette[object % kPalette.size()] * tint;
}

glm::vec3 sky(const glm::vec3& dir) {
  const float a = glm::clamp(glm::normalize(dir).y, 0.0f, 1.0f);
  return glm::mix(glm::vec3(0.92f, 0.94f, 1.0f), glm::vec3(0.42f, 0.58f, 0.88f), a);
}

std::uint8_t toSrgb8Exact(float linear) {
  const float encoded = std::pow(glm::clamp(linear, 0.0f, 1.0f), 1.0f / 2.2f);
  return static_cast<std::uint8_t>(encoded * 255.0f + 0.5f);
}

// toSrgb8Exact without a pow per channel (the frame's costliest shading step), to the same byte:
// a table over 4096 buckets of [0, 1] gives the code at a bucket's start, and the exact thresholds
// between codes (found by bisection on toSrgb8Exact, which is monotonic) step it up within the bucket.
class SrgbEncoder {
 public:
  SrgbEncoder() {
    first_[0] = 0.0f;
    for (int k = 1; k < 256; ++k) {
      float lo = 0.0f, hi = 1.0f;  // toSrgb8Exact(lo) < k <= toSrgb8Exact(hi)
      while (std::nextafter(lo, 1.0f) < hi) {
        const float mid = 0.5f * (lo + hi);
        if (mid <= lo || mid >= hi) break;
        (toSrgb8Exact(mid) >= k ? hi : lo) = mid;
      }
      first_[k] = toSrgb8Exact(lo) >= k ? lo : hi;
    }
    for (int b = 0; b < kBuckets; ++b) bucket_[b] = toSrgb8Exact(static_cast<float>(b) / kBuckets);
  }
  [[nodiscard]] std::uint8_t operator()(float linear) const {
    if (!(linear > 0.0f)) return toSrgb8Exact(linear);  // 0, negatives and NaN as the exact form
    if (linear >= 1.0f) return 255;
    int code = bucket_[std::min(kBuckets - 1, static_cast<int>(linear * kBuckets))];
    while (code < 255 && linear >= first_[code + 1]) ++code;
    return static_cast<std::uint8_t>(code);
  }

 private:
  static constexpr int kBuckets = 4096;
  std::array<float, 256> first_{};  ///< the smallest linear value encoded as each code
  std::array<std::uint8_t, kBuckets> bucket_{};
};

std::uint8_t toSrgb8(float linear) {
  static const SrgbEncoder encoder;
  return encoder(linear);
}

// The normal of a hit, unit length and facing the viewer (surfaces are two-sided).
glm::vec3 facingNormal(const Hit& h, const Ray& r) {
  const glm::vec3 n = glm::normalize(h.ng);
  return glm::dot(n, r.dir) > 0.0f ? -n : n;
}

}  // namespace

DemoRenderer::DemoRenderer(const SceneTracer& tracer, const PinholeCamera& camera, const RenderSettings& settings)
    : tracer_(tracer), settings_(settings) {
  setView(camera, settings.width, settings.height, 0, settings.height);
}

DemoRenderer::DemoRenderer(const SceneTracer& tracer, const RenderSettings& settings)
    : tracer_(tracer), settings_(settings) {}

void DemoRenderer::setView(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height,
                           std::uint32_t row_begin, std::uint32_t row_end) {
  // The same view as the last frame (a drag moves the scene, not the camera): its rays are there.
  const auto same = [](const PinholeCamera& a, const PinholeCamera& b) {
    return a.eye == b.eye && a.forward == b.forward && a.right == b.right && a.up == b.up &&
           a.vertical_fov_deg == b.vertical_fov_deg;
  };
  if (view_valid_ && same(camera, view_camera_) && width == settings_.width && height == view_height_ &&
      row_begin == view_row_begin_ && row_end - row_begin == settings_.height)
    return;
  view_valid_ = true;
  view_camera_ = camera;
  view_height_ = height;
  view_row_begin_ = row_begin;
  settings_.width = width;
  settings_.height = row_end - row_begin;
  pixel_size_ = static_cast<float>(2.0 * std::tan(0.5 * camera.vertical_fov_deg * std::numbers::pi / 180.0) / height);
  const std::size_t n = static_cast<std::size_t>(width) * (row_end - row_begin);
  primary_.resize(n);
  pixel_of_.resize(n);
  ray_of_pixel_.resize(n);
  const glm::vec3 eye(camera.eye);
  // In tiles of 4 x 4 pixels: the batch queries trace 16 consecutive rays as one packet, and
  // neighbouring pixels' rays (and their shadow rays, made in the same order) are coherent. A band
  // of tiles (4 rows) starts at ray (its first row - row_begin) x width: bands are made in parallel.
  constexpr std::uint32_t kTile = 4;
  const std::uint32_t bands = (row_end - row_begin + kTile - 1) / kTile;
  tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, bands), [&](const tbb::blocked_range<std::uint32_t>& r) {
    for (std::uint32_t band = r.begin(); band != r.end(); ++band) {
      const std::uint32_t ty = row_begin + band * kTile;
      std::size_t ray = static_cast<std::size_t>(ty - row_begin) * width;
      for (std::uint32_t tx = 0; tx < width; tx += kTile)
        for (std::uint32_t y = ty; y < std::min(ty + kTile, row_end); ++y)
          for (std::uint32_t x = tx; x < std::min(tx + kTile, width); ++x, ++ray) {
            const std::size_t pixel = static_cast<std::size_t>(y - row_begin) * width + x;
            ray_of_pixel_[pixel] = ray;
            primary_[ray] =
                Ray{eye, 0.0f, camera.direction(x, y, width, height), std::numeric_limits<float>::infinity()};
            pixel_of_[ray] = pixel;
          }
    }
  });
  hits_.resize(n);
}

RgbImage DemoRenderer::render(FrameStats& stats) {
  const std::size_t n = primary_.size();
  const glm::vec3 to_light = glm::normalize(settings_.to_light);
  // Shadow rays start this far off the surface (world units), so they do not hit their own triangle.
  const Box bounds = tracer_.bounds();
  const float offset = bounds.empty() ? 1e-4f : 1e-5f * glm::length(bounds.extent());

  // Base colours of this commit's instances, looked up per hit by node id.
  const SceneGraph& graph = tracer_.graph();
  colour_of_node_.assign(colour_of_node_.size(), glm::vec3(0.0f));
  for (const NodeId id : graph.visibleInstances()) {
    if (id >= colour_of_node_.size()) colour_of_node_.resize(id + 1, glm::vec3(0.0f));
    colour_of_node_[id] = baseColour(graph.node(id).object, id);
  }

  // Primary rays: closest hits, one batch.
  auto t0 = Clock::now();
  tracer_.intersect(primary_, hits_);
  stats.primary_ms = msSince(t0);
  stats.primary_rays = n;

  // Each hit's unit normal facing the viewer, once (shadow rays, light, edges and shading use it).
  normal_.resize(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i)
      if (hits_[i].valid()) normal_[i] = facingNormal(hits_[i], primary_[i]);
  });

  // Shadow rays of the hits that face the light, compacted into one batch.
  shadow_.clear();
  shadow_pixel_.clear();
  for (std::size_t i = 0; i < n; ++i) {
    const Hit& h = hits_[i];
    if (!h.valid()) continue;
    const glm::vec3& nrm = normal_[i];
    if (glm::dot(nrm, to_light) <= 0.0f) continue;
    const glm::vec3 p = primary_[i].origin + h.t * primary_[i].dir;
    shadow_.push_back(Ray{p + offset * nrm, 0.0f, to_light, std::numeric_limits<float>::infinity()});
    shadow_pixel_.push_back(i);
  }
  blocked_.assign(shadow_.size(), 0);
  t0 = Clock::now();
  tracer_.occluded(shadow_, blocked_);
  stats.shadow_ms = msSince(t0);
  stats.shadow_rays = shadow_.size();
  stats.shadowed = static_cast<std::size_t>(std::count(blocked_.begin(), blocked_.end(), std::uint8_t{1}));

  // Light arriving per pixel: n.l where the shadow ray is free, else 0.
  std::vector<float>& direct = direct_;
  direct.assign(n, 0.0f);
  for (std::size_t k = 0; k < shadow_pixel_.size(); ++k) {
    const std::size_t i = shadow_pixel_[k];
    if (!blocked_[k]) direct[i] = glm::dot(normal_[i], to_light);
  }

  // Edges: a pixel on a different surface than one of its four neighbours, when it is the nearer
  // of the two (so that a line is one pixel wide and lies on the front surface).
  const float cos_edge = static_cast<float>(std::cos(settings_.edge_angle_deg * std::numbers::pi / 180.0));
  const std::uint32_t w = settings_.width, h_rows = settings_.height;
  const auto onEdge = [&](std::size_t i) {
    const Hit& h = hits_[i];
    const std::size_t pixel = pixel_of_[i];
    const auto x = static_cast<std::uint32_t>(pixel % w), y = static_cast<std::uint32_t>(pixel / w);
    const glm::vec3& n = normal_[i];
    const glm::vec3 p = primary_[i].origin + h.t * primary_[i].dir;
    // Two surfaces apart in depth: the neighbour's point lies off this pixel's tangent plane by
    // more than a few pixel widths at this distance.
    const float apart = 3.0f * pixel_size_ * h.t;
    const std::size_t around[4] = {x > 0 ? pixel - 1 : pixel, x + 1 < w ? pixel + 1 : pixel, y > 0 ? pixel - w : pixel,
                                   y + 1 < h_rows ? pixel + w : pixel};
    for (const std::size_t q : around) {
      if (q == pixel) continue;
      const std::size_t j = ray_of_pixel_[q];
      const Hit& o = hits_[j];
      if (!o.valid()) return true;
      if (o.t < h.t) continue;  // the neighbour is nearer: the line goes there
      if (o.instance_id != h.instance_id) return true;
      if (o.prim_id == h.prim_id) continue;
      if (glm::dot(n, normal_[j]) < cos_edge) return true;
      if (std::abs(glm::dot(n, primary_[j].origin + o.t * primary_[j].dir - p)) > apart) return true;
    }
    return false;
  };

  // Shade: sky for misses, ambient (brighter towards +y) plus Lambert.
  RgbImage image{settings_.width, settings_.height, std::vector<std::uint8_t>(n * 3)};
  // Pixels are independent: shaded in parallel (the sRGB encoding is the costly part).
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Hit& h = hits_[i];
      glm::vec3 colour;
      if (!h.valid()) {
        colour = sky(primary_[i].dir);
      } else {
        const glm::vec3& nrm = normal_[i];
        const float ambient = 0.12f + 0.14f * (0.5f + 0.5f * nrm.y);
        const glm::vec3 base =
            h.instance_id < colour_of_node_.size() ? colour_of_node_[h.instance_id] : glm::vec3(1.0f, 0.0f, 1.0f);
        colour = base * (ambient + 0.85f * direct[i]);
        // The highlighted part: pulled towards a bright cyan that no palette colour is close to.
        if (h.instance_id == settings_.highlight) colour = glm::mix(colour, glm::vec3(0.1f, 0.85f, 1.0f), 0.55f);
        if (settings_.edges && onEdge(i)) colour = glm::mix(colour, glm::vec3(0.01f), 0.8f);
      }
      for (int c = 0; c < 3; ++c) image.pixels[pixel_of_[i] * 3 + c] = toSrgb8(colour[c]);
    }
  });
  const auto primary_hits = static_cast<std::size_t>(std::count_if(
      hits_.begin(), hits_.begin() + static_cast<std::ptrdiff_t>(n), [](const Hit& h) { return h.valid(); }));
  stats.primary_hits = primary_hits;
  return image;
}

}  // namespace duplex::demo
