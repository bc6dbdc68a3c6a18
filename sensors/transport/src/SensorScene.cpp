#include "duplex/objects/MeshObject.h"
#include "duplex/sensors/SensorScene.h"

#include "duplex/accel/Error.h"
#include "duplex/sensors/Photometry.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <numbers>
#include <string>
#include <unordered_set>

namespace duplex {

// The Derived of the graph's last commit. The pointer is read without the lock on every access
// (the hot loop asks for materials per hit), so it is atomic; a new one is made under the mutex.
struct SensorScene::Cache {
  std::mutex mutex;
  std::atomic<const Derived*> current{nullptr};
  std::unique_ptr<Derived> owned;
};

SensorScene::SensorScene(SceneGraph& graph, std::vector<Light> lights, std::vector<Material> materials,
                         std::vector<std::string> bands, std::vector<FarFieldSensor> far_field,
                         std::vector<std::array<double, 2>> band_nm,
                         std::vector<std::pair<NodeId, Material>> instance_materials)
    : graph_(&graph),
      given_lights_(std::move(lights)),
      materials_(std::move(materials)),
      bands_(std::move(bands)),
      far_field_(std::move(far_field)),
      band_nm_(std::move(band_nm)),
      instance_materials_(instance_materials.begin(), instance_materials.end()),
      cache_(std::make_unique<Cache>()) {
  // What does not depend on the graph is checked once: bands, per-object materials, far-field sensors.
  std::unordered_set<std::string> band_names;
  for (const std::string& b : bands_)
    if (b.empty() || !band_names.insert(b).second)
      throw InvalidArgument("SensorScene: band names must be non-empty and distinct ('" + b + "')");
  if (bands_.size() > 256) throw InvalidArgument("SensorScene: more than 256 bands");
  const std::uint32_t nb = bandCount();
  for (const Light& l : given_lights_) {
    if (l.node != kInvalidNode && !graph_->contains(l.node))
      throw InvalidArgument("light '" + l.name + "': node " + std::to_string(l.node) + " is not in the graph");
    if (!l.spectrum.empty() && l.spectrum.size() != nb)
      throw InvalidArgument("light '" + l.name + "': spectrum has " + std::to_string(l.spectrum.size()) +
                            " entries, the scene has " + std::to_string(nb) + " band(s)");
  }
  resolvePhotometry();
  const ObjectLibrary& library = graph_->library();
  auto checkMaterial = [nb](Material& m, const std::string& what) { m.validate(what, nb); };
  for (std::size_t id = 0; id < materials_.size(); ++id)
    checkMaterial(materials_[id],
                  "material of object " +
                      (id < library.size() ? "'" + library.name(static_cast<ObjectId>(id)) + "'" : std::to_string(id)));
  for (auto& [node, m] : instance_materials_)
    checkMaterial(m, "material of instance " +
                         (graph_->contains(node) ? "'" + graph_->path(node) + "'" : "node " + std::to_string(node)));
  for (const FarFieldSensor& f : far_field_) {
    if (!f.object || f.object->spec().shape != SensorShape::FarField)
      throw InvalidArgument("far-field sensor '" + f.name + "': needs a far-field sensor object");
    const glm::dmat3& l = f.world_from_sensor.linear;
    if (!isSimilarity(l) || !(std::abs(glm::determinant(l) - 1.0) < 1e-9) ||
        f.world_from_sensor.translation != glm::dvec3(0.0))
      throw InvalidArgument("far-field sensor '" + f.name + "': its transform must be a rotation (no translation)");
  }
  if (graph_->hasPendingEdits()) throw InvalidArgument("SensorScene: the scene graph has uncommitted edits");
  tracer_ = std::make_unique<SceneTracer>(*graph_);
  (void)current();  // validates the graph's sensors, media and lights now
}

void BandValue::check(const std::string& what, const char* name, double lo, double hi,
                      std::uint32_t scene_bands) const {
  // A programmatic scene must not reach the run with a value out of range: a reflectance above 1
  // acts as 1, a NaN one never absorbs (a perfect mirror).
  const std::string range = hi == std::numeric_limits<double>::max()
                                ? "finite and >= " + std::to_string(lo)
                                : "in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (!bands.empty() && bands.size() != scene_bands)
    throw InvalidArgument(what + ": " + std::to_string(bands.size()) + " per-band values, the scene has " +
                          std::to_string(scene_bands) + " band(s)");
  for (const double x : bands)
    if (!(x >= lo && x <= hi)) throw InvalidArgument(what + ": per-band " + name + " values must be " + range);
  if (!(value >= lo && value <= hi))
    throw InvalidArgument(what + ": " + name + " " + std::to_string(value) + " must be " + range);
}

void SensorScene::resolvePhotometry() {
  const std::uint32_t nb = bandCount();
  const Light* in_lumens = nullptr;
  const Light* in_watts = nullptr;
  for (const Light& l : given_lights_) (l.lumens > 0.0 ? in_lumens : in_watts) = &l;
  photometric_ = in_lumens || !band_nm_.empty();
  if (!photometric_) return;
  band_lm_.assign(nb, 1.0);  // luminous flux transported directly, unless the bands have wavelengths
  if (!band_nm_.empty()) {
    if (band_nm_.size() != bands_.size())
      throw InvalidArgument("SensorScene: wavelengths for " + std::to_string(band_nm_.size()) +
                            " bands, the scene has " + std::to_string(bands_.size()));
    for (std::size_t k = 0; k < band_nm_.size(); ++k) {
      const auto [lo, hi] = band_nm_[k];
      if (!(std::isfinite(lo) && std::isfinite(hi) && lo > 0.0 && lo < hi))
        throw InvalidArgument("band '" + bands_[k] + "': wavelengths [" + std::to_string(lo) + ", " +
                              std::to_string(hi) + "] nm must be finite with 0 < lo < hi");
      band_xyz_.push_back(kLumensPerWatt * cieBandMean(lo, hi));
      band_lm_[k] = band_xyz_.back().y;
    }
  } else if (in_watts) {
    throw InvalidArgument("light '" + in_watts->name + "' is given in watts and light '" + in_lumens->name +
                          "' in lumens: without band wavelengths (\"bands\": [{\"name\": ..., \"nm\": [lo, hi]}]) "
                          "watts and lumens cannot be converted; give every light in lumens, or the bands wavelengths");
  }
  for (Light& l : given_lights_) {
    if (!(l.lumens > 0.0)) continue;
    // Lumens per watt of the light's spectrum: each band's share times its efficacy.
    double sum = 0.0, efficacy = 0.0;
    for (std::uint32_t k = 0; k < nb; ++k) sum += l.spectrum.empty() ? 1.0 : l.spectrum[k];
    for (std::uint32_t k = 0; k < nb; ++k) efficacy += (l.spectrum.empty() ? 1.0 : l.spectrum[k]) / sum * band_lm_[k];
    if (!(efficacy > 0.0))
      throw InvalidArgument("light '" + l.name +
                            "': given in lumens, but its spectrum has no power in a band where "
                            "V(lambda) > 0 (its luminous efficacy is 0)");
    l.power_w = l.lumens / efficacy;
  }
}

SensorScene::SensorScene(SensorScene&&) noexcept = default;
SensorScene& SensorScene::operator=(SensorScene&&) noexcept = default;
SensorScene::~SensorScene() = default;

const SensorScene::Derived& SensorScene::current() const {
  const std::uint64_t revision = graph_->revision();
  if (const Derived* d = cache_->current.load(std::memory_order_acquire); d && d->revision == revision) return *d;
  std::lock_guard lock(cache_->mutex);
  if (const Derived* d = cache_->current.load(std::memory_order_acquire); d && d->revision == revision) return *d;
  std::unique_ptr<Derived> fresh = derive();  // throws: the previous tables stay
  cache_->current.store(fresh.get(), std::memory_order_release);
  cache_->owned = std::move(fresh);
  return *cache_->owned;
}

std::unique_ptr<SensorScene::Derived> SensorScene::derive() const {
  if (graph_->hasPendingEdits())
    throw InvalidArgument("SensorScene: the scene graph has uncommitted edits (commit them before a run)");
  auto out = std::make_unique<Derived>();
  Derived& d = *out;
  d.revision = graph_->revision();
  const std::uint32_t nb = bandCount();
  // Lights: placed at their nodes as of this commit; a hidden node's light is off.
  for (const Light& given : given_lights_) {
    Light l = given;
    if (given.node != kInvalidNode) {
      if (!graph_->contains(given.node))
        throw InvalidArgument("light '" + given.name + "': its node (id " + std::to_string(given.node) +
                              ") was removed from the graph");
      bool visible = true;
      for (const NodeId id : graph_->pathIds(given.node)) visible = visible && graph_->node(id).visible;
      if (!visible) continue;
      l = placeLight(given, graph_->worldTransform(given.node));
    }
    l.validate();
    d.total_power += l.power_w;
    std::vector<double> cdf(nb);
    double acc = 0.0, sum = 0.0;
    for (std::uint32_t k = 0; k < nb; ++k) sum += l.spectrum.empty() ? 1.0 : l.spectrum[k];
    for (std::uint32_t k = 0; k < nb; ++k) cdf[k] = (acc += l.spectrum.empty() ? 1.0 : l.spectrum[k]) / sum;
    cdf.back() = 1.0;
    d.band_cdf.push_back(std::move(cdf));
    d.lights.push_back(std::move(l));
  }
  // Per-node table (node ids are small integers): which material.
  std::vector<NodeId> instances = graph_->visibleInstances();
  std::sort(instances.begin(), instances.end());
  const NodeId max_node = instances.empty() ? 0 : instances.back();
  d.material_of_node.assign(instances.empty() ? 0 : max_node + 1, Material{});
  d.surface_of_node.assign(d.material_of_node.size(), SurfaceInstance{});
  const ObjectLibrary& library = graph_->library();
  std::unordered_set<std::string> names;
  bool scatters = false;
  std::vector<NodeId> media;
  auto addSensor = [&](SensorInstance s) {
    if (!names.insert(s.name).second) throw InvalidArgument("SensorScene: two sensors named '" + s.name + "'");
    s.first_bin = d.bin_count;
    if (static_cast<std::uint64_t>(d.bin_count) + s.object->binCount() > 0xFFFFFFF0ull)
      throw InvalidArgument("SensorScene: more than 2^32 sensor bins");
    d.bin_count += s.object->binCount();
    s.first_angle_bin = d.angle_bin_count;
    if (static_cast<std::uint64_t>(d.angle_bin_count) + s.object->spec().angleBinCount() > 0x7FFFFFF0ull)
      throw InvalidArgument("SensorScene: more than 2^31 angular bins");
    d.angle_bin_count += s.object->spec().angleBinCount();
    d.sensors.push_back(std::move(s));
  };
  for (const NodeId node : instances) {
    const NodeInfo info = graph_->node(node);
    // An instance's own material, else its object's.
    if (const auto it = instance_materials_.find(node); it != instance_materials_.end())
      d.material_of_node[node] = it->second;
    else if (info.object < materials_.size()) d.material_of_node[node] = materials_[info.object];
    const Material& m = d.material_of_node[node];
    const ObjectRole role = library.get(info.object)->role();
    // Paths restart from surfaces that do not absorb: the bound on a hit's rounding error there
    // needs the triangle's object-space vertices and the transform the top level applies.
    if (role == ObjectRole::Surface && !m.endsPaths()) {
      if (auto mesh = std::dynamic_pointer_cast<const MeshObject>(library.get(info.object))) {
        SurfaceInstance& si = d.surface_of_node[node];
        si.mesh = std::move(mesh);
        si.world_from_object = graph_->worldTransform(node);
        si.object_from_world = si.world_from_object.inverse();
        si.identity =
            si.world_from_object.linear == glm::dmat3(1.0) && si.world_from_object.translation == glm::dvec3(0.0);
      }
    }
    if (role == ObjectRole::Medium) {
      if (!m.is<Absorber>() && !m.is<Medium>())
        throw InvalidArgument("object '" + std::string(library.name(info.object)) +
                              "' is a medium: its material must be \"medium\" (or none)");
      scatters |= m.is<Medium>();
      media.push_back(node);
    } else if (m.is<Medium>()) {
      throw InvalidArgument("object '" + std::string(library.name(info.object)) +
                            "' has a \"medium\" material but is not a fog volume");
    }
    auto object = std::dynamic_pointer_cast<const SensorObject>(library.get(info.object));
    if (!object) continue;
    SensorInstance s;
    s.name = std::string(info.name);
    s.node = node;
    s.object = std::move(object);
    if (s.object->spec().shape == SensorShape::FarField)
      throw InvalidArgument("sensor '" + s.name +
                            "': a far-field sensor is not placed in the scene graph (it records the rays leaving it)");
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
    addSensor(std::move(s));
  }
  for (const FarFieldSensor& f : far_field_) {
    SensorInstance s;
    s.name = f.name;
    s.object = f.object;
    s.world_from_object = f.world_from_sensor;
    s.frame_x = f.world_from_sensor.vector(glm::dvec3(1, 0, 0));
    s.frame_y = f.world_from_sensor.vector(glm::dvec3(0, 1, 0));
    s.normal = f.world_from_sensor.vector(glm::dvec3(0, 0, 1));
    addSensor(std::move(s));
  }
  if (static_cast<std::uint64_t>(d.bin_count) + d.angle_bin_count > 0xFFFFFFF0ull)
    throw InvalidArgument("SensorScene: more than 2^32 sensor bins and angular bins");
  // Scattering media: every fog is then sampled by free flights (one without a material absorbs at
  // each collision), so only fogs that can sample free flights are allowed.
  if (!scatters) return out;
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
    mi.material = d.material_of_node[node];
    d.media.push_back(std::move(mi));
  }
  return out;
}

