#include "duplex/scenegraph/Scene.h"

#include "duplex/accel/Error.h"

namespace duplex {

std::uint32_t Scene::addObject(std::string name, std::shared_ptr<const Object> object) {
  if (name.empty()) throw InvalidArgument("scene: object name must not be empty");
  if (!object) throw InvalidArgument("scene: object '" + name + "' is null");
  if (findObject(name)) throw InvalidArgument("scene: duplicate object name '" + name + "'");
  by_name_.emplace(name, static_cast<std::uint32_t>(names_.size()));
  names_.push_back(std::move(name));
  objects_.push_back(std::move(object));
  return static_cast<std::uint32_t>(objects_.size() - 1);
}

std::uint32_t Scene::addInstance(std::uint32_t object, const Affine& world_from_object) {
  const std::string what = "scene: instance " + std::to_string(instances_.size());
  if (object >= objects_.size()) throw InvalidArgument(what + " refers to unknown object " + std::to_string(object));
  if (!world_from_object.isFinite())
    throw InvalidArgument(what + " of '" + names_[object] + "': transform has NaN or infinite entries");
  if (world_from_object.isSingular())
    throw InvalidArgument(what + " of '" + names_[object] + "': transform is singular");
  instances_.push_back({object, world_from_object});
  return static_cast<std::uint32_t>(instances_.size() - 1);
}

std::optional<std::uint32_t> Scene::findObject(const std::string& name) const {
  const auto it = by_name_.find(name);
  if (it == by_name_.end()) return std::nullopt;
  return it->second;
}

std::vector<InstanceDesc> Scene::instanceDescs() const {
  std::vector<InstanceDesc> out;
  out.reserve(instances_.size());
  for (std::size_t i = 0; i < instances_.size(); ++i)
    out.push_back({objects_[instances_[i].object], instances_[i].world_from_object, static_cast<std::uint32_t>(i)});
  return out;
}

Box Scene::worldBounds() const {
  Box b;
  for (const SceneInstance& inst : instances_) b.extend(inst.world_from_object.apply(objects_[inst.object]->bounds()));
  return b;
}

}  // namespace duplex
