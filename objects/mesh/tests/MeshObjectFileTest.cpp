// Saved bottom-level structures (MeshObjectFile.h), kd-trees (.dkdt) and BVHs (.dbvh): a round trip
// answers every query bit for bit like the built object; damaged, truncated, foreign or forged
// files are refused with a FileError naming the file (MeshObject::fromParts for structures that are
// well framed but wrong), never a crash.

#include "KdTreeChecks.h"
#include "MemoryLimitScope.h"
#include "MeshChecks.h"
#include "TestSupport.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/accel/RayGenerator.h"
#include "duplex/accel/Xxh64.h"
#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"
#include "duplex/accel/WideBvh.h"
#include "duplex/accel/KdTree.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstddef>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace duplex::test {
namespace {

bool sameBits(float a, float b) { return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b); }

/// Every ray: same closest hit (t, u, v, prim_id, ng to the bit) and same occlusion.
void expectIdenticalQueries(const MeshObject& a, const MeshObject& b, std::span<const Ray> rays,
                            bool require_hits = true) {
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
  if (require_hits) {
    EXPECT_GT(hits, rays.size() / 10) << "too few hits for the comparison to mean much";
  }
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

// ---- BVH files ----

/// A BVH object built with `config`, its BVH checked by the same checker a loaded one goes through.
std::shared_ptr<const MeshObject> bvhChecked(std::shared_ptr<const TriangleMesh> mesh, const BvhBuildConfig& config) {
  auto object = std::make_shared<const MeshObject>(mesh, config);
  EXPECT_EQ(object->structure(), MeshStructure::Bvh);
  EXPECT_NO_THROW((void)MeshObject::fromParts(mesh, object->bvh())) << "mesh '" << mesh->name() << "', " << config;
  return object;
}

void bvhRoundTrip(std::shared_ptr<const TriangleMesh> mesh, std::size_t rays, const BvhBuildConfig& config,
                  bool require_hits = true) {
  const TempDir dir;
  const auto built = bvhChecked(mesh, config);
  EXPECT_EQ(built->preparedExtension(), ".dbvh");
  const auto path = dir / ("object" + std::string(built->preparedExtension()));
  saveMeshObject(*built, path);
  const auto loaded = loadMeshObject(path, mesh);
  ASSERT_TRUE(loaded);
  EXPECT_EQ(loaded->structure(), MeshStructure::Bvh);
  EXPECT_EQ(loaded->name(), built->name());
  const WideBvh &a = built->bvh(), &b = loaded->bvh();
  EXPECT_EQ(b.root, a.root);
  EXPECT_EQ(b.leaf_block, a.leaf_block);
  EXPECT_EQ(std::memcmp(&b.bounds, &a.bounds, sizeof(Box)), 0) << b.bounds << " vs " << a.bounds;
  ASSERT_EQ(b.nodes.size(), a.nodes.size());
  // (memcmp is not given the null data of empty vectors: a leaf root has no nodes.)
  if (!a.nodes.empty()) {
    EXPECT_EQ(std::memcmp(b.nodes.data(), a.nodes.data(), a.nodes.size() * sizeof(BvhNode8)), 0);
  }
  EXPECT_EQ(b.prim_indices, a.prim_indices);
  EXPECT_TRUE(loaded->tree().nodes.empty());
  EXPECT_EQ(loaded->accelBytes(), built->accelBytes());
  expectIdenticalQueries(*built, *loaded, testRays(mesh->bounds(), rays), require_hits);
}

// A prepared file is read whole and its arrays copied out: twice its size is checked against the
// memory limit before it is read, naming the file; building the same structure instead is checked
// too.
TEST(MeshObjectFileBvh, FilesPastTheMemoryLimitAreRefusedNamingThem) {
  const TempDir dir;
  const auto mesh = std::make_shared<const TriangleMesh>(icosphere(4));
  const auto path = dir / "object.dbvh";
  const MeshObject built(mesh, BvhBuildConfig{});
  saveMeshObject(built, path);
  const std::uint64_t size = std::filesystem::file_size(path);
  {
    MemoryLimitScope limit(2 * size - 1);
    expectErrorNaming<ResourceError>([&] { (void)loadMeshObject(path, mesh); },
                                     "bottom-level structure file '" + path.string() + "' (" + formatBytes(size) +
                                         ") needs " + formatBytes(2 * size));
    expectErrorNaming<ResourceError>([&] { (void)MeshObject(mesh, BvhBuildConfig{}); }, "triangles: its BVH) needs");
  }
  {
    MemoryLimitScope limit(2 * size);
    // Reading needs less than building (no boxes, no builder): the file loads where a build is refused.
    EXPECT_EQ(loadMeshObject(path, mesh)->bvh().prim_indices, built.bvh().prim_indices);
  }
}

TEST(MeshObjectFileBvh, RoundTripPresets) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(4));
  for (const BvhPreset preset : {BvhPreset::Fast, BvhPreset::Medium}) {
    SCOPED_TRACE(toString(preset));
    bvhRoundTrip(mesh, 3000, BvhBuildConfig::preset(preset));
  }
  // Leaves of at most 4 and 16 triangles: other leaf ranges, the same format.
  bvhRoundTrip(mesh, 1000, BvhBuildConfig::parse("medium,leaf=4"));
  bvhRoundTrip(mesh, 1000, BvhBuildConfig::parse("fast,leaf=16"));
}

