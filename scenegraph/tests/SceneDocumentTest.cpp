// Scene files into a SceneGraph (SceneDocument.h): scene-json-v1 to the letter (inline and file mesh
// objects, relative paths against the JSON file's folder, one build per distinct file, instance ids
// = position, row-major transforms as written, unknown keys ignored); the own format's groups and
// transforms give the hand-computed world transforms; procedural objects, prepared structures, timed
// edits, custom object types; every malformed input names the file and the JSON pointer.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "SceneFiles.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/TopLevel.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"
#include "duplex/objects/ProceduralMesh.h"
#include "duplex/scenegraph/ObjectTypeRegistry.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneTracer.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <nlohmann/json.hpp>

#include <array>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

::testing::AssertionResult sameAffine(const Affine& a, const Affine& b, double tol = 0.0) {
  const auto x = a.toRowMajor3x4(), y = b.toRowMajor3x4();
  for (std::size_t k = 0; k < 12; ++k)
    if (!(std::abs(x[k] - y[k]) <= tol))
      return ::testing::AssertionFailure() << a << " != " << b << " (entry " << k << ")";
  return ::testing::AssertionSuccess();
}

// ---- scene-json-v1 ----

TEST(SceneDocumentV1, InlineAndFileObjectsInstancesAndUnknownKeys) {
  SceneDir d;
  const auto absolute = (d.scenes / "meshes" / "quad_cube.obj").string();
  const std::string json = R"({
    "format": "scene-json-v1",
    "comment": "unknown keys are ignored at every level",
    "objects": [
      {"name": "cube", "mesh": {"file": "meshes/quad_cube.obj", "units": "m"}, "material": "steel"},
      {"name": "tetra", "mesh": )" +
                           std::string(kTetraInline) + R"(},
      {"name": "cube-again", "mesh": {"file": ")" +
                           absolute + R"("}},
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
  const SceneDocument doc = loadChecked(d.write(json));
  const SceneGraph& g = *doc.graph;
  const ObjectLibrary& lib = g.library();
  EXPECT_EQ(doc.format, "scene-json-v1");
  ASSERT_EQ(doc.objects.size(), 4u);
  EXPECT_EQ(lib.name(doc.objects[0]), "cube");
  EXPECT_EQ(lib.name(doc.objects[1]), "tetra");
  EXPECT_EQ(lib.find("cube-again"), std::optional<ObjectId>(doc.objects[2]));
  EXPECT_FALSE(lib.find("nope").has_value());
  // One mesh file, named three ways: read and built once, shared.
  EXPECT_EQ(lib.get(doc.objects[0]).get(), lib.get(doc.objects[2]).get());
  EXPECT_EQ(lib.get(doc.objects[0]).get(), lib.get(doc.objects[3]).get());
  EXPECT_NE(lib.get(doc.objects[0]).get(), lib.get(doc.objects[1]).get());
  EXPECT_EQ(doc.figures.count("mesh_files"), 1u);
  EXPECT_EQ(doc.figures.objects, 4u);
  EXPECT_EQ(doc.figures.count("triangles"), 12u + 4u);
  EXPECT_EQ(doc.figures.count("degenerate_triangles"), 0u);

  const auto* cube = dynamic_cast<const MeshObject*>(lib.get(doc.objects[0]).get());
  const auto* tetra = dynamic_cast<const MeshObject*>(lib.get(doc.objects[1]).get());
  ASSERT_NE(cube, nullptr);
  ASSERT_NE(tetra, nullptr);
  EXPECT_EQ(cube->typeName(), "mesh");
  EXPECT_EQ(lib.typeName(doc.objects[0]), "mesh");
  EXPECT_EQ(cube->mesh().triangleCount(), 12u);
  EXPECT_EQ(tetra->mesh().positions(), (std::vector<glm::vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}));
  EXPECT_EQ(tetra->mesh().triangles(),
            (std::vector<TriangleMesh::Triangle>{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}));

  // Instances in file order: node "/instance<k>" is instance id k, placing the named object with
  // the transform as written (row-major, object to world).
  ASSERT_EQ(doc.instances.size(), 4u);
  const std::vector<ObjectId> objects{doc.objects[1], doc.objects[0], doc.objects[2], doc.objects[1]};
  const std::vector<Affine> world{Affine::identity(),
                                  Affine::fromRowMajor3x4({0, -2, 0, 10.5, 2, 0, 0, -3, 0, 0, 2, 0.25}),
                                  Affine::fromRowMajor3x4({1.5, 0, 0, -20, 0, 1.5, 0, 0, 0, 0, 1.5, 0}),
                                  Affine::fromRowMajor3x4({1e-3, 0, 0, 0, 0, 1e-3, 0, 0, 0, 0, 1e-3, 100})};
  for (std::size_t k = 0; k < 4; ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(g.path(doc.instances[k]), "/instance" + std::to_string(k));
    EXPECT_EQ(g.node(doc.instances[k]).object, objects[k]);
    EXPECT_TRUE(sameAffine(g.worldTransform(doc.instances[k]), world[k]));
    EXPECT_TRUE(g.isVisibleInstance(doc.instances[k]));
  }
  EXPECT_EQ(g.worldTransform(doc.instances[1]).toRowMajor3x4(),
            (std::array<double, 12>{0, -2, 0, 10.5, 2, 0, 0, -3, 0, 0, 2, 0.25}));
  EXPECT_EQ(g.worldTransform(doc.instances[3]).translation, glm::dvec3(0, 0, 100));
  EXPECT_EQ(g.instances(), doc.instances) << "the graph holds exactly the file's instances";

  // Traced: the top level covers every instance's world box, hits name the instance's node, and
  // the transform is applied as written. Instance 1 maps the cube [0,1]^3 to x in [8.5, 10.5],
  // y in [-3, -1], z in [0.25, 2.25].
  const SceneTracer tracer(*doc.graph);
  const TopLevel& top = tracer.topLevel();
  ASSERT_EQ(top.size(), 4u);
  std::vector<Box> boxes;
  for (std::uint32_t slot = 0; slot < top.size(); ++slot) {
    const NodeId node = top.idAt(slot);
    ASSERT_TRUE(g.contains(node)) << "slot " << slot;
    boxes.push_back(g.worldTransform(node).apply(lib.get(g.node(node).object)->bounds()));
  }
  EXPECT_TRUE(checkBoxKdTree(top.tree(), boxes));
  QueryContext ctx;
  Ray r;
  r.origin = glm::vec3(9.5f, -2.0f, 50.0f);
  r.dir = glm::vec3(0.0f, 0.0f, -1.0f);
  const Hit h = tracer.intersect(r, ctx);
  ASSERT_TRUE(h.valid());
  EXPECT_EQ(h.instance_id, doc.instances[1]);
  EXPECT_NEAR(h.t, 50.0f - 2.25f, 1e-4f);
  r.origin = glm::vec3(-19.0f, 0.5f, 50.0f);  // instance 2: cube scaled 1.5 at x = -20
  EXPECT_EQ(tracer.intersect(r, ctx).instance_id, doc.instances[2]);
  EXPECT_TRUE(tracer.bounds().contains(glm::vec3(10.5f, -1.0f, 2.25f)));
  EXPECT_TRUE(tracer.bounds().contains(glm::vec3(-20.0f, 0.0f, 0.0f)));
}

