// Sphere sensors (flux through a sphere, binned by direction):
// crossing geometry (in and out, tangent rays, rays from inside, one-sided), the crossing query's
// order with a wall, an isotropic source at the centre filling equal-area bins, a source outside
// entering through the sphere's solid angle, and the errors.

#include "duplex/accel/Error.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

namespace duplex {
namespace {

using namespace test;

std::shared_ptr<const SensorObject> sphere(double diameter, std::uint32_t nx, std::uint32_t ny, bool two_sided,
                                           const std::string& name) {
  return std::make_shared<const SensorObject>(name, SensorSpec{.shape = SensorShape::Sphere,
                                                               .width = diameter,
                                                               .height = diameter,
                                                               .nx = nx,
                                                               .ny = ny,
                                                               .two_sided = two_sided});
}

Ray ray(glm::vec3 o, glm::vec3 d) {
  Ray r;
  r.origin = o;
  r.dir = d;
  return r;
}

TEST(SensorSphere, CrossingsInAndOutInOrder) {
  const auto s = sphere(2.0, 8, 4, true, "s");
  EXPECT_NEAR(s->area(), 4.0 * kPi, 1e-12);
  EXPECT_NEAR(s->binArea(5), 4.0 * kPi / 32.0, 1e-15);
  EXPECT_EQ(s->bounds().hi.x, std::nextafter(1.0f, 2.0f));
  QueryContext ctx;
  std::vector<Hit> hits;
  // Through the centre along +x: in at x = -1 (normal -x: azimuth 180 degrees), out at x = +1.
  s->intersectAll(ray({-3, 0, 0.5f}, {1, 0, 0}), hits, ctx);
  ASSERT_EQ(hits.size(), 2u);
  const double x = std::sqrt(1.0 - 0.25);
  EXPECT_NEAR(hits[0].t, 3.0 - x, 1e-6);
  EXPECT_NEAR(hits[1].t, 3.0 + x, 1e-6);
  EXPECT_EQ(hits[0].prim_id, 3u * 8u + 4u);  // n = (-x, 0, 0.5): z = 0.5, an inner edge -> iy 3; azimuth 180 -> ix 4
  EXPECT_EQ(hits[1].prim_id, 3u * 8u + 0u);  // n = (x, 0, 0.5): azimuth 0
  EXPECT_NEAR(hits[0].ng.x, -x, 1e-6);
  // One-sided: only the entering crossing.
  hits.clear();
  sphere(2.0, 8, 4, false, "one")->intersectAll(ray({-3, 0, 0.5f}, {1, 0, 0}), hits, ctx);
  ASSERT_EQ(hits.size(), 1u);
  EXPECT_NEAR(hits[0].t, 3.0 - x, 1e-6);
  // From inside: the exit only (two-sided), nothing (one-sided).
  hits.clear();
  s->intersectAll(ray({0, 0, 0}, {0, 0, 2}), hits, ctx);
  ASSERT_EQ(hits.size(), 1u);
  EXPECT_NEAR(hits[0].t, 0.5, 1e-7);  // t in units of the unnormalised direction
  EXPECT_EQ(hits[0].prim_id, 3u * 8u + 0u);
  hits.clear();
  sphere(2.0, 8, 4, false, "one")->intersectAll(ray({0, 0, 0}, {0, 0, 1}), hits, ctx);
  EXPECT_TRUE(hits.empty());
  // Tangent and missing rays, and a range that ends before the sphere.
  hits.clear();
  s->intersectAll(ray({-3, 1, 0}, {1, 0, 0}), hits, ctx);
  s->intersectAll(ray({-3, 1.5f, 0}, {1, 0, 0}), hits, ctx);
  Ray short_ray = ray({-3, 0, 0}, {1, 0, 0});
  short_ray.tfar = 1.5f;
  s->intersectAll(short_ray, hits, ctx);
  EXPECT_TRUE(hits.empty());
  // Bins: equal steps of the azimuth and of z.
  EXPECT_EQ(s->sphereBinAt({0, 0, -1}), 0u);
  EXPECT_EQ(s->sphereBinAt({0, 0, 1}), 3u * 8u);
  EXPECT_EQ(s->sphereBinAt(glm::normalize(glm::dvec3(0, -1, 0.1))), 2u * 8u + 6u);  // azimuth 270
}

TEST(SensorSphere, CrossingQueryReportsBothCrossingsBeforeTheWall) {
  Fixture f;
  f.add(sphere(1.0, 4, 2, true, "ball"), translate(0, 0, 2), "ball");
  f.add(sensor(4, 4, 1, 1, true, "plane"), translate(0, 0, 4), "plane");
  SensorScene open = f.scene({pointLight({0, 0, 0}, 1.0)});
  std::vector<Crossing> crossings;
  QueryContext ctx;
  Ray r = ray({0.1f, 0, 0}, {0, 0, 1});
  (void)open.tracer().topLevel().intersectWithCrossings(r, crossings, ctx, CrossingQuery{});
  ASSERT_EQ(crossings.size(), 3u);
  EXPECT_EQ(crossings[0].hit.instance_id, open.sensors()[0].node);
  EXPECT_EQ(crossings[1].hit.instance_id, open.sensors()[0].node);
  EXPECT_LT(crossings[0].hit.t, crossings[1].hit.t);
  EXPECT_NEAR(crossings[2].hit.t, 4.0, 1e-6);
  // A wall inside the sphere: only the entering crossing is before the blocking hit.
  Fixture g;
  g.add(sphere(1.0, 4, 2, true, "ball"), translate(0, 0, 2), "ball");
  g.add(quad(0.2, "wall"), translate(0, 0, 2), "wall");
  SensorScene walled = g.scene({pointLight({0, 0, 0}, 1.0)});
  const SegmentEnd end = walled.tracer().topLevel().intersectWithCrossings(r, crossings, ctx, CrossingQuery{});
  ASSERT_TRUE(end.hit.valid());
  ASSERT_EQ(crossings.size(), 1u);
  EXPECT_NEAR(crossings[0].hit.t, 2.0 - std::sqrt(0.25 - 0.01), 1e-5);
}

TEST(SensorSphere, IsotropicSourceAtTheCentreFillsEqualAreaBins) {
  Fixture f;
  // Rotated and scaled by 2 (a similarity): world radius 1.5; bins keep equal areas.
  Affine world = facing({1, 1, 0}, {0.2, -0.1, 0.3});
  world.linear *= 2.0;
  f.add(sphere(1.5, 8, 4, true, "far_field"), world, "far_field");
  f.add(sphere(1.5, 8, 4, false, "one_sided"), world, "one_sided");
  SensorScene scene = f.scene({pointLight({0.2, -0.1, 0.3}, 3.0)});
  EXPECT_NEAR(scene.sensors()[0].binAreaWorld(0), 4.0 * kPi * 1.5 * 1.5 / 32.0, 1e-12);
  SensorRun run(scene);
  (void)run.runUntil(200000);
  const SensorRunResults r = run.results();
  const SensorResult& s = r.sensors[scene.findSensor("far_field")];
  EXPECT_NEAR(s.total_flux_w, 3.0, 1e-12);  // every ray leaves once
  double z2 = 0.0;
  for (std::size_t b = 0; b < 32; ++b) {
    const double z = (s.flux_w[b] - 3.0 / 32.0) / s.flux_stderr_w[b];
    EXPECT_LT(std::abs(z), 4.5) << "bin " << b;
    z2 += z * z;
    EXPECT_NEAR(s.irradiance_w_m2[b], s.flux_w[b] / (4.0 * kPi * 2.25 / 32.0), 1e-12);
  }
  EXPECT_GT(z2 / 32.0, 0.4);
  EXPECT_LT(z2 / 32.0, 2.0);
  EXPECT_EQ(r.sensors[scene.findSensor("one_sided")].total_flux_w, 0.0);  // nothing enters
}

TEST(SensorSphere, ExternalSourceEntersThroughTheSolidAngle) {
  // A source at distance D = 4 on the sphere's +z axis (radius 1): the rays that enter carry
  // P (1 - sqrt(1 - 1/D^2)) / 2; they enter on the cap n.z >= 1/D only; two-sided sensors also
  // count the exits: exactly twice the one-sided flux (same paths).
  auto flux = [](bool two_sided) {
    Fixture f;
    f.add(sphere(2.0, 6, 8, two_sided, "ball"), Affine::identity(), "ball");
    SensorScene scene = f.scene({pointLight({0, 0, 4}, 5.0)});
    SensorRunConfig cfg;
    cfg.seed = 8;
    SensorRun run(scene, cfg);
    (void)run.runUntil(300000);
    return run.results().sensors[0];
  };
  const SensorResult one = flux(false), two = flux(true);
  const double exact = 5.0 * (1.0 - std::sqrt(1.0 - 1.0 / 16.0)) / 2.0;
  EXPECT_LT(std::abs(one.total_flux_w - exact), 4.5 * one.total_flux_stderr_w) << one.total_flux_w << " vs " << exact;
  EXPECT_EQ(two.total_flux_w, 2.0 * one.total_flux_w);
  for (std::uint32_t iy = 0; iy < 8; ++iy)  // z bands of width 0.25: the cap z >= 0.25 is bands 5-7
    for (std::uint32_t ix = 0; ix < 6; ++ix) {
      const double f = one.flux_w[iy * 6 + ix];
      if (iy < 5) EXPECT_EQ(f, 0.0) << "band " << iy;
      else EXPECT_GT(f, 0.0) << "band " << iy;
    }
}

TEST(SensorSphere, BadSpheresAreRefused) {
  SensorSpec s;
  s.shape = SensorShape::Sphere;
  s.width = 1.0;
  s.height = 2.0;
  EXPECT_THROW(SensorObject("oval", s), InvalidArgument);
  s.height = 1.0;
  s.theta_bins = 3;
  EXPECT_THROW(SensorObject("angles", s), InvalidArgument);
  Fixture f;
  Affine squashed = Affine::identity();
  squashed.linear[2][2] = 0.5;
  f.add(sphere(1.0, 2, 2, true, "squashed"), squashed, "squashed");
  EXPECT_THROW((void)f.scene({pointLight({0, 0, 3}, 1.0)}), InvalidArgument);

  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("duplex_sphere_" + std::to_string(::getpid()) + ".json");
  auto load = [&](const std::string& sensor) {
    std::ofstream(file) << R"({"format": "scene-json-v1", "objects": [], "instances": [],
      "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}], "sensors": [)"
                        << sensor << "]}";
    return SensorScene::load(file);
  };
  const SensorScene scene = load(R"({"name": "ball", "shape": "sphere", "size": 3, "bins": [12, 6]})");
  EXPECT_EQ(scene.sensors()[0].object->spec().shape, SensorShape::Sphere);
  EXPECT_EQ(scene.sensors()[0].object->spec().width, 3.0);
  for (const auto& [bad, pointer] : std::vector<std::pair<std::string, std::string>>{
           {R"({"name": "b", "shape": "sphere", "size": [3, 2]})", "/sensors/0/size"},
           {R"({"name": "b", "shape": "sphere", "size": 3, "angular_bins": 4})", "/sensors/0/angular_bins"},
           {R"({"name": "b", "shape": "ball", "size": 3})", "/sensors/0/shape"},
           // Not a similarity: the error names the transform's pointer (it named no pointer).
           {R"({"name": "b", "shape": "sphere", "size": 3, "transform": [1,0,0,0, 0,1,0,0, 0,0,0.5,0]})",
            "/sensors/0/transform"},
           {R"({"name": "b", "shape": "sphere", "size": 3, "transform": [1,0.5,0,0, 0,1,0,0, 0,0,1,0]})",
            "/sensors/0/transform"}}) {
    try {
      (void)load(bad);
      ADD_FAILURE() << bad << ": no error";
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(pointer), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace duplex
