// Sensor scenes follow the edits of their graph: for every edit kind (move, rotate, scale, hide,
// replace, re-parent) on a sensor, on a light placed at a node, and on a surface's material, a run
// started after the edit equals, bit for bit, a run of a scene made after the same edit; it differs
// from the run before the edit; and a run made before the commit refuses to go on. Analytic checks:
// a sensor scaled by 0.5 keeps the irradiance of the point source (its bin areas follow), and a
// light moved twice as far gives a quarter of it.

#include "duplex/accel/Error.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"
#include "SensorFixture.h"

#include <gtest/gtest.h>
#include <unistd.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace duplex {
namespace {

using namespace test;

Affine scaled(double s, const glm::dvec3& at) {
  Affine a = translate(at.x, at.y, at.z);
  a.linear = glm::dmat3(s);
  return a;
}

// A rotation by `degrees` about x, then a translation.
Affine tilted(double degrees, const glm::dvec3& at) {
  const double r = degrees * kPi / 180.0, c = std::cos(r), s = std::sin(r);
  Affine a = translate(at.x, at.y, at.z);
  a.linear = glm::dmat3(1, 0, 0, 0, c, s, 0, -s, c);  // columns
  return a;
}

// A room: a Lambertian floor, a one-sided 1 x 1 sensor (4 x 4 bins, 3 x 4 angular bins) facing down
// under the transform node "rig", a second rig elsewhere, a point light at the node "lamp" (with an
// instance "housing" under it that a light can also be placed at) and a spot at "spot_rig".
struct Room {
  SceneGraph graph;
  std::vector<Material> materials;
  ObjectId sensor_a = kInvalidObject, sensor_b = kInvalidObject, floor = kInvalidObject, white = kInvalidObject,
           housing_a = kInvalidObject, housing_b = kInvalidObject;
  NodeId rig = kInvalidNode, rig2 = kInvalidNode, sensor = kInvalidNode, lamp = kInvalidNode, housing = kInvalidNode,
         spot_rig = kInvalidNode, floor_node = kInvalidNode;
  std::vector<Light> lights;

  ObjectId object(std::shared_ptr<const Object> o, const std::string& name, Material m = {}) {
    const ObjectId id = graph.library().add(name, std::move(o));
    materials.resize(graph.library().size());
    materials[id] = m;
    return id;
  }

