// Scene files (loadScene, scene-json-v1 exactly as documented in SceneFile.h) and the flat Scene:
// inline and file mesh objects (relative paths against the JSON file's folder, one build per
// distinct file), instance ids = position, row-major transforms, unknown keys ignored; every error
// throws FileError naming the file and the JSON path of the bad value.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/Scene.h"
#include "duplex/scenegraph/SceneFile.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace duplex::test {
namespace {

const char* kTetraInline = R"({"positions": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1], "indices": [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]})";

/// A scene folder: scenes/scene.json next to scenes/meshes/quad_cube.obj (a copy of the fixture).
struct SceneDir {
  TempDir dir;
  std::filesystem::path scenes = dir.path() / "scenes";
  SceneDir() {
    std::filesystem::create_directories(scenes / "meshes");
    std::filesystem::copy_file(fixtureDir() / "quad_cube.obj", scenes / "meshes" / "quad_cube.obj");
  }
  std::filesystem::path write(const std::string& json, const std::string& name = "scene.json") const {
    writeTextFile(scenes / name, json);
    return scenes / name;
  }
};

/// Loads a scene and runs the tree checker on every mesh object it built.
Scene loadChecked(const std::filesystem::path& path, const SceneLoadOptions& options = {},
                  SceneLoadReport* report = nullptr) {
  Scene s = loadScene(path, options, report);
  for (std::uint32_t i = 0; i < s.objectCount(); ++i) {
    if (const auto* m = dynamic_cast<const MeshObject*>(s.object(i).get())) {
      EXPECT_TRUE(checkMeshTree(*m, options.build.max_depth)) << "object '" << s.objectName(i) << "'";
    }
  }
  return s;
}

/// A valid scene text with `objects` and `instances` spliced in.
std::string scene(const std::string& objects, const std::string& instances) {
  return R"({"format": "scene-json-v1", "objects": [)" + objects + R"(], "instances": [)" + instances + "]}";
}

const std::string kCubeObject = R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}})";
const std::string kIdentity = "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]";

/// loadScene must throw FileError whose message names the file and contains `pointer`.
void expectSceneError(const SceneDir& d, const std::string& json, const std::string& pointer,
                      const std::string& also = "") {
  const auto path = d.write(json, "bad_scene.json");
  try {
    (void)loadScene(path);
    ADD_FAILURE() << "no FileError for " << json;
  } catch (const FileError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("bad_scene.json"), std::string::npos) << "message does not name the file: " << msg;
    EXPECT_NE(msg.find(pointer), std::string::npos) << "message does not name '" << pointer << "': " << msg;
    if (!also.empty()) {
      EXPECT_NE(msg.find(also), std::string::npos) << "message does not mention '" << also << "': " << msg;
    }
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type for " << json << ": " << e.what();
  }
}

// ---------------------------------------------------------------------------------------------

