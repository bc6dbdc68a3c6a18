#include "duplex/accel/RayGenerator.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

namespace duplex {

namespace {
void requireBounds(const Box& b, const char* what) {
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(b.lo[k]) || !std::isfinite(b.hi[k]))
      throw InvalidArgument(std::string(what) +
                            ": the world bounds are empty or not finite (a scene without instances?)");
  if (b.empty()) throw InvalidArgument(std::string(what) + ": the world bounds are empty (a scene without instances?)");
}
}  // namespace

PinholeCamera PinholeCamera::looking_at_box(const Box& b) {
  requireBounds(b, "PinholeCamera::looking_at_box");
  PinholeCamera cam;
  const glm::dvec3 lo(b.lo), hi(b.hi);
  const glm::dvec3 centre = 0.5 * (lo + hi);
  const double diagonal = glm::length(hi - lo);
  cam.eye = centre + diagonal * glm::normalize(glm::dvec3(1.0, 0.6, 0.8));
  cam.forward = glm::normalize(centre - cam.eye);
  cam.right = glm::normalize(glm::cross(cam.forward, glm::dvec3(0.0, 1.0, 0.0)));
  cam.up = glm::cross(cam.right, cam.forward);
  return cam;
}

glm::vec3 PinholeCamera::direction(std::uint32_t px, std::uint32_t py, std::uint32_t width,
                                   std::uint32_t height) const {
  return glm::vec3(directionAt(px + 0.5, py + 0.5, width, height));
}

glm::dvec3 PinholeCamera::directionAt(double x, double y, std::uint32_t width, std::uint32_t height) const {
  const double half_h = std::tan(0.5 * vertical_fov_deg * std::numbers::pi / 180.0);
  const double half_w = half_h * static_cast<double>(width) / static_cast<double>(height);
  const double sx = (2.0 * x / width - 1.0) * half_w;
  const double sy = (1.0 - 2.0 * y / height) * half_h;
  return glm::normalize(forward + sx * right + sy * up);
}

std::vector<Ray> primaryRays(const Box& world_bounds, std::uint32_t width, std::uint32_t height) {
  std::vector<Ray> rays(static_cast<std::size_t>(width) * height);
  primaryRays(world_bounds, width, height, 0, rays);
  return rays;
}

void primaryRays(const Box& world_bounds, std::uint32_t width, std::uint32_t height, std::size_t first,
                 std::span<Ray> out) {
  const PinholeCamera cam = PinholeCamera::looking_at_box(world_bounds);
  const std::size_t total = static_cast<std::size_t>(width) * height;
  if (first > total || out.size() > total - first) {
    std::ostringstream msg;
    msg << "primaryRays: rays " << first << ".." << first + out.size() << " asked of " << total;
    throw InvalidArgument(msg.str());
  }
  for (std::size_t i = 0; i < out.size(); ++i) {
    const std::size_t pixel = first + i;
    Ray& r = out[i];
    r.origin = glm::vec3(cam.eye);
    r.dir = cam.direction(static_cast<std::uint32_t>(pixel % width), static_cast<std::uint32_t>(pixel / width), width,
                          height);
    r.tnear = 0.0f;
    r.tfar = std::numeric_limits<float>::infinity();
  }
}

RandomRayStream::RandomRayStream(const Box& world_bounds, std::uint64_t seed) : bounds_(world_bounds), rng_(seed) {
  requireBounds(world_bounds, "randomRays");
}

void RandomRayStream::next(std::span<Ray> out) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);  // stateless for doubles: blocks do not matter
  const Box& b = bounds_;
  for (Ray& r : out) {
    for (int k = 0; k < 3; ++k) r.origin[k] = static_cast<float>(b.lo[k] + unit(rng_) * (b.hi[k] - b.lo[k]));
    // Uniform on the sphere: z uniform in [-1, 1], azimuth uniform.
    const double z = 2.0 * unit(rng_) - 1.0;
    const double phi = 2.0 * std::numbers::pi * unit(rng_);
    const double s = std::sqrt(std::max(0.0, 1.0 - z * z));
    r.dir =
        glm::vec3(static_cast<float>(s * std::cos(phi)), static_cast<float>(s * std::sin(phi)), static_cast<float>(z));
    r.tnear = 0.0f;
    r.tfar = std::numeric_limits<float>::infinity();
  }
}

std::vector<Ray> randomRays(const Box& b, std::size_t count, std::uint64_t seed) {
  RandomRayStream stream(b, seed);
  std::vector<Ray> rays(count);
  stream.next(rays);
  return rays;
}

}  // namespace duplex
