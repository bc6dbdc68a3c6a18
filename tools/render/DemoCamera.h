#pragma once
/// \file DemoCamera.h
/// The demo's fixed camera: framed once on the scene as loaded and kept for every frame of the
/// animation, so that frames can be compared; and projecting world points to image coordinates
/// (for picking a given point of the scene).

#include <duplex/accel/Box.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/scenegraph/SceneGraph.h>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <cstdint>
#include <optional>

namespace duplex::demo {

/// World bounds of the visible instances of `graph` (last commit) that are not flat: an instance
/// whose world box is thinner than 1e-3 of its largest extent along some axis (a ground plane) does
/// not count, so that a large floor does not push the camera away from the subject. Falls back to
/// all visible instances when every one is flat; empty when none is visible.
[[nodiscard]] Box subjectBounds(const SceneGraph& graph);

/// The camera of `duplex rays --primary` (direction normalize(1, 0.6, 0.8) from the box centre, up
/// +y, 45 degrees vertical field of view) for `subject_ws`, moved to `distance` x the box diagonal
/// from the centre (1.0: the contract camera). Throws InvalidArgument for an empty box or a
/// non-positive distance.
[[nodiscard]] PinholeCamera frameCamera(const Box& subject_ws, double distance);

/// Continuous image coordinates ((0, 0) the top-left corner, (width, height) the bottom-right, the
/// convention of PinholeCamera::directionAt) of the world point `p_ws`; nullopt when the point is
/// not in front of the camera.
[[nodiscard]] std::optional<glm::dvec2> project(const PinholeCamera& camera, const glm::dvec3& p_ws,
                                                std::uint32_t width, std::uint32_t height);

}  // namespace duplex::demo
