#include "EmbreeTwoLevel.h"

#include <tbb/parallel_for.h>

#include <array>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <string>

namespace duplex::bench {

namespace {

double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Embree's RTC_FORMAT_FLOAT3X4_ROW_MAJOR: the scene-json-v1 layout, rounded to float.
std::array<float, 12> rowMajor3x4(const Affine& a) {
  const std::array<double, 12> m = a.toRowMajor3x4();
  std::array<float, 12> f{};
  for (std::size_t i = 0; i < 12; ++i) f[i] = static_cast<float>(m[i]);
  return f;
}

// One object scene of the given build quality (Embree's default: medium).
RTCScene newObjectScene(EmbreeDevice& device, const TriangleMesh& mesh, RTCBuildQuality quality, RTCSceneFlags flags) {
  RTCScene scene = rtcNewScene(device.get());
  rtcSetSceneFlags(scene, flags);
  rtcSetSceneBuildQuality(scene, quality);
  attachTriangleMesh(device, scene, mesh, quality);
  rtcCommitScene(scene);
  return scene;
}

}  // namespace

const char* toString(EmbreeTopLevelMode mode) {
  switch (mode) {
    case EmbreeTopLevelMode::Default: return "default";
    case EmbreeTopLevelMode::DynamicLow: return "dynamic_low";
    case EmbreeTopLevelMode::Robust: return "robust";
  }
  return "?";
}

EmbreeTwoLevel::EmbreeTwoLevel(EmbreeDevice& device, std::span<const TriangleMesh* const> meshes,
                               std::span<const EmbreeInstanceDesc> instances, EmbreeTopLevelMode mode,
                               RTCBuildQuality object_quality)
    : device_(device) {
  const RTCSceneFlags flags = mode == EmbreeTopLevelMode::Robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE;
  const auto start = std::chrono::steady_clock::now();
  object_scenes_.assign(meshes.size(), nullptr);
  tbb::parallel_for(std::size_t{0}, meshes.size(), [&](std::size_t i) {
    object_scenes_[i] = newObjectScene(device, *meshes[i], object_quality, flags);
  });
  device.check("object scenes");
  build_times_.objects_ms = msSince(start);

  const auto top_start = std::chrono::steady_clock::now();
  top_ = rtcNewScene(device.get());
  if (mode == EmbreeTopLevelMode::DynamicLow) {
    rtcSetSceneFlags(top_, RTC_SCENE_FLAG_DYNAMIC);
    rtcSetSceneBuildQuality(top_, RTC_BUILD_QUALITY_LOW);
  } else {
    rtcSetSceneFlags(top_, flags);
    rtcSetSceneBuildQuality(top_, RTC_BUILD_QUALITY_MEDIUM);
  }
  instances_.reserve(instances.size());
  for (const EmbreeInstanceDesc& instance : instances) addInstance(instance.object, instance.world_from_object);
  commit();
  build_times_.top_ms = msSince(top_start);
}

EmbreeTwoLevel::~EmbreeTwoLevel() {
  for (RTCGeometry g : instances_)
    if (g) rtcReleaseGeometry(g);
  if (top_) rtcReleaseScene(top_);
  for (RTCScene s : object_scenes_)
    if (s) rtcReleaseScene(s);
}

RTCGeometry EmbreeTwoLevel::newInstanceGeometry(std::uint32_t object, const Affine& world_from_object) {
  if (object >= object_scenes_.size())
    throw std::out_of_range("EmbreeTwoLevel: object " + std::to_string(object) + " of " +
                            std::to_string(object_scenes_.size()));
  RTCGeometry geometry = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(geometry, object_scenes_[object]);
  rtcSetGeometryTimeStepCount(geometry, 1);
  const std::array<float, 12> m = rowMajor3x4(world_from_object);
  rtcSetGeometryTransform(geometry, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m.data());
  rtcCommitGeometry(geometry);
  return geometry;
}

void EmbreeTwoLevel::setTransform(std::uint32_t instance, const Affine& world_from_object) {
  RTCGeometry geometry = instance < instances_.size() ? instances_[instance] : nullptr;
  if (!geometry) throw std::out_of_range("EmbreeTwoLevel: no live instance " + std::to_string(instance));
  const std::array<float, 12> m = rowMajor3x4(world_from_object);
  rtcSetGeometryTransform(geometry, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, m.data());
  rtcCommitGeometry(geometry);
}

std::uint32_t EmbreeTwoLevel::addInstance(std::uint32_t object, const Affine& world_from_object) {
  const auto id = static_cast<std::uint32_t>(instances_.size());
  RTCGeometry geometry = newInstanceGeometry(object, world_from_object);
  rtcAttachGeometryByID(top_, geometry, id);
  instances_.push_back(geometry);
  return id;
}

void EmbreeTwoLevel::removeInstance(std::uint32_t instance) {
  RTCGeometry geometry = instance < instances_.size() ? instances_[instance] : nullptr;
  if (!geometry) throw std::out_of_range("EmbreeTwoLevel: no live instance " + std::to_string(instance));
  rtcDetachGeometry(top_, instance);
  rtcReleaseGeometry(geometry);
  instances_[instance] = nullptr;
}

void EmbreeTwoLevel::commit() {
  rtcCommitScene(top_);
  device_.check("rtcCommitScene (top level)");
}

Hit EmbreeTwoLevel::intersect(const Ray& ray_ws) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh = toRayHit(ray_ws, ray_ws.tfar);
  rtcIntersect1(top_, &context, &rh);
  Hit hit;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.t = rh.ray.tfar;
  hit.u = rh.hit.u;
  hit.v = rh.hit.v;
  hit.prim_id = rh.hit.primID;
  hit.instance_id = rh.hit.instID[0];
  // Embree 3 reports an instanced hit's geometric normal in the object's space; left so.
  hit.ng = {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
  return hit;
}

}  // namespace duplex::bench
