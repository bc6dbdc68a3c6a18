// Saved bottom-level structures (MeshObjectFile.h): a round trip answers every query bit for bit
// like the built object; damaged, truncated, foreign or forged files are refused with a FileError
// naming the file (MeshObject::fromParts for trees that are well framed but wrong), never a crash.

#include "KdTreeChecks.h"
#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

bool sameBits(float a, float b) { return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b); }

/// Every ray: same closest hit (t, u, v, prim_id, ng to the bit) and same occlusion.
void expectIdenticalQueries(const MeshObject& a, const MeshObject& b, std::span<const Ray> rays) {
  std::size_t hits = 0, failures = 0;
  for (const Ray& ray : rays) {
    Hit ha, hb;
    const bool ra = a.intersect(ray, ha), rb = b.intersect(ray, hb);
    hits += ra;
    const bool same = ra == rb && sameBits(ha.t, hb.t) && sameBits(ha.u, hb.u) && sameBits(ha.v, hb.v) &&
                      ha.prim_id == hb.prim_id && sameBits(ha.ng.x, hb.ng.x) && sameBits(ha.ng.y, hb.ng.y) &&
                      sameBits(ha.ng.z, hb.ng.z) && a.occluded(ray) == b.occluded(ray);
    if (!same && ++failures <= 5) ADD_FAILURE() << ray << ": built " << ha << ", loaded " << hb;
  }
  EXPECT_EQ(failures, 0u);
  EXPECT_GT(hits, rays.size() / 10) << "too few hits for the comparison to mean much";
}

std::vector<Ray> testRays(const Box& bounds, std::size_t count) {
  std::vector<Ray> rays = randomRays(bounds, count, 99);
  const auto outer = randomRays(enlarged(bounds, 1.0f), count / 2, 100);
  rays.insert(rays.end(), outer.begin(), outer.end());
  const auto primary = primaryRays(bounds, 40, 40);
  rays.insert(rays.end(), primary.begin(), primary.end());
  return rays;
}

void roundTrip(std::shared_ptr<const TriangleMesh> mesh, std::size_t rays, const KdBuildConfig& config = {}) {
  const TempDir dir;
  const auto built = buildChecked(mesh, config);
  saveMeshObject(*built, dir / "object.dkdt");
  const auto loaded = loadMeshObject(dir / "object.dkdt", mesh);
  ASSERT_TRUE(loaded);
  EXPECT_TRUE(checkMeshTree(*loaded, 0));
  EXPECT_EQ(loaded->name(), built->name());
  EXPECT_EQ(loaded->tree().bounds, built->tree().bounds);
  ASSERT_EQ(loaded->tree().nodes.size(), built->tree().nodes.size());
  EXPECT_EQ(
      std::memcmp(loaded->tree().nodes.data(), built->tree().nodes.data(), built->tree().nodes.size() * sizeof(KdNode)),
      0);
  EXPECT_EQ(loaded->tree().prim_indices, built->tree().prim_indices);
  EXPECT_EQ(loaded->accelBytes(), built->accelBytes());
  expectIdenticalQueries(*built, *loaded, testRays(mesh->bounds(), rays));
}

TEST(MeshObjectFile, RoundTripIcosphere) { roundTrip(std::make_shared<const TriangleMesh>(icosphere(4)), 4000); }

// A file holds the tree, not the costs it was built with: a structure saved under another build
// configuration (intersection cost 0.1, or the top level's 1) still loads and
// answers like the object it was saved from.
TEST(MeshObjectFile, RoundTripTreesBuiltWithOtherCosts) {
  for (const float ci : {0.1f, 1.0f}) {
    KdBuildConfig config;
    config.intersection_cost = ci;
    SCOPED_TRACE(ci);
    roundTrip(std::make_shared<const TriangleMesh>(icosphere(4)), 2000, config);
  }
}

TEST(MeshObjectFile, RoundTripTriangleSoupWithDegenerates) {
  roundTrip(std::make_shared<const TriangleMesh>(triangleSoup(3000, 7)), 4000);
}

