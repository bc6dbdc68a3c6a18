#pragma once
/// \file EmbreeBaseline.h
/// Embree 3 as the baseline: one triangle geometry per scene, traced with rtcIntersect1 /
/// rtcOccluded1 (single rays, no packets). Compiled only when Embree is found
/// (DUPLEX_BENCH_HAVE_EMBREE).
///
/// Threads: with TBB tasking, Embree builds inside its device's own task_arena, sized from the
/// device's "threads=N" setting, and "threads=N" also installs a process-wide
/// tbb::global_control(max_allowed_parallelism) for the largest N among the live devices. Measured
/// here (Embree 3.13.5, oneTBB 2021.8): while a "threads=2" device is alive, a "threads=1" device's
/// build runs on two threads (process CPU = 2x the calling thread's). So the benchmark keeps one
/// device alive at a time: a fresh device with threads=N for each N-thread build measurement, and
/// one more for the scenes it traces (rtcIntersect1 runs on the calling thread, in our arenas).

#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/TriangleMesh.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <string>

#include <sys/types.h>

namespace duplex::bench {

/// An RTCDevice limited to `threads` build threads, counting the bytes Embree allocates.
class EmbreeDevice {
 public:
  /// `extra_config` is appended to the rtcNewDevice configuration string (e.g. "isa=avx2").
  EmbreeDevice(int threads, const std::string& extra_config);
  ~EmbreeDevice();
  EmbreeDevice(const EmbreeDevice&) = delete;
  EmbreeDevice& operator=(const EmbreeDevice&) = delete;

  [[nodiscard]] RTCDevice get() const { return device_; }
  [[nodiscard]] int threads() const { return threads_; }
  /// Bytes currently allocated through this device (memory monitor callback).
  [[nodiscard]] std::int64_t allocatedBytes() const { return bytes_.load(); }
  /// Throws std::runtime_error with `what` when Embree reported an error since the last check.
  void check(const std::string& what) const;

 private:
  static bool monitor(void* self, ssize_t bytes, bool post);
  RTCDevice device_ = nullptr;
  int threads_;
  std::atomic<std::int64_t> bytes_{0};
};

/// A committed Embree scene over one triangle mesh. Thread-safe queries after construction.
/// Embree's ray-hit record of `ray` with t in [ray.tnear, tfar] and no hit yet.
inline RTCRayHit toRayHit(const Ray& ray, float tfar) {
  RTCRayHit rh;
  rh.ray.org_x = ray.origin.x;
  rh.ray.org_y = ray.origin.y;
  rh.ray.org_z = ray.origin.z;
  rh.ray.tnear = ray.tnear;
  rh.ray.dir_x = ray.dir.x;
  rh.ray.dir_y = ray.dir.y;
  rh.ray.dir_z = ray.dir.z;
  rh.ray.time = 0.0f;
  rh.ray.tfar = tfar;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

/// Copies `mesh` into a new triangle geometry built with `quality` and attaches it to `scene`
/// (not committed). Throws std::runtime_error when Embree cannot allocate the buffers.
void attachTriangleMesh(EmbreeDevice& device, RTCScene scene, const TriangleMesh& mesh, RTCBuildQuality quality);

class EmbreeMesh {
 public:
  /// Copies the mesh into Embree buffers and commits with `quality` and scene `flags` (the timed
  /// "build" is this constructor: geometry setup plus rtcCommitScene). RTC_SCENE_FLAG_ROBUST makes
  /// Embree's traversal and triangle test watertight at some speed.
  EmbreeMesh(EmbreeDevice& device, const TriangleMesh& mesh, RTCBuildQuality quality,
             RTCSceneFlags flags = RTC_SCENE_FLAG_NONE);
  ~EmbreeMesh();
  EmbreeMesh(const EmbreeMesh&) = delete;
  EmbreeMesh& operator=(const EmbreeMesh&) = delete;

  /// Closest hit with t in [ray.tnear, min(ray.tfar, hit.t)]; fills hit like MeshObject::intersect.
  bool intersect(const Ray& ray, Hit& hit) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh = toRayHit(ray, std::min(ray.tfar, hit.t));
    rtcIntersect1(scene_, &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
    hit.t = rh.ray.tfar;
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
    hit.prim_id = rh.hit.primID;
    hit.ng = {rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
    return true;
  }

  /// Whether anything is hit within [tnear, tfar].
  [[nodiscard]] bool occluded(const Ray& ray) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRay r;
    r.org_x = ray.origin.x;
    r.org_y = ray.origin.y;
    r.org_z = ray.origin.z;
    r.tnear = ray.tnear;
    r.dir_x = ray.dir.x;
    r.dir_y = ray.dir.y;
    r.dir_z = ray.dir.z;
    r.time = 0.0f;
    r.tfar = ray.tfar;
    r.mask = 0xFFFFFFFFu;
    r.id = 0;
    r.flags = 0;
    rtcOccluded1(scene_, &context, &r);
    return r.tfar < 0.0f;  // Embree sets tfar to -inf on an occlusion
  }

  /// The committed scene, for queries the wrapper does not offer (rtcPointQuery).
  [[nodiscard]] RTCScene scene() const { return scene_; }

  /// Bytes Embree allocated for the scene (memory monitor), minus our vertex and index buffers:
  /// the BVH with its leaf triangle data, comparable to MeshObject::accelBytes().
  [[nodiscard]] std::size_t accelBytes() const { return accel_bytes_; }
  /// Everything allocated for the scene, buffers included.
  [[nodiscard]] std::size_t totalBytes() const { return total_bytes_; }

 private:
  RTCScene scene_ = nullptr;
  std::size_t accel_bytes_ = 0;
  std::size_t total_bytes_ = 0;
};

[[nodiscard]] const char* toString(RTCBuildQuality quality);

}  // namespace duplex::bench
