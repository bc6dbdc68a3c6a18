// The main benchmark's agreement checks: the tracers answer every ray alike (see MainBenchParts.h).

#include "MainBenchParts.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <iostream>

namespace duplex::bench::main_detail {

void MeshBench::checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out) {
  const int ref = find(kReferenceKey);
  if (ref < 0) {
    out["agreement"] = nullptr;
    return;
  }
  nlohmann::json agreement;
  tbb::task_arena& arena = arenas_.get(threads_.back());
  const float inf = std::numeric_limits<float>::infinity();
  const std::vector<int> tracers = live();
  const double scale = glm::length(mesh.bounds().extent());
  for (const RaySet& set : sets) {
    const std::size_t n = set.rays.size();
    std::vector<std::vector<float>> t(defs_.size());
    std::vector<std::vector<std::uint8_t>> occ(defs_.size());
    for (const int k : tracers) {
      t[k].assign(n, inf);
      occ[k].assign(n, 0);
    }
    parallelFor(arena, n, [&](std::size_t i) {
      const Ray& r = set.rays[i];
      for (const int k : tracers) {
        Hit h;
        if (intersect(k, r, h)) t[k][i] = h.t;
        occ[k][i] = occluded(k, r);
      }
    });
    // Per tracer against Embree's medium build; rays where any of ours disagree on hit or miss go
    // to the referee.
    nlohmann::json by_tracer;
    std::vector<std::size_t> disputed;
    for (std::size_t i = 0; i < n; ++i) {
      const bool hr = t[ref][i] < inf;
      if (std::any_of(tracers.begin(), tracers.end(), [&](int k) { return defs_[k].ours() && (t[k][i] < inf) != hr; }))
        disputed.push_back(i);
    }
    std::cerr << "  agreement   " << pad(set.name, 8) << "hit/miss vs embree_medium:";
    for (const int k : tracers) {
      if (k == ref) continue;
      std::uint64_t hits = 0, hitmiss = 0, t_mismatch = 0, any_disagree = 0, any_vs_closest = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const bool hk = t[k][i] < inf, hr = t[ref][i] < inf;
        hits += hk;
        hitmiss += hk != hr;
        if (hk && hr) {
          const double dt = std::abs(static_cast<double>(t[k][i]) - t[ref][i]);
          if (dt > 1e-4 * std::max<double>(t[k][i], t[ref][i]) + 1e-6 * scale) ++t_mismatch;
        }
        any_disagree += occ[k][i] != occ[ref][i];
        any_vs_closest += (occ[k][i] != 0) != hk;
      }
      by_tracer[defs_[k].key] = {{"hits", hits},
                                 {"hitmiss_disagree_vs_embree_medium", hitmiss},
                                 {"t_mismatch_vs_embree_medium", t_mismatch},
                                 {"anyhit_disagree_vs_embree_medium", any_disagree},
                                 {"anyhit_vs_closest_disagree", any_vs_closest}};
      std::cerr << " " << defs_[k].key << " " << thousands(hitmiss);
      if (any_vs_closest != 0 && defs_[k].ours())
        std::cerr << "\n  WARNING: occluded() and intersect() of " << defs_[k].key << " disagree on " << any_vs_closest
                  << " rays\n";
    }
    std::uint64_t ref_hits = 0;
    for (std::size_t i = 0; i < n; ++i) ref_hits += t[ref][i] < inf;
    by_tracer[kReferenceKey] = {{"hits", ref_hits}};

    // A double-precision brute force decides a sample of the disputed rays.
    constexpr std::size_t kRefereeSample = 48;
    const std::size_t examined = std::min(disputed.size(), kRefereeSample);
    std::vector<std::uint64_t> right(defs_.size(), 0);
    nlohmann::json wrong = nlohmann::json::array();  // rays to reproduce where the referee says one of ours is wrong
    for (std::size_t e = 0; e < examined; ++e) {
      const std::size_t i = disputed[e * disputed.size() / examined];
      const Ray& r = set.rays[i];
      const bool truth = refereeHits(arena, mesh, r);
      for (const int k : tracers) {
        if ((t[k][i] < inf) == truth) {
          ++right[k];
        } else if (defs_[k].ours() && wrong.size() < 5) {
          wrong.push_back({{"index", i},
                           {"structure", defs_[k].key},
                           {"origin", {r.origin.x, r.origin.y, r.origin.z}},
                           {"dir", {r.dir.x, r.dir.y, r.dir.z}},
                           {"tnear", r.tnear},
                           {"t", num(t[k][i])},
                           {"embree_medium_t", num(t[ref][i])},
                           {"referee_hits", truth}});
        }
      }
    }
    nlohmann::json referee{{"disputed", disputed.size()}, {"examined", examined}};
    for (const int k : tracers) referee["right"][defs_[k].key] = right[k];
    referee["rays_referee_says_ours_wrong"] = wrong;
    agreement[set.name] = {{"rays", n}, {"by_structure", by_tracer}, {"referee", referee}};
    std::cerr << " (of " << thousands(n) << "); referee on " << examined << " of " << thousands(disputed.size())
              << " disputed\n";
  }
  out["agreement"] = agreement;
}

}  // namespace duplex::bench::main_detail