// A real mesh round-trips exactly. How much faster loading is than building is a benchmark figure
// (`duplex bench update`, the prepared-library column), not a test: timings do not belong here.
TEST(MeshObjectFile, RoundTripKoala) {
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, "koala.obj");
  const TempDir dir;
  const auto built = buildChecked(mesh);
  saveMeshObject(*built, dir / "koala.dkdt");
  const auto loaded = loadMeshObject(dir / "koala.dkdt", mesh);
  EXPECT_TRUE(checkMeshTree(*loaded, 0));
  ASSERT_EQ(loaded->tree().nodes.size(), built->tree().nodes.size());
  EXPECT_EQ(loaded->tree().prim_indices, built->tree().prim_indices);
  expectIdenticalQueries(*built, *loaded, testRays(mesh->bounds(), 1500));
}

// ---- refused files ----

class MeshObjectFileTamper : public ::testing::Test {
 protected:
  void SetUp() override {
    mesh_ = std::make_shared<const TriangleMesh>(icosphere(3));
    object_ = buildChecked(mesh_);
    saveMeshObject(*object_, good_);
    bytes_ = readBinaryFile(good_);
    nodes_ = object_->tree().nodes.size();
    prims_ = object_->tree().prim_indices.size();
    ASSERT_EQ(bytes_.size(), 64 + 8 * nodes_ + 4 * prims_ + 8);
  }
  /// Writes `bytes` to a file and expects loading it to throw a FileError naming it and `problem`.
  void expectRefused(const std::vector<char>& bytes, const std::string& problem, const std::string& what) {
    SCOPED_TRACE(what);
    const auto path = dir_ / "tampered.dkdt";
    writeBinaryFile(path, bytes);
    try {
      auto loaded = loadMeshObject(path, mesh_);
      ADD_FAILURE() << "accepted";
    } catch (const FileError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(path.string()), std::string::npos) << msg;
      EXPECT_NE(msg.find(problem), std::string::npos) << msg;
    }
  }

  TempDir dir_;
  std::filesystem::path good_ = dir_ / "good.dkdt";
  std::shared_ptr<const TriangleMesh> mesh_;
  std::shared_ptr<const MeshObject> object_;
  std::vector<char> bytes_;
  std::size_t nodes_ = 0, prims_ = 0;
};

TEST_F(MeshObjectFileTamper, EveryFlippedByteIsRefused) {
  // Every header byte, and a spread of bytes in the nodes, the indices and the checksum itself.
  std::vector<std::size_t> offsets;
  for (std::size_t i = 0; i < 64; ++i) offsets.push_back(i);
  for (std::size_t i = 64; i < bytes_.size(); i += 37) offsets.push_back(i);
  offsets.push_back(64 + 8 * nodes_);    // first index
  offsets.push_back(bytes_.size() - 9);  // last index byte
  offsets.push_back(bytes_.size() - 1);  // checksum
  for (const std::size_t at : offsets) {
    for (const unsigned char mask : {0x01, 0x80}) {
      std::vector<char> bad = bytes_;
      bad[at] = static_cast<char>(bad[at] ^ mask);
      const std::string region = at < 64                  ? "header"
                                 : at < 64 + 8 * nodes_   ? "nodes"
                                 : at < bytes_.size() - 8 ? "indices"
                                                          : "checksum";
      // Magic, version and sizes have their own messages; anything else is caught by the checksum.
      std::string problem = at < 8                ? "bad magic"
                            : at < 12             ? "version"
                            : at < 16             ? "header size"
                            : at >= 32 && at < 40 ? "truncated or damaged"
                                                  : "checksum mismatch";
      expectRefused(bad, problem, region + " byte " + std::to_string(at) + " ^ " + std::to_string(mask));
    }
  }
}

