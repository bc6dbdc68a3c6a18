// The main benchmark's agreement checks: the tracers answer every ray alike (see MainBenchParts.h).

#include "MainBenchParts.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <iostream>
#include <map>
#include <sstream>
#include <tuple>

namespace duplex::bench::main_detail {

void MeshBench::checkAgreement(const TriangleMesh& mesh, const std::vector<RaySet>& sets, nlohmann::json& out) {
  nlohmann::json agreement;
  if (!haveEmbree()) {
    out["agreement"] = nullptr;
    return;
  }
#if DUPLEX_BENCH_HAVE_EMBREE
  tbb::task_arena& arena = arenas_.get(threads_.back());
  const float inf = std::numeric_limits<float>::infinity();
  for (const RaySet& set : sets) {
    const std::size_t n = set.rays.size();
    std::vector<float> t[kTracers];
    std::vector<std::uint8_t> occluded_ours(n), occluded_medium(n);
    for (auto& v : t) v.assign(n, inf);
    parallelFor(arena, n, [&](std::size_t i) {
      const Ray& r = set.rays[i];
      Hit h[kTracers];
      if (ours_->intersect(r, h[kOurs])) t[kOurs][i] = h[kOurs].t;
      if (embree_.scenes[kEmbreeMedium]->intersect(r, h[kEmbreeMedium])) t[kEmbreeMedium][i] = h[kEmbreeMedium].t;
      if (embree_.scenes[kEmbreeHigh]->intersect(r, h[kEmbreeHigh])) t[kEmbreeHigh][i] = h[kEmbreeHigh].t;
      occluded_ours[i] = ours_->occluded(r);
      occluded_medium[i] = embree_.scenes[kEmbreeMedium]->occluded(r);
    });
    std::uint64_t hits[kTracers] = {}, hitmiss_medium = 0, hitmiss_high = 0, t_mismatch = 0, any_disagree = 0,
                  ours_any_vs_closest = 0;
    std::vector<std::size_t> disputed;
    const double scale = glm::length(mesh.bounds().extent());
    for (std::size_t i = 0; i < n; ++i) {
      const bool ho = t[kOurs][i] < inf, hm = t[kEmbreeMedium][i] < inf, hh = t[kEmbreeHigh][i] < inf;
      hits[kOurs] += ho;
      hits[kEmbreeMedium] += hm;
      hits[kEmbreeHigh] += hh;
      if (ho != hm) {
        ++hitmiss_medium;
        disputed.push_back(i);
      }
      hitmiss_high += ho != hh;
      if (ho && hm) {
        const double dt = std::abs(static_cast<double>(t[kOurs][i]) - t[kEmbreeMedium][i]);
        if (dt > 1e-4 * std::max<double>(t[kOurs][i], t[kEmbreeMedium][i]) + 1e-6 * scale) ++t_mismatch;
      }
      any_disagree += occluded_ours[i] != occluded_medium[i];
      ours_any_vs_closest += (occluded_ours[i] != 0) != ho;
    }
    // A double-precision brute force decides a sample of the disputed rays.
    constexpr std::size_t kRefereeSample = 48;
    std::uint64_t referee_ours = 0, referee_embree = 0;
    const std::size_t examined = std::min(disputed.size(), kRefereeSample);
    nlohmann::json wrong_ours = nlohmann::json::array();  // rays to reproduce where the referee says we are wrong
    for (std::size_t k = 0; k < examined; ++k) {
      const std::size_t i = disputed[k * disputed.size() / examined];
      const Ray& r = set.rays[i];
      const bool truth = refereeHits(arena, mesh, r);
      if (truth == (t[kOurs][i] < inf)) {
        ++referee_ours;
      } else if (wrong_ours.size() < 5) {
        wrong_ours.push_back({{"index", i},
                              {"origin", {r.origin.x, r.origin.y, r.origin.z}},
                              {"dir", {r.dir.x, r.dir.y, r.dir.z}},
                              {"tnear", r.tnear},
                              {"ours_t", num(t[kOurs][i])},
                              {"embree_medium_t", num(t[kEmbreeMedium][i])},
                              {"referee_hits", truth}});
      }
      if (truth == (t[kEmbreeMedium][i] < inf)) ++referee_embree;
    }
    agreement[set.name] = {{"rays", n},
                           {"hits_ours", hits[kOurs]},
                           {"hits_embree_medium", hits[kEmbreeMedium]},
                           {"hits_embree_high", hits[kEmbreeHigh]},
                           {"hitmiss_disagree_vs_medium", hitmiss_medium},
                           {"hitmiss_disagree_vs_high", hitmiss_high},
                           {"t_mismatch_vs_medium", t_mismatch},
                           {"anyhit_disagree_vs_medium", any_disagree},
                           {"ours_anyhit_vs_closest_disagree", ours_any_vs_closest},
                           {"referee_examined", examined},
                           {"referee_sides_with_ours", referee_ours},
                           {"referee_sides_with_embree", referee_embree},
                           {"rays_referee_says_ours_wrong", wrong_ours}};
    std::cerr << "  agreement   " << pad(set.name, 8) << thousands(hitmiss_medium) << " hit/miss (vs high "
              << thousands(hitmiss_high) << "), " << thousands(any_disagree) << " any-hit, " << thousands(t_mismatch)
              << " t differ, of " << thousands(n) << "; referee on " << examined << ": ours right " << referee_ours
              << ", Embree right " << referee_embree << "\n";
    if (ours_any_vs_closest != 0)
      std::cerr << "  WARNING: our occluded() and intersect() disagree on " << ours_any_vs_closest << " rays\n";
  }
#endif
  out["agreement"] = agreement;
}

}  // namespace duplex::bench::main_detail