// Exact values for a second file: shared file objects under two names ("./" prefix), a non-v1
// type key ignored, transforms with large and small entries kept bit for bit.
TEST(SceneDocumentV1, InstancesAndTransformsAreExactlyTheFilesValues) {
  SceneDir d;
  const std::vector<std::array<double, 12>> transforms{{1, 0, 0, 5, 0, 1, 0, -2, 0, 0, 1, 0.5},
                                                       {0, -2, 0, 1, 2, 0, 0, 2, 0, 0, 2, 3},
                                                       {0.3, 0.1, 0, 1e6, 0, 0.7, 0.2, -3, 0.1, 0, 0.9, 1e-3},
                                                       {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0}};
  const std::vector<std::string> names{"cube", "tetra", "cube2", "cube"};
  nlohmann::json instances = nlohmann::json::array();
  for (std::size_t k = 0; k < names.size(); ++k)
    instances.push_back({{"object", names[k]}, {"transform", transforms[k]}});
  instances.back()["comment"] = "ignored";  // an unknown key
  // cube2 names the same file as cube: read and built once. Unknown keys and a non-v1 type key
  // ("sphere", not part of scene-json-v1) are ignored, as v1 requires.
  const auto path =
      d.write(R"({"format": "scene-json-v1", "extra": {"x": 1}, "objects": [)" + kCube + "," + kTetra +
              R"(, {"name": "cube2", "mesh": {"file": "./meshes/quad_cube.obj"}, "sphere": 3}], "instances": )" +
              instances.dump() + "}");
  const SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  EXPECT_EQ(doc.format, "scene-json-v1");
  ASSERT_EQ(doc.instances.size(), 4u);
  for (std::size_t k = 0; k < doc.instances.size(); ++k) {
    SCOPED_TRACE(k);
    const NodeInfo info = doc.graph->node(doc.instances[k]);
    EXPECT_EQ(info.kind, NodeKind::Instance);
    EXPECT_EQ(info.name, "instance" + std::to_string(k));
    EXPECT_EQ(info.parent, kRootNode);
    EXPECT_EQ(doc.graph->library().name(info.object), names[k]);
    EXPECT_EQ(doc.graph->worldTransform(doc.instances[k]).toRowMajor3x4(), transforms[k]);
    EXPECT_TRUE(doc.graph->isVisibleInstance(doc.instances[k]));
  }
  EXPECT_EQ(doc.figures.count("triangles"), 12u + 4u);
  EXPECT_EQ(doc.figures.count("mesh_files"), 1u);
  EXPECT_EQ(doc.figures.objects, 3u);
  const ObjectLibrary& lib = doc.graph->library();
  EXPECT_EQ(lib.get(doc.objects[0]).get(), lib.get(doc.objects[2]).get()) << "one object per distinct file";
  EXPECT_EQ(doc.graph->commitCount(), 1u);
}

TEST(SceneDocumentV1, EmptyObjectAndInstanceLists) {
  SceneDir d;
  const SceneDocument doc = loadChecked(d.write(v1("", "")));
  EXPECT_TRUE(doc.objects.empty());
  EXPECT_EQ(doc.graph->library().size(), 0u);
  EXPECT_TRUE(doc.instances.empty());
  EXPECT_TRUE(doc.graph->instances().empty());
  EXPECT_TRUE(SceneTracer(*doc.graph).bounds().empty());
}

// ---- scene-json-v1: malformed input names the file and the JSON pointer ----

/// For input the JSON parser refuses: the message names the file (and the parser's position), no pointer.
const std::string kParserError = "";

TEST(SceneDocumentV1Errors, DocumentLevel) {
  SceneDir d;
  expectDocError(d, "{ this is not json", kParserError);
  expectDocError(d, R"({"format": "scene-json-v1", "objects": [], "instances": [])", kParserError);  // cut
  expectDocError(d, "[1, 2, 3]", kParserError);
  expectDocError(d, R"({"format": "scene-json-v2", "objects": [], "instances": []})", "/format", "scene-json-v2");
  expectDocError(d, R"({"format": 1, "objects": [], "instances": []})", "/format");
  expectDocError(d, R"({"objects": [], "instances": []})", "/", "format");
  expectDocError(d, R"({"format": "scene-json-v1", "instances": []})", "/", "objects");
  expectDocError(d, R"({"format": "scene-json-v1", "objects": []})", "/", "instances");
  expectDocError(d, R"({"format": "scene-json-v1", "objects": {}, "instances": []})", "/objects");
  expectDocError(d, R"({"format": "scene-json-v1", "objects": [], "instances": 5})", "/instances");
}

TEST(SceneDocumentV1Errors, MissingSceneFileNamesIt) {
  SceneDir d;
  const auto path = d.scenes / "no_such_scene.json";
  expectError([&] { (void)loadSceneDocument(path, builtinObjectTypes()); }, path, kParserError);
}