TEST_F(MeshObjectFileTamper, TruncatedOrExtendedIsRefused) {
  for (const std::size_t keep : {std::size_t(0), std::size_t(10), std::size_t(64), std::size_t(71), bytes_.size() / 2,
                                 bytes_.size() - 8, bytes_.size() - 1}) {
    expectRefused(std::vector<char>(bytes_.begin(), bytes_.begin() + static_cast<std::ptrdiff_t>(keep)),
                  keep < 72 ? "too short" : "truncated", "kept " + std::to_string(keep) + " bytes");
  }
  std::vector<char> longer = bytes_;
  longer.push_back(0);
  expectRefused(longer, "truncated or damaged", "one byte appended");
}

TEST_F(MeshObjectFileTamper, WrongMeshIsRefused) {
  // Same counts, one vertex moved: only the checksum tells.
  std::vector<glm::vec3> positions = mesh_->positions();
  positions[5].x += 1e-3f;
  auto moved =
      std::make_shared<const TriangleMesh>(TriangleMesh::fromTriangles(positions, mesh_->triangles(), "moved"));
  try {
    auto loaded = loadMeshObject(good_, moved);
    ADD_FAILURE() << "accepted a structure saved for another mesh";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find(good_.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("another mesh"), std::string::npos) << e.what();
  }
  // Triangles reordered: same vertices, other ids.
  std::vector<TriangleMesh::Triangle> tris = mesh_->triangles();
  std::swap(tris[0], tris[1]);
  auto reordered = std::make_shared<const TriangleMesh>(TriangleMesh::fromTriangles(mesh_->positions(), tris, "re"));
  expectErrorNaming<FileError>([&] { (void)loadMeshObject(good_, reordered); }, good_.string());
  // Another mesh altogether: the counts differ.
  auto other = std::make_shared<const TriangleMesh>(icosphere(2));
  expectErrorNaming<FileError>([&] { (void)loadMeshObject(good_, other); }, "triangles");
}

TEST_F(MeshObjectFileTamper, MissingFileAndNullMesh) {
  expectErrorNaming<FileError>([&] { (void)loadMeshObject(dir_ / "absent.dkdt", mesh_); }, "absent.dkdt");
  expectErrorNaming<InvalidArgument>([&] { (void)loadMeshObject(good_, nullptr); }, "null mesh");
  expectErrorNaming<FileError>([&] { saveMeshObject(*object_, dir_ / "no" / "such" / "dir" / "x.dkdt"); }, "x.dkdt");
}

// ---- forged trees: well framed, checksum right, contents wrong (MeshObject::fromParts) ----

KdTree treeOf(const MeshObject& o) { return o.tree(); }

void expectRejected(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, const std::string& problem) {
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject::fromParts(mesh, std::move(tree)); }, problem);
}