bool SensorScene::isSimilarity(const glm::dmat3& linear) {
  const glm::dmat3 g = glm::transpose(linear) * linear;
  const double s2 = g[0][0];
  double off = 0.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) off = std::max(off, std::abs(g[i][j] - (i == j ? s2 : 0.0)));
  return off <= 1e-9 * s2;  // false for NaN
}

PointMeter pinholeMeter(std::string name, const glm::dvec3& eye, const glm::dvec3& target, const glm::dvec3& up,
                        double fov_y, std::uint32_t width, std::uint32_t height) {
  const std::string what = "meter '" + name + "'";
  const auto finite = [](const glm::dvec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  if (!finite(eye) || !finite(target) || !finite(up) || !(glm::length(target - eye) > 0.0))
    throw InvalidArgument(what + ": the camera's eye and target must be finite and differ");
  if (!(fov_y > 0.0 && fov_y < std::numbers::pi))
    throw InvalidArgument(what + ": the camera's field of view must be in (0, 180) degrees");
  if (width == 0 || height == 0 || std::uint64_t{width} * height > (std::uint64_t{1} << 24))
    throw InvalidArgument(what + ": the camera needs 1 to 2^24 pixels");
  PointMeter m;
  m.name = std::move(name);
  m.image_forward = glm::normalize(target - eye);
  const glm::dvec3 right = glm::cross(m.image_forward, up);
  if (!(glm::length(right) > 1e-12 * glm::length(up)))
    throw InvalidArgument(what + ": the camera's up must not be parallel to its view");
  m.image_right = glm::normalize(right);
  m.image_up = glm::cross(m.image_right, m.image_forward);
  m.image_width = width;
  m.image_height = height;
  m.image_tan_y = std::tan(0.5 * fov_y);
  m.image_tan_x = m.image_tan_y * width / height;
  // The solid angle of the pixel [x0, x1] x [y0, y1] of the image plane at distance 1: F(x1, y1) -
  // F(x0, y1) - F(x1, y0) + F(x0, y0), F(x, y) = atan(x y / sqrt(1 + x^2 + y^2)).
  const auto f = [](double x, double y) { return std::atan(x * y / std::sqrt(1.0 + x * x + y * y)); };
  for (std::uint32_t py = 0; py < height; ++py)
    for (std::uint32_t px = 0; px < width; ++px) {
      const double x0 = m.image_tan_x * (2.0 * px / width - 1.0), x1 = m.image_tan_x * (2.0 * (px + 1) / width - 1.0);
      const double y1 = m.image_tan_y * (1.0 - 2.0 * py / height), y0 = m.image_tan_y * (1.0 - 2.0 * (py + 1) / height);
      m.pixel_solid_angle.push_back(f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0));
      m.points.push_back(eye);
      m.normals.push_back(
          glm::normalize(m.image_forward + 0.5 * (x0 + x1) * m.image_right + 0.5 * (y0 + y1) * m.image_up));
    }
  return m;
}

