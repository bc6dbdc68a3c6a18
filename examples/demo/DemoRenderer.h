#pragma once
/// \file DemoRenderer.h
/// A small shading pass over the two-level structure: primary rays from the contract camera
/// (duplex::primaryRays), Lambert shading on the world-space geometric normal, one shadow ray per
/// lit hit (TopLevel::occluded).

#include "PngWriter.h"

#include <duplex/accel/TopLevel.h>
#include <duplex/scenegraph/Scene.h>

#include <glm/vec3.hpp>

#include <cstddef>
#include <cstdint>

namespace duplex::demo {

struct RenderSettings {
  std::uint32_t width = 960;
  std::uint32_t height = 540;
  /// Direction towards the (distant) light, world space; need not be unit length.
  glm::vec3 to_light{-0.45f, 1.0f, 0.35f};
};

/// Figures of one render. Times are wall-clock milliseconds.
struct RenderStats {
  std::size_t primary_rays = 0;
  std::size_t primary_hits = 0;
  double primary_ms = 0.0;
  std::size_t shadow_rays = 0;
  std::size_t shadowed = 0;
  double shadow_ms = 0.0;
};

/// Renders `scene` (already built into `top`) with the camera of `duplex rays --primary`. Runs on
/// the calling TBB arena; one QueryContext per task.
[[nodiscard]] RgbImage render(const Scene& scene, const TopLevel& top, const RenderSettings& settings,
                              RenderStats& stats);

}  // namespace duplex::demo
