#pragma once
/// \file SlabRuns.h
/// Light-transport set-ups shared by the sensor tests and the validation cases: a box authored at
/// any point, a slab (pane, layer) lit by a narrow collimated beam at an angle with one-sided
/// sensors on both sides, and what they measured.

#include "OpticsReference.h"
#include "SensorFixture.h"

#include "duplex/objects/ProceduralMesh.h"

#include <cmath>
#include <string>
#include <vector>

namespace duplex::test {

/// A collimated beam of `power` W along `dir` over a disk of `radius` centred at `at`.
inline Light beamLight(const glm::dvec3& at, const glm::dvec3& dir, double radius, double power = 1.0) {
  Light l;
  l.type = LightType::Directional;
  l.name = "beam";
  l.position = at;
  l.direction = dir;
  l.radius = radius;
  l.power_w = power;
  return l;
}

// A box of edge lengths `size` centred at `centre`, its vertices authored there (object space = world).
inline std::shared_ptr<const Object> boxAt(const glm::dvec3& size, const glm::dvec3& centre, const std::string& name,
                                           const std::vector<glm::dvec3>& extra_triangle = {}) {
  const TriangleMesh box = makeBox(size, name);
  std::vector<glm::vec3> positions;
  std::vector<TriangleMesh::Triangle> triangles;
  for (std::size_t i = 0; i < box.triangleCount(); ++i) {
    const std::uint32_t b = static_cast<std::uint32_t>(positions.size());
    for (const glm::vec3& v : box.vertices(i)) positions.push_back(glm::vec3(glm::dvec3(v) + centre));
    triangles.push_back({b, b + 1, b + 2});
  }
  if (!extra_triangle.empty()) {
    const std::uint32_t b = static_cast<std::uint32_t>(positions.size());
    for (const glm::dvec3& v : extra_triangle) positions.push_back(glm::vec3(v));
    triangles.push_back({b, b + 1, b + 2});
  }
  // The default structure, as users build it (no test assertions here: the validation tool uses it too).
  return std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(
      TriangleMesh::fromTriangles(std::move(positions), std::move(triangles), name)));
}

// A frame for a slab: its unit normal `n` (a coordinate axis) and a tangent `t`.
struct SlabFrame {
  glm::dvec3 centre, n, t;
};

/// What a slab run measured: transmittance and reflectance, their standard errors, and the paths
/// that ended by a numerical failure or a path limit (none expected).
struct Measured {
  SlabResponse value, se;
  std::uint64_t failed_rays = 0, depth_limited_rays = 0;
};

// A slab of thickness d (lateral 20 x 20) with its faces normal to frame.n, a narrow beam at theta
// in the (t, n) plane aimed at the centre, one-sided sensors 1 mm from the faces (plus 1e-6 of the
// distance along the normal: world rays are float, and a restart there is a few ulps off the face).
// `placed`: the slab is authored at the origin and placed by a translation; else its vertices are
// authored at the centre. `extra`: one more triangle in the slab's mesh (authored vertices).
inline Measured slabRun(const SlabFrame& fr, double d, const Material& m, double theta, bool placed,
                        const std::vector<glm::dvec3>& extra = {}, std::uint64_t rays = 40000,
                        std::uint64_t seed = 11) {
  Fixture f;
  const glm::dvec3 size = glm::dvec3(20.0) - (20.0 - d) * glm::abs(fr.n);
  if (placed)
    f.add(boxAt(size, glm::dvec3(0.0), "slab", extra), translate(fr.centre.x, fr.centre.y, fr.centre.z), "slab", m);
  else f.add(boxAt(size, fr.centre, "slab", extra), Affine::identity(), "slab", m);
  const double gap = 1e-3 + 1e-6 * std::abs(glm::dot(fr.centre, fr.n));
  f.add(sensor(60.0, 60.0, 1, 1, false, "below"), facing(fr.n, fr.centre - (d / 2 + gap) * fr.n), "below");
  f.add(sensor(60.0, 60.0, 1, 1, false, "above"), facing(-fr.n, fr.centre + (d / 2 + gap) * fr.n), "above");
  const glm::dvec3 dir = std::sin(theta) * fr.t - std::cos(theta) * fr.n;
  const SensorScene scene =
      f.scene({beamLight(fr.centre + (d / 2) * fr.n - dir * ((0.02 + 2.0 * gap) / std::cos(theta)), dir, 1e-3)});
  SensorRunConfig cfg;
  cfg.seed = seed;
  SensorRun run(scene, cfg);
  (void)run.runUntil(rays);
  const SensorRunResults r = run.results();
  const SensorResult& below = r.sensors[scene.findSensor("below")];
  const SensorResult& above = r.sensors[scene.findSensor("above")];
  return {{below.total_flux_w, above.total_flux_w},
          {below.total_flux_stderr_w, above.total_flux_stderr_w},
          r.energy.failed_rays,
          r.energy.depth_limited_rays};
}

/// Asserts a slab's measured transmittance and reflectance within 4 standard errors + 0.2% of the
/// exact values, with no path ended by a failure or a limit (none by default), and prints them.
inline void expectSlab(const Measured& got, const SlabResponse& ref, const std::string& what) {
  std::printf("%s: T %.5f +- %.5f (exact %.5f), R %.5f +- %.5f (exact %.5f)\n", what.c_str(), got.value.t, got.se.t,
              ref.t, got.value.r, got.se.r, ref.r);
  EXPECT_LT(std::abs(got.value.t - ref.t), 4.0 * got.se.t + 2e-3 * ref.t) << what;
  EXPECT_LT(std::abs(got.value.r - ref.r), 4.0 * got.se.r + 2e-3 * ref.r) << what;
  EXPECT_EQ(got.failed_rays, 0u) << what;
  EXPECT_EQ(got.depth_limited_rays, 0u) << what;
}

}  // namespace duplex::test
