// The "mesh" type of scene files: inline arrays and mesh files (paths relative to the scene file),
// build options reaching the objects, errors naming the file and pointer, and prepared structures
// loaded instead of built.

#include "SceneFiles.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"
#include "duplex/objects/MeshTypes.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/KdTree.h"

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
  options.structure = "kdtree";  // the build options are the kd-tree's
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

// Saved and loaded again, for both structures (the BVH by default, the kd-tree by the scene-wide
// default): each file has its structure's extension and loads back as that structure.
TEST(SceneDocumentStructures, SavedStructuresAreLoadedInsteadOfBuilt) {
  for (const std::string structure : {"", "kdtree"}) {
    SCOPED_TRACE("default structure '" + structure + "'");
    const bool kd = structure == "kdtree";
    const std::string ext = kd ? ".dkdt" : ".dbvh";
    SceneDir d;
    const std::string objs = kCube + "," + kTetra + R"(, {"name": "ball", "sphere": {"subdivisions": 2}})";
    const auto path =
        d.write(own(objs, R"({"instance": "a", "object": "cube"}, {"instance": "b", "object": "tetra"})"));
    SceneDocumentOptions options;
    options.structure = structure;
    const SceneDocument built = loadChecked(path, options);
    EXPECT_EQ(built.figures.structures_loaded, 0u);
    const auto files = saveStructures(built, d.scenes / "prepared");
    ASSERT_EQ(files.size(), 3u);
    EXPECT_EQ(files[0].filename(), "0_cube" + ext);
    EXPECT_EQ(files[1].filename(), "1_tetra" + ext);
    const std::string prepared =
        R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": "prepared/0_cube)" + ext +
        R"("},)"
        R"({"name": "tetra", "mesh": )" +
        nlohmann::json::parse(kTetra)["mesh"].dump() + R"(, "structure": "prepared/1_tetra)" + ext + R"("})";
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
      // The file decides the structure, whatever the load's default.
      SceneDocumentOptions other;
      other.structure = kd ? "bvh" : "kdtree";
      const SceneDocument loaded = loadSceneDocument(p2, builtinObjectTypes(), other);
      EXPECT_EQ(loaded.figures.structures_loaded, 2u);
      for (int k = 0; k < 2; ++k) {
        const auto& a = dynamic_cast<const MeshObject&>(*built.graph->library().get(built.objects[k]));
        const auto& b = dynamic_cast<const MeshObject&>(*loaded.graph->library().get(loaded.objects[k]));
        EXPECT_EQ(b.structure(), a.structure());
        EXPECT_EQ(a.tree().prim_indices, b.tree().prim_indices);
        EXPECT_EQ(a.tree().nodes.size(), b.tree().nodes.size());
        EXPECT_EQ(a.bvh().prim_indices, b.bvh().prim_indices);
        EXPECT_EQ(a.bvh().nodes.size(), b.bvh().nodes.size());
      }
      SceneDocumentOptions no_structures;
      no_structures.use_structures = false;
      EXPECT_EQ(loadSceneDocument(p2, builtinObjectTypes(), no_structures).figures.structures_loaded, 0u);
    }
    // A structure saved for another mesh is refused: the scene file, the entry and the structure file.
    const auto wrong = d.write(own(R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": )"
                                   R"("prepared/1_tetra)" +
                                       ext + R"("})",
                                   ""),
                               "wrong.json");
    expectError([&] { (void)loadSceneDocument(wrong, builtinObjectTypes()); }, wrong, "/objects/0/structure",
                "1_tetra" + ext);
  }
}

const MeshObject& meshAt(const SceneDocument& doc, std::size_t k) {
  return dynamic_cast<const MeshObject&>(*doc.graph->library().get(doc.objects.at(k)));
}

std::string cubeWith(const std::string& name, const std::string& structure) {
  return R"({"name": ")" + name + R"(", "mesh": {"file": "meshes/quad_cube.obj"})" +
         (structure.empty() ? std::string() : R"(, "structure": ")" + structure + "\"") + "}";
}

