// The "mesh" type of scene files: inline arrays and mesh files (paths relative to the scene file),
// build options reaching the objects, errors naming the file and pointer, and prepared structures
// loaded instead of built.

#include "SceneFiles.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"
#include "duplex/scenegraph/SceneDocument.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

TEST(SceneDocumentV1, RelativeMeshPathIsResolvedAgainstTheJsonFolderNotTheWorkingDirectory) {
  SceneDir d;
  const auto path = d.write(v1(kCube, R"({"object": "cube", "transform": )" + kIdentity + "}"));
  auto cubeTriangles = [](const SceneDocument& doc) {
    return dynamic_cast<const MeshObject&>(*doc.graph->library().get(doc.objects.at(0))).mesh().triangleCount();
  };
  // From the test's working directory (elsewhere) ...
  EXPECT_EQ(cubeTriangles(loadChecked(path)), 12u);
  {
    // ... from the scene folder's parent, with a relative JSON path ...
    const WorkingDirectory cwd(d.dir.path());
    EXPECT_EQ(cubeTriangles(loadSceneDocument(std::filesystem::path("scenes") / "scene.json", builtinObjectTypes())),
              12u);
  }
  {
    // ... and from inside the meshes folder, where "meshes/quad_cube.obj" does not exist.
    const WorkingDirectory cwd(d.scenes / "meshes");
    EXPECT_EQ(cubeTriangles(loadSceneDocument(std::filesystem::path("..") / "scene.json", builtinObjectTypes())), 12u);
  }
}

TEST(SceneDocumentV1, BuildOptionsReachTheMeshes) {
  SceneDir d;
  SceneDocumentOptions options;
  options.build.heuristic = KdHeuristic::SpatialMiddle;
  options.build.max_depth = 2;
  const SceneDocument doc = loadChecked(d.write(v1(kCube, "")), options);
  const auto* cube = dynamic_cast<const MeshObject*>(doc.graph->library().get(doc.objects.at(0)).get());
  ASSERT_NE(cube, nullptr);
  EXPECT_LE(cube->tree().stats(1.0f, 1.0f).max_depth, 2u);
  EXPECT_GT(cube->tree().nodes.size(), 1u);  // the middle heuristic splits 12 triangles
}

TEST(SceneDocumentV1Errors, InlineMeshes) {
  SceneDir d;
  auto inline_object = [](const std::string& positions, const std::string& indices) {
    return R"({"name": "m", "mesh": {"positions": )" + positions + R"(, "indices": )" + indices + "}}";
  };
  const std::string good_positions = "[0, 0, 0, 1, 0, 0, 0, 1, 0]";
  expectDocError(d, v1(inline_object(R"([0, 0, 0, 1, "x", 0, 0, 1, 0])", "[0, 1, 2]"), ""),
                 "/objects/0/mesh/positions/4");
  // Finite as a double, infinite as the float it is stored in.
  expectDocError(d, v1(inline_object("[0, 0, 0, 1, 0, 0, 0, 1e39, 0]", "[0, 1, 2]"), ""), "/objects/0/mesh/positions/7",
                 "float range");
  expectDocError(d, v1(inline_object(good_positions, "[0, -1, 2]"), ""), "/objects/0/mesh/indices/1");
  expectDocError(d, v1(inline_object(good_positions, "[0, 1.5, 2]"), ""), "/objects/0/mesh/indices/1");
  expectDocError(d, v1(inline_object(good_positions, "[0, 1, null]"), ""), "/objects/0/mesh/indices/2");
  expectDocError(d, v1(inline_object(good_positions, "{}"), ""), "/objects/0/mesh/indices");
  expectDocError(d, v1(R"({"name": "m", "mesh": {"positions": [0, 0, 0]}})", ""), "/objects/0/mesh", "indices");
  expectDocError(d, v1(inline_object(good_positions, "[0, 1, 7]"), ""), "/objects/0/mesh");     // out of range
  expectDocError(d, v1(inline_object(good_positions, "[]"), ""), "/objects/0/mesh");            // no triangle
  expectDocError(d, v1(inline_object("[0, 0, 0, 1, 0]", "[0, 1, 2]"), ""), "/objects/0/mesh");  // ragged
  expectDocError(d, v1(inline_object("[0, 0, 0, 1, 0, 0, 2, 0, 0]", "[0, 1, 2]"), ""),
                 "/objects/0/mesh");  // degenerate
}

TEST(SceneDocumentStructures, SavedStructuresAreLoadedInsteadOfBuilt) {
  SceneDir d;
  const std::string objs = kCube + "," + kTetra + R"(, {"name": "ball", "sphere": {"subdivisions": 2}})";
  const auto path = d.write(own(objs, R"({"instance": "a", "object": "cube"}, {"instance": "b", "object": "tetra"})"));
  const SceneDocument built = loadSceneDocument(path, builtinObjectTypes());
  EXPECT_EQ(built.figures.structures_loaded, 0u);
  const auto files = saveStructures(built, d.scenes / "prepared");
  ASSERT_EQ(files.size(), 3u);
  EXPECT_EQ(files[0].filename(), "0_cube.dkdt");
  EXPECT_EQ(files[1].filename(), "1_tetra.dkdt");
  const std::string prepared =
      R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": "prepared/0_cube.dkdt"},)"
      R"({"name": "tetra", "mesh": )" +
      nlohmann::json::parse(kTetra)["mesh"].dump() + R"(, "structure": "prepared/1_tetra.dkdt"})";
  for (const std::string format : {"duplex-scene-v1", "scene-json-v1"}) {
    SCOPED_TRACE(format);
    const auto p2 =
        d.write(R"({"format": ")" + format + R"(", "objects": [)" + prepared + R"(], "instances": [], "nodes": []})",
                format + ".json");
    if (format == std::string("duplex-scene-v1")) {
      // "instances" is not a key of the own format.
      expectError([&] { (void)loadSceneDocument(p2, builtinObjectTypes()); }, p2, "/instances", "unknown key");
      d.write(own(prepared, ""), format + ".json");
    }
    const SceneDocument loaded = loadSceneDocument(p2, builtinObjectTypes());
    EXPECT_EQ(loaded.figures.structures_loaded, 2u);
    for (int k = 0; k < 2; ++k) {
      const auto& a = dynamic_cast<const MeshObject&>(*built.graph->library().get(built.objects[k]));
      const auto& b = dynamic_cast<const MeshObject&>(*loaded.graph->library().get(loaded.objects[k]));
      EXPECT_EQ(a.tree().prim_indices, b.tree().prim_indices);
      EXPECT_EQ(a.tree().nodes.size(), b.tree().nodes.size());
    }
    SceneDocumentOptions no_structures;
    no_structures.use_structures = false;
    EXPECT_EQ(loadSceneDocument(p2, builtinObjectTypes(), no_structures).figures.structures_loaded, 0u);
  }
  // A structure saved for another mesh is refused: the scene file, the entry and the structure file.
  const auto wrong = d.write(
      own(R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": "prepared/1_tetra.dkdt"})", ""),
      "wrong.json");
  expectError([&] { (void)loadSceneDocument(wrong, builtinObjectTypes()); }, wrong, "/objects/0/structure",
              "1_tetra.dkdt");
}

}  // namespace
}  // namespace duplex::test