TEST(SceneDocumentV1Errors, DirectoriesAndFifosAreRefusedNamingThem) {
  SceneDir d;
  // As the scene file itself, as a mesh file, and as a prepared structure.
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(d.scenes, builtinObjectTypes()); },
                               "scenes: cannot open scene file: a directory, not a file");
  const auto fifo = d.scenes / "fifo.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(fifo, builtinObjectTypes()); },
                               "fifo.json: cannot open scene file: not a regular file");
  std::filesystem::create_directories(d.scenes / "meshes" / "dir.obj");
  const auto mesh_dir = d.write(v1(R"({"name": "m", "mesh": {"file": "meshes/dir.obj"}})", ""));
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(mesh_dir, builtinObjectTypes()); },
                               "dir.obj': a directory, not a file");
  std::filesystem::create_directories(d.scenes / "prepared.dbvh");
  const auto structure_dir =
      d.write(own(R"({"name": "m", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": "prepared.dbvh"})", ""));
  expectErrorNaming<FileError>([&] { (void)loadSceneDocument(structure_dir, builtinObjectTypes()); },
                               "prepared.dbvh: cannot open bottom-level structure file: a directory, not a file");
}

TEST(SceneDocumentV1Errors, Objects) {
  SceneDir d;
  expectDocError(d, v1("42", ""), "/objects/0");
  expectDocError(d, v1(R"({"mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0", "name");
  expectDocError(d, v1(R"({"name": 7, "mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0/name");
  expectDocError(d, v1(kCube + R"(, {"name": "tetra"})", ""), "/objects/1", "mesh");
  expectDocError(d, v1(R"({"name": "x", "mesh": "meshes/quad_cube.obj"})", ""), "/objects/0/mesh");
  expectDocError(d, v1(R"({"name": "x", "mesh": {"vertices": []}})", ""), "/objects/0/mesh");
  expectDocError(d, v1(R"({"name": "x", "mesh": {"file": 3}})", ""), "/objects/0/mesh/file");
  expectDocError(d, v1(kCube + R"(, {"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}})", ""),
                 "/objects/1/name", "cube");
  expectDocError(d, v1(R"({"name": "", "mesh": {"file": "meshes/quad_cube.obj"}})", ""), "/objects/0/name");
  // Missing and unreadable mesh files: the JSON pointer and the mesh file are both named.
  expectDocError(d, v1(kCube + R"(, {"name": "gone", "mesh": {"file": "meshes/gone.obj"}})", ""), "/objects/1/mesh",
                 "gone.obj");
  expectDocError(d, v1(R"({"name": "txt", "mesh": {"file": "scene.json"}})", ""), "/objects/0/mesh", "scene.json");
  expectDocError(d, v1(R"({"name": "txt", "mesh": {"file": "bad_scene.json"}})", ""), "/objects/0/mesh");  // not a mesh
  // A type that is not part of scene-json-v1 does not count as a type there.
  expectDocError(d, v1(R"({"name": "s", "sphere": {"radius": 1}})", ""), "/objects/0", "no object type");
}

TEST(SceneDocumentV1Errors, Instances) {
  SceneDir d;
  auto instance = [](const std::string& object, const std::string& transform) {
    return R"({"object": ")" + object + R"(", "transform": )" + transform + "}";
  };
  expectDocError(d, v1(kCube, "1"), "/instances/0");
  expectDocError(d, v1(kCube, R"({"transform": )" + kIdentity + "}"), "/instances/0", "object");
  expectDocError(d, v1(kCube, R"({"object": "cube"})"), "/instances/0", "transform");
  expectDocError(d, v1(kCube, R"({"object": 0, "transform": )" + kIdentity + "}"), "/instances/0/object");
  expectDocError(d, v1(kCube, instance("cube", kIdentity) + ", " + instance("sphere", kIdentity)),
                 "/instances/1/object", "sphere");
  expectDocError(d, v1(kCube, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]")), "/instances/0/transform", "11");
  expectDocError(d, v1(kCube, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0]")), "/instances/0/transform");
  expectDocError(d, v1(kCube, instance("cube", R"("identity")")), "/instances/0/transform");
  expectDocError(d, v1(kCube, instance("cube", R"([1, 0, 0, 0, 0, "one", 0, 0, 0, 0, 1, 0])")),
                 "/instances/0/transform/5");
  expectDocError(d, v1(kCube, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, null]")),
                 "/instances/0/transform/11");
  expectDocError(
      d, v1(kCube, instance("cube", kIdentity) + ", " + instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, null]")),
      "/instances/1/transform/11");
  expectDocError(d, v1(kCube, instance("cube", "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]")), "/instances/0/transform",
                 "singular");
  expectDocError(d, v1(kCube, instance("cube", "[1, 2, 3, 0, 2, 4, 6, 0, 0, 0, 1, 0]")), "/instances/0/transform");
  // A number beyond double's range is rejected (by the parser: the file is named).
  expectDocError(d, v1(kCube, instance("cube", "[1e999, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]")), kParserError);
}

// ---- the own format ----

TEST(SceneDocumentOwn, WorldTransformsAreTheHandComputedProducts) {
  SceneDir d;
  // car (translate 10, 0, 0) > wheel_hub (rotate 90 degrees about z, then translate 0, 1, 0) >
  // wheel instance (scale 2). world = T(10,0,0) * [T(0,1,0) R_z(90)] * S(2).
  const std::string nodes = R"(
    {"group": "car", "translate": [10, 0, 0], "children": [
       {"group": "parts", "children": [
         {"group": "hub", "translate": [0, 1, 0], "rotate": {"axis": [0, 0, 2], "degrees": 90}, "children": [
           {"instance": "wheel", "object": "cube", "transform": {"scale": 2}, "mask": 5}]}]},
       {"instance": "body", "object": "tetra", "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 3], "visible": false}]},
    {"group": "free", "matrix": [0, 0, 1, 7, 0, 1, 0, 8, -1, 0, 0, 9], "children": [
       {"instance": "e", "object": "tetra", "transform": {"rotate": {"euler_xyz": [90, 0, 90]}}}]})";
  const auto path = d.write(own(kCube + "," + kTetra, nodes));
  const SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  EXPECT_EQ(doc.format, "duplex-scene-v1");
  ASSERT_EQ(doc.instances.size(), 3u);
  const SceneGraph& g = *doc.graph;
  EXPECT_EQ(g.path(doc.instances[0]), "/car/parts/hub/wheel");
  EXPECT_EQ(g.path(doc.instances[1]), "/car/body");
  EXPECT_EQ(g.node(*g.find("/car")).kind, NodeKind::Transform);
  EXPECT_EQ(g.node(*g.find("/car/parts")).kind, NodeKind::Group);
  EXPECT_EQ(g.node(doc.instances[0]).mask, 5u);
  // Hand-computed: R_z(90) maps x -> y, y -> -x; scaled by 2; translation (10, 1, 0).
  EXPECT_TRUE(sameAffine(g.worldTransform(doc.instances[0]),
                         Affine::fromRowMajor3x4({0, -2, 0, 10, 2, 0, 0, 1, 0, 0, 2, 0}), 1e-12));
  EXPECT_TRUE(sameAffine(g.worldTransform(doc.instances[1]),
                         Affine::fromRowMajor3x4({1, 0, 0, 10, 0, 1, 0, 0, 0, 0, 1, 3}), 0.0));
  EXPECT_FALSE(g.isVisibleInstance(doc.instances[1]));
  EXPECT_TRUE(g.isVisibleInstance(doc.instances[0]));
  // euler_xyz [90, 0, 90] = R_z(90) R_x(90): x -> y, y -> z, z -> x. Then the "free" matrix.
  const Affine euler = Affine::fromRowMajor3x4({0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0});
  const Affine free = Affine::fromRowMajor3x4({0, 0, 1, 7, 0, 1, 0, 8, -1, 0, 0, 9});
  EXPECT_TRUE(sameAffine(g.worldTransform(doc.instances[2]), free * euler, 1e-12));
  EXPECT_EQ(g.visibleInstances().size(), 2u);
}

TEST(SceneDocumentOwn, TimedEditsAreReadSortedAndApplied) {
  SceneDir d;
  const std::string edits = R"(
    {"time": 2.0, "remove": "/arm/tip"},
    {"time": 0.5, "node": "/arm", "set_transform": {"translate": [0, 0, 5]}},
    {"time": 1.0, "add": {"group": "extra", "translate": [1, 1, 1], "children": [{"instance": "x", "object": "cube"}]}, "parent": "/arm"},
    {"time": 1.0, "node": "/arm/tip", "visible": false},
    {"time": 1.5, "node": "/arm/tip", "object": "cube"},
    {"time": 1.5, "node": "/arm/tip", "mask": 3},
    {"time": 3.0, "node": "/gone", "visible": true})";
  const auto path = d.write(
      own(kCube + "," + kTetra,
          R"({"group": "arm", "matrix": )" + kIdentity + R"(, "children": [{"instance": "tip", "object": "tetra"}]})",
          edits));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  ASSERT_EQ(doc.edits.size(), 7u);
  std::vector<std::string> order;
  for (const auto& e : doc.edits) order.push_back(e.pointer);
  EXPECT_EQ(order, (std::vector<std::string>{"/edits/1", "/edits/2", "/edits/3", "/edits/4", "/edits/5", "/edits/0",
                                             "/edits/6"}));
  SceneGraph& g = *doc.graph;
  const NodeId tip = doc.instances[0];
  (void)applyEdit(doc, doc.edits[0]);
  (void)g.commit();
  EXPECT_TRUE(sameAffine(g.worldTransform(tip), Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 5})));
  const auto added = applyEdit(doc, doc.edits[1]);
  ASSERT_EQ(added.size(), 2u);
  (void)applyEdit(doc, doc.edits[2]);
  (void)g.commit();
  EXPECT_EQ(g.path(added[1]), "/arm/extra/x");
  EXPECT_TRUE(sameAffine(g.worldTransform(added[1]), Affine::fromRowMajor3x4({1, 0, 0, 1, 0, 1, 0, 1, 0, 0, 1, 6})));
  EXPECT_FALSE(g.isVisibleInstance(tip));
  (void)applyEdit(doc, doc.edits[3]);
  (void)applyEdit(doc, doc.edits[4]);
  EXPECT_EQ(g.node(tip).object, doc.objects[0]);
  EXPECT_EQ(g.node(tip).mask, 3u);
  (void)applyEdit(doc, doc.edits[5]);
  (void)g.commit();
  EXPECT_FALSE(g.contains(tip));
  expectError([&] { (void)applyEdit(doc, doc.edits[6]); }, path, "/edits/6", "/gone");
}

// applyEditsUntil plays the edits up to a time, one commit per group of equal times (a node added
// by one group is edited by a later one); a failing edit rolls its group back, the earlier groups
// stay committed; a time before every edit applies none.
TEST(SceneDocumentOwn, EditsUntilATimeArePlayedGroupByGroup) {
  SceneDir d;
  const std::string edits = R"(
    {"time": 0.5, "node": "/arm", "set_transform": {"translate": [0, 0, 5]}},
    {"time": 1.0, "add": {"instance": "x", "object": "cube"}, "parent": "/arm"},
    {"time": 1.5, "node": "/arm/x", "set_transform": {"translate": [1, 0, 0]}},
    {"time": 2.0, "node": "/arm/tip", "visible": false},
    {"time": 2.0, "node": "/gone", "visible": true})";
  const auto path = d.write(
      own(kCube + "," + kTetra,
          R"({"group": "arm", "matrix": )" + kIdentity + R"(, "children": [{"instance": "tip", "object": "tetra"}]})",
          edits));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  SceneGraph& g = *doc.graph;
  const NodeId tip = doc.instances[0];
  EXPECT_EQ(applyEditsUntil(doc, 0.25), 0u);
  EXPECT_EQ(applyEditsUntil(doc, std::nan("")), 0u);
  EXPECT_TRUE(sameAffine(g.worldTransform(tip), Affine::identity()));
  const std::uint64_t commits = g.commitCount();
  EXPECT_EQ(applyEditsUntil(doc, 1.5), 3u);
  EXPECT_EQ(g.commitCount(), commits + 3);  // one commit per time
  EXPECT_FALSE(g.hasPendingEdits());
  EXPECT_TRUE(
      sameAffine(g.worldTransform(*g.find("/arm/x")), Affine::fromRowMajor3x4({1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 5})));
  // Both edits of t = 2: the hide stays pending when the second fails.
  expectError([&] { (void)applyEditGroup(doc, 3); }, path, "/edits/4", "/gone");
  EXPECT_TRUE(g.hasPendingEdits());
  g.rollback();
  // A commit whose edits change no instance (a rename) is a revision, not a commit that changed something.
  const std::uint64_t revision = g.revision(), changed = g.commitCount();
  g.rename(*g.find("/arm"), "arm2");
  (void)g.commit();
  EXPECT_EQ(g.commitCount(), changed);
  EXPECT_EQ(g.revision(), revision + 1);
  (void)g.commit();  // nothing pending
  EXPECT_EQ(g.revision(), revision + 1);
  SceneDocument again = loadSceneDocument(path, builtinObjectTypes());
  expectError([&] { (void)applyEditsUntil(again, 10.0); }, path, "/edits/4", "/gone");
  // The groups before t = 2 are committed, the group of t = 2 (a valid hide, then the failure) is not.
  EXPECT_FALSE(again.graph->hasPendingEdits());
  EXPECT_TRUE(again.graph->find("/arm/x"));
  EXPECT_TRUE(again.graph->isVisibleInstance(again.instances[0]));
}

// Edits given at run time (parseLiveEdits): the file's vocabulary without "time"; applied like the
// file's; edits that read files, a "time", unknown objects and non-finite numbers are refused naming
// the source and the pointer, and nothing is parsed then.
TEST(SceneDocumentOwn, LiveEditsUseTheFilesVocabularyAndNeverReadFiles) {
  SceneDir d;
  const auto path = d.write(own(
      kCube + "," + kTetra,
      R"({"group": "arm", "matrix": )" + kIdentity + R"(, "children": [{"instance": "tip", "object": "tetra"}]})", ""));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  const auto live = [&](const std::string& text) {
    return parseLiveEdits(doc, nlohmann::json::parse(text), "request", builtinObjectTypes());
  };
  const std::vector<SceneEdit> edits = live(R"([
    {"node": "/arm", "set_transform": {"translate": [0, 0, 5]}},
    {"add": {"instance": "x", "object": "cube"}, "parent": "/arm"},
    {"node": "/arm/tip", "mask": 3}])");
  ASSERT_EQ(edits.size(), 3u);
  EXPECT_EQ(edits[0].pointer, "/0");
  EXPECT_EQ(edits[0].kind, SceneEditKind::SetTransform);
  for (const SceneEdit& e : edits) (void)applyEdit(doc, e);
  (void)doc.graph->commit();
  EXPECT_TRUE(sameAffine(doc.graph->worldTransform(*doc.graph->find("/arm/x")),
                         Affine::fromRowMajor3x4({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 5})));
  EXPECT_EQ(doc.graph->node(doc.instances[0]).mask, 3u);
  expectErrorNaming<FileError>(
      [&] { (void)live(R"([{"node": "/arm", "visible": true}, {"time": 1, "remove": "/arm"}])"); },
      "request: /1/time: an edit applied now has no \"time\"");
  expectErrorNaming<FileError>([&] { (void)live(R"([{"add_object": {"name": "m", "mesh": {"file": "a.obj"}}}])"); },
                               "request: /0/add_object: \"add_object\" reads files");
  expectErrorNaming<FileError>([&] { (void)live(R"([{"deform": "cube", "file": "a.obj"}])"); },
                               "request: /0/file: a \"deform\" edit from a file reads files");
  expectErrorNaming<FileError>([&] { (void)live(R"([{"node": "/arm", "object": "nothing"}])"); },
                               "request: /0/object: no object named \"nothing\"");
  expectErrorNaming<FileError>(
      [&] { (void)live(R"([{"node": "/arm", "set_transform": [1, 0, 0, "x", 0, 1, 0, 0, 0, 0, 1, 0]}])"); },
      "request: /0/set_transform/3: expected a number");
  expectErrorNaming<FileError>([&] { (void)live(R"({"node": "/arm"})"); }, "request: /: expected an array of edits");
}

// The complete example of docs/scene-format.md loads and all its edits apply (mesh files replaced by
// a fixture, the prepared structure dropped).
TEST(SceneDocumentOwn, TheDocumentedExampleLoadsAndPlays) {
  const auto doc_path = sourceDir() / "docs" / "scene-format.md";
  std::ifstream in(doc_path);
  ASSERT_TRUE(in) << doc_path;
  std::stringstream text;
  text << in.rdbuf();
  const std::string md = text.str();
  const std::size_t section = md.find("### Complete example");
  ASSERT_NE(section, std::string::npos);
  const std::size_t begin = md.find("```json\n", section) + 8, end = md.find("```", begin);
  nlohmann::json scene = nlohmann::json::parse(md.substr(begin, end - begin));
  for (auto& object : scene["objects"]) {
    object.erase("structure");
    if (object.contains("mesh") && object["mesh"].contains("file")) object["mesh"]["file"] = "meshes/quad_cube.obj";
  }
  SceneDir d;
  const auto path = d.write(scene.dump(2));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  EXPECT_EQ(doc.instances.size(), 9u);
  EXPECT_EQ(doc.figures.count("mesh_files"), 1u);
  EXPECT_EQ(doc.graph->visibleInstances().size(), 7u);
  ASSERT_EQ(doc.edits.size(), 6u);
  for (const SceneEdit& e : doc.edits) {
    (void)applyEdit(doc, e);
    (void)doc.graph->commit();
  }
  EXPECT_EQ(doc.graph->visibleInstances().size(), 9u);
  EXPECT_TRUE(doc.graph->find("/car/spare"));
  EXPECT_FALSE(doc.graph->find("/car/wheels/rear_right"));
}

TEST(SceneDocumentOwn, MalformedInputNamesFileAndPointer) {
  SceneDir d;
  const std::string objs = kCube + "," + kTetra;
  const std::string inst = R"({"instance": "i", "object": "cube"})";
  expectDocError(d, R"({"format": "duplex-scene-v1", "objects": [], "nodes": [], "extra": 1})", "/extra",
                 "unknown key");
  expectDocError(d, R"({"format": "duplex-scene-v1", "objects": [], "nodes": {}})", "/nodes");
  expectDocError(d, own(R"({"name": "c", "mesh": {"file": "meshes/quad_cube.obj"}, "colour": 1})", ""),
                 "/objects/0/colour");
  expectDocError(d, own(R"({"name": "c", "mesh": {"file": "meshes/quad_cube.obj"}, "box": {}})", ""), "/objects/0",
                 "two object types");
  expectDocError(d, own(R"({"name": "c"})", ""), "/objects/0", "no object type");
  expectDocError(d, own(R"({"name": "c", "mesh": {"file": "meshes/quad_cube.obj", "positions": []}})", ""),
                 "/objects/0/mesh/positions", "unknown key");
  expectDocError(d, own(R"({"name": "c", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": 5})", ""),
                 "/objects/0/structure");
  expectDocError(d, own(R"({"name": "c", "mesh": {"file": "meshes/quad_cube.obj"}, "structure": "none.dkdt"})", ""),
                 "/objects/0/structure", "none.dkdt");
  // Nodes.
  expectDocError(d, own(objs, "3"), "/nodes/0");
  expectDocError(d, own(objs, R"({"name": "x"})"), "/nodes/0", "group");
  expectDocError(d, own(objs, R"({"group": "g", "instance": "i", "object": "cube"})"), "/nodes/0", "not both");
  expectDocError(d, own(objs, R"({"group": 1})"), "/nodes/0/group");
  expectDocError(d, own(objs, R"({"group": "g", "children": [)" + inst + ", 7]}"), "/nodes/0/children/1");
  expectDocError(d, own(objs, R"({"group": "g", "children": {}})"), "/nodes/0/children");
  expectDocError(d, own(objs, R"({"group": "g", "visible": 1})"), "/nodes/0/visible");
  expectDocError(d, own(objs, R"({"group": "g", "translate": [1, 2]})"), "/nodes/0/translate");
  expectDocError(d, own(objs, R"({"group": "g", "translate": [1, 2, "z"]})"), "/nodes/0/translate/2");
  expectDocError(d, own(objs, R"({"group": "g", "matrix": )" + kIdentity + R"(, "scale": 2})"), "/nodes/0/matrix",
                 "cannot be combined");
  expectDocError(d, own(objs, R"({"group": "g", "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]})"), "/nodes/0/matrix",
                 "singular");
  expectDocError(d, own(objs, R"({"group": "g", "scale": [1, 0, 1]})"), "/nodes/0/scale/1");
  expectDocError(d, own(objs, R"({"group": "g", "rotate": {"axis": [0, 0, 0], "degrees": 5}})"),
                 "/nodes/0/rotate/axis");
  expectDocError(d, own(objs, R"({"group": "g", "rotate": {"axis": [0, 0, 1]}})"), "/nodes/0/rotate", "degrees");
  expectDocError(d, own(objs, R"({"group": "g", "rotate": {"euler_xyz": [0, 0, 1], "degrees": 3}})"),
                 "/nodes/0/rotate");
  expectDocError(d, own(objs, R"({"group": "g", "rotate": {"euler": [0, 0, 1]}})"), "/nodes/0/rotate/euler");
  expectDocError(d, own(objs, R"({"group": "g", "tranlsate": [0, 0, 1]})"), "/nodes/0/tranlsate", "unknown key");
  expectDocError(d, own(objs, R"({"group": "a/b"})"), "/nodes/0", "/");
  expectDocError(d, own(objs, inst + "," + inst), "/nodes/1");  // duplicate sibling name
  expectDocError(d, own(objs, R"({"instance": "i"})"), "/nodes/0", "object");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "nothing"})"), "/nodes/0/object", "nothing");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "mask": -1})"), "/nodes/0/mask");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "mask": 4294967296})"), "/nodes/0/mask");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "transform": [1, 2]})"), "/nodes/0/transform");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "transform": "id"})"), "/nodes/0/transform");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "transform": {"shear": 1}})"),
                 "/nodes/0/transform/shear");
  expectDocError(d, own(objs, R"({"instance": "i", "object": "cube", "children": []})"), "/nodes/0/children");
  std::string deep = inst;
  for (int i = 0; i < 300; ++i) deep = R"({"group": "g", "children": [)" + deep + "]}";
  expectDocError(d, own(objs, deep), "/children/0", "nested deeper");
  // Edits.
  const std::string tree = R"({"group": "g", "translate": [0, 0, 0], "children": [)" + inst + "]}";
  expectDocError(d, own(objs, tree, "5"), "/edits/0");
  expectDocError(d, own(objs, tree, R"({"node": "/g", "visible": true})"), "/edits/0", "time");
  expectDocError(d, own(objs, tree, R"({"time": -1, "node": "/g", "visible": true})"), "/edits/0/time");
  expectDocError(d, own(objs, tree, R"({"time": 1})"), "/edits/0", "set_transform");
  expectDocError(d, own(objs, tree, R"({"time": 1, "node": "/g", "visible": true, "remove": "/g"})"), "/edits/0",
                 "one thing");
  expectDocError(d, own(objs, tree, R"({"time": 1, "set_transform": [1]})"), "/edits/0", "node");
  expectDocError(d, own(objs, tree, R"({"time": 1, "node": "/g", "set_transform": [1]})"), "/edits/0/set_transform");
  expectDocError(d, own(objs, tree, R"({"time": 1, "node": "/g", "object": "none"})"), "/edits/0/object");
  expectDocError(d, own(objs, tree, R"({"time": 1, "add": {"group": 3}})"), "/edits/0/add/group");
  expectDocError(d, own(objs, tree, R"({"time": 1, "remove": "/g", "node": "/g"})"), "/edits/0/node", "unknown key");
  expectDocError(d, R"({"format": "duplex-scene-v1", "objects": [], "edits": {}})", "/edits");
}