TEST(SceneFile, InlineAndFileObjectsInstancesAndUnknownKeys) {
  SceneDir d;
  const auto absolute = (d.scenes / "meshes" / "quad_cube.obj").string();
  const std::string json = R"({
    "format": "scene-json-v1",
    "comment": "unknown keys are ignored at every level",
    "objects": [
      {"name": "cube", "mesh": {"file": "meshes/quad_cube.obj", "units": "m"}, "material": "steel"},
      {"name": "tetra", "mesh": )" + std::string(kTetraInline) + R"(},
      {"name": "cube-again", "mesh": {"file": ")" + absolute + R"("}},
      {"name": "cube-detour", "mesh": {"file": "meshes/../meshes/quad_cube.obj"}}
    ],
    "instances": [
      {"object": "tetra", "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0], "visible": true},
      {"object": "cube", "transform": [0, -2, 0, 10.5, 2, 0, 0, -3, 0, 0, 2, 0.25]},
      {"object": "cube-again", "transform": [1.5, 0, 0, -20, 0, 1.5, 0, 0, 0, 0, 1.5, 0]},
      {"object": "tetra", "transform": [1e-3, 0, 0, 0, 0, 1e-3, 0, 0, 0, 0, 1e-3, 100]}
    ],
    "extra": {"nested": [1, 2, 3]}
  })";
  SceneLoadReport report;
  const Scene s = loadChecked(d.write(json), {}, &report);
  ASSERT_EQ(s.objectCount(), 4u);
  EXPECT_EQ(s.objectName(0), "cube");
  EXPECT_EQ(s.objectName(1), "tetra");
  EXPECT_EQ(s.findObject("cube-again"), std::optional<std::uint32_t>(2));
  EXPECT_FALSE(s.findObject("nope").has_value());
  // One mesh file, named three ways: read and built once, shared.
  EXPECT_EQ(s.object(0).get(), s.object(2).get());
  EXPECT_EQ(s.object(0).get(), s.object(3).get());
  EXPECT_NE(s.object(0).get(), s.object(1).get());
  EXPECT_EQ(report.triangles, 12u + 4u);
  EXPECT_EQ(report.degenerate_triangles, 0u);

  const auto* cube = dynamic_cast<const MeshObject*>(s.object(0).get());
  const auto* tetra = dynamic_cast<const MeshObject*>(s.object(1).get());
  ASSERT_NE(cube, nullptr);
  ASSERT_NE(tetra, nullptr);
  EXPECT_EQ(cube->typeName(), "mesh");
  EXPECT_EQ(cube->mesh().triangleCount(), 12u);
  EXPECT_EQ(tetra->mesh().positions(), (std::vector<glm::vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
  EXPECT_EQ(tetra->mesh().triangles(),
            (std::vector<TriangleMesh::Triangle>{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}));

  ASSERT_EQ(s.instances().size(), 4u);
  EXPECT_EQ(s.instances()[0].object, 1u);
  EXPECT_EQ(s.instances()[1].object, 0u);
  EXPECT_EQ(s.instances()[2].object, 2u);
  EXPECT_EQ(s.instances()[1].world_from_object.toRowMajor3x4(),
            (std::array<double, 12>{0, -2, 0, 10.5, 2, 0, 0, -3, 0, 0, 2, 0.25}));
  EXPECT_EQ(s.instances()[3].world_from_object.translation, glm::dvec3(0, 0, 100));
  const auto descs = s.instanceDescs();
  ASSERT_EQ(descs.size(), 4u);
  for (std::uint32_t i = 0; i < 4; ++i) {
    EXPECT_EQ(descs[i].id, i);
    EXPECT_EQ(descs[i].object.get(), s.object(s.instances()[i].object).get());
  }

  // Traced through the top level: instance ids are positions, and the transform is applied as
  // written (row-major, object to world). Instance 1 maps the cube [0,1]^3 to x in [8.5, 10.5],
  // y in [-3, -1], z in [0.25, 2.25].
  TopLevel top;
  top.build(descs);
  std::vector<Box> boxes;
  for (const InstanceDesc& desc : descs) boxes.push_back(desc.world_from_object.apply(desc.object->bounds()));
  EXPECT_TRUE(checkBoxKdTree(top.tree(), boxes));
  QueryContext ctx;
  Ray r;
  r.origin = glm::vec3(9.5f, -2.0f, 50.0f);
  r.dir = glm::vec3(0.0f, 0.0f, -1.0f);
  const Hit h = top.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, 1u);
  EXPECT_NEAR(h.t, 50.0f - 2.25f, 1e-4f);
  r.origin = glm::vec3(-19.0f, 0.5f, 50.0f);  // instance 2: cube scaled 1.5 at x = -20
  EXPECT_EQ(top.intersect(r, ctx).instance_id, 2u);
  EXPECT_TRUE(s.worldBounds().contains(glm::vec3(10.5f, -1.0f, 2.25f)));
  EXPECT_TRUE(s.worldBounds().contains(glm::vec3(-20.0f, 0.0f, 0.0f)));
}

TEST(SceneFile, RelativeMeshPathIsResolvedAgainstTheJsonFolderNotTheWorkingDirectory) {
  SceneDir d;
  const auto path = d.write(scene(kCubeObject, R"({"object": "cube", "transform": )" + kIdentity + "}"));
  // From the test's working directory (elsewhere) ...
  EXPECT_EQ(loadChecked(path).objectCount(), 1u);
  // ... from the scene folder's parent, with a relative JSON path ...
  const auto saved = std::filesystem::current_path();
  std::filesystem::current_path(d.dir.path());
  EXPECT_NO_THROW((void)loadScene(std::filesystem::path("scenes") / "scene.json"));
  // ... and from inside the meshes folder, where "meshes/quad_cube.obj" does not exist.
  std::filesystem::current_path(d.scenes / "meshes");
  EXPECT_NO_THROW((void)loadScene(std::filesystem::path("..") / "scene.json"));
  std::filesystem::current_path(saved);
}

TEST(SceneFile, EmptyObjectAndInstanceLists) {
  SceneDir d;
  const Scene s = loadChecked(d.write(scene("", "")));
  EXPECT_EQ(s.objectCount(), 0u);
  EXPECT_TRUE(s.instances().empty());
  EXPECT_TRUE(s.worldBounds().empty());
}

