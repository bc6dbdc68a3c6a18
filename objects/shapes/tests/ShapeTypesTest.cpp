// The procedural shapes of the own scene format ("sphere", "box", "plane"): their meshes as the
// specs ask, and errors naming the file and pointer.

#include "SceneFiles.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/ProceduralMesh.h"
#include "duplex/scenegraph/SceneDocument.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

TEST(SceneDocumentOwn, ProceduralObjects) {
  SceneDir d;
  const auto path = d.write(own(R"({"name": "ball", "sphere": {"radius": 2, "subdivisions": 2}},
      {"name": "crate", "box": {"size": [1, 2, 3]}}, {"name": "cubeish", "box": {"size": 4}},
      {"name": "ground", "plane": {"size": [10, 20]}}, {"name": "unit", "sphere": {}})",
                                R"({"instance": "b", "object": "ball"}, {"instance": "c", "object": "crate"},
      {"instance": "g", "object": "ground"})"));
  const SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  const ObjectLibrary& lib = doc.graph->library();
  auto mesh = [&](ObjectId id) { return &dynamic_cast<const MeshObject&>(*lib.get(id)).mesh(); };
  EXPECT_EQ(mesh(doc.objects[0])->triangleCount(), 320u);
  EXPECT_NEAR(mesh(doc.objects[0])->bounds().hi.x, 2.0f, 1e-5f);
  EXPECT_EQ(mesh(doc.objects[1])->triangleCount(), 12u);
  EXPECT_EQ(mesh(doc.objects[1])->bounds(), Box(glm::vec3(-0.5f, -1.0f, -1.5f), glm::vec3(0.5f, 1.0f, 1.5f)));
  EXPECT_EQ(mesh(doc.objects[2])->bounds(), Box(glm::vec3(-2.0f), glm::vec3(2.0f)));
  EXPECT_EQ(mesh(doc.objects[3])->triangleCount(), 2u);
  EXPECT_EQ(mesh(doc.objects[3])->bounds(), Box(glm::vec3(-5.0f, -10.0f, 0.0f), glm::vec3(5.0f, 10.0f, 0.0f)));
  EXPECT_EQ(mesh(doc.objects[4])->triangleCount(), 20u * 64u);
  EXPECT_EQ(doc.figures.count("triangles"), 320u + 12u + 12u + 2u + 1280u);
  // Outward winding: the box's normals point away from its centre.
  const TriangleMesh& box = *mesh(doc.objects[1]);
  for (std::size_t t = 0; t < box.triangleCount(); ++t) {
    const auto v = box.vertices(t);
    const glm::vec3 n = glm::cross(v[1] - v[0], v[2] - v[0]);
    EXPECT_GT(glm::dot(n, (v[0] + v[1] + v[2]) / 3.0f), 0.0f) << "triangle " << t;
  }
}

TEST(ShapeTypes, MalformedSpecsNameFileAndPointer) {
  SceneDir d;
  expectDocError(d, own(R"({"name": "s", "sphere": {"radius": -1}})", ""), "/objects/0/sphere/radius");
  expectDocError(d, own(R"({"name": "s", "sphere": {"subdivisions": 9}})", ""), "/objects/0/sphere/subdivisions");
  expectDocError(d, own(R"({"name": "s", "sphere": {"subdivisions": 1.5}})", ""), "/objects/0/sphere/subdivisions");
  expectDocError(d, own(R"({"name": "s", "sphere": {"radius": 1, "segments": 3}})", ""), "/objects/0/sphere/segments");
  expectDocError(d, own(R"({"name": "b", "box": {"size": [1, 2]}})", ""), "/objects/0/box/size");
  expectDocError(d, own(R"({"name": "b", "box": {"size": [1, 0, 2]}})", ""), "/objects/0/box/size/1");
  expectDocError(d, own(R"({"name": "p", "plane": {"size": "big"}})", ""), "/objects/0/plane/size");
  expectDocError(d, own(R"({"name": "p", "plane": 3})", ""), "/objects/0/plane");
  expectDocError(d, own(R"({"name": "s", "sphere": {}, "structure": "x.dkdt"})", ""), "/objects/0/structure");
}

}  // namespace
}  // namespace duplex::test