TEST(SceneDocumentOwn, EditsThatTheGraphRefusesNameTheEditAndChangeNothing) {
  SceneDir d;
  const auto path = d.write(own(kCube, R"({"group": "g", "children": [{"instance": "i", "object": "cube"}]})",
                                R"({"time": 0, "node": "/g", "set_transform": {"translate": [1, 0, 0]}},
                                   {"time": 0, "add": {"group": "h", "children": [{"instance": "i", "object": "cube"},
                                                                                    {"instance": "i", "object": "cube"}]}},
                                   {"time": 0, "remove": "/"})"));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  const std::size_t nodes = doc.graph->nodeCount();
  expectError([&] { (void)applyEdit(doc, doc.edits[0]); }, path, "/edits/0");  // a plain group has no transform
  expectError([&] { (void)applyEdit(doc, doc.edits[1]); }, path, "/edits/1/add/children/1");
  expectError([&] { (void)applyEdit(doc, doc.edits[2]); }, path, "/edits/2");
  (void)doc.graph->commit();
  EXPECT_EQ(doc.graph->nodeCount(), nodes);
  EXPECT_FALSE(doc.graph->find("/h"));
}

TEST(SceneDocumentOwn, DeformAndAddObjectEditsReachTheLibraryWhenApplied) {
  SceneDir d;
  // The cube fixture twice as large (same faces), and a prepared structure of the tetrahedron.
  std::ifstream in(d.scenes / "meshes" / "quad_cube.obj");
  std::ostringstream big;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("v ", 0) == 0) {
      std::istringstream v(line.substr(2));
      double x, y, z;
      v >> x >> y >> z;
      big << "v " << 2 * x << ' ' << 2 * y << ' ' << 2 * z << '\n';
    } else {
      big << line << '\n';
    }
  }
  writeTextFile(d.scenes / "meshes" / "big_cube.obj", big.str());
  const auto prepared =
      saveStructures(loadSceneDocument(d.write(own(kTetra, "")), builtinObjectTypes()), d.scenes / "prepared");
  const std::string edits = R"(
    {"time": 1, "deform": "cube", "file": "meshes/big_cube.obj"},
    {"time": 2, "deform": "tetra", "positions": [0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 2]},
    {"time": 3, "add_object": {"name": "late", "mesh": )" +
                            std::string(kTetraInline) + R"(, "structure": "prepared/)" +
                            prepared[0].filename().string() + R"("}},
    {"time": 4, "add": {"instance": "l", "object": "late"}},
    {"time": 5, "deform": "tetra", "file": "meshes/big_cube.obj"},
    {"time": 5, "deform": "cube", "positions": [0, 0, 0]})";
  const auto path = d.write(
      own(kCube + "," + kTetra, R"({"instance": "c", "object": "cube"}, {"instance": "t", "object": "tetra"})", edits));
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  SceneGraph& g = *doc.graph;
  ObjectLibrary& lib = g.library();
  const ObjectId cube = doc.objects[0], tetra = doc.objects[1];
  ASSERT_EQ(doc.edits.size(), 6u);
  const auto late = lib.find("late");
  ASSERT_TRUE(late);
  EXPECT_EQ(doc.objects.size(), 2u);  // not an "objects" entry
  EXPECT_FALSE(lib.isBuilt(*late));   // not read before its edit
  const Box cube_box = lib.get(cube)->bounds();

  (void)applyEdit(doc, doc.edits[0]);
  ChangeSet cs = g.commit();
  EXPECT_EQ(cs.objects_changed, (std::vector<ObjectId>{cube}));
  EXPECT_EQ(cs.object_changed, (std::vector<NodeId>{doc.instances[0]}));
  EXPECT_EQ(lib.get(cube)->bounds().hi, 2.0f * cube_box.hi);
  EXPECT_EQ(lib.get(cube)->bounds().lo, 2.0f * cube_box.lo);
  (void)applyEdit(doc, doc.edits[1]);
  (void)g.commit();
  EXPECT_EQ(lib.get(tetra)->bounds().hi, glm::vec3(2.0f));

  (void)applyEdit(doc, doc.edits[2]);
  EXPECT_TRUE(lib.isBuilt(*late));
  const auto added = applyEdit(doc, doc.edits[3]);
  (void)g.commit();
  ASSERT_EQ(added.size(), 1u);
  EXPECT_EQ(g.node(added[0]).object, *late);
  EXPECT_TRUE(g.isVisibleInstance(added[0]));

  // Refused when applied, naming the edit; nothing changes.
  const auto before = lib.get(tetra);
  expectError([&] { (void)applyEdit(doc, doc.edits[4]); }, path, "/edits/4", "topology");
  expectError([&] { (void)applyEdit(doc, doc.edits[5]); }, path, "/edits/5", "vertices");
  EXPECT_FALSE(g.hasPendingEdits());
  EXPECT_EQ(lib.get(tetra), before);

  // Refused when read.
  const std::string objs = kCube + "," + kTetra;
  const std::string tree = R"({"instance": "c", "object": "cube"})";
  expectDocError(d, own(objs, tree, R"({"time": 1, "deform": "nothing", "positions": [0, 0, 0]})"), "/edits/0/deform");
  expectDocError(d, own(objs, tree, R"({"time": 1, "deform": "cube"})"), "/edits/0", "exactly one");
  expectDocError(d, own(objs, tree, R"({"time": 1, "deform": "cube", "positions": [0, 0, 0], "file": "x.obj"})"),
                 "/edits/0", "exactly one");
  expectDocError(d, own(objs, tree, R"({"time": 1, "deform": "cube", "positions": [0, 0]})"), "/edits/0/positions");
  expectDocError(d, own(objs, tree, R"({"time": 1, "deform": "cube", "positions": [0, 0, "a"]})"),
                 "/edits/0/positions/2");
  expectDocError(d, own(objs, tree, R"({"time": 1, "add_object": {"name": "cube", "box": {}}})"),
                 "/edits/0/add_object/name", "duplicate");
  expectDocError(d, own(objs, tree, R"({"time": 1, "add_object": {"name": "b", "box": {}}, "node": "/c"})"),
                 "/edits/0/node", "unknown key");
}

