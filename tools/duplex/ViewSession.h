#pragma once
/// \file ViewSession.h
/// The scene behind `duplex view`, without HTTP: what each request of the viewer's interface does
/// (docs/viewer.md), on one scene shared by every client. Requests come as parsed JSON and answer
/// JSON (or an image); a bad request throws RequestError naming the problem and changes nothing.
///
/// Threading: any number of threads may call any method at once. Renders, picks and reads of the
/// graph share a WriterPreferringMutex; edits, undo and the timeline take it exclusively (and the
/// graph's commit updates the tracer inside), so a drag's commit waits only for the frames already
/// being traced, never behind a queue of new ones.

#include "DemoRenderer.h"
#include "LoadScene.h"
#include "WorkerThreads.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/RayGenerator.h>
#include <duplex/accel/WriterPreferringMutex.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/sensors/SensorRun.h>
#include <duplex/sensors/SensorScene.h>

#include <nlohmann/json.hpp>

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace duplex::cli {

/// A request the viewer refuses (HTTP 400): the message names the input and the problem.
class RequestError : public InvalidArgument {
 public:
  using InvalidArgument::InvalidArgument;
};

/// A camera of a request, as given ({"eye", "target", "up", "fov_deg", "width", "height"}, world
/// space), checked and turned into the library's pinhole camera.
struct ViewCamera {
  PinholeCamera camera;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
};

/// Largest image side a request may ask for, pixels.
inline constexpr std::uint32_t kMaxImageSide = 8192;

/// Reads a camera object; `what` names it in messages ("camera"). Throws RequestError for missing
/// keys, non-numbers, NaN or infinite values, a zero or non-integer size or one over kMaxImageSide,
/// a field of view outside (0, 180) degrees, eye == target, or up parallel to the view direction.
[[nodiscard]] ViewCamera readCamera(const nlohmann::json& value, const std::string& what);

/// A sensor's map from the last run, to draw on its surface in frames (object space: a flat
/// sensor's plane z = 0, centred, width x height, bins row-major with x fastest; a sphere of
/// diameter width centred at the origin, bins by outward normal as SensorObject::sphereBinAt).
struct SensorOverlay {
  Affine object_from_world;
  bool disk = false;
  std::shared_ptr<const SensorObject> sphere;  ///< a sphere sensor (its bins); null for flat ones
  double width = 1.0, height = 1.0;
  std::uint32_t nx = 1, ny = 1;
  std::vector<double> values;  ///< irradiance per bin
  double max = 0.0;            ///< the largest finite value (> 0)
};

/// The maps of a run's results on `scene` of the sensors with a surface (rectangles, disks, spheres).
[[nodiscard]] std::vector<SensorOverlay> sensorOverlays(const SensorScene& scene, const SensorRunResults& r);

/// Draws `overlays` into rows [r0, r1) of `image` (the frame of `cam`) where the primary ray of
/// `renderer`'s last strip (rows r0..r1) crosses a sensor before its hit.
void drawOverlays(const std::vector<SensorOverlay>& overlays, const ViewCamera& cam, const demo::DemoRenderer& renderer,
                  std::uint32_t r0, std::uint32_t r1, demo::RgbImage& image);

/// A rendered frame and its figures.
struct ViewFrame {
  demo::RgbImage image;
  /// Per pixel (row-major), the hit file's instance id and the triangle of the primary hit
  /// (0xFFFFFFFF for a miss; 0xFFFFFFFE for an instance that is not one of the file's, added by an edit).
  std::vector<std::uint32_t> ids;
  double trace_ms = 0.0;     ///< primary and shadow queries, wall-clock milliseconds
  std::size_t rays = 0;      ///< primary + shadow rays
  std::uint64_t commit = 0;  ///< the graph's commit count the frame shows
};

/// See the file comment.
class ViewSession {
 public:
  /// Loads `scene` (either format, lights and sensors included) with `threads` workers (the TBB
  /// arena every render, pick, commit and sensor run uses). Throws duplex::Error naming the file.
  ViewSession(const std::filesystem::path& scene, int threads);
  ~ViewSession();
  ViewSession(const ViewSession&) = delete;
  ViewSession& operator=(const ViewSession&) = delete;

  /// GET /api/scene.
  [[nodiscard]] nlohmann::json scene() const;
  /// POST /api/render's frame (the body's camera, an optional "highlight" node path tinted). With
  /// `ids`, the per-pixel ids are filled too.
  [[nodiscard]] ViewFrame render(const nlohmann::json& body, bool ids) const;
  /// POST /api/pick.
  [[nodiscard]] nlohmann::json pick(const nlohmann::json& body) const;
  /// POST /api/edits: applied and committed as one commit, or refused with the scene unchanged.
  [[nodiscard]] nlohmann::json edits(const nlohmann::json& body);
  /// POST /api/undo: rolls back the last commit made by edits().
  [[nodiscard]] nlohmann::json undo();
  /// POST /api/time: the scene as its timed edits leave it at t.
  [[nodiscard]] nlohmann::json time(const nlohmann::json& body);
  /// POST /api/sensors/run.
  [[nodiscard]] nlohmann::json sensorsRun(const nlohmann::json& body);
  /// GET /api/sensors/status.
  [[nodiscard]] nlohmann::json sensorsStatus() const;
  /// POST /api/sensors/cancel.
  [[nodiscard]] nlohmann::json sensorsCancel();

  /// The number of worker threads.
  [[nodiscard]] int threads() const { return threads_; }

 private:
  using Inverse = std::function<void(SceneGraph&)>;
  /// Applies `edits` with their inverses (in order) and commits; rolls back and rethrows on failure.
  nlohmann::json applyAndCommit(const std::vector<SceneEdit>& edits, std::vector<Inverse>* inverses);
  /// Applies the inverses (last first) and commits; rolls back and rethrows on failure.
  nlohmann::json revert(const std::vector<Inverse>& inverses);
  void refuseWhileSensorsRun(const char* what) const;
  /// Brings the sensor scene's derived state up to date (after a commit, under the exclusive lock).
  void deriveSensorScene();
  void joinSensorThread();

  int threads_;
  std::unique_ptr<WorkerThreads> workers_;  ///< --threads: the arena and the process-wide limit
  tbb::task_arena* arena_ = nullptr;
  std::optional<SensorScene> scene_;
  SceneDocument* doc_ = nullptr;
  /// The hit file's instance id per node id (kInvalidId for nodes that are not the file's
  /// instances); instances that undo adds back take over their predecessors' ids.
  std::vector<std::uint32_t> hit_ids_;
  [[nodiscard]] std::uint32_t hitId(NodeId node) const { return node < hit_ids_.size() ? hit_ids_[node] : kInvalidId; }
  mutable WriterPreferringMutex mutex_;
  mutable std::mutex pool_mutex_;
  mutable std::vector<std::unique_ptr<demo::DemoRenderer>> renderers_;  ///< idle renderers, for reuse

  std::vector<std::vector<Inverse>> undo_;      ///< commits made through edits(), oldest first
  std::string undo_group_;                      ///< the "group" of the last edits() commit
  std::vector<std::vector<Inverse>> timeline_;  ///< one per group of timed edits applied, oldest first
  std::vector<std::size_t> timeline_end_;       ///< edits applied after each entry of timeline_
  double time_ = 0.0;

  // Sensor runs: one at a time, on a thread of their own; edits are refused while one runs.
  mutable std::mutex sensor_mutex_;
  std::unique_ptr<SensorRun> run_;
  std::thread sensor_thread_;
  std::atomic<bool> sensor_running_{false};
  std::atomic<bool> sensor_cancel_{false};  ///< /api/sensors/cancel was asked during this run
  std::atomic<std::uint64_t> sensor_done_{0};
  std::uint64_t sensor_target_ = 0;
  std::string sensor_state_ = "idle";  ///< idle, running, completed, cancelled, failed
  std::string sensor_error_;
  nlohmann::json sensor_results_;
  std::vector<SensorOverlay> overlays_;  ///< the last run's planar maps
};

}  // namespace duplex::cli
