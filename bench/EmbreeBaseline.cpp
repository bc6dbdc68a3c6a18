#include "EmbreeBaseline.h"

#include <cstring>
#include <mutex>
#include <stdexcept>

namespace duplex::bench {

namespace {

// Embree reports errors through a callback on whichever thread hit them; keep the first message.
std::mutex g_error_mutex;
std::string g_error;

void onError(void*, RTCError code, const char* message) {
  std::lock_guard<std::mutex> lock(g_error_mutex);
  if (g_error.empty())
    g_error = "Embree error " + std::to_string(static_cast<int>(code)) + ": " + (message ? message : "");
}

}  // namespace

EmbreeDevice::EmbreeDevice(int threads, const std::string& extra_config) : threads_(threads) {
  // start_threads: spawn the TBB workers now rather than inside the first timed commit.
  std::string config = "threads=" + std::to_string(threads) + ",start_threads=1,set_affinity=0";
  if (!extra_config.empty()) config += "," + extra_config;
  device_ = rtcNewDevice(config.c_str());
  if (!device_) throw std::runtime_error("rtcNewDevice(\"" + config + "\") failed");
  rtcSetDeviceErrorFunction(device_, onError, nullptr);
  rtcSetDeviceMemoryMonitorFunction(device_, &EmbreeDevice::monitor, this);
}

EmbreeDevice::~EmbreeDevice() { rtcReleaseDevice(device_); }

bool EmbreeDevice::monitor(void* self, ssize_t bytes, bool) {
  static_cast<EmbreeDevice*>(self)->bytes_.fetch_add(bytes, std::memory_order_relaxed);
  return true;
}

void EmbreeDevice::check(const std::string& what) const {
  std::lock_guard<std::mutex> lock(g_error_mutex);
  if (!g_error.empty()) {
    const std::string message = what + ": " + g_error;
    g_error.clear();
    throw std::runtime_error(message);
  }
}

void attachTriangleMesh(EmbreeDevice& device, RTCScene scene, const TriangleMesh& mesh, RTCBuildQuality quality) {
  RTCGeometry geometry = rtcNewGeometry(device.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geometry, quality);
  const auto& positions = mesh.positions();
  const auto& triangles = mesh.triangles();
  // rtcSetNewGeometryBuffer pads vertex buffers for Embree's 16-byte loads; we copy, as our
  // MeshObject copies the vertices into its own triangle array.
  void* vertices = rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                           positions.size());
  void* indices = rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                          3 * sizeof(std::uint32_t), triangles.size());
  if (!vertices || !indices) {
    rtcReleaseGeometry(geometry);
    device.check("rtcSetNewGeometryBuffer");
    throw std::runtime_error("rtcSetNewGeometryBuffer failed");
  }
  std::memcpy(vertices, positions.data(), positions.size() * 3 * sizeof(float));
  std::memcpy(indices, triangles.data(), triangles.size() * 3 * sizeof(std::uint32_t));
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
}

EmbreeMesh::EmbreeMesh(EmbreeDevice& device, const TriangleMesh& mesh, RTCBuildQuality quality, RTCSceneFlags flags) {
  const std::int64_t bytes_before = device.allocatedBytes();
  scene_ = rtcNewScene(device.get());
  rtcSetSceneBuildQuality(scene_, quality);
  rtcSetSceneFlags(scene_, flags);
  attachTriangleMesh(device, scene_, mesh, quality);
  const auto& positions = mesh.positions();
  const auto& triangles = mesh.triangles();
  rtcCommitScene(scene_);
  device.check("rtcCommitScene");
  const std::int64_t total = device.allocatedBytes() - bytes_before;
  const std::int64_t buffers =
      static_cast<std::int64_t>(positions.size() * 3 * sizeof(float) + triangles.size() * 3 * sizeof(std::uint32_t));
  total_bytes_ = total > 0 ? static_cast<std::size_t>(total) : 0;
  accel_bytes_ = total > buffers ? static_cast<std::size_t>(total - buffers) : 0;
}

EmbreeMesh::~EmbreeMesh() {
  if (scene_) rtcReleaseScene(scene_);
}

const char* toString(RTCBuildQuality quality) {
  switch (quality) {
    case RTC_BUILD_QUALITY_LOW: return "low";
    case RTC_BUILD_QUALITY_MEDIUM: return "medium";
    case RTC_BUILD_QUALITY_HIGH: return "high";
    case RTC_BUILD_QUALITY_REFIT: return "refit";
  }
  return "?";
}

}  // namespace duplex::bench