TEST(SceneDocumentOwn, LoadsReportProgressAndACancelledLoadReturnsNothing) {
  SceneDir d;
  const auto path = d.write(own(kCube + "," + kTetra + R"(, {"name": "ball", "sphere": {"subdivisions": 4}})",
                                R"({"instance": "c", "object": "cube"})"));
  SceneDocumentOptions options;
  std::vector<std::pair<std::size_t, std::size_t>> reports;
  options.control.progress = [&](std::size_t done, std::size_t total) { reports.emplace_back(done, total); };
  const SceneDocument doc = loadSceneDocument(path, builtinObjectTypes(), options);
  ASSERT_FALSE(reports.empty());
  EXPECT_EQ(reports.back().first, reports.back().second);
  EXPECT_LE(reports.back().second, 3u);
  CancelToken token;
  token.cancel();
  options.control.cancel = &token;
  EXPECT_THROW((void)loadSceneDocument(path, builtinObjectTypes(), options), Cancelled);
  // Cancelled during the builds, from the progress callback.
  token.reset();
  options.control.progress = [&](std::size_t, std::size_t) { token.cancel(); };
  EXPECT_THROW((void)loadSceneDocument(path, builtinObjectTypes(), options), Cancelled);
}

// ---- prepared structures ----

// ---- the registry ----

