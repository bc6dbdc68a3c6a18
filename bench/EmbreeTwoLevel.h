#pragma once
/// \file EmbreeTwoLevel.h
/// Embree 3 two-level scenes as the baseline of the update benchmark (`duplex bench update`): one
/// Embree scene per object, a top-level scene with one RTC_GEOMETRY_TYPE_INSTANCE per instance.
/// Moving, adding or removing an instance edits its instance geometry; commit() then recommits the
/// top level, which Embree rebuilds over all instances. Compiled only when Embree is found
/// (DUPLEX_BENCH_HAVE_EMBREE).
///
/// Threads: builds run in the device's own TBB arena (see EmbreeDevice); queries are thread-safe
/// between commits; edits and commit() must come from one thread with no query running.

#include "EmbreeBaseline.h"

#include "duplex/accel/Affine.h"
#include "duplex/accel/Hit.h"
#include "duplex/accel/Ray.h"
#include "duplex/objects/TriangleMesh.h"

#include <embree3/rtcore.h>

#include <cstdint>
#include <span>
#include <vector>

namespace duplex::bench {

/// Build flags of the top-level scene. Object scenes use Embree's defaults (medium quality, static)
/// unless the constructor is given another object quality.
enum class EmbreeTopLevelMode : std::uint8_t {
  Default,     ///< RTC_BUILD_QUALITY_MEDIUM, no scene flags (Embree's defaults)
  DynamicLow,  ///< RTC_SCENE_FLAG_DYNAMIC + RTC_BUILD_QUALITY_LOW (Embree's advice for scenes that change)
  Robust,      ///< RTC_SCENE_FLAG_ROBUST on the top level and every object scene (Embree's watertight mode)
};

[[nodiscard]] const char* toString(EmbreeTopLevelMode mode);

/// One instance: which object (index into the object list) and world_from_object.
struct EmbreeInstanceDesc {
  std::uint32_t object = 0;
  Affine world_from_object;
};

/// Figures of the constructor's build (wall-clock milliseconds).
struct EmbreeTwoLevelBuildTimes {
  double objects_ms = 0.0;  ///< every object scene: buffers plus rtcCommitScene (in parallel over objects)
  double top_ms = 0.0;      ///< instance geometries plus the top-level rtcCommitScene
};

class EmbreeTwoLevel {
 public:
  /// Builds one scene per mesh (in parallel, in the calling thread's TBB arena) and the committed
  /// top level; instance ids are positions in `instances`. The meshes are copied into Embree
  /// buffers (they need not outlive the scene). `object_quality`: the object scenes' build quality
  /// (RTC_BUILD_QUALITY_HIGH adds spatial splits, Embree's counterpart of our clipped references).
  EmbreeTwoLevel(EmbreeDevice& device, std::span<const TriangleMesh* const> meshes,
                 std::span<const EmbreeInstanceDesc> instances, EmbreeTopLevelMode mode,
                 RTCBuildQuality object_quality = RTC_BUILD_QUALITY_MEDIUM);
  ~EmbreeTwoLevel();
  EmbreeTwoLevel(const EmbreeTwoLevel&) = delete;
  EmbreeTwoLevel& operator=(const EmbreeTwoLevel&) = delete;

  [[nodiscard]] const EmbreeTwoLevelBuildTimes& buildTimes() const { return build_times_; }
  /// Ids ever handed out (removed ones included).
  [[nodiscard]] std::uint32_t instanceIdBound() const { return static_cast<std::uint32_t>(instances_.size()); }

  // ---- edits: visible to queries after commit() ----
  /// New world_from_object of a live instance (rtcSetGeometryTransform + rtcCommitGeometry).
  void setTransform(std::uint32_t instance, const Affine& world_from_object);
  /// Attaches a new instance of `object`; returns its id (the next unused id).
  std::uint32_t addInstance(std::uint32_t object, const Affine& world_from_object);
  /// Detaches a live instance; its id is not reused.
  void removeInstance(std::uint32_t instance);
  /// rtcCommitScene of the top level.
  void commit();

  /// Closest hit: t (units of the world ray's direction), u, v, prim_id (triangle in its object),
  /// instance_id, and ng in the object's space (Embree 3's convention for instanced hits). A miss
  /// is an invalid Hit. Thread-safe between commits.
  [[nodiscard]] Hit intersect(const Ray& ray_ws) const;
  /// The committed top-level scene, for queries the wrapper does not offer (packets, occlusion).
  [[nodiscard]] RTCScene scene() const { return top_; }

 private:
  RTCGeometry newInstanceGeometry(std::uint32_t object, const Affine& world_from_object);

  EmbreeDevice& device_;
  std::vector<RTCScene> object_scenes_;
  std::vector<RTCGeometry> instances_;  ///< by id; null once removed
  RTCScene top_ = nullptr;
  EmbreeTwoLevelBuildTimes build_times_;
};

}  // namespace duplex::bench
