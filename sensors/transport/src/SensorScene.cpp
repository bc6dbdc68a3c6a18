#include "duplex/sensors/SensorScene.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>
#include <unordered_set>

namespace duplex {

SensorScene::SensorScene(SceneGraph& graph, std::vector<Light> lights, std::vector<Material> materials,
                         std::vector<std::string> bands)
    : graph_(&graph), lights_(std::move(lights)), bands_(std::move(bands)) {
  prepare(std::move(materials));
}

SensorScene::SensorScene(SensorScene&&) noexcept = default;
SensorScene& SensorScene::operator=(SensorScene&&) noexcept = default;
SensorScene::~SensorScene() = default;

void SensorScene::prepare(std::vector<Material> materials) {
  // Bands, and each light's cumulative spectrum (what a ray's band is drawn from).
  std::unordered_set<std::string> band_names;
  for (const std::string& b : bands_)
    if (b.empty() || !band_names.insert(b).second)
      throw InvalidArgument("SensorScene: band names must be non-empty and distinct ('" + b + "')");
  if (bands_.size() > 256) throw InvalidArgument("SensorScene: more than 256 bands");
  const std::uint32_t nb = bandCount();
  for (const Light& l : lights_) {
    l.validate();
    total_power_ += l.power_w;
    if (!l.spectrum.empty() && l.spectrum.size() != nb)
      throw InvalidArgument("light '" + l.name + "': spectrum has " + std::to_string(l.spectrum.size()) +
                            " entries, the scene has " + std::to_string(nb) + " band(s)");
    std::vector<double> cdf(nb);
    double acc = 0.0, sum = 0.0;
    for (std::uint32_t k = 0; k < nb; ++k) sum += l.spectrum.empty() ? 1.0 : l.spectrum[k];
    for (std::uint32_t k = 0; k < nb; ++k) cdf[k] = (acc += l.spectrum.empty() ? 1.0 : l.spectrum[k]) / sum;
    cdf.back() = 1.0;
    band_cdf_.push_back(std::move(cdf));
  }
  if (graph_->hasPendingEdits()) throw InvalidArgument("SensorScene: the scene graph has uncommitted edits");
  tracer_ = std::make_unique<SceneTracer>(*graph_);
  // Per-node table (node ids are small integers): which material.
  std::vector<NodeId> instances = graph_->visibleInstances();
  std::sort(instances.begin(), instances.end());
  const NodeId max_node = instances.empty() ? 0 : instances.back();
  material_of_node_.assign(instances.empty() ? 0 : max_node + 1, Material{});
  const ObjectLibrary& library = graph_->library();
  std::unordered_set<std::string> names;
  for (std::size_t id = 0; id < materials.size(); ++id) {
    const Material& m = materials[id];
    const std::string what =
        "material of object " +
        (id < library.size() ? "'" + library.name(static_cast<ObjectId>(id)) + "'" : std::to_string(id));
    if (!m.band_reflectance.empty() && m.band_reflectance.size() != nb)
      throw InvalidArgument(what + ": " + std::to_string(m.band_reflectance.size()) +
                            " per-band values, the scene has " + std::to_string(nb) + " band(s)");
    for (const double r : m.band_reflectance)
      if (!(r >= 0.0 && r <= 1.0)) throw InvalidArgument(what + ": per-band values must be in [0, 1]");
    // The file reader checks these too; a programmatic scene must not reach the run with a
    // reflectance above 1 (acts as 1), a NaN one (never absorbs: a perfect mirror) or a NaN index.
    if (!(m.reflectance >= 0.0 && m.reflectance <= 1.0))
      throw InvalidArgument(what + ": reflectance (albedo) " + std::to_string(m.reflectance) + " must be in [0, 1]");
    if (m.type == MaterialType::Dielectric && !(std::isfinite(m.ior) && m.ior > 0.0))
      throw InvalidArgument(what + ": index of refraction " + std::to_string(m.ior) + " must be finite and positive");
    if (m.type == MaterialType::Medium && !(m.g > -1.0 && m.g < 1.0))
      throw InvalidArgument(what + ": g must be in (-1, 1)");
  }
  bool scatters = false;
  std::vector<NodeId> media;
  for (const NodeId node : instances) {
    const NodeInfo info = graph_->node(node);
    if (info.object < materials.size()) material_of_node_[node] = materials[info.object];
    const Material& m = material_of_node_[node];
    const ObjectRole role = library.get(info.object)->role();
    if (role == ObjectRole::Medium) {
      if (m.type != MaterialType::Absorber && m.type != MaterialType::Medium)
        throw InvalidArgument("object '" + std::string(library.name(info.object)) +
                              "' is a medium: its material must be \"medium\" (or none)");
      scatters |= m.type == MaterialType::Medium;
      media.push_back(node);
    } else if (m.type == MaterialType::Medium) {
      throw InvalidArgument("object '" + std::string(library.name(info.object)) +
                            "' has a \"medium\" material but is not a fog volume");
    }
    auto object = std::dynamic_pointer_cast<const SensorObject>(library.get(info.object));
    if (!object) continue;
    SensorInstance s;
    s.name = std::string(info.name);
    s.node = node;
    s.object = std::move(object);
    s.world_from_object = graph_->worldTransform(node);
    const glm::dvec3 ex = s.world_from_object.vector(glm::dvec3(1, 0, 0)),
                     ey = s.world_from_object.vector(glm::dvec3(0, 1, 0));
    s.area_scale = glm::length(glm::cross(ex, ey));
    s.normal = glm::normalize(glm::cross(ex, ey));
    s.frame_x = glm::normalize(ex);
    s.frame_y = glm::cross(s.normal, s.frame_x);
    if (s.object->spec().shape == SensorShape::Sphere && !isSimilarity(s.world_from_object.linear))
      throw InvalidArgument("sensor '" + s.name +
                            "': a sphere sensor's transform must be a rotation with uniform scale");
    if (!names.insert(s.name).second) throw InvalidArgument("SensorScene: two sensors named '" + s.name + "'");
    s.first_bin = bin_count_;
    if (static_cast<std::uint64_t>(bin_count_) + s.object->binCount() > 0xFFFFFFF0ull)
      throw InvalidArgument("SensorScene: more than 2^32 sensor bins");
    bin_count_ += s.object->binCount();
    s.first_angle_bin = angle_bin_count_;
    if (static_cast<std::uint64_t>(angle_bin_count_) + s.object->spec().angleBinCount() > 0x7FFFFFF0ull)
      throw InvalidArgument("SensorScene: more than 2^31 angular bins");
    angle_bin_count_ += s.object->spec().angleBinCount();
    sensors_.push_back(std::move(s));
  }
  if (static_cast<std::uint64_t>(bin_count_) + angle_bin_count_ > 0xFFFFFFF0ull)
    throw InvalidArgument("SensorScene: more than 2^32 sensor bins and angular bins");
  // Scattering media: every fog is then sampled by free flights (one without a material absorbs at
  // each collision), so only fogs that can sample free flights are allowed.
  if (!scatters) return;
  for (const NodeId node : media) {
    const NodeInfo info = graph_->node(node);
    MediumInstance mi;
    mi.node = node;
    mi.volume = std::dynamic_pointer_cast<const VolumeObject>(library.get(info.object));
    if (!mi.volume)
      throw InvalidArgument(
          "object '" + std::string(library.name(info.object)) + "' (type " +
          std::string(library.get(info.object)->typeName()) +
          ") is a medium that cannot sample free flights: a scene whose fogs scatter takes volume fogs only");
    const Affine& world = graph_->worldTransform(node);
    mi.object_from_world = world.inverse();
    const Box box = world.apply(mi.volume->bounds());
    mi.world_lo = glm::dvec3(box.lo);
    mi.world_hi = glm::dvec3(box.hi);
    mi.mask = info.mask;
    mi.material = material_of_node_[node];
    media_.push_back(std::move(mi));
  }
}

bool SensorScene::isSimilarity(const glm::dmat3& linear) {
  const glm::dmat3 g = glm::transpose(linear) * linear;
  const double s2 = g[0][0];
  double off = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) off = std::max(off, std::abs(g[i][j] - (i == j ? s2 : 0.0)));
  return off <= 1e-9 * s2;  // false for NaN
}

int SensorScene::findSensor(const std::string& name) const {
  for (std::size_t k = 0; k < sensors_.size(); ++k)
    if (sensors_[k].name == name) return static_cast<int>(k);
  return -1;
}

}  // namespace duplex