// Spatial splits reference a triangle from several leaves, each box holding only its part.
TEST(MeshObjectFileBvh, RoundTripHighPreset) {
  auto mesh = std::make_shared<const TriangleMesh>(triangleSoup(3000, 11));
  bvhRoundTrip(mesh, 3000, BvhBuildConfig::preset(BvhPreset::High));
}

TEST(MeshObjectFileBvh, RoundTripTriangleSoupWithDegenerates) {
  bvhRoundTrip(std::make_shared<const TriangleMesh>(triangleSoup(3000, 7)), 4000, {});
}

// A root that is a single leaf (one triangle). (An empty root needs a mesh without a valid
// triangle, which TriangleMesh refuses.)
TEST(MeshObjectFileBvh, RoundTripLeafRoot) {
  auto one = std::make_shared<const TriangleMesh>(TriangleMesh::fromArrays(
      std::vector<float>{0, 0, 0, 1, 0, 0, 0, 1, 0}, std::vector<std::uint32_t>{0, 1, 2}, "one"));
  ASSERT_TRUE(BvhRef::isLeaf(MeshObject(one, BvhBuildConfig{}).bvh().root));
  bvhRoundTrip(one, 400, {}, /*require_hits=*/false);
}

TEST(MeshObjectFileBvh, RoundTripKoala) {
  DUPLEX_SHARED_MESH_OR_SKIP(mesh, "koala.obj");
  bvhRoundTrip(mesh, 1500, {});
}

// One mesh, both structures: each file loads back as the structure it holds, whatever its name.
TEST(MeshObjectFileBvh, TheMagicTellsTheStructure) {
  const TempDir dir;
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(2));
  const MeshObject kd(mesh, KdBuildConfig{}), bvh(mesh);
  EXPECT_EQ(kd.preparedExtension(), ".dkdt");
  EXPECT_EQ(bvh.preparedExtension(), ".dbvh");
  saveMeshObject(kd, dir / "kd.bin");
  saveMeshObject(bvh, dir / "bvh.bin");
  EXPECT_EQ(loadMeshObject(dir / "kd.bin", mesh)->structure(), MeshStructure::KdTree);
  EXPECT_EQ(loadMeshObject(dir / "bvh.bin", mesh)->structure(), MeshStructure::Bvh);
  EXPECT_EQ(readBinaryFile(dir / "kd.bin").size(),
            64 + 8 * kd.tree().nodes.size() + 4 * kd.tree().prim_indices.size() + 8);
  EXPECT_EQ(readBinaryFile(dir / "bvh.bin").size(),
            72 + 256 * bvh.bvh().nodes.size() + 4 * bvh.bvh().prim_indices.size() + 8);
}

// ---- refused files ----