TEST(SceneFile, BuildOptionsReachTheMeshes) {
  SceneDir d;
  SceneLoadOptions options;
  options.build.heuristic = KdHeuristic::SpatialMiddle;
  options.build.max_depth = 2;
  const Scene s = loadChecked(d.write(scene(kCubeObject, "")), options);
  const auto* cube = dynamic_cast<const MeshObject*>(s.object(0).get());
  ASSERT_NE(cube, nullptr);
  EXPECT_LE(cube->tree().stats(1.0f, 1.0f).max_depth, 2u);
  EXPECT_GT(cube->tree().nodes.size(), 1u);  // the middle heuristic splits 12 triangles
}

// ---------------------------------------------------------------------------------------------

TEST(SceneFileErrors, DocumentLevel) {
  SceneDir d;
  expectSceneError(d, "{ this is not json", "bad_scene.json");
  expectSceneError(d, R"({"format": "scene-json-v1", "objects": [], "instances": [])", "bad_scene.json");  // cut
  expectSceneError(d, "[1, 2, 3]", "bad_scene.json");
  expectSceneError(d, R"({"format": "scene-json-v2", "objects": [], "instances": []})", "/format", "scene-json-v2");
  expectSceneError(d, R"({"format": 1, "objects": [], "instances": []})", "/format");
  expectSceneError(d, R"({"objects": [], "instances": []})", "format");
  expectSceneError(d, R"({"format": "scene-json-v1", "instances": []})", "objects");
  expectSceneError(d, R"({"format": "scene-json-v1", "objects": []})", "instances");
  expectSceneError(d, R"({"format": "scene-json-v1", "objects": {}, "instances": []})", "/objects");
  expectSceneError(d, R"({"format": "scene-json-v1", "objects": [], "instances": 5})", "/instances");
}

TEST(SceneFileErrors, MissingSceneFileNamesIt) {
  SceneDir d;
  try {
    (void)loadScene(d.scenes / "no_such_scene.json");
    ADD_FAILURE() << "no FileError";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_scene.json"), std::string::npos) << e.what();
  }
}

