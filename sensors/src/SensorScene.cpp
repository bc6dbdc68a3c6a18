#include "duplex/sensors/SensorScene.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <unordered_set>

namespace duplex {

SensorScene::SensorScene(SceneGraph& graph, std::vector<Light> lights, std::vector<Material> materials)
    : graph_(&graph), lights_(std::move(lights)) {
  prepare(std::move(materials));
}

SensorScene::SensorScene(SensorScene&&) noexcept = default;
SensorScene& SensorScene::operator=(SensorScene&&) noexcept = default;
SensorScene::~SensorScene() = default;

void SensorScene::prepare(std::vector<Material> materials) {
  for (const Light& l : lights_) {
    l.validate();
    total_power_ += l.power_w;
  }
  if (graph_->hasPendingEdits()) throw InvalidArgument("SensorScene: the scene graph has uncommitted edits");
  tracer_ = std::make_unique<SceneTracer>(*graph_);
  // Per-node tables (node ids are small integers): which sensor, which material.
  std::vector<NodeId> instances = graph_->visibleInstances();
  std::sort(instances.begin(), instances.end());
  const NodeId max_node = instances.empty() ? 0 : instances.back();
  sensor_of_node_.assign(instances.empty() ? 0 : max_node + 1, -1);
  material_of_node_.assign(sensor_of_node_.size(), Material{});
  const ObjectLibrary& library = graph_->library();
  std::unordered_set<std::string> names;
  for (const NodeId node : instances) {
    const NodeInfo info = graph_->node(node);
    if (info.object < materials.size()) material_of_node_[node] = materials[info.object];
    auto object = std::dynamic_pointer_cast<const SensorObject>(library.get(info.object));
    if (!object) continue;
    SensorInstance s;
    s.name = std::string(info.name);
    s.node = node;
    s.object = std::move(object);
    s.world_from_object = graph_->worldTransform(node);
    const glm::dvec3 ex = s.world_from_object.vector(glm::dvec3(1, 0, 0)), ey = s.world_from_object.vector(glm::dvec3(0, 1, 0));
    s.area_scale = glm::length(glm::cross(ex, ey));
    if (!names.insert(s.name).second) throw InvalidArgument("SensorScene: two sensors named '" + s.name + "'");
    s.first_bin = bin_count_;
    if (static_cast<std::uint64_t>(bin_count_) + s.object->binCount() > 0xFFFFFFF0ull)
      throw InvalidArgument("SensorScene: more than 2^32 sensor bins");
    bin_count_ += s.object->binCount();
    sensor_of_node_[node] = static_cast<int>(sensors_.size());
    sensors_.push_back(std::move(s));
  }
}

int SensorScene::findSensor(const std::string& name) const {
  for (std::size_t k = 0; k < sensors_.size(); ++k)
    if (sensors_[k].name == name) return static_cast<int>(k);
  return -1;
}

}  // namespace duplex
