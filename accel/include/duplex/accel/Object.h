#pragma once
/// \file Object.h
/// The interface every object type implements: bounds and ray queries in object space.
/// One coarse virtual interface, called once per instance visit; what happens inside an object
/// (its own acceleration structure and primitive tests) is statically dispatched.

#include "duplex/accel/Box.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <cstddef>
#include <string>
#include <string_view>

namespace duplex {

/// An immutable, shareable object (a mesh, later a volume or a sensor). Any number of instances
/// refer to one Object and share its bottom-level structure. All methods are const and thread-safe.
class Object {
 public:
  virtual ~Object() = default;

  /// The registered type name ("mesh", ...).
  [[nodiscard]] virtual std::string_view typeName() const = 0;
  /// The user-visible name (the scene file's object name, or the file name).
  [[nodiscard]] const std::string& name() const { return name_; }
  /// Bounds in object space. Empty for an object that cannot be hit.
  [[nodiscard]] virtual Box bounds() const = 0;
  /// Whether a hit on this object stops a ray (meshes: yes; sensors: no).
  [[nodiscard]] virtual bool blocks() const { return true; }

  /// Closest hit of `ray_os` (object space, direction not normalised) with t in
  /// [ray_os.tnear, hit.t]. On a closer hit, overwrites hit.t, u, v, prim_id and hit.ng (object
  /// space geometric normal) and returns true; otherwise leaves `hit` alone and returns false.
  virtual bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const = 0;
  /// Whether anything blocks `ray_os` within [tnear, tfar] (object space).
  [[nodiscard]] virtual bool occluded(const Ray& ray_os, QueryContext& ctx) const = 0;

  /// Bytes held by the object's geometry and acceleration structure.
  [[nodiscard]] virtual std::size_t memoryBytes() const = 0;

 protected:
  explicit Object(std::string name) : name_(std::move(name)) {}

 private:
  std::string name_;
};

}  // namespace duplex
