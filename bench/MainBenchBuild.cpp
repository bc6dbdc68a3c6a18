// The main benchmark's builds: our kd-tree and Embree's at each thread count (see MainBenchParts.h).

#include "MainBenchParts.h"

#include <algorithm>
#include <iostream>
#include <map>
#include <sstream>
#include <tuple>

namespace duplex::bench::main_detail {

void MeshBench::build(const LoadedMesh& loaded, nlohmann::json& out) {
  const TriangleMesh& mesh = *loaded.mesh;
  const double triangles = static_cast<double>(mesh.triangleCount());
  // Wall ms per tracer and thread count; CPU ms (calling thread) for one thread only, with the
  // process's CPU ms next to it to check that one thread did all the work.
  std::map<int, std::vector<double>> ms[kTracers], cpu_ms[kTracers], process_cpu_ms[kTracers];
  double bytes[kTracers] = {0.0, 0.0, 0.0};
  const Stopwatch phase;
  for (int rep = 0; rep < options_.repeat; ++rep) {
    for (const int t : threads_) {
      auto record = [&](int tracer, const Timing& time) {
        ms[tracer][t].push_back(time.wall_ms);
        if (t == 1) {
          cpu_ms[tracer][t].push_back(time.cpu_ms);
          process_cpu_ms[tracer][t].push_back(time.process_cpu_ms);
        }
      };
      auto buildOurs = [&] {
        ours_.reset();
        record(kOurs, timeIt(t, [&] {
                 arenas_.get(t).execute([&] { ours_ = std::make_unique<MeshObject>(loaded.mesh, config_); });
               }));
      };
      auto buildEmbree = [&] {
#if DUPLEX_BENCH_HAVE_EMBREE
        if (!haveEmbree()) return;
        // A fresh device limited to t threads, the only one alive while it builds.
        embree_.release();
        embree_.device = std::make_unique<EmbreeDevice>(t, embree_.config);
        for (const Tracer e : {kEmbreeMedium, kEmbreeHigh}) {
          std::unique_ptr<EmbreeMesh> scene;
          record(e, timeIt(t, [&] {
                   scene = std::make_unique<EmbreeMesh>(
                       *embree_.device, mesh, e == kEmbreeMedium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
                 }));
          bytes[e] = static_cast<double>(scene->accelBytes());
        }
        embree_.release();
#endif
      };
      // Alternate the order between repetitions so that drift on the shared machine hits both sides.
      if (rep % 2 == 0) {
        buildOurs();
        buildEmbree();
      } else {
        buildEmbree();
        buildOurs();
      }
    }
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  // The scenes that are traced (untimed builds, on a device with the most threads).
  if (haveEmbree()) {
    embree_.device = std::make_unique<EmbreeDevice>(threads_.back(), embree_.config);
    embree_.scenes[kEmbreeMedium] = std::make_unique<EmbreeMesh>(*embree_.device, mesh, RTC_BUILD_QUALITY_MEDIUM);
    embree_.scenes[kEmbreeHigh] = std::make_unique<EmbreeMesh>(*embree_.device, mesh, RTC_BUILD_QUALITY_HIGH);
  }
#endif
  std::cerr << "  builds: " << options_.repeat << " x " << threads_.size() << " thread counts in "
            << fmt(phase.ms() / 1e3, 1) << " s\n";

  const KdTreeStats stats = ours_->tree().stats(config_.traversal_cost, config_.intersection_cost);
  nlohmann::json& ours = out["ours"];
  ours["config"] = configJson(config_);
  ours["stats"] = statsJson(stats);
  ours["accel_bytes"] = ours_->accelBytes();
  ours["memory_bytes"] = ours_->memoryBytes();
  ours["bytes_per_triangle"] = static_cast<double>(ours_->accelBytes()) / triangles;
  double bytes_per_triangle[kTracers] = {static_cast<double>(ours_->accelBytes()) / triangles, kNaN, kNaN};
#if DUPLEX_BENCH_HAVE_EMBREE
  if (haveEmbree()) {
    for (const Tracer e : {kEmbreeMedium, kEmbreeHigh}) {
      nlohmann::json& j = out[kTracerKey[e]];
      j["quality"] = toString(e == kEmbreeMedium ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
      j["accel_bytes"] = embree_.scenes[e]->accelBytes();
      j["total_bytes"] = embree_.scenes[e]->totalBytes();
      j["accel_bytes_timed_build"] = bytes[e];
      bytes_per_triangle[e] = static_cast<double>(embree_.scenes[e]->accelBytes()) / triangles;
      j["bytes_per_triangle"] = bytes_per_triangle[e];
    }
  }
#endif
  nlohmann::json builds = nlohmann::json::array();
  std::cerr << "  build ms    " << pad("threads", 9) << lpad("ours", 10) << lpad("emb-med", 10) << lpad("emb-high", 10)
            << lpad("/med", 8) << lpad("/high", 8) << lpad("/med cpu", 10) << "\n";
  for (const int t : threads_) {
    double med[kTracers], cpu[kTracers];
    for (int k = 0; k < kTracers; ++k) {
      med[k] = ms[k].count(t) ? median(ms[k][t]) : kNaN;
      cpu[k] = cpu_ms[k].count(t) ? median(cpu_ms[k][t]) : kNaN;
    }
    nlohmann::json rec{{"threads", t}};
    for (int k = 0; k < kTracers; ++k) {
      if (!std::isfinite(med[k])) continue;
      const std::string name = kTracerKey[k];
      rec[name + "_ms"] = med[k];
      rec[name + "_ms_samples"] = ms[k][t];
      out[name]["build_ms"][std::to_string(t)] = med[k];
      if (std::isfinite(cpu[k])) {
        rec[name + "_cpu_ms"] = cpu[k];
        rec[name + "_cpu_ms_samples"] = cpu_ms[k][t];
        rec[name + "_process_cpu_ms"] = median(process_cpu_ms[k][t]);
        out[name]["build_cpu_ms"][std::to_string(t)] = cpu[k];
        // A one-thread build whose process used clearly more CPU than the calling thread ran elsewhere too.
        const double process = median(process_cpu_ms[k][t]);
        if (process > 1.2 * cpu[k] + 5.0)
          std::cerr << "  WARNING: the 1-thread build of " << name << " used " << fmt(process / cpu[k])
                    << "x the CPU of the calling thread\n";
      }
    }
    rec["ratio_vs_embree_medium"] = num(ratio(med[kOurs], med[kEmbreeMedium]));
    rec["ratio_vs_embree_high"] = num(ratio(med[kOurs], med[kEmbreeHigh]));
    rec["ratio_cpu_vs_embree_medium"] = num(ratio(cpu[kOurs], cpu[kEmbreeMedium]));
    rec["ratio_cpu_vs_embree_high"] = num(ratio(cpu[kOurs], cpu[kEmbreeHigh]));
    builds.push_back(rec);
    std::cerr << "              " << pad(std::to_string(t), 9) << lpad(fmt(med[kOurs], 1), 10)
              << lpad(fmt(med[kEmbreeMedium], 1), 10) << lpad(fmt(med[kEmbreeHigh], 1), 10)
              << lpad(fmt(ratio(med[kOurs], med[kEmbreeMedium])) + "x", 8)
              << lpad(fmt(ratio(med[kOurs], med[kEmbreeHigh])) + "x", 8)
              << lpad(fmt(ratio(cpu[kOurs], cpu[kEmbreeMedium])) + "x", 10) << "\n";
  }
  out["build"] = builds;
  std::cerr << "  bytes/tri   ours " << fmt(bytes_per_triangle[kOurs], 1) << "  emb-med "
            << fmt(bytes_per_triangle[kEmbreeMedium], 1) << "  emb-high " << fmt(bytes_per_triangle[kEmbreeHigh], 1)
            << "\n";
  std::cerr << "  tree        nodes " << thousands(stats.nodes) << "  leaves " << thousands(stats.leaves) << " ("
            << thousands(stats.empty_leaves) << " empty)  avg leaf " << fmt(stats.avg_leaf_size) << "  SAH "
            << fmt(stats.sah_cost, 1) << "  depth " << stats.max_depth << "\n";
  out["ratios"]["vs_embree_medium"]["bytes_per_triangle"] =
      num(ratio(bytes_per_triangle[kOurs], bytes_per_triangle[kEmbreeMedium]));
  out["ratios"]["vs_embree_high"]["bytes_per_triangle"] =
      num(ratio(bytes_per_triangle[kOurs], bytes_per_triangle[kEmbreeHigh]));
  for (const auto& rec : builds) {
    const std::string key = std::to_string(rec["threads"].get<int>()) + "T";
    out["ratios"]["vs_embree_medium"]["build"][key] = rec["ratio_vs_embree_medium"];
    out["ratios"]["vs_embree_high"]["build"][key] = rec["ratio_vs_embree_high"];
    if (!rec["ratio_cpu_vs_embree_medium"].is_null()) {
      out["ratios"]["vs_embree_medium"]["build_cpu"][key] = rec["ratio_cpu_vs_embree_medium"];
      out["ratios"]["vs_embree_high"]["build_cpu"][key] = rec["ratio_cpu_vs_embree_high"];
    }
  }
}

}  // namespace duplex::bench::main_detail
