// The worked example type of docs/object-types.md, registered as an application would register its
// own type: scene files read it through the registry, the top level traces its instances, and its
// hits agree with the closed-form answer computed here in world space.

#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/example/AnalyticSphere.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneTracer.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <random>
#include <string>

namespace duplex::example {
namespace {

using test::TempDir;

ObjectTypeRegistry withExample() {
  ObjectTypeRegistry registry = builtinObjectTypes();
  registerAnalyticSphereType(registry);
  return registry;
}

std::filesystem::path writeScene(const TempDir& dir, const std::string& text) {
  const auto path = dir / "scene.json";
  test::writeTextFile(path, text);
  return path;
}

// Two instances of one sphere of radius 2 (one moved, one moved and scaled by 0.5), and a box.
const char* kScene = R"({"format": "duplex-scene-v1",
  "objects": [{"name": "ball", "analytic_sphere": {"radius": 2}}, {"name": "crate", "box": {"size": 1}}],
  "nodes": [
    {"instance": "a", "object": "ball", "transform": {"translate": [-3, 0, 0]}},
    {"instance": "b", "object": "ball", "transform": {"translate": [3, 1, 0], "scale": 0.5}},
    {"instance": "c", "object": "crate", "transform": {"translate": [0, 0, 6]}}]})";

struct Ball {
  glm::dvec3 centre;
  double radius;
};

// Whether origin + t dir passes close to the ball's rim, where hit or miss and t are ill-conditioned
// (the float ray transformed to object space may decide either way).
bool grazes(const Ball& ball, const glm::dvec3& o, const glm::dvec3& d) {
  const glm::dvec3 oc = o - ball.centre;
  const double a = glm::dot(d, d), b = glm::dot(oc, d), c = glm::dot(oc, oc) - ball.radius * ball.radius;
  return std::abs(b * b - a * c) < 1e-3 * b * b;
}

// The first t >= 0 where origin + t dir meets the ball, in double.
std::optional<double> firstCrossing(const Ball& ball, const glm::dvec3& o, const glm::dvec3& d) {
  const glm::dvec3 oc = o - ball.centre;
  const double a = glm::dot(d, d), b = glm::dot(oc, d), c = glm::dot(oc, oc) - ball.radius * ball.radius;
  const double disc = b * b - a * c;
  if (disc < 0.0) return std::nullopt;
  const double s = std::sqrt(disc);
  for (const double t : {(-b - s) / a, (-b + s) / a})
    if (t >= 0.0) return t;
  return std::nullopt;
}

TEST(AnalyticSphere, RaysAgreeWithTheClosedFormInWorldSpace) {
  TempDir dir;
  const SceneDocument doc = loadSceneDocument(writeScene(dir, kScene), withExample());
  ASSERT_EQ(doc.instances.size(), 3u);
  EXPECT_EQ(doc.graph->library().typeName(doc.objects[0]), "analytic_sphere");
  EXPECT_EQ(doc.figures.count("analytic_spheres"), 1u);  // one object, two instances
  EXPECT_EQ(doc.figures.count("triangles"), 12u);

  SceneTracer tracer(*doc.graph);
  const Ball balls[2] = {{{-3, 0, 0}, 2.0}, {{3, 1, 0}, 1.0}};
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(-4.0, 4.0);
  QueryContext ctx;
  int hits = 0;
  for (int i = 0; i < 4000; ++i) {
    // From a point on a large box around the scene towards a random point near the balls.
    const double fx = coord(rng), fy = coord(rng), tx = coord(rng), ty = coord(rng), tz = coord(rng);
    const glm::dvec3 from(fx * 3.0, fy * 3.0, -20.0);
    const glm::dvec3 to(tx * 1.5, ty, tz * 0.5);
    const glm::dvec3 d = glm::normalize(to - from);
    Ray ray;
    ray.origin = glm::vec3(from);
    ray.dir = glm::vec3(d);
    // The reference uses the float ray the tracer sees.
    const glm::dvec3 o(ray.origin), dd(ray.dir);
    if (grazes(balls[0], o, dd) || grazes(balls[1], o, dd)) continue;
    std::optional<double> best;
    int best_ball = -1;
    for (int k = 0; k < 2; ++k)
      if (const auto t = firstCrossing(balls[k], o, dd); t && (!best || *t < *best)) {
        best = t;
        best_ball = k;
      }
    const Hit hit = tracer.intersect(ray, ctx);
    EXPECT_EQ(tracer.occluded(ray, ctx), hit.valid());
    if (!best) {
      // Only the box (behind the balls, at z = 6) may be hit.
      if (hit.valid()) {
        EXPECT_EQ(hit.instance_id, doc.instances[2]) << ray;
      }
      continue;
    }
    ASSERT_TRUE(hit.valid()) << ray;
    ++hits;
    EXPECT_EQ(hit.instance_id, doc.instances[static_cast<std::size_t>(best_ball)]) << ray;
    EXPECT_NEAR(hit.t, *best, 1e-4 * *best) << ray;
    // The world normal points away from the centre.
    const glm::dvec3 p = o + static_cast<double>(hit.t) * dd;
    EXPECT_GT(glm::dot(glm::dvec3(hit.ng), p - balls[best_ball].centre), 0.0) << ray;
    // Through both layers: a ray that enters a ball leaves it again (two crossings).
    EXPECT_GE(tracer.intersectAll(ray, ctx).size(), 2u) << ray;
  }
  EXPECT_GT(hits, 500);  // the property was checked on enough hits
}