// "structure" as a choice: the structure and its parameters reach the object; entries of one mesh
// file share an object only when they build the same structure with the same parameters.
TEST(SceneDocumentStructures, StructureChoicesAreBuiltAndSharedByStructure) {
  SceneDir d;
  const std::string objs = cubeWith("plain", "") + "," + cubeWith("bvh", "bvh") + "," + cubeWith("kd", "kdtree") + "," +
                           cubeWith("fast", "bvh:fast,leaf=2") + "," + cubeWith("kd2", "kdtree") + "," +
                           R"({"name": "tetra", "mesh": )" + kTetraInline + R"(, "structure": "kdtree"})";
  const SceneDocument doc = loadChecked(d.write(own(objs, "")));
  EXPECT_EQ(meshAt(doc, 0).structure(), MeshStructure::Bvh);
  EXPECT_EQ(meshAt(doc, 1).structure(), MeshStructure::Bvh);
  EXPECT_EQ(meshAt(doc, 2).structure(), MeshStructure::KdTree);
  EXPECT_EQ(meshAt(doc, 3).structure(), MeshStructure::Bvh);
  EXPECT_EQ(meshAt(doc, 5).structure(), MeshStructure::KdTree);
  const ObjectLibrary& lib = doc.graph->library();
  EXPECT_EQ(lib.get(doc.objects[0]), lib.get(doc.objects[1]));  // "bvh" is the default
  EXPECT_EQ(lib.get(doc.objects[2]), lib.get(doc.objects[4]));  // both "kdtree"
  EXPECT_NE(lib.get(doc.objects[0]), lib.get(doc.objects[2]));
  EXPECT_NE(lib.get(doc.objects[0]), lib.get(doc.objects[3]));
  // The parameters were used: leaves of at most 2 triangles, as a direct build with them.
  const MeshObject direct(std::make_shared<const TriangleMesh>(meshAt(doc, 3).mesh()),
                          BvhBuildConfig::parse("fast,leaf=2"));
  EXPECT_EQ(meshAt(doc, 3).bvh().prim_indices, direct.bvh().prim_indices);
  EXPECT_NE(meshAt(doc, 3).bvh().prim_indices, meshAt(doc, 0).bvh().prim_indices);
  // A choice is no prepared structure: it applies without use_structures too.
  SceneDocumentOptions no_structures;
  no_structures.use_structures = false;
  EXPECT_EQ(meshAt(loadChecked(d.write(own(objs, "")), no_structures), 2).structure(), MeshStructure::KdTree);
}

// The load's default applies to the entries that choose nothing, in the types that offer it.
TEST(SceneDocumentStructures, DefaultStructure) {
  SceneDir d;
  const std::string objs =
      cubeWith("plain", "") + "," + cubeWith("bvh", "bvh") + R"(, {"name": "ball", "sphere": {"subdivisions": 1}})";
  const auto path = d.write(own(objs, ""));
  SceneDocumentOptions options;
  options.structure = "kdtree";
  const SceneDocument doc = loadChecked(path, options);
  EXPECT_EQ(meshAt(doc, 0).structure(), MeshStructure::KdTree);
  EXPECT_EQ(meshAt(doc, 1).structure(), MeshStructure::Bvh);
  options.structure = "bvh:fast,leaf=2";
  const SceneDocument fast = loadChecked(path, options);
  EXPECT_EQ(meshAt(fast, 0).structure(), MeshStructure::Bvh);
  EXPECT_NE(meshAt(fast, 0).bvh().prim_indices, meshAt(fast, 1).bvh().prim_indices);
}

TEST(SceneDocumentStructures, BadStructureChoices) {
  SceneDir d;
  expectDocError(d, own(cubeWith("c", "bvh:medium,nonsense=1"), ""), "/objects/0/structure", "nonsense");
  expectDocError(d, own(cubeWith("c", "bvh:ultra"), ""), "/objects/0/structure", "ultra");
  expectDocError(d, own(cubeWith("c", "bvh:bins=1"), ""), "/objects/0/structure", "bins");
  expectDocError(d, own(cubeWith("c", "kdtree:sah"), ""), "/objects/0/structure", "no parameters");
  // A structure name on a type without that choice: an error, not a path.
  expectDocError(d, own(R"({"name": "s", "sphere": {}, "structure": "bvh"})", ""), "/objects/0/structure",
                 "offer no structure \"bvh\"");
  // The load's default: a name no type offers names the scene file; bad parameters the entry.
  SceneDocumentOptions options;
  options.structure = "octree";
  const auto good = d.write(own(kCube, ""), "good.json");
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(good, builtinObjectTypes(), options); }, "octree");
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(good, builtinObjectTypes(), options); }, good.string());
  options.structure = "bvh:leaf=99";
  expectDocError(d, own(kCube, ""), "/objects/0", "default structure \"bvh:leaf=99\"", options);
}

TEST(MeshStructureChoice, ParsesAndPrints) {
  EXPECT_EQ(parseMeshStructureChoice("bvh").structure, MeshStructure::Bvh);
  EXPECT_EQ(parseMeshStructureChoice("bvh").bvh, BvhBuildConfig{});
  EXPECT_EQ(parseMeshStructureChoice("kdtree").structure, MeshStructure::KdTree);
  EXPECT_EQ(parseMeshStructureChoice("bvh:fast").bvh, BvhBuildConfig::preset(BvhPreset::Fast));
  KdBuildConfig kd;
  kd.max_depth = 7;
  EXPECT_EQ(parseMeshStructureChoice("kdtree", kd).kd.max_depth, 7);
  const MeshBuildConfig c = parseMeshStructureChoice("bvh:medium,leaf=4,bins=16");
  EXPECT_EQ(parseMeshStructureChoice(toString(c)).bvh, c.bvh);
  EXPECT_EQ(toString(parseMeshStructureChoice("kdtree")), "kdtree");
  for (const char* bad : {"", "octree", "bvh:nope", "kdtree:x", "BVH"})
    EXPECT_THROW((void)parseMeshStructureChoice(bad), InvalidArgument) << bad;
}

}  // namespace
}  // namespace duplex::test
