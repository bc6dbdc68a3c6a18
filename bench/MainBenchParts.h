#pragma once
// Private to bench/: the parts of the main benchmark (MainBench.cpp runs it): one mesh's run
// (MeshBench), split by concept into its builds (MainBenchBuild.cpp), the agreement checks of the
// tracers (MainBenchAgreement.cpp), the traces with the time split (MainBenchTrace.cpp) and the
// watertightness count (MainBenchWatertight.cpp).

#include "BenchChecks.h"
#include "BenchMeshes.h"
#include "BenchModes.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif

#include "duplex/accel/BvhBuildConfig.h"
#include "duplex/accel/KdBuildConfig.h"
#include "duplex/accel/KdTree.h"
#include "duplex/objects/MeshObject.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace duplex::bench::main_detail {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One structure measured by the run: one of ours (a BVH config or the kd-tree) or one of Embree's
/// builds. `key` names it in the JSON ("bvh_medium", "kdtree", "embree_robust", ...).
struct TracerDef {
  enum class Kind { Bvh, KdTree, Embree };
  std::string key;
  std::string spec;  ///< as given on the command line ("bvh:medium", "kdtree", "embree:robust")
  Kind kind = Kind::Bvh;
  BvhBuildConfig bvh;
  KdBuildConfig kd;
  bool embree_high = false;    ///< RTC_BUILD_QUALITY_HIGH (else MEDIUM)
  bool embree_robust = false;  ///< RTC_SCENE_FLAG_ROBUST
  bool is_default = false;     ///< MeshObject's default structure and config
  [[nodiscard]] bool ours() const { return kind != Kind::Embree; }
};

/// The reference of every ratio: Embree's medium build, non-robust (its default).
inline constexpr const char* kReferenceKey = "embree_medium";

/// The tracers of a run from --structures and --embree-builds (Embree's medium build always, as
/// the reference, when Embree takes part). Throws InvalidArgument for an unknown spec.
[[nodiscard]] std::vector<TracerDef> tracerDefs(const Options& options, bool with_embree);
/// The key of MeshObject's default structure ("bvh_medium").
[[nodiscard]] std::string defaultStructureKey();

struct RaySet {
  std::string name;
  std::vector<Ray> rays;
};

// The build configuration and the tree's figures as the JSON reports them.
nlohmann::json configJson(const KdBuildConfig& c);
nlohmann::json statsJson(const KdTreeStats& s);

inline double ratio(double a, double b) { return (std::isfinite(a) && std::isfinite(b) && b > 0.0) ? a / b : kNaN; }

// JSON number or null (nlohmann writes NaN as null anyway; this keeps the intent visible).
inline nlohmann::json num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

// Embree's side of a run: whether it takes part, and the device being used. Only one device lives
// at a time (see EmbreeBaseline.h: a second device with more threads lets a "threads=1" device
// build on two).
struct EmbreeSide {
  bool enabled_ = false;
#if DUPLEX_BENCH_HAVE_EMBREE
  std::string config;
  std::unique_ptr<EmbreeDevice> device;
#endif
  [[nodiscard]] bool enabled() const { return enabled_; }
};

/// The built structure of one tracer: a MeshObject or an Embree scene.
struct Built {
  std::unique_ptr<MeshObject> object;
#if DUPLEX_BENCH_HAVE_EMBREE
  std::unique_ptr<EmbreeMesh> scene;
#endif
  bool available = true;  ///< false when its build threw (the reason in `note`)
  std::string note;
};

class MeshBench {
 public:
  MeshBench(const Options& options, const std::vector<int>& threads, Arenas& arenas, EmbreeSide& embree,
            std::vector<TracerDef> defs)
      : options_(options), threads_(threads), arenas_(arenas), embree_(embree), defs_(std::move(defs)) {}

  nlohmann::json run(const LoadedMesh& loaded);
  [[nodiscard]] const std::vector<TracerDef>& defs() const { return defs_; }

 private:
  [[nodiscard]] bool haveEmbree() const { return embree_.enabled(); }
  /// Index of the tracer `key` among defs_ when it was built, else -1.
  [[nodiscard]] int find(const std::string& key) const;
  /// The tracers built, in defs_ order.
  [[nodiscard]] std::vector<int> live() const;
  /// Closest hit / any hit of tracer k (untimed checks; the timed loops call the structures directly).
  bool intersect(int k, const Ray& ray, Hit& hit) const;
  [[nodiscard]] bool occluded(int k, const Ray& ray) const;
  [[nodiscard]] TraceTiming timeTracer(int k, tbb::task_arena& arena, std::span<const Ray> rays, Query q) const;
  /// Builds tracer k with `threads` threads (Embree: on embree_.device); returns its timing.
  Timing buildOne(int k, const TriangleMesh& mesh, const std::shared_ptr<const TriangleMesh>& shared, int threads);

  void build(const LoadedMesh& loaded, nlohmann::json& out);
  void checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out);
  void trace(const std::vector<RaySet>& sets, nlohmann::json& out);
  void timeSplit(const RaySet& random, nlohmann::json& out);
  void watertight(const TriangleMesh& mesh, nlohmann::json& out);
  /// ratios.<key>_vs_embree_medium.<section>[label] (or .<section> for an empty label) = values[k] / values[reference]
  /// for every tracer but the reference (and <key>_vs_embree_high for ours); the default structure's also as
  /// ratios.vs_embree_medium / vs_embree_high. `values` is indexed like defs_; NaN: not measured.
  void addRatios(nlohmann::json& out, const std::string& section, const std::string& label,
                 const std::vector<double>& values) const;

  const Options& options_;
  const std::vector<int>& threads_;
  Arenas& arenas_;
  EmbreeSide& embree_;
  std::vector<TracerDef> defs_;
  std::vector<Built> built_;
};

}  // namespace duplex::bench::main_detail
