#include "DemoCamera.h"

#include <duplex/accel/Error.h>

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace duplex::demo {

Box subjectBounds(const SceneGraph& graph) {
  Box subject, all;
  for (const NodeId id : graph.visibleInstances()) {
    const Box object_os = graph.library().get(graph.node(id).object)->bounds();
    const Box box_ws = graph.worldTransform(id).apply(object_os);
    if (box_ws.empty()) continue;
    all.extend(box_ws);
    const glm::vec3 e = box_ws.extent();
    const float largest = std::max({e.x, e.y, e.z});
    if (std::min({e.x, e.y, e.z}) >= 1e-3f * largest) subject.extend(box_ws);
  }
  return subject.empty() ? all : subject;
}

PinholeCamera frameCamera(const Box& subject_ws, double distance) {
  if (!(distance > 0.0)) throw InvalidArgument("camera distance must be positive, got " + std::to_string(distance));
  // The contract camera sits at 1.0 x the diagonal: scale the box about its centre to move it.
  const glm::vec3 centre = subject_ws.center();
  const glm::vec3 half = 0.5f * static_cast<float>(distance) * subject_ws.extent();
  return PinholeCamera::looking_at_box(Box(centre - half, centre + half));
}

std::optional<glm::dvec2> project(const PinholeCamera& camera, const glm::dvec3& p_ws, std::uint32_t width,
                                  std::uint32_t height) {
  // Inverts PinholeCamera::directionAt: the direction is forward + sx * right + sy * up.
  const glm::dvec3 v = p_ws - camera.eye;
  const double depth = glm::dot(v, camera.forward);
  if (!(depth > 0.0)) return std::nullopt;
  const double half_h = std::tan(0.5 * camera.vertical_fov_deg * std::numbers::pi / 180.0);
  const double half_w = half_h * static_cast<double>(width) / static_cast<double>(height);
  const double sx = glm::dot(v, camera.right) / depth;
  const double sy = glm::dot(v, camera.up) / depth;
  return glm::dvec2((sx / half_w + 1.0) * 0.5 * width, (1.0 - sy / half_h) * 0.5 * height);
}

}  // namespace duplex::demo