TEST(AnalyticSphere, ReaderErrorsNameTheFileAndPointer) {
  TempDir dir;
  const auto registry = withExample();
  const auto bad = [&](const std::string& spec, const std::string& pointer) {
    const auto path = writeScene(dir, R"({"format": "duplex-scene-v1", "objects": [{"name": "s", "analytic_sphere": )" +
                                          spec + R"(}], "nodes": []})");
    test::expectErrorNaming<FileError>([&] { (void)loadSceneDocument(path, registry); }, pointer);
    test::expectErrorNaming<FileError>([&] { (void)loadSceneDocument(path, registry); }, path.string());
  };
  bad(R"({"radius": -1})", "/objects/0/analytic_sphere/radius");
  bad(R"({"radius": "big"})", "/objects/0/analytic_sphere/radius");
  bad(R"({"radius": 1, "centre": [0, 0, 0]})", "/objects/0/analytic_sphere/centre");  // own format: strict
  bad(R"(3)", "/objects/0/analytic_sphere");
  // Unregistered, the key is no type at all.
  const auto path = writeScene(dir, kScene);
  test::expectErrorNaming<FileError>([&] { (void)loadSceneDocument(path, builtinObjectTypes()); }, "/objects/0");
  // Registered twice: refused.
  ObjectTypeRegistry twice = registry;
  EXPECT_THROW(registerAnalyticSphereType(twice), InvalidArgument);
}

TEST(AnalyticSphere, ObjectSpaceQueriesRespectTheRaySegment) {
  const AnalyticSphere ball("ball", 2.0);
  EXPECT_THROW(AnalyticSphere("bad", 0.0), InvalidArgument);
  EXPECT_THROW(AnalyticSphere("bad", std::nan("")), InvalidArgument);
  EXPECT_TRUE(ball.bounds().contains(glm::vec3(2.0f, -2.0f, 2.0f)));
  QueryContext ctx;
  Ray ray;
  ray.origin = glm::vec3(0, 0, -5);
  ray.dir = glm::vec3(0, 0, 1);
  Hit hit;
  ASSERT_TRUE(ball.intersect(ray, hit, ctx));
  EXPECT_FLOAT_EQ(hit.t, 3.0f);
  EXPECT_FLOAT_EQ(hit.v, 1.0f);  // the south pole (z = -r): colatitude pi
  // A closer hit already found is kept.
  Hit closer;
  closer.t = 2.0f;
  EXPECT_FALSE(ball.intersect(ray, closer, ctx));
  // The segment ends before the sphere, or starts inside it: only what lies within counts.
  ray.tfar = 2.5f;
  EXPECT_FALSE(ball.occluded(ray, ctx));
  ray.tfar = std::numeric_limits<float>::infinity();
  ray.tnear = 4.0f;
  Hit inside;
  ASSERT_TRUE(ball.intersect(ray, inside, ctx));
  EXPECT_FLOAT_EQ(inside.t, 7.0f);
  std::vector<Hit> all;
  ray.tnear = 0.0f;
  ball.intersectAll(ray, all, ctx);
  ASSERT_EQ(all.size(), 2u);
  // Tangent: one crossing.
  ray.origin = glm::vec3(2, 0, -5);
  all.clear();
  ball.intersectAll(ray, all, ctx);
  EXPECT_EQ(all.size(), 1u);
}

}  // namespace
}  // namespace duplex::example
