#pragma once
/// \file SensorFixture.h
/// Scene building blocks of the sensor-run tests: quads, sensors, placements, a point light, a graph
/// with per-object materials, a closed box of sensors, and comparisons of run results.

#include "MeshChecks.h"
#include "OpticsReference.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/TriangleMesh.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/sensors/SensorRun.h"
#include "duplex/sensors/SensorScene.h"

#include <gtest/gtest.h>
#include <glm/geometric.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <unistd.h>

namespace duplex::test {

inline constexpr double kPi = std::numbers::pi;

// A square of half size `half` in the plane z (object space), normal +z, its tree checked.
std::shared_ptr<const Object> quad(double half, const std::string& name, double z = 0.0);

inline std::shared_ptr<const SensorObject> sensor(double w, double h, std::uint32_t nx, std::uint32_t ny,
                                                  bool two_sided = true, const std::string& name = "sensor") {
  return std::make_shared<const SensorObject>(
      name, SensorSpec{.width = w, .height = h, .nx = nx, .ny = ny, .two_sided = two_sided});
}

inline Affine translate(double x, double y, double z) {
  Affine a;
  a.translation = glm::dvec3(x, y, z);
  return a;
}

// Rotation taking +z to unit vector n (about the axis z x n).
inline Affine facing(const glm::dvec3& n_in, const glm::dvec3& at) {
  const glm::dvec3 n = glm::normalize(n_in);
  glm::dvec3 axis = glm::cross(glm::dvec3(0, 0, 1), n);
  const double s = glm::length(axis), c = n.z;
  Affine a = translate(at.x, at.y, at.z);
  if (s < 1e-12) {
    if (c < 0) a.linear = glm::dmat3(1, 0, 0, 0, -1, 0, 0, 0, -1);
    return a;
  }
  axis /= s;
  const double k = 1 - c, x = axis.x, y = axis.y, z = axis.z;
  a.linear = glm::transpose(glm::dmat3(c + x * x * k, x * y * k - z * s, x * z * k + y * s,  //
                                       y * x * k + z * s, c + y * y * k, y * z * k - x * s,  //
                                       z * x * k - y * s, z * y * k + x * s, c + z * z * k));
  return a;
}

// Solid angle of the rectangle [x0, x1] x [y0, y1] in the plane z = 0 seen from (0, 0, h).
inline double rectangleSolidAngle(double x0, double x1, double y0, double y1, double h) {
  return rectangleSolidAngleFrom(x0, x1, y0, y1, h);
}

// Writes `text` to the file `name` in a folder of this process's own in the temporary directory.
std::filesystem::path writeTestFile(const std::string& name, const std::string& text);

// Loading the scene file `path` throws a FileError whose message names the file and every needle.
void expectLoadError(const std::filesystem::path& path, const std::vector<std::string>& needles);

inline Light pointLight(glm::dvec3 p, double power) {
  Light l;
  l.type = LightType::Point;
  l.name = "point";
  l.position = p;
  l.power_w = power;
  return l;
}

// A one-sided Lambertian rectangle width x height, placed by `world` (emitting towards its local +z).
inline Light areaLight(double width, double height, const Affine& world, double power) {
  Light l;
  l.type = LightType::Area;
  l.name = "panel";
  l.width = width;
  l.height = height;
  l.world_from_light = world;
  l.power_w = power;
  return l;
}

// A graph built by the test, kept alive with the scene.
struct Fixture {
  SceneGraph graph;
  std::vector<Material> materials;
  ObjectId add(std::shared_ptr<const Object> o, const Affine& world, const std::string& name, Material m = {}) {
    const ObjectId id = graph.library().add(name, std::move(o));
    materials.resize(graph.library().size());
    materials[id] = m;
    (void)graph.addInstance(kRootNode, id, world, name);
    return id;
  }
  SensorScene scene(std::vector<Light> lights, std::vector<std::string> bands = {}) {
    (void)graph.commit();
    return SensorScene(graph, std::move(lights), materials, std::move(bands));
  }
};

// Six two-sided sensors closing the cube [-1, 1]^3 around a point source.
void closeBox(Fixture& f);

inline double sensorSum(const SensorRunResults& r) {
  double sum = 0.0;
  for (const SensorResult& s : r.sensors) sum += s.total_flux_w;
  return sum;
}

// The results of `rays` rays of a run with `cfg` on `threads` threads in chunks of `chunk` rays.
SensorRunResults runWith(const SensorScene& scene, unsigned threads, std::uint32_t chunk, std::uint64_t rays,
                         SensorRunConfig cfg = {});

void expectIdentical(const SensorRunResults& a, const SensorRunResults& b);

}  // namespace duplex::test
