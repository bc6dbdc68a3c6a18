// Scene files against the memory limit: the JSON document and the instances (or nodes) are
// checked before they are built, so that a file with a huge instance count is refused with a
// ResourceError naming the file, its largest allocation no larger than the file's text; the same
// files load under the default limit.

#include "MemoryLimitScope.h"
#include "TestSupport.h"

#include "duplex/accel/MemoryLimit.h"
#include "duplex/objects/BuiltinTypes.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneMemory.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <sstream>
#include <string>

// The largest single allocation since the last reset: replacing the global operator new is the
// only way to see every allocation a load makes.
namespace {
std::atomic<std::size_t> g_largest_allocation{0};
}

// GCC sees free() of what operator new returned; both are ours and use malloc/free.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void* operator new(std::size_t n) {
  std::size_t seen = g_largest_allocation.load(std::memory_order_relaxed);
  while (n > seen && !g_largest_allocation.compare_exchange_weak(seen, n, std::memory_order_relaxed)) {
  }
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace duplex::test {
namespace {

constexpr const char* kTriangle =
    R"({"name": "tri", "mesh": {"positions": [0, 0, 0, 1, 0, 0, 0, 1, 0], "indices": [0, 1, 2]}})";

// scene-json-v1 with `n` instances of one triangle, each moved along x.
std::string v1Scene(std::size_t n, const std::string& object = kTriangle) {
  std::ostringstream s;
  s << R"({"format": "scene-json-v1", "objects": [)" << object << R"(], "instances": [)";
  for (std::size_t i = 0; i < n; ++i)
    s << (i ? ",\n" : "") << R"({"object": "tri", "transform": [1, 0, 0, )" << i << R"(, 0, 1, 0, 0, 0, 0, 1, 0]})";
  s << "]}";
  return s.str();
}

// duplex-scene-v1 with `n` instance nodes of one triangle.
std::string ownScene(std::size_t n, const std::string& object = kTriangle) {
  std::ostringstream s;
  s << R"({"format": "duplex-scene-v1", "objects": [)" << object << R"(], "nodes": [)";
  for (std::size_t i = 0; i < n; ++i) s << (i ? ",\n" : "") << R"({"instance": "i)" << i << R"(", "object": "tri"})";
  s << "]}";
  return s.str();
}

std::string resourceMessage(const std::filesystem::path& file) {
  try {
    (void)loadSceneDocument(file, builtinObjectTypes());
  } catch (const ResourceError& e) {
    return e.what();
  }
  return "no ResourceError";
}

TEST(SceneMemoryLimit, TheJsonOfAHugeInstanceCountIsRefusedBeforeItIsBuilt) {
  TempDir dir;
  const std::size_t n = 20000;
  const auto file = dir / "many.json";
  const std::string text = v1Scene(n);
  writeTextFile(file, text);
  {
    // The text fits, the document nlohmann::json would build from it (hundreds of bytes per
    // instance) does not.
    MemoryLimitScope limit(text.size() + 4096);
    g_largest_allocation = 0;
    const std::string m = resourceMessage(file);
    EXPECT_NE(m.find("scene file '" + file.string() + "' (its text and its"), std::string::npos) << m;
    EXPECT_NE(m.find("JSON values) needs"), std::string::npos) << m;
    EXPECT_NE(m.find("--max-memory"), std::string::npos) << m;
    EXPECT_LE(g_largest_allocation.load(), text.size() + 4096) << "an allocation larger than the file's text";
  }
  {
    // Not even the text fits.
    MemoryLimitScope limit(text.size() - 1);
    EXPECT_NE(resourceMessage(file).find("(its text) needs " + formatBytes(text.size())), std::string::npos);
  }
  const SceneDocument doc = loadSceneDocument(file, builtinObjectTypes());
  EXPECT_EQ(doc.instances.size(), n);
}

TEST(SceneMemoryLimit, InstancesAndNodesAreCheckedBeforeAnyObjectIsRead) {
  TempDir dir;
  const std::size_t n = 20000;
  // The object's mesh file does not exist: a load that reached the objects would fail naming it.
  const std::string missing = R"({"name": "tri", "mesh": {"file": "missing.obj"}})";
  const auto v1 = dir / "v1.json", own = dir / "own.json";
  writeTextFile(v1, v1Scene(n, missing));
  writeTextFile(own, ownScene(n, missing));
  // The JSON of a node is a few hundred bytes, what the graph and the top level keep of it more:
  // a limit just below the latter passes the document and refuses the instances.
  ASSERT_GT(sceneBytesPerInstance(), 700u);
  {
    MemoryLimitScope limit(n * sceneBytesPerInstance() - 1);
    std::ostringstream bytes;
    bytes << "(20000 instances) needs " << formatBytes(n * sceneBytesPerInstance()) << " of memory";
    const std::string m = resourceMessage(v1);
    EXPECT_NE(m.find("scene file '" + v1.string() + "' " + bytes.str()), std::string::npos) << m;
    const std::string m_own = resourceMessage(own);
    EXPECT_NE(m_own.find("scene file '" + own.string() + "' (20000 nodes)"), std::string::npos) << m_own;
  }
  {
    // At the limit the load goes on, to the missing mesh.
    MemoryLimitScope limit(n * sceneBytesPerInstance());
    expectErrorNaming<FileError>([&] { (void)loadSceneDocument(v1, builtinObjectTypes()); }, "missing.obj");
  }
  const auto good = dir / "good.json";
  writeTextFile(good, ownScene(n));
  EXPECT_EQ(loadSceneDocument(good, builtinObjectTypes()).instances.size(), n);
}

// A mesh the scene names, past the limit when it is read or built, fails the load with the
// ResourceError (not a FileError: the tool and Python tell the two apart), naming the scene file,
// the entry and the mesh file.
TEST(SceneMemoryLimit, AMeshPastTheLimitFailsTheLoadAsAResourceError) {
  TempDir dir;
  std::ostringstream off;
  const std::size_t n = 20000;  // a strip of n triangles
  off << "OFF\n" << n + 2 << " " << n << " 0\n";
  for (std::size_t i = 0; i < n + 2; ++i) off << i / 2 << " " << i % 2 << " 0\n";
  for (std::size_t i = 0; i < n; ++i) off << "3 " << i << " " << i + 1 << " " << i + 2 << "\n";
  writeTextFile(dir / "strip.off", off.str());
  const auto scene = dir / "scene.json";
  writeTextFile(scene, R"({"format": "scene-json-v1", "objects": [{"name": "tri", "mesh": {"file": "strip.off"}}],
    "instances": [{"object": "tri", "transform": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]}]})");
  {
    MemoryLimitScope limit(off.str().size() + 1000);  // the text fits, its arrays do not
    const std::string m = resourceMessage(scene);
    EXPECT_NE(m.find(scene.string() + ": /objects/0/mesh: mesh file '" + (dir / "strip.off").string() +
                     "' (20002 "
                     "vertices, 20000 faces) needs"),
              std::string::npos)
        << m;
  }
  {
    // The arrays fit, the structure's boxes, references and leaf blocks do not.
    MemoryLimitScope limit(off.str().size() + 24 * n + 1000);
    const std::string m = resourceMessage(scene);
    EXPECT_NE(m.find("mesh '" + (dir / "strip.off").string() + "' (20000 triangles: its BVH) needs"), std::string::npos)
        << m;
    EXPECT_NE(m.find(scene.string()), std::string::npos) << m;
  }
  EXPECT_EQ(loadSceneDocument(scene, builtinObjectTypes()).instances.size(), 1u);
}

}  // namespace
}  // namespace duplex::test