TEST(MeshObjectFromParts, RejectsEveryKindOfBrokenTree) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const MeshObject built(mesh);
  const KdTree good = treeOf(built);
  ASSERT_GT(good.nodes.size(), 3u);
  ASSERT_FALSE(good.nodes[0].isLeaf());
  EXPECT_NO_THROW((void)MeshObject::fromParts(mesh, good));

  KdTree t = good;
  t.nodes.clear();
  expectRejected(mesh, t, "no nodes");

  t = good;
  t.nodes[0].setUpperChild(static_cast<std::uint32_t>(t.nodes.size()));
  expectRejected(mesh, t, "out of range");

  t = good;
  t.nodes[0].setUpperChild(0);  // a cycle back to the root
  expectRejected(mesh, t, "out of range");

  t = good;
  t.nodes[0].setUpperChild(t.nodes[0].upperChild() + 1);  // skips a node: not where the lower subtree ends
  expectRejected(mesh, t, "sibling subtree");

  t = good;
  t.nodes.push_back(KdNode::leaf(0, 0));  // a node no parent reaches
  expectRejected(mesh, t, "after the end");

  t = good;
  t.nodes[1] = KdNode::jump(0);  // a jump (top levels only) back to the root: an endless traversal
  expectRejected(mesh, t, "jump node");

  t = good;
  for (auto& n : t.nodes)
    if (n.isLeaf() && n.primCount() > 0) {
      n = KdNode::leaf(static_cast<std::uint32_t>(t.prim_indices.size()) - n.primCount() + 1, n.primCount());
      break;
    }
  expectRejected(mesh, t, "beyond prim_indices");

  t = good;
  for (auto& n : t.nodes)
    if (n.isLeaf() && n.primCount() > 0) {
      n = KdNode::leaf(0xFFFFFFF0u, n.primCount());  // offset + count overflows 32 bits
      break;
    }
  expectRejected(mesh, t, "beyond prim_indices");

  t = good;
  t.prim_indices[3] = static_cast<std::uint32_t>(mesh->triangleCount());
  expectRejected(mesh, t, "not a valid triangle");

  t = good;
  t.nodes[0] = KdNode::inner(t.nodes[0].axis(), std::numeric_limits<float>::quiet_NaN(), t.nodes[0].upperChild());
  expectRejected(mesh, t, "not finite");

  t = good;
  t.bounds.hi.x = t.bounds.lo.x;  // no longer holds the mesh
  expectRejected(mesh, t, "bounds");

  t = good;
  t.bounds.lo.y = -std::numeric_limits<float>::infinity();
  expectRejected(mesh, t, "bounds");

  // A chain deeper than the traversal stack: inner nodes whose lower child is the next inner node.
  t = good;
  t.nodes.clear();
  const std::uint32_t depth = kKdStackSize + 2;
  for (std::uint32_t i = 0; i < depth; ++i) t.nodes.push_back(KdNode::inner(0, 0.0f, 0));
  t.nodes.push_back(KdNode::leaf(0, 1));
  for (std::uint32_t i = 0; i < depth; ++i) {
    t.nodes[depth - 1 - i].setUpperChild(static_cast<std::uint32_t>(t.nodes.size()));
    t.nodes.push_back(KdNode::leaf(0, 1));
  }
  expectRejected(mesh, t, "deeper than the traversal stack");

  // A triangle the mesh marks degenerate.
  std::vector<glm::vec3> p = mesh->positions();
  std::vector<TriangleMesh::Triangle> tris = mesh->triangles();
  tris.push_back({0, 0, 1});
  auto with_degenerate = std::make_shared<const TriangleMesh>(TriangleMesh::fromTriangles(p, tris, "deg"));
  t = good;
  t.prim_indices[0] = static_cast<std::uint32_t>(tris.size() - 1);
  expectRejected(with_degenerate, t, "not a valid triangle");
}

// Random corruption of the node array: either refused, or (when the bits happen to describe a valid
// tree) queries run without reading out of bounds (checked by ASan in the sanitizer build).
TEST(MeshObjectFromParts, RandomCorruptionIsRefusedOrHarmless) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(2));
  const MeshObject built(mesh);
  const auto rays = randomRays(mesh->bounds(), 200, 5);
  std::mt19937_64 rng(2024);
  std::size_t refused = 0, accepted = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    KdTree t = built.tree();
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int f = 0; f < flips; ++f) {
      if (rng() % 4 == 0) {
        auto& idx = t.prim_indices[rng() % t.prim_indices.size()];
        idx ^= 1u << (rng() % 32);
      } else {
        auto* bytes = reinterpret_cast<unsigned char*>(t.nodes.data());
        bytes[rng() % (t.nodes.size() * sizeof(KdNode))] ^= static_cast<unsigned char>(1u << (rng() % 8));
      }
    }
    std::shared_ptr<const MeshObject> o;
    try {
      o = MeshObject::fromParts(mesh, std::move(t));
    } catch (const InvalidArgument&) {
      ++refused;
      continue;
    }
    ++accepted;
    for (const Ray& r : rays) {
      Hit h;
      (void)o->intersect(r, h);
      (void)o->occluded(r);
    }
  }
  EXPECT_GT(refused, 0u);
  std::printf("random corruption: %zu refused, %zu accepted (split planes or indices changed within range)\n", refused,
              accepted);
}

}  // namespace
}  // namespace duplex::test