/// The tamper tests, for a kd-tree file and a BVH file.
class MeshObjectFileTamper : public ::testing::TestWithParam<MeshStructure> {
 protected:
  void SetUp() override {
    mesh_ = std::make_shared<const TriangleMesh>(icosphere(3));
    if (GetParam() == MeshStructure::KdTree) {
      object_ = buildChecked(mesh_);
      header_ = 64;
      node_bytes_ = sizeof(KdNode);
      nodes_ = object_->tree().nodes.size();
      prims_ = object_->tree().prim_indices.size();
    } else {
      object_ = bvhChecked(mesh_, {});
      header_ = 72;
      node_bytes_ = sizeof(BvhNode8);
      nodes_ = object_->bvh().nodes.size();
      prims_ = object_->bvh().prim_indices.size();
      ASSERT_GT(nodes_, 1u) << "the fixture needs inner nodes below the root";
    }
    good_ = dir_ / ("good" + std::string(object_->preparedExtension()));
    saveMeshObject(*object_, good_);
    bytes_ = readBinaryFile(good_);
    ASSERT_EQ(bytes_.size(), header_ + node_bytes_ * nodes_ + 4 * prims_ + 8);
  }
  /// Writes `bytes` to a file and expects loading it to throw a FileError naming it and `problem`.
  void expectRefused(const std::vector<char>& bytes, const std::string& problem, const std::string& what) {
    SCOPED_TRACE(what);
    const auto path = dir_ / "tampered.bin";
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
  /// `bytes` with the file checksum recomputed: a forged file, which only the checks behind the
  /// checksum can refuse.
  static std::vector<char> resealed(std::vector<char> bytes) {
    const std::size_t body = bytes.size() - 8;
    const std::uint64_t checksum = xxh64({reinterpret_cast<const unsigned char*>(bytes.data()), body}, 0);
    std::memcpy(bytes.data() + body, &checksum, 8);
    return bytes;
  }
  /// The good file with `value` written at `offset`, resealed.
  template <class T>
  std::vector<char> forged(std::size_t offset, T value) const {
    std::vector<char> bad = bytes_;
    std::memcpy(bad.data() + offset, &value, sizeof(T));
    return resealed(std::move(bad));
  }
  template <class T>
  [[nodiscard]] T field(std::size_t offset) const {
    T value;
    std::memcpy(&value, bytes_.data() + offset, sizeof(T));
    return value;
  }

  TempDir dir_;
  std::filesystem::path good_;
  std::shared_ptr<const TriangleMesh> mesh_;
  std::shared_ptr<const MeshObject> object_;
  std::vector<char> bytes_;
  std::size_t header_ = 0, node_bytes_ = 0, nodes_ = 0, prims_ = 0;
};

INSTANTIATE_TEST_SUITE_P(Structures, MeshObjectFileTamper, ::testing::Values(MeshStructure::KdTree, MeshStructure::Bvh),
                         [](const auto& info) { return std::string(toString(info.param)); });

TEST_P(MeshObjectFileTamper, EveryFlippedByteIsRefused) {
  // Every header byte, and a spread of bytes in the nodes, the indices and the checksum itself.
  std::vector<std::size_t> offsets;
  for (std::size_t i = 0; i < header_; ++i) offsets.push_back(i);
  for (std::size_t i = header_; i < bytes_.size(); i += 37) offsets.push_back(i);
  offsets.push_back(header_ + node_bytes_ * nodes_);  // first index
  offsets.push_back(bytes_.size() - 9);               // last index byte
  offsets.push_back(bytes_.size() - 1);               // checksum
  for (const std::size_t at : offsets) {
    for (const unsigned char mask : {0x01, 0x80}) {
      std::vector<char> bad = bytes_;
      bad[at] = static_cast<char>(bad[at] ^ mask);
      const std::string region = at < header_                          ? "header"
                                 : at < header_ + node_bytes_ * nodes_ ? "nodes"
                                 : at < bytes_.size() - 8              ? "indices"
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

TEST_P(MeshObjectFileTamper, TruncatedOrExtendedIsRefused) {
  for (const std::size_t keep : {std::size_t(0), std::size_t(10), std::size_t(47), header_, header_ + 7,
                                 bytes_.size() / 2, bytes_.size() - 8, bytes_.size() - 1}) {
    expectRefused(std::vector<char>(bytes_.begin(), bytes_.begin() + static_cast<std::ptrdiff_t>(keep)),
                  keep < header_ + 8 ? "too short" : "truncated", "kept " + std::to_string(keep) + " bytes");
  }
  std::vector<char> longer = bytes_;
  longer.push_back(0);
  expectRefused(longer, "truncated or damaged", "one byte appended");
}

TEST_P(MeshObjectFileTamper, WrongMeshIsRefused) {
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

// Every header field changed and the file resealed (checksum recomputed): the framing, the mesh
// check or MeshObject::fromParts still refuses it, each with its own message.
TEST_P(MeshObjectFileTamper, ForgedHeaderFieldsAreRefused) {
  expectRefused(forged<std::uint32_t>(8, field<std::uint32_t>(8) + 1), "version", "a later version");
  expectRefused(forged<std::uint32_t>(12, static_cast<std::uint32_t>(header_ + 8)), "header size", "header size");
  expectRefused(forged<std::uint64_t>(16, field<std::uint64_t>(16) ^ 1), "another mesh", "mesh checksum");
  expectRefused(forged<std::uint32_t>(24, field<std::uint32_t>(24) + 1), "saved for a mesh of", "vertex count");
  expectRefused(forged<std::uint32_t>(28, field<std::uint32_t>(28) - 1), "saved for a mesh of", "triangle count");
  for (const std::uint32_t delta : {1u, 0xFFFFFFFFu}) {
    expectRefused(forged<std::uint32_t>(32, field<std::uint32_t>(32) + delta), "truncated or damaged", "node count");
    expectRefused(forged<std::uint32_t>(36, field<std::uint32_t>(36) + delta), "truncated or damaged", "index count");
  }
  const std::size_t bounds = GetParam() == MeshStructure::KdTree ? 40 : 48;
  expectRefused(forged<float>(bounds + 12, field<float>(bounds)), "bounds", "bounds hi.x = lo.x");
  expectRefused(forged<float>(bounds + 4, -std::numeric_limits<float>::infinity()), "bounds", "bounds lo.y = -inf");
  expectRefused(forged<float>(bounds + 20, std::numeric_limits<float>::quiet_NaN()), "bounds", "bounds hi.z NaN");
  if (GetParam() == MeshStructure::Bvh) {
    expectRefused(forged<std::uint32_t>(40, 1), "root", "root node 1");
    expectRefused(forged<std::uint32_t>(40, BvhRef::kEmpty), "root", "root empty");
    expectRefused(forged<std::uint32_t>(40, BvhRef::leaf(0, 4)), "root", "root a leaf");
    expectRefused(forged<std::uint32_t>(44, 8), "leaf block", "leaf block 8");
    // Version 1 had 224-byte nodes without the child orders.
    expectRefused(forged<std::uint32_t>(8, 1), "version", "version 1");
    // Node 0's order[3] made equal to order[2]: no longer a permutation of the slots.
    constexpr std::size_t order0 = 72 + offsetof(BvhNode8, order);
    expectRefused(forged<std::uint32_t>(order0 + 12, field<std::uint32_t>(order0 + 8)), "child order",
                  "node 0's child order");
  }
}

// Random bit flips anywhere before the checksum, resealed: refused with a FileError, or (when the
// bits happen to describe a valid structure) queries run without reading out of bounds (ASan in the
// sanitizer build). A BVH that passes has every triangle inside its leaf's box and every box inside
// its parent's, so it answers exactly as the saved one: the same closest distance and occlusion.
TEST_P(MeshObjectFileTamper, RandomForgedFlipsAreRefusedOrHarmless) {
  const auto rays = randomRays(mesh_->bounds(), 100, 5);
  const auto path = dir_ / "forged.bin";
  std::mt19937_64 rng(77);
  std::size_t refused = 0, accepted = 0;
  for (int trial = 0; trial < 600; ++trial) {
    std::vector<char> bad = bytes_;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int f = 0; f < flips; ++f) {
      // Mostly the nodes: the part the checksum alone would otherwise guard.
      const std::size_t at = rng() % 4 != 0 ? header_ + rng() % (node_bytes_ * nodes_) : rng() % (bytes_.size() - 8);
      bad[at] = static_cast<char>(bad[at] ^ (1 << (rng() % 8)));
    }
    writeBinaryFile(path, resealed(std::move(bad)));
    std::shared_ptr<const MeshObject> o;
    try {
      o = loadMeshObject(path, mesh_);
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
      ++refused;
      continue;
    }
    ++accepted;
    for (const Ray& r : rays) {
      Hit h, expected;
      const bool hit = o->intersect(r, h);
      const bool occluded = o->occluded(r);
      if (GetParam() != MeshStructure::Bvh) continue;
      const bool expected_hit = object_->intersect(r, expected);
      EXPECT_EQ(hit, expected_hit) << r;
      if (hit && expected_hit) {
        EXPECT_TRUE(sameBits(h.t, expected.t)) << r << ": " << h << " vs " << expected;
      }
      EXPECT_EQ(occluded, object_->occluded(r)) << r;
    }
  }
  EXPECT_GT(refused, 0u);
  std::printf("%s forged flips: %zu refused, %zu accepted\n", std::string(toString(GetParam())).c_str(), refused,
              accepted);
}

TEST_P(MeshObjectFileTamper, MissingFileAndNullMesh) {
  expectErrorNaming<FileError>([&] { (void)loadMeshObject(dir_ / "absent.dbvh", mesh_); }, "absent.dbvh");
  expectErrorNaming<InvalidArgument>([&] { (void)loadMeshObject(good_, nullptr); }, "null mesh");
  expectErrorNaming<FileError>([&] { saveMeshObject(*object_, dir_ / "no" / "such" / "dir" / "x.dbvh"); }, "x.dbvh");
}

// ---- forged trees: well framed, checksum right, contents wrong (MeshObject::fromParts) ----

KdTree treeOf(const MeshObject& o) { return o.tree(); }

void expectRejected(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, const std::string& problem) {
  expectErrorNaming<InvalidArgument>([&] { (void)MeshObject::fromParts(mesh, std::move(tree)); }, problem);
}

TEST(MeshObjectFromParts, RejectsEveryKindOfBrokenTree) {
  auto mesh = std::make_shared<const TriangleMesh>(icosphere(3));
  const MeshObject built(mesh, KdBuildConfig{});
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
  const MeshObject built(mesh, KdBuildConfig{});
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