  Room() {
    auto spec = [](std::uint32_t nx, std::uint32_t ny) {
      SensorSpec s{.width = 1.0, .height = 1.0, .nx = nx, .ny = ny, .two_sided = false};
      s.theta_bins = 3;
      s.phi_bins = 4;
      return s;
    };
    sensor_a = object(std::make_shared<const SensorObject>("a", spec(4, 4)), "sensor_a");
    sensor_b = object(std::make_shared<const SensorObject>("b", spec(2, 3)), "sensor_b");
    floor = object(quad(3.0, "floor"), "floor", Material{Lambertian{0.5}});
    white = object(quad(3.0, "white"), "white", Material{Lambertian{0.9}});
    housing_a = object(quad(0.05, "housing_a", 0.3), "housing_a");
    housing_b = object(quad(0.05, "housing_b", -0.3), "housing_b");
    floor_node = graph.addInstance(kRootNode, floor, Affine::identity(), "floor");
    rig = graph.addTransform(kRootNode, translate(0.2, -0.1, 1.5), "rig");
    rig2 = graph.addTransform(kRootNode, tilted(20.0, {-0.5, 0.4, 1.2}), "rig2");
    // Facing down (normal -z) so that it sees the floor and the lights above it only from behind.
    sensor = graph.addInstance(rig, sensor_a, facing({0, 0, -1}, {0, 0, 0}), "sensor");
    lamp = graph.addTransform(kRootNode, translate(0.1, 0.3, 2.5), "lamp");
    housing = graph.addInstance(lamp, housing_a, Affine::identity(), "housing");
    spot_rig = graph.addTransform(kRootNode, translate(-0.3, 0.0, 2.2), "spot_rig");
    Light point = pointLight({0.4, 0, 0}, 30.0);  // off the node's origin: a scale moves it
    point.node = lamp;
    Light spot;
    spot.type = LightType::Spot;
    spot.name = "spot";
    spot.power_w = 20.0;
    spot.direction = {0.2, 0, -1};
    spot.cone_angle = 0.4;
    spot.node = spot_rig;
    lights = {point, spot};
  }
  SensorScene scene() { return SensorScene(graph, lights, materials); }
};

SensorRunResults run(const SensorScene& scene, std::uint64_t rays = 20000) {
  SensorRunConfig cfg;
  cfg.seed = 5;
  cfg.threads = 2;
  SensorRun r(scene, cfg);
  (void)r.runUntil(rays);
  return r.results();
}

void expectSameSensors(const SensorRunResults& a, const SensorRunResults& b) {
  expectIdentical(a, b);
  for (std::size_t k = 0; k < a.sensors.size() && k < b.sensors.size(); ++k) {
    EXPECT_EQ(a.sensors[k].name, b.sensors[k].name);
    EXPECT_EQ(a.sensors[k].bin_area_m2, b.sensors[k].bin_area_m2);
    EXPECT_EQ(a.sensors[k].irradiance_w_m2, b.sensors[k].irradiance_w_m2);
  }
  EXPECT_EQ(a.energy.emitted_w, b.energy.emitted_w);
}

bool sameSensors(const SensorRunResults& a, const SensorRunResults& b) {
  if (a.sensors.size() != b.sensors.size() || a.energy.absorbed_w != b.energy.absorbed_w ||
      a.energy.emitted_w != b.energy.emitted_w)
    return false;
  for (std::size_t k = 0; k < a.sensors.size(); ++k)
    if (a.sensors[k].flux_w != b.sensors[k].flux_w || a.sensors[k].bin_area_m2 != b.sensors[k].bin_area_m2 ||
        a.sensors[k].angular_flux_w != b.sensors[k].angular_flux_w)
      return false;
  return true;
}

struct EditCase {
  const char* name;
  std::function<void(Room&)> edit;
};

// Every edit kind: the scene made before the edit and run after it equals a scene made after it.
TEST(SensorEdits, RunsAfterEveryEditKindEqualAFreshScene) {
  const std::vector<EditCase> cases = {
      {"move sensor",
       [](Room& r) {
         r.graph.setTransform(r.sensor, facing({0, 0, -1}, {0.3, 0.2, -0.4}));
       }},
      {"rotate sensor",
       [](Room& r) {
         r.graph.setTransform(r.sensor, tilted(150.0, {0, 0, 0}));
       }},
      {"scale sensor",
       [](Room& r) {
         r.graph.setTransform(r.sensor, scaled(0.5, {0, 0, 0}) * facing({0, 0, -1}, {0, 0, 0}));
       }},
      {"hide sensor", [](Room& r) { r.graph.setVisible(r.rig, false); }},
      {"replace sensor (setObject)", [](Room& r) { r.graph.setObject(r.sensor, r.sensor_b); }},
      {"replace sensor (replaceObject)",
       [](Room& r) {
         const SensorSpec s{.shape = SensorShape::Disk, .width = 0.6, .height = 0.6, .nx = 3, .ny = 3};
         r.graph.replaceObject(r.sensor_a, std::make_shared<const SensorObject>("a2", s));
       }},
      {"re-parent sensor", [](Room& r) { r.graph.reparent(r.sensor, r.rig2); }},
      {"move light", [](Room& r) { r.graph.setTransform(r.lamp, translate(-0.4, 0.1, 3.5)); }},
      {"rotate light (spot)",
       [](Room& r) {
         r.graph.setTransform(r.spot_rig, tilted(25.0, {-0.3, 0.0, 2.2}));
       }},
      {"scale light",
       [](Room& r) {
         r.graph.setTransform(r.lamp, scaled(0.5, {0.1, 0.3, 2.5}));
       }},
      {"hide light", [](Room& r) { r.graph.setVisible(r.lamp, false); }},
      {"replace at a light's node", [](Room& r) { r.graph.setObject(r.housing, r.housing_b); }},
      {"re-parent light", [](Room& r) { r.graph.reparent(r.spot_rig, r.rig2); }},
      {"replace floor (material)", [](Room& r) { r.graph.setObject(r.floor_node, r.white); }},
      {"add instance (material)",
       [](Room& r) { (void)r.graph.addInstance(r.rig2, r.white, translate(0, 0, -1.0), "added"); }},
  };
  for (const EditCase& c : cases) {
    SCOPED_TRACE(c.name);
    Room before;
    (void)before.graph.commit();
    const SensorScene scene = before.scene();
    const SensorRunResults initial = run(scene);
    SensorRun stale(scene, {});
    c.edit(before);
    (void)before.graph.commit();
    const SensorRunResults after = run(scene);

    Room fresh;
    c.edit(fresh);
    (void)fresh.graph.commit();
    const SensorRunResults expected = run(fresh.scene());
    expectSameSensors(after, expected);
    EXPECT_FALSE(sameSensors(after, initial)) << "the edit changed nothing: the case tests nothing";
    EXPECT_THROW((void)stale.runUntil(10), InvalidArgument);
    EXPECT_THROW((void)stale.results(), InvalidArgument);
  }
}

// The scaled sensor of the bug report: the flux follows the smaller sensor, and so do the bin areas,
// so the irradiance stays I cos / d^2 of the point source (not a quarter of it); a light moved twice
// as far gives a quarter.
TEST(SensorEdits, ScaledSensorsAndMovedLightsKeepTheAnalyticIrradiance) {
  SceneGraph graph;
  const ObjectId id = graph.library().add("s", sensor(0.2, 0.2, 2, 2, true, "s"));
  const NodeId node = graph.addInstance(kRootNode, id, Affine::identity(), "s");
  const NodeId lamp = graph.addTransform(kRootNode, translate(0, 0, 1), "lamp");
  (void)graph.commit();
  Light l = pointLight({0, 0, 0}, 4.0 * kPi);  // I = 1 W/sr
  l.node = lamp;
  const SensorScene scene(graph, {l});
  // Mean irradiance over a centred square of half size h at distance d: I * Omega / area.
  auto expected = [](double h, double d) {
    return 4.0 * std::atan(h * h / (d * std::sqrt(2.0 * h * h + d * d))) / (4.0 * h * h);
  };
  auto check = [&](double h, double d) {
    const SensorRunResults r = run(scene, 400000);
    ASSERT_EQ(r.sensors.size(), 1u);
    const SensorResult& s = r.sensors[0];
    double area = 0.0;
    for (const double a : s.bin_area_m2) area += a;
    EXPECT_NEAR(area, 4.0 * h * h, 1e-12);
    const double mean = s.total_flux_w / area, se = s.total_flux_stderr_w / area;
    EXPECT_LT(std::abs(mean - expected(h, d)), 4.5 * se) << mean << " vs " << expected(h, d);
  };
  check(0.1, 1.0);
  graph.setTransform(node, scaled(0.5, {0, 0, 0}));
  (void)graph.commit();
  check(0.05, 1.0);
  graph.setTransform(lamp, translate(0, 0, 2));
  (void)graph.commit();
  check(0.05, 2.0);
}

// What a committed graph may not do to a scene: an error naming the sensor or light, at the next
// run (the scene keeps its previous tables until the graph is fixed).
TEST(SensorEdits, InvalidEditsAreRefusedNamingTheSensorOrLight) {
  Room r;
  SceneGraph& g = r.graph;
  const ObjectId sphere = r.object(std::make_shared<const SensorObject>(
                                       "ball", SensorSpec{.shape = SensorShape::Sphere, .width = 0.4, .height = 0.4}),
                                   "ball");
  const NodeId ball = g.addInstance(r.rig2, sphere, Affine::identity(), "ball");
  (void)g.commit();
  const SensorScene scene = r.scene();
  EXPECT_EQ(scene.sensors().size(), 2u);
  Affine squash = Affine::identity();
  squash.linear[2][2] = 0.5;
  g.setTransform(ball, squash);
  (void)g.commit();
  try {
    SensorRun bad(scene, {});
    ADD_FAILURE() << "a squashed sphere sensor was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("'ball'"), std::string::npos) << e.what();
  }
  g.setTransform(ball, Affine::identity());
  (void)g.commit();
  EXPECT_NO_THROW(SensorRun ok(scene, {}));
  g.remove(r.lamp);
  (void)g.commit();
  try {
    (void)scene.lights();
    ADD_FAILURE() << "a light whose node was removed was accepted";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("'point'"), std::string::npos) << e.what();
  }
  // Uncommitted edits: the scene is not derived from a half-edited graph.
  Room p;
  (void)p.graph.commit();
  const SensorScene pending = p.scene();
  p.graph.setVisible(p.rig, false);
  EXPECT_EQ(pending.sensors().size(), 1u);  // the last commit
  (void)p.graph.commit();
  EXPECT_TRUE(pending.sensors().empty());
  p.graph.setVisible(p.rig, true);
  (void)p.graph.commit();
  p.graph.setVisible(p.rig2, false);  // a commit not derived yet, and edits after it
  EXPECT_THROW((void)pending.sensors(), InvalidArgument);
  (void)p.graph.commit();
  EXPECT_EQ(pending.sensors().size(), 1u);
}