TEST(ObjectTypeRegistry, BuiltinAndCustomTypes) {
  const auto names = builtinObjectTypes().names();
  EXPECT_EQ(names, (std::vector<std::string>{"mesh", "sphere", "box", "plane", "volume"}));
  ObjectTypeRegistry registry = builtinObjectTypes();
  expectErrorNaming<InvalidArgument>(
      [&] {
        registry.add({"mesh", builtinObjectTypes().find("mesh")->reader});
      },
      "already registered");
  expectErrorNaming<InvalidArgument>(
      [&] {
        registry.add({"name", builtinObjectTypes().find("mesh")->reader});
      },
      "name");
  expectErrorNaming<InvalidArgument>([&] { registry.add({"x", nullptr}); }, "no reader");
  // A custom type: a tetrahedron of a given edge, built now ("tetra") or deferred ("lazy_tetra").
  int built_now = 0;
  auto tetra = [](double edge, const std::string& name) {
    const float e = static_cast<float>(edge);
    return test::buildChecked(TriangleMesh::fromTriangles({{0, 0, 0}, {e, 0, 0}, {0, e, 0}, {0, 0, e}},
                                                          {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}, name));
  };
  registry.add({"tetra", [&](const nlohmann::json& spec, const ObjectSpecContext& ctx) -> ObjectSpecResult {
                  ctx.onlyKeys(spec, ctx.pointer, {"edge"});
                  const double edge = ctx.positiveNumber(ctx.member(spec, ctx.pointer, "edge"), ctx.pointer + "/edge");
                  ++built_now;
                  return std::shared_ptr<const Object>(tetra(edge, ctx.object_name));
                }});
  registry.add({"lazy_tetra", [&](const nlohmann::json& spec, const ObjectSpecContext& ctx) -> ObjectSpecResult {
                  const double edge = ctx.positiveNumber(ctx.member(spec, ctx.pointer, "edge"), ctx.pointer + "/edge");
                  return ObjectLibrary::Factory([=] {
                    if (edge > 100) throw InvalidArgument("edge too long");
                    return std::shared_ptr<const Object>(tetra(edge, ctx.object_name));
                  });
                }});
  SceneDir d;
  const SceneDocumentOptions options;
  const auto path = d.write(own(R"({"name": "t", "tetra": {"edge": 2}}, {"name": "l", "lazy_tetra": {"edge": 3}})",
                                R"({"instance": "a", "object": "t"}, {"instance": "b", "object": "l"})"));
  const SceneDocument doc = loadSceneDocument(path, registry, options);
  EXPECT_EQ(built_now, 1);
  EXPECT_EQ(doc.graph->library().typeName(doc.objects[1]), "lazy_tetra");
  EXPECT_EQ(doc.graph->library().get(doc.objects[1])->bounds().hi.x, 3.0f);
  EXPECT_EQ(doc.instances.size(), 2u);
  expectDocError(d, own(R"({"name": "t", "tetra": {"edge": -2}})", ""), "/objects/0/tetra/edge", "", options, registry);
  expectDocError(d, own(R"({"name": "t", "tetra": {}})", ""), "/objects/0/tetra", "edge", options, registry);
  expectDocError(d, own(kCube + R"(, {"name": "l", "lazy_tetra": {"edge": 300}})", ""), "/objects/1/lazy_tetra",
                 "edge too long", options, registry);
  // Without the registry, the key is no type at all.
  expectDocError(d, own(R"({"name": "t", "tetra": {"edge": 2}})", ""), "/objects/0", "no object type");
  // Not a scene-json-v1 type: v1 files ignore the key.
  expectDocError(d, v1(R"({"name": "t", "tetra": {"edge": 2}})", ""), "/objects/0", "no object type", options,
                 registry);
}