TEST(SceneFileErrors, Objects) {
  SceneDir d;
  expectSceneError(d, scene("42", ""), "/objects/0");
  expectSceneError(d, scene(R"({"mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0", "name");
  expectSceneError(d, scene(R"({"name": 7, "mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0/name");
  expectSceneError(d, scene(kCubeObject + R"(, {"name": "tetra"})", ""), "/objects/1", "mesh");
  expectSceneError(d, scene(R"({"name": "x", "mesh": "meshes/quad_cube.obj"})", ""), "/objects/0/mesh");
  expectSceneError(d, scene(R"({"name": "x", "mesh": {"vertices": []}})", ""), "/objects/0/mesh");
  expectSceneError(d, scene(R"({"name": "x", "mesh": {"file": 3}})", ""), "/objects/0/mesh/file");
  expectSceneError(d, scene(kCubeObject + R"(, {"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}})", ""),
                   "/objects/1/name", "cube");
  expectSceneError(d, scene(R"({"name": "", "mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0/name");
  // Missing and unreadable mesh files: the JSON path and the mesh file are both named.
  expectSceneError(d, scene(kCubeObject + R"(, {"name": "gone", "mesh": {"file": "meshes/gone.obj"}})", ""),
                   "/objects/1/mesh", "gone.obj");
  expectSceneError(d, scene(R"({"name": "txt", "mesh": {"file": "scene.json"}})", ""), "/objects/0/mesh");
}

TEST(SceneFileErrors, InlineMeshes) {
  SceneDir d;
  auto inline_object = [](const std::string& positions, const std::string& indices) {
    return R"({"name": "m", "mesh": {"positions": )" + positions + R"(, "indices": )" + indices + "}}";
  };
  const std::string good_positions = "[0, 0, 0, 1, 0, 0, 0, 1, 0]";
  expectSceneError(d, scene(inline_object(R"([0, 0, 0, 1, "x", 0, 0, 1, 0])", "[0, 1, 2]"), ""),
                   "/objects/0/mesh/positions/4");
  expectSceneError(d, scene(inline_object(good_positions, "[0, -1, 2]"), ""), "/objects/0/mesh/indices/1");
  expectSceneError(d, scene(inline_object(good_positions, "[0, 1.5, 2]"), ""), "/objects/0/mesh/indices/1");
  expectSceneError(d, scene(inline_object(good_positions, "[0, 1, null]"), ""), "/objects/0/mesh/indices/2");
  expectSceneError(d, scene(inline_object(good_positions, "{}"), ""), "/objects/0/mesh/indices");
  expectSceneError(d, scene(R"({"name": "m", "mesh": {"positions": [0, 0, 0]}})", ""), "/objects/0/mesh", "indices");
  expectSceneError(d, scene(inline_object(good_positions, "[0, 1, 7]"), ""), "/objects/0/mesh");   // out of range
  expectSceneError(d, scene(inline_object(good_positions, "[]"), ""), "/objects/0/mesh");          // no triangle
  expectSceneError(d, scene(inline_object("[0, 0, 0, 1, 0]", "[0, 1, 2]"), ""), "/objects/0/mesh");  // ragged
  expectSceneError(d, scene(inline_object("[0, 0, 0, 1, 0, 0, 2, 0, 0]", "[0, 1, 2]"), ""), "/objects/0/mesh");  // degenerate
}

TEST(SceneFileErrors, Instances) {
  SceneDir d;
  auto instance = [](const std::string& object, const std::string& transform) {
    return R"({"object": ")" + object + R"(", "transform": )" + transform + "}";
  };
  expectSceneError(d, scene(kCubeObject, "1"), "/instances/0");
  expectSceneError(d, scene(kCubeObject, R"({"transform": )" + kIdentity + "}"), "/instances/0", "object");
  expectSceneError(d, scene(kCubeObject, R"({"object": "cube"})"), "/instances/0", "transform");
  expectSceneError(d, scene(kCubeObject, R"({"object": 0, "transform": )" + kIdentity + "}"), "/instances/0/object");
  expectSceneError(d, scene(kCubeObject, instance("cube", kIdentity) + ", " + instance("sphere", kIdentity)),
                   "/instances/1/object", "sphere");
  expectSceneError(d, scene(kCubeObject, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]")), "/instances/0/transform",
                   "11");
  expectSceneError(d, scene(kCubeObject, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0]")),
                   "/instances/0/transform");
  expectSceneError(d, scene(kCubeObject, instance("cube", R"("identity")")), "/instances/0/transform");
  expectSceneError(d, scene(kCubeObject, instance("cube", R"([1, 0, 0, 0, 0, "one", 0, 0, 0, 0, 1, 0])")),
                   "/instances/0/transform/5");
  expectSceneError(d, scene(kCubeObject, instance("cube", kIdentity) + ", " +
                                             instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, null]")),
                   "/instances/1/transform/11");
  expectSceneError(d, scene(kCubeObject, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]")), "/instances/0/transform",
                   "singular");
  expectSceneError(d, scene(kCubeObject, instance("cube", "[1, 2, 3, 0, 2, 4, 6, 0, 0, 0, 1, 0]")), "/instances/0/transform");
  // A number beyond double's range is rejected (by the parser: the file is named).
  expectSceneError(d, scene(kCubeObject, instance("cube", "[1e999, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]")), "bad_scene.json");
}

// ---------------------------------------------------------------------------------------------

TEST(Scene, AddObjectAndInstanceValidation) {
  Scene s;
  const auto sphere = buildChecked(icosphere(1));
  EXPECT_EQ(s.addObject("sphere", sphere), 0u);
  EXPECT_THROW(s.addObject("sphere", sphere), InvalidArgument);  // duplicate
  EXPECT_THROW(s.addObject("", sphere), InvalidArgument);
  EXPECT_THROW(s.addObject("null", nullptr), InvalidArgument);
  EXPECT_EQ(s.objectCount(), 1u);
  EXPECT_EQ(s.addInstance(0, Affine::identity()), 0u);
  EXPECT_EQ(s.addInstance(0, Affine::fromRowMajor3x4({2, 0, 0, 5, 0, 2, 0, 0, 0, 0, 2, 0})), 1u);
  EXPECT_THROW(s.addInstance(1, Affine::identity()), InvalidArgument);  // unknown object
  EXPECT_THROW(s.addInstance(0, Affine::fromRowMajor3x4({std::nan(""), 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0})), InvalidArgument);
  EXPECT_THROW(s.addInstance(0, Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0})), InvalidArgument);
  EXPECT_EQ(s.instances().size(), 2u) << "a rejected instance changed the scene";
  const Box wb = s.worldBounds();
  EXPECT_TRUE(wb.contains(glm::vec3(7.0f, 0.0f, 0.0f)) && wb.contains(glm::vec3(-1.0f, 0.0f, 0.0f))) << wb;
  EXPECT_LE(wb.hi.x, 7.001f);
  const auto descs = s.instanceDescs();
  ASSERT_EQ(descs.size(), 2u);
  EXPECT_EQ(descs[1].id, 1u);
  EXPECT_EQ(descs[1].world_from_object.translation, glm::dvec3(5, 0, 0));
}

}  // namespace
}  // namespace duplex::test