// A scene file's timed edits through applyEditsUntil: an object declared by an "add_object" edit
// keeps its "material" once an "add" edit instances it, and a light at a node follows a
// "set_transform" of that node.
TEST(SensorEdits, FileEditsBringTheirMaterialsAndMoveLightsAtNodes) {
  const std::filesystem::path file =
      std::filesystem::temp_directory_path() / ("sensor_edits_" + std::to_string(::getpid()) + ".json");
  std::ofstream(file) << R"({"format": "duplex-scene-v1",
    "objects": [{"name": "plate", "sensor": {"size": 1}}],
    "nodes": [{"instance": "plate", "object": "plate"}, {"group": "lamp", "translate": [0, 0, 1]}],
    "lights": [{"type": "point", "node": "/lamp", "position": [0, 0, 0.5], "power": 1}],
    "edits": [{"time": 1, "add_object": {"name": "wall", "plane": {"size": 2},
                                         "material": {"type": "mirror", "reflectance": 0.25}}},
              {"time": 1, "add": {"instance": "wall", "object": "wall"}},
              {"time": 2, "node": "/lamp", "set_transform": {"translate": [0, 0, 3]}}]})";
  SensorScene scene = SensorScene::load(file);
  std::filesystem::remove(file);
  ASSERT_EQ(scene.lights().size(), 1u);
  EXPECT_EQ(scene.lights()[0].position, glm::dvec3(0, 0, 1.5));
  EXPECT_EQ(applyEditsUntil(*scene.document(), 2.0), 3u);
  const std::optional<NodeId> wall = scene.graph().find("/wall");
  ASSERT_TRUE(wall);
  ASSERT_TRUE(scene.materialOf(*wall).is<Mirror>());
  EXPECT_EQ(scene.materialOf(*wall).as<Mirror>()->reflectance.value, 0.25);
  EXPECT_EQ(scene.lights()[0].position, glm::dvec3(0, 0, 3.5));
}

}  // namespace
}  // namespace duplex
