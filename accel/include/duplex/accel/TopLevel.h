#pragma once
/// \file TopLevel.h
/// The top level of the two-level structure: a kd-tree over the world boxes of object instances,
/// built with the same builder and traversed with the same code as the bottom level.

#include "duplex/accel/Affine.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/accel/Object.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <glm/mat3x3.hpp>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace duplex {

/// One instance as the top level sees it.
struct InstanceDesc {
  std::shared_ptr<const Object> object;
  Affine world_from_object;
  std::uint32_t id = 0;  ///< reported in Hit::instance_id
};

/// Immutable after build(); queries are thread-safe with one QueryContext per thread.
class TopLevel {
 public:
  /// Builds over `instances`; throws InvalidArgument for a null object or a non-finite or
  /// singular transform (naming the instance id).
  void build(std::span<const InstanceDesc> instances, const KdBuildConfig& config = {});

  /// Closest hit of a world-space ray; t is in units of the world ray's direction, hit.ng is
  /// cross(v1 - v0, v2 - v0) of the world-space triangle (unnormalised), hit.instance_id the
  /// instance's id. Returns a
  /// miss (hit.valid() false) when nothing is hit.
  [[nodiscard]] Hit intersect(const Ray& ray_ws, QueryContext& ctx) const;
  /// Whether any blocking object is hit within [tnear, tfar] of the world-space ray.
  [[nodiscard]] bool occluded(const Ray& ray_ws, QueryContext& ctx) const;

  [[nodiscard]] const KdTree& tree() const { return tree_; }
  /// World-space bounds of everything.
  [[nodiscard]] Box bounds() const { return tree_.bounds; }
  [[nodiscard]] std::size_t size() const { return instances_.size(); }

 private:
  struct Instance {
    const Object* object;
    Affine object_from_world;
    glm::mat3 normal_to_world;  // cofactor matrix of the world_from_object linear part
    std::uint32_t id;
    bool identity;  // skip the transform for instances placed as authored
  };
  std::vector<std::shared_ptr<const Object>> owners_;
  std::vector<Instance> instances_;
  KdTree tree_;
};

}  // namespace duplex
