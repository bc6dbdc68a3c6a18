#pragma once
// Scene files for the tests of scene documents and of object types' readers: a temporary scene
// folder with the cube fixture, the two formats' skeletons, and checks that a load fails naming the
// file and the JSON pointer.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/scenegraph/ObjectTypeRegistry.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/accel/WideBvh.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace duplex::test {

inline const std::string kCube = R"({"name": "cube", "mesh": {"file": "meshes/quad_cube.obj"}})";
inline const std::string kTetra =
    R"({"name": "tetra", "mesh": {"positions": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1], "indices": [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]}})";
inline const std::string kIdentity = "[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]";

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

inline std::string v1(const std::string& objects, const std::string& instances) {
  return R"({"format": "scene-json-v1", "objects": [)" + objects + R"(], "instances": [)" + instances + "]}";
}
inline std::string own(const std::string& objects, const std::string& nodes, const std::string& edits = "") {
  return R"({"format": "duplex-scene-v1", "objects": [)" + objects + R"(], "nodes": [)" + nodes + "]" +
         (edits.empty() ? "" : R"(, "edits": [)" + edits + "]") + "}";
}

/// `load` must throw FileError naming the file and `pointer` (and `also` when given).
template <class Load>
void expectError(Load&& load, const std::filesystem::path& file, const std::string& pointer,
                 const std::string& also = "") {
  try {
    load();
    ADD_FAILURE() << "no FileError (expected " << pointer << ")";
  } catch (const FileError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file.filename().string()), std::string::npos) << "does not name the file: " << msg;
    EXPECT_NE(msg.find(pointer + ":"), std::string::npos) << "does not name '" << pointer << "': " << msg;
    if (!also.empty()) {
      EXPECT_NE(msg.find(also), std::string::npos) << "does not mention '" << also << "': " << msg;
    }
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type: " << e.what();
  }
}

inline void expectDocError(const SceneDir& d, const std::string& json, const std::string& pointer,
                           const std::string& also = "", const SceneDocumentOptions& options = {},
                           const ObjectTypeRegistry& registry = builtinObjectTypes()) {
  SCOPED_TRACE(json);
  const auto path = d.write(json, "bad_scene.json");
  expectError([&] { (void)loadSceneDocument(path, registry, options); }, path, pointer, also);
}

inline const char* kTetraInline =
    R"({"positions": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1], "indices": [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]})";

/// Loads a scene file and checks every mesh object of its "objects" list: a kd-tree with the tree
/// checker, a BVH with the checker MeshObject::fromParts runs.
inline SceneDocument loadChecked(const std::filesystem::path& path, const SceneDocumentOptions& options = {}) {
  SceneDocument doc = loadSceneDocument(path, builtinObjectTypes(), options);
  const ObjectLibrary& lib = doc.graph->library();
  for (const ObjectId id : doc.objects) {
    if (const auto* m = dynamic_cast<const MeshObject*>(lib.get(id).get())) {
      if (m->structure() == MeshStructure::KdTree) {
        EXPECT_TRUE(checkMeshTree(*m, options.build.max_depth)) << "object '" << lib.name(id) << "'";
      } else {
        const std::shared_ptr<const TriangleMesh> mesh(std::shared_ptr<const TriangleMesh>{}, &m->mesh());
        EXPECT_NO_THROW((void)MeshObject::fromParts(mesh, m->bvh())) << "object '" << lib.name(id) << "'";
      }
    }
  }
  return doc;
}

/// The working directory for one scope (restored even when an assertion throws).
struct WorkingDirectory {
  std::filesystem::path saved = std::filesystem::current_path();
  explicit WorkingDirectory(const std::filesystem::path& dir) { std::filesystem::current_path(dir); }
  ~WorkingDirectory() { std::filesystem::current_path(saved); }
  WorkingDirectory(const WorkingDirectory&) = delete;
  WorkingDirectory& operator=(const WorkingDirectory&) = delete;
};

}  // namespace duplex::test
