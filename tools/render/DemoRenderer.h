#pragma once
/// \file DemoRenderer.h
/// A small shading pass through a SceneTracer and its batch queries: primary rays from a fixed
/// camera (SceneTracer::intersect over all pixels), Lambert shading on the world-space geometric
/// normal, one shadow ray per lit hit (SceneTracer::occluded over the lit pixels). The base colour
/// comes from the hit instance's library object, tinted slightly per instance.

#include "PngWriter.h"

#include <duplex/accel/Hit.h>
#include <duplex/accel/Ray.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/scenegraph/NodeId.h>
#include <duplex/scenegraph/SceneTracer.h>

#include <glm/vec3.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace duplex::demo {

struct RenderSettings {
  std::uint32_t width = 640;
  std::uint32_t height = 400;
  /// Direction towards the (distant) light, world space; need not be unit length.
  glm::vec3 to_light{-0.35f, 1.0f, 0.45f};
  /// An instance node drawn tinted (a selection or the part under the cursor); kInvalidNode: none.
  NodeId highlight = kInvalidNode;
  /// Feature edges drawn as dark lines, found on the image's hits (the nearer pixel of two
  /// neighbours whose hits lie on different instances, on faces whose normals differ by more than
  /// edge_angle_deg, or on surfaces apart in depth), silhouettes against the sky included.
  bool edges = false;
  double edge_angle_deg = 30.0;  ///< degrees, as SceneTracer's pick feature angle
};

/// Figures of one frame. Times are wall-clock milliseconds of the batch queries alone.
struct FrameStats {
  std::size_t primary_rays = 0;
  std::size_t primary_hits = 0;
  double primary_ms = 0.0;
  std::size_t shadow_rays = 0;
  std::size_t shadowed = 0;
  double shadow_ms = 0.0;

  [[nodiscard]] std::size_t rays() const { return primary_rays + shadow_rays; }
  [[nodiscard]] double traceMs() const { return primary_ms + shadow_ms; }
};

/// Renders frames of the scene a tracer sees. The camera and the primary rays are set at
/// construction (or by setView); buffers are reused from frame to frame. Call render() between
/// commits of the graph (it reads the graph for colours), from one thread; the queries run in
/// parallel on the calling TBB arena.
class DemoRenderer {
 public:
  DemoRenderer(const SceneTracer& tracer, const PinholeCamera& camera, const RenderSettings& settings);
  /// No rays until setView().
  DemoRenderer(const SceneTracer& tracer, const RenderSettings& settings);

  /// Aims the renderer at rows [row_begin, row_end) of a width x height image seen by `camera`
  /// (world space; pixel rays as `duplex rays --primary` makes them: origin the eye, direction
  /// PinholeCamera::direction). render() then returns those rows only (a strip of a large image).
  /// The caller has checked the camera (SceneTracer::pick's rules) and the sizes.
  void setView(const PinholeCamera& camera, std::uint32_t width, std::uint32_t height, std::uint32_t row_begin,
               std::uint32_t row_end);
  /// The tinted instance of the next frames (kInvalidNode: none).
  void setHighlight(NodeId instance) { settings_.highlight = instance; }
  /// Whether the next frames draw feature edges (RenderSettings::edges).
  void setEdges(bool edges) { settings_.edges = edges; }

  /// Traces and shades the scene as of the graph's last commit.
  [[nodiscard]] RgbImage render(FrameStats& stats);

  /// The primary hit of pixel (x, y - row_begin) of the last render (row-major index into the
  /// strip): instance_id is the node id, invalid for a miss.
  [[nodiscard]] const Hit& hitOfPixel(std::size_t pixel) const { return hits_[ray_of_pixel_[pixel]]; }

 private:
  const SceneTracer& tracer_;
  RenderSettings settings_;
  std::vector<Ray> primary_;               ///< one per pixel, in tiles of 4 x 4 pixels
  std::vector<std::size_t> pixel_of_;      ///< the pixel (row-major from the top left) of primary_[i]
  std::vector<std::size_t> ray_of_pixel_;  ///< inverse of pixel_of_
  std::vector<Hit> hits_;
  std::vector<Ray> shadow_;  ///< towards the light, for the lit pixels listed in shadow_pixel_
  std::vector<std::size_t> shadow_pixel_;
  std::vector<std::uint8_t> blocked_;
  std::vector<glm::vec3> normal_;          ///< per primary ray: the hit's unit normal facing the viewer
  std::vector<float> direct_;              ///< light arriving per primary ray (n.l where the shadow ray is free)
  std::vector<glm::vec3> colour_of_node_;  ///< base colour per node id (instances of the last commit)
  /// Width of a pixel at unit distance along the view direction (the edges' depth test).
  float pixel_size_ = 0.0f;
  // The view the rays were made for (setView skips remaking them for the same one).
  bool view_valid_ = false;
  PinholeCamera view_camera_;
  std::uint32_t view_height_ = 0, view_row_begin_ = 0;
};

}  // namespace duplex::demo
