#pragma once
/// \file Scene.h
/// A flat scene: an object library and instances placing library objects in the world.
/// (The hierarchical graph with change notifications builds on this.)

#include "duplex/accel/Affine.h"
#include "duplex/accel/Box.h"
#include "duplex/accel/Object.h"
#include "duplex/accel/TopLevel.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

namespace duplex {

/// An instance: which library object, and where (world_from_object, double precision).
struct SceneInstance {
  std::uint32_t object = 0;
  Affine world_from_object;
};

/// Objects are shared: any number of instances refer to one object and its bottom-level structure.
class Scene {
 public:
  /// Adds an object under a unique `name`; returns its index. Throws InvalidArgument for an empty or
  /// duplicate name or a null object.
  std::uint32_t addObject(std::string name, std::shared_ptr<const Object> object);
  /// Places object `object` with `world_from_object`; returns the instance id (its position).
  /// Throws InvalidArgument for an unknown object or a NaN/inf or singular transform; the scene is
  /// then unchanged.
  std::uint32_t addInstance(std::uint32_t object, const Affine& world_from_object);

  [[nodiscard]] std::size_t objectCount() const { return objects_.size(); }
  [[nodiscard]] const std::string& objectName(std::uint32_t i) const { return names_.at(i); }
  [[nodiscard]] const std::shared_ptr<const Object>& object(std::uint32_t i) const { return objects_.at(i); }
  [[nodiscard]] std::optional<std::uint32_t> findObject(const std::string& name) const;
  [[nodiscard]] const std::vector<SceneInstance>& instances() const { return instances_; }

  /// The instances in the form the top level takes (instance id = position).
  [[nodiscard]] std::vector<InstanceDesc> instanceDescs() const;
  /// World-space bounds of all instances.
  [[nodiscard]] Box worldBounds() const;

 private:
  std::vector<std::string> names_;
  std::unordered_map<std::string, std::uint32_t> by_name_;
  std::vector<std::shared_ptr<const Object>> objects_;
  std::vector<SceneInstance> instances_;
};

}  // namespace duplex
