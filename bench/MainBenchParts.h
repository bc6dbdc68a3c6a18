#pragma once
// Private to bench/: the parts of the main benchmark (MainBench.cpp runs it): one mesh's run
// (MeshBench), split by concept into its builds (MainBenchBuild.cpp), the agreement checks of the
// tracers (MainBenchAgreement.cpp) and the traces with the time split (MainBenchTrace.cpp).

#include "BenchChecks.h"
#include "BenchMeshes.h"
#include "BenchModes.h"

#if DUPLEX_BENCH_HAVE_EMBREE
#include "EmbreeBaseline.h"
#endif

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

// The tracers of one run: ours always, Embree's two qualities when available.
enum Tracer { kOurs = 0, kEmbreeMedium = 1, kEmbreeHigh = 2, kTracers = 3 };
inline constexpr const char* kTracerKey[kTracers] = {"ours", "embree_medium", "embree_high"};

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

// Embree's side of a run: whether it takes part, and the device and scenes being traced. Only one
// device lives at a time (see EmbreeBaseline.h: a second device with more threads lets a
// "threads=1" device build on two).
struct EmbreeSide {
  bool enabled_ = false;
#if DUPLEX_BENCH_HAVE_EMBREE
  std::string config;
  std::unique_ptr<EmbreeDevice> device;
  std::unique_ptr<EmbreeMesh> scenes[kTracers];  // [kEmbreeMedium], [kEmbreeHigh]
  void release() {
    for (auto& scene : scenes) scene.reset();  // scenes before their device
    device.reset();
  }
#endif
  [[nodiscard]] bool enabled() const { return enabled_; }
};

class MeshBench {
 public:
  MeshBench(const Options& options, const std::vector<int>& threads, Arenas& arenas, EmbreeSide& embree)
      : options_(options), threads_(threads), arenas_(arenas), embree_(embree) {}

  nlohmann::json run(const LoadedMesh& loaded);

 private:
  [[nodiscard]] bool haveEmbree() const { return embree_.enabled(); }
  void build(const LoadedMesh& loaded, nlohmann::json& out);
  void checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out);
  void trace(const std::vector<RaySet>& sets, nlohmann::json& out);
  void timeSplit(const RaySet& random, nlohmann::json& out);

  const Options& options_;
  const std::vector<int>& threads_;
  Arenas& arenas_;
  KdBuildConfig config_{};
  EmbreeSide& embree_;
  std::unique_ptr<MeshObject> ours_;
};

}  // namespace duplex::bench::main_detail