// Many small objects: each deferred build runs once, in parallel, before the instances are added.
TEST(SceneDocumentScale, ThousandsOfInlineObjects) {
  SceneDir d;
  nlohmann::json scene = {
      {"format", "scene-json-v1"}, {"objects", nlohmann::json::array()}, {"instances", nlohmann::json::array()}};
  const int n = 3000;
  for (int i = 0; i < n; ++i) {
    const float o = static_cast<float>(i);
    // Not "o" + std::to_string(i): GCC 12 warns about that expression (-Wrestrict, a false positive).
    const std::string name = std::string("o").append(std::to_string(i));
    scene["objects"].push_back({{"name", name},
                                {"mesh",
                                 {{"positions", {o, 0, 0, o + 1, 0, 0, o, 1, 0, o, 0, 1}},
                                  {"indices", {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3}}}}});
    scene["instances"].push_back({{"object", name}, {"transform", {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, i}}});
  }
  const auto path = d.write(scene.dump());
  const SceneDocument doc = loadSceneDocument(path, builtinObjectTypes());
  EXPECT_EQ(doc.instances.size(), std::size_t(n));
  EXPECT_EQ(doc.graph->library().buildCount(), std::size_t(n));
  EXPECT_EQ(doc.figures.count("triangles"), std::size_t(4 * n));
  EXPECT_EQ(doc.graph->worldTransform(doc.instances[17]).translation.z, 17.0);
  std::printf("%d inline objects: load %.1f ms, build %.1f ms, graph %.1f ms\n", n, doc.figures.load_ms,
              doc.figures.build_ms, doc.figures.graph_ms);
}

}  // namespace
}  // namespace duplex::test
