#pragma once
/// \file RayGenerator.h
/// The ray sets of `duplex rays` (primary camera rays and random rays), shared by the tool, the
/// tests and the benchmarks so that all of them trace the same rays.

#include "duplex/accel/Box.h"
#include "duplex/accel/Ray.h"

#include <cstdint>
#include <random>
#include <span>
#include <vector>

namespace duplex {

/// Pinhole camera in world space.
struct PinholeCamera {
  glm::dvec3 eye{0.0};                 ///< centre of projection, world space
  glm::dvec3 forward{0.0, 0.0, -1.0};  ///< unit
  glm::dvec3 right{1.0, 0.0, 0.0};     ///< unit
  glm::dvec3 up{0.0, 1.0, 0.0};        ///< unit
  double vertical_fov_deg = 45.0;      ///< full vertical field of view, degrees

  /// The camera of `duplex rays --primary`: at 1.0 x the bbox diagonal from the bbox centre along
  /// normalize(1, 0.6, 0.8), looking at the centre, up = +y, 45 degrees vertical field of view.
  /// Throws InvalidArgument for empty or non-finite bounds.
  static PinholeCamera looking_at_box(const Box& world_bounds);
  /// Unit direction through the centre of pixel (px, py) of a width x height image, pixel (0, 0)
  /// at the top left, square pixels. Preconditions (not checked here: the hot loop of primary rays):
  /// width and height > 0, unit and orthogonal forward/right/up, 0 < vertical_fov_deg < 180;
  /// SceneTracer::pick checks them.
  [[nodiscard]] glm::vec3 direction(std::uint32_t px, std::uint32_t py, std::uint32_t width,
                                    std::uint32_t height) const;
  /// Unit direction (double) through continuous image coordinates (x, y): (0, 0) is the top-left
  /// corner of the image, (width, height) the bottom-right; pixel (i, j) has its centre at
  /// (i + 0.5, j + 0.5). For picking and rectangle selection.
  [[nodiscard]] glm::dvec3 directionAt(double x, double y, std::uint32_t width, std::uint32_t height) const;
};

/// width * height primary rays, row-major from the top-left pixel; unit directions, t in [0, inf).
/// Throws InvalidArgument for empty or non-finite bounds.
[[nodiscard]] std::vector<Ray> primaryRays(const Box& world_bounds, std::uint32_t width, std::uint32_t height);
/// Rays [first, first + out.size()) of primaryRays(world_bounds, width, height), written to `out`:
/// the same rays, a block at a time. Throws InvalidArgument for empty or non-finite bounds and
/// for a range past width * height.
void primaryRays(const Box& world_bounds, std::uint32_t width, std::uint32_t height, std::size_t first,
                 std::span<Ray> out);
/// `count` rays with origins uniform in `world_bounds` and directions uniform on the unit sphere,
/// t in [0, inf). Deterministic for a seed (std::mt19937_64, independent of the thread count).
/// Throws InvalidArgument for empty or non-finite bounds.
[[nodiscard]] std::vector<Ray> randomRays(const Box& world_bounds, std::size_t count, std::uint64_t seed);

/// The rays of randomRays(world_bounds, count, seed) a block at a time: the first n calls of
/// next() give, in order, exactly the rays randomRays gives, whatever the block sizes.
class RandomRayStream {
 public:
  /// Throws InvalidArgument for empty or non-finite bounds.
  RandomRayStream(const Box& world_bounds, std::uint64_t seed);
  /// Fills `out` with the next out.size() rays.
  void next(std::span<Ray> out);

 private:
  Box bounds_;
  std::mt19937_64 rng_;
};

}  // namespace duplex