void SensorScene::setMeters(std::vector<PointMeter> meters) {
  std::unordered_set<std::string> names;
  std::uint64_t points = 0;
  const auto finite = [](const glm::dvec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  for (PointMeter& m : meters) {
    const std::string what = "meter '" + m.name + "'";
    if (m.name.empty()) throw InvalidArgument("a meter has an empty name");
    if (!names.insert(m.name).second) throw InvalidArgument("two meters named '" + m.name + "'");
    if (m.points.empty()) throw InvalidArgument(what + ": no points");
    if (m.image_width != 0 && (m.half_angle != 0.0 || m.pixel_solid_angle.size() != m.points.size() ||
                               std::uint64_t{m.image_width} * m.image_height != m.points.size()))
      throw InvalidArgument(what + ": a camera's pixels are not set (pinholeMeter)");
    if (!(m.half_angle >= 0.0 && m.half_angle <= std::numbers::pi / 2))
      throw InvalidArgument(what +
                            ": the half-angle of a luminance meter must be in (0, 90] degrees (0: an "
                            "illuminance meter)");
    if (m.normals.size() != m.points.size())
      throw InvalidArgument(what + ": " + std::to_string(m.normals.size()) + " normals for " +
                            std::to_string(m.points.size()) + " points (one per point)");
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      const double len = glm::length(m.normals[i]);
      if (!finite(m.points[i]) || !finite(m.normals[i]) || !(len > 0.0) || !std::isfinite(len))
        throw InvalidArgument(what + ": point " + std::to_string(i) +
                              " has a non-finite position or a zero or non-finite normal");
      m.normals[i] /= len;
    }
    points += m.points.size();
    if (points > (std::uint64_t{1} << 24)) throw InvalidArgument(what + ": more than 2^24 meter points in all");
  }
  meters_ = std::move(meters);
  meter_points_ = static_cast<std::uint32_t>(points);
}

void SensorScene::checkMeterMaterials() const {
  if (meters_.empty()) return;
  const Derived& d = current();
  for (std::size_t node = 0; node < d.material_of_node.size(); ++node) {
    const Material& m = d.material_of_node[node];
    if (m.metersSeeAll()) continue;
    const NodeId id = static_cast<NodeId>(node);
    throw InvalidArgument("meters: the material of instance " +
                          (graph_->contains(id) ? "'" + graph_->path(id) + "'" : "node " + std::to_string(node)) +
                          " is not an absorber or Lambertian: meters connect to the lights and to diffuse "
                          "reflections only, and would miss the light it sends (use sensors there)");
  }
}

int SensorScene::findSensor(const std::string& name) const {
  const std::vector<SensorInstance>& list = sensors();
  for (std::size_t k = 0; k < list.size(); ++k)
    if (list[k].name == name) return static_cast<int>(k);
  return -1;
}

}  // namespace duplex
