#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/MemoryLimit.h"
#include "duplex/objects/TriangleClip.h"
#include "duplex/objects/WatertightTriangle.h"
#include "MeshBvh.h"
#include "MeshClosestPoint.h"
#include "MeshLeafTest.h"
#include "MeshParts.h"
#include "MeshRay.h"
#include "TriangleBlock4.h"
#include "WatertightTriangle4.h"

#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <utility>

namespace duplex {

namespace {

// Work per task of the parallel passes around the build (triangle bounds, leaf blocks).
constexpr std::size_t kTrianglesPerTask = 8192;
constexpr std::size_t kNodesPerTask = 2048;

// body(begin, end) over [0, n) in tasks of `grain`; a range of one task runs inline (the many tiny
// objects of a split scene pay no task overhead).
template <class Body>
void forChunks(std::size_t n, std::size_t grain, const Body& body) {
  if (n <= grain) {
    body(std::size_t{0}, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                    [&](const tbb::blocked_range<std::size_t>& range) { body(range.begin(), range.end()); });
}

// The checks of MeshObject::fromParts (see MeshObject.h): what traversal and the leaf tests rely
// on, so that a tree from a file, however damaged, can only be refused, never crash a query.
void checkTreeAgainstMesh(const KdTree& tree, const TriangleMesh& mesh) {
  auto fail = [](const std::string& problem) { throw InvalidArgument("kd-tree does not fit its mesh: " + problem); };
  const std::size_t n = tree.nodes.size();
  if (n == 0) fail("no nodes");
  if (n > KdNode::kMaxIndex) fail("more nodes than a node can address");
  const Box& b = tree.bounds;
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(b.lo[k]) || !std::isfinite(b.hi[k]) || !(b.lo[k] <= b.hi[k])) fail("bounds not finite");
  const Box& mb = mesh.bounds();
  if (!b.contains(mb.lo) || !b.contains(mb.hi)) fail("bounds do not contain the mesh");
  for (std::size_t i = 0; i < tree.prim_indices.size(); ++i) {
    const std::uint32_t prim = tree.prim_indices[i];
    if (prim >= mesh.triangleCount() || !mesh.isValid(prim))
      fail("prim_indices[" + std::to_string(i) + "] = " + std::to_string(prim) + " is not a valid triangle (" +
           std::to_string(mesh.triangleCount()) + " triangles)");
  }
  // Depth-first layout: walk the nodes in order; an inner node's lower child is the next node, its
  // upper child must start exactly where the lower subtree ends. `pending` holds the upper children
  // not reached yet with their depth (inner nodes above them), bounded by the traversal stack.
  std::vector<std::pair<std::uint32_t, int>> pending;
  std::uint32_t index = 0;
  int depth = 0;
  while (true) {
    const KdNode& node = tree.nodes[index];
    auto at = [index] { return "node " + std::to_string(index) + ": "; };  // only built on failure
    if (!node.isLeaf()) {
      if (!std::isfinite(node.split())) fail(at() + "split plane not finite");
      if (depth + 1 >= kKdStackSize)
        fail(at() + "deeper than the traversal stack (" + std::to_string(kKdStackSize) + ")");
      const std::uint32_t upper = node.upperChild();
      if (upper <= index + 1 || upper >= n)
        fail(at() + "upper child " + std::to_string(upper) + " out of range (" + std::to_string(n) + " nodes)");
      pending.emplace_back(upper, depth + 1);
      ++index;
      ++depth;
      continue;
    }
    // Jumps exist only in incrementally updated top levels; in a saved mesh tree one would send the
    // traversal anywhere.
    if (node.isJump()) fail(at() + "jump node in a bottom-level tree");
    const std::uint64_t end = std::uint64_t{node.primOffset()} + node.primCount();
    if (end > tree.prim_indices.size())
      fail(at() + "leaf range [" + std::to_string(node.primOffset()) + ", " + std::to_string(end) +
           ") beyond prim_indices (" + std::to_string(tree.prim_indices.size()) + ")");
    if (pending.empty()) {
      if (index + 1 != n) fail("nodes after the end of the tree (" + std::to_string(n - index - 1) + ")");
      return;
    }
    const auto [upper, upper_depth] = pending.back();
    pending.pop_back();
    if (upper != index + 1)
      fail("node " + std::to_string(upper) + " is not where its sibling subtree ends (node " +
           std::to_string(index + 1) + ")");
    index = upper;
    depth = upper_depth;
  }
}

// The checks of MeshObject::fromParts for a BVH (see MeshObject.h): what traversal and the leaf
// tests rely on, and that every box holds what it bounds, so that a BVH from a file, however
// damaged, can only be refused, never crash a query or miss a triangle.
void checkBvhAgainstMesh(const WideBvh& bvh, const TriangleMesh& mesh) {
  auto fail = [](const std::string& problem) { throw InvalidArgument("BVH does not fit its mesh: " + problem); };
  if (bvh.leaf_block != 4) fail("leaf block " + std::to_string(bvh.leaf_block) + " (expected 4)");
  const std::vector<std::uint32_t>& prims = bvh.prim_indices;
  if (prims.size() % 4 != 0) fail("prim_indices not a whole number of blocks");
  const std::size_t block_count = prims.size() / 4;
  const Box& mb = mesh.bounds();
  if (bvh.root == BvhRef::kEmpty) {
    if (!bvh.nodes.empty() || !prims.empty()) fail("an empty root with nodes or indices");
    for (std::size_t t = 0; t < mesh.triangleCount(); ++t)
      if (mesh.isValid(t)) fail("an empty tree for a mesh with valid triangles");
    return;
  }
  if (!bvh.bounds.finite() || bvh.bounds.empty()) fail("bounds not finite");
  if (!bvh.bounds.contains(mb.lo) || !bvh.bounds.contains(mb.hi)) fail("bounds do not contain the mesh");
  if (bvh.nodes.size() > BvhRef::kMaxNodes) fail("more nodes than a reference can address");
  std::vector<bool> block_seen(block_count, false);
  const auto& tris = mesh.triangles();
  const auto& pos = mesh.positions();
  // A leaf's range: inside prim_indices, valid triangles inside `box`, padding to the block end,
  // blocks referenced once.
  auto checkLeaf = [&](std::uint32_t ref, const Box& box, const std::string& where) {
    const std::size_t block = BvhRef::leafBlock(ref), count = BvhRef::leafCount(ref);
    const std::size_t blocks = (count + 3) / 4;
    if (block + blocks > block_count)
      fail(where + ": leaf blocks [" + std::to_string(block) + ", " + std::to_string(block + blocks) +
           ") beyond prim_indices (" + std::to_string(block_count) + " blocks)");
    for (std::size_t b = block; b < block + blocks; ++b) {
      if (block_seen[b]) fail(where + ": block " + std::to_string(b) + " referenced twice");
      block_seen[b] = true;
    }
    for (std::size_t i = 4 * block; i < 4 * (block + blocks); ++i) {
      const std::uint32_t prim = prims[i];
      if (i >= 4 * block + count) {
        if (prim != WideBvh::kPadding) fail(where + ": prim_indices[" + std::to_string(i) + "] is not padding");
        continue;
      }
      if (prim >= mesh.triangleCount() || !mesh.isValid(prim))
        fail(where + ": prim_indices[" + std::to_string(i) + "] = " + std::to_string(prim) +
             " is not a valid triangle (" + std::to_string(mesh.triangleCount()) + " triangles)");
      // With spatial splits a leaf's box holds only the part of a triangle inside it: require that
      // the triangle's bounds meet the box (traversal then finds every part it was built for).
      Box tri_box;
      for (int k = 0; k < 3; ++k) tri_box.extend(pos[tris[prim][k]]);
      if (!box.overlaps(tri_box)) fail(where + ": triangle " + std::to_string(prim) + " outside its leaf's box");
    }
  };
  if (BvhRef::isLeaf(bvh.root)) {
    if (!bvh.nodes.empty()) fail("a leaf root with nodes");
    checkLeaf(bvh.root, bvh.bounds, "root");
  } else {
    if (bvh.root != 0 || bvh.nodes.empty()) fail("root " + std::to_string(bvh.root) + " is not node 0");
    // Depth-first from the root: every inner node must be the next in the array when reached.
    struct Pending {
      std::uint32_t node;
      int depth;
      Box box;
    };
    std::vector<Pending> stack{{0, 1, bvh.bounds}};
    std::uint32_t next = 0;
    constexpr float kInf = std::numeric_limits<float>::infinity();
    while (!stack.empty()) {
      const Pending p = stack.back();
      stack.pop_back();
      const std::string at = "node " + std::to_string(p.node);
      if (p.node != next)
        fail(at + " reached where node " + std::to_string(next) + " should be (not depth-first, or shared)");
      ++next;
      if (p.depth > WideBvh::kMaxDepth) fail(at + ": deeper than " + std::to_string(WideBvh::kMaxDepth));
      const BvhNode8& node = bvh.nodes[p.node];
      int used = 0;
      for (int k = 0; k < BvhNode8::kWidth; ++k) {
        const std::uint32_t c = node.child[k];
        const Box box = node.childBox(k);
        const std::string slot = at + " slot " + std::to_string(k);
        if (c == BvhRef::kEmpty) {
          for (int a = 0; a < 3; ++a)
            if (!(node.lo[a][k] == kInf && node.hi[a][k] == -kInf)) fail(slot + ": empty slot with a box");
          continue;
        }
        if (used != k) fail(slot + ": used after an empty slot");
        ++used;
        if (!box.finite() || box.empty()) fail(slot + ": box not finite");
        if (!p.box.contains(box.lo) || !p.box.contains(box.hi)) fail(slot + ": box outside its parent's");
        if (BvhRef::isLeaf(c)) checkLeaf(c, box, slot);
        else if (c <= p.node || c >= bvh.nodes.size()) fail(slot + ": child " + std::to_string(c) + " out of range");
      }
      if (used < 2) fail(at + ": fewer than two children");
      if (!node.orderValid()) fail(at + ": child order is not a permutation of the slots");
      for (int k = used - 1; k >= 0; --k)
        if (BvhRef::isInner(node.child[k])) stack.push_back({node.child[k], p.depth + 1, node.childBox(k)});
    }
    if (next != bvh.nodes.size()) fail(std::to_string(bvh.nodes.size() - next) + " nodes not reached from the root");
  }
  for (std::size_t b = 0; b < block_count; ++b)
    if (!block_seen[b]) fail("block " + std::to_string(b) + " not referenced by any leaf");
  // Every valid triangle referenced: the scene would silently lose the others.
  std::vector<bool> referenced(mesh.triangleCount(), false);
  for (const std::uint32_t prim : prims)
    if (prim != WideBvh::kPadding) referenced[prim] = true;
  for (std::size_t t = 0; t < mesh.triangleCount(); ++t)
    if (mesh.isValid(t) && !referenced[t]) fail("valid triangle " + std::to_string(t) + " not referenced");
}

// Object-space bounds of every triangle; degenerate triangles get an empty box, which the builders
// leave out. In parallel: on its own this pass would hold the other threads idle before the build
// (as the leaf blocks after it).
std::vector<Box> triangleBounds(const TriangleMesh& m) {
  std::vector<Box> bounds(m.triangleCount());
  forChunks(m.triangleCount(), kTrianglesPerTask, [&](std::size_t first, std::size_t last) {
    for (std::size_t i = first; i < last; ++i) {
      if (!m.isValid(i)) continue;
      const auto v = m.vertices(i);
      Box b;
      for (const auto& p : v) b.extend(p);
      bounds[i] = b;
    }
  });
  return bounds;
}

// Block `block` of a BVH's leaf blocks from its four prim_indices entries `refs`. Lane 0 always
// holds a triangle (leaf ranges start at blocks); padding lanes repeat the block's last triangle
// (masked off by the leaf's count). `visit(a, b, c)` sees the corners of each triangle lane, not of
// the padding, so that a refit can take the leaf's box and the validity test from the same loads.
template <class Visit>
void fillBvhBlock(detail::TriangleBlock4& block, const std::uint32_t* refs, const TriangleMesh::Triangle* tris,
                  const glm::vec3* positions, const Visit& visit) {
  std::uint32_t prim = refs[0];
  for (std::uint32_t k = 0; k < 4; ++k) {
    const bool padding = refs[k] == WideBvh::kPadding;
    if (!padding) prim = refs[k];
    const TriangleMesh::Triangle& t = tris[prim];
    const glm::vec3 &a = positions[t[0]], &b = positions[t[1]], &c = positions[t[2]];
    if (!padding) visit(a, b, c);
    block.set(static_cast<int>(k), a, b, c, prim);
  }
}

// The refit visits the leaf blocks in increasing order (the depth-first layout), and each block's
// corners are two dependent loads away (prim_indices, then the triangle, then its vertices), which
// no hardware prefetcher follows: this fetches the triangles a few blocks ahead and the vertices of
// the triangles fetched before.
inline void prefetchBlockCorners(const std::uint32_t* refs, std::size_t block_count, std::size_t b,
                                 const TriangleMesh::Triangle* tris, const glm::vec3* positions) {
  constexpr std::size_t kTriangleDistance = 8, kVertexDistance = 4;
  if (b + kTriangleDistance < block_count)
    for (int k = 0; k < 4; ++k)
      if (const std::uint32_t prim = refs[4 * (b + kTriangleDistance) + k]; prim != WideBvh::kPadding)
        __builtin_prefetch(&tris[prim]);
  if (b + kVertexDistance < block_count)
    for (int k = 0; k < 4; ++k)
      if (const std::uint32_t prim = refs[4 * (b + kVertexDistance) + k]; prim != WideBvh::kPadding)
        for (int c = 0; c < 3; ++c) __builtin_prefetch(&positions[tris[prim][c]]);
}

}  // namespace

std::string_view toString(MeshStructure s) { return s == MeshStructure::Bvh ? "bvh" : "kdtree"; }

MeshStructure parseMeshStructure(std::string_view name) {
  if (name == "bvh") return MeshStructure::Bvh;
  if (name == "kdtree") return MeshStructure::KdTree;
  throw InvalidArgument("unknown mesh structure '" + std::string(name) + "' (expected bvh or kdtree)");
}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, const MeshBuildConfig& config)
    : Object(mesh ? mesh->name() : std::string()),
      mesh_(std::move(mesh)),
      structure_(config.structure),
      config_(config),
      parts_(std::make_unique<detail::MeshParts>()) {
  if (!mesh_) throw InvalidArgument("MeshObject: null mesh");
  if (structure_ == MeshStructure::Bvh) buildBvh(config.bvh);
  else buildKd(config.kd);
}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, const KdBuildConfig& config)
    : MeshObject(std::move(mesh), MeshBuildConfig{MeshStructure::KdTree, {}, config}) {}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, const BvhBuildConfig& config)
    : MeshObject(std::move(mesh), MeshBuildConfig{MeshStructure::Bvh, config, {}}) {}

namespace {

// The least a build of either structure over `m` holds besides the mesh, against the memory limit:
// per triangle its box (and the builder's copy of it), a reference, and a quarter of the
// four-triangle leaf block it lands in. Nodes, spatial-split duplicates and the builders' own
// working lists come on top.
void requireBuildMemory(const TriangleMesh& m, const char* structure) {
  const std::uint64_t per_triangle = 2 * sizeof(Box) + sizeof(std::uint32_t) + (sizeof(detail::TriangleBlock4) + 3) / 4;
  std::ostringstream what;
  what << "mesh '" << m.name() << "' (" << m.triangleCount() << " triangles: its " << structure << ")";
  requireMemory(arrayBytes(m.triangleCount(), per_triangle), what.str());
}

}  // namespace

void MeshObject::buildKd(const KdBuildConfig& config) {
  const TriangleMesh& m = *mesh_;
  requireBuildMemory(m, "kd-tree");
  const std::vector<Box> bounds = triangleBounds(m);
  try {
    parts_->tree = buildKdTree(
        bounds,
        // A straddling triangle is clipped once per split, not once per child.
        [&m](std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper) {
          const auto v = m.vertices(prim);
          splitTriangleInBox(v[0], v[1], v[2], box, axis, pos, lower, upper);
        },
        config);
  } catch (const InvalidArgument& e) {
    // The builder knows bounds, not meshes: say which mesh the refused build was for.
    throw InvalidArgument("mesh '" + m.name() + "': " + e.what());
  }
  buildLeafBlocks();
}

void MeshObject::buildBvh(const BvhBuildConfig& config) {
  const TriangleMesh& m = *mesh_;
  requireBuildMemory(m, "BVH");
  const std::vector<Box> bounds = triangleBounds(m);
  try {
    parts_->bvh = buildWideBvh(bounds, config,
                               [&m](std::uint32_t prim, const Box& box, int axis, float pos, Box& lower, Box& upper) {
                                 const auto v = m.vertices(prim);
                                 splitTriangleInBox(v[0], v[1], v[2], box, axis, pos, lower, upper);
                               });
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("mesh '" + m.name() + "': " + e.what());
  }
  built_sah_ = parts_->bvh.sahCost(config);
  buildBvhBlocks();
}

void MeshObject::buildBvhBlocks() {
  const TriangleMesh& m = *mesh_;
  const std::vector<std::uint32_t>& refs = parts_->bvh.prim_indices;
  parts_->blocks.resize(refs.size() / 4);
  forChunks(parts_->blocks.size(), kNodesPerTask, [&](std::size_t first, std::size_t last) {
    for (std::size_t b = first; b < last; ++b)
      fillBvhBlock(parts_->blocks[b], &refs[4 * b], m.triangles().data(), m.positions().data(),
                   [](const glm::vec3&, const glm::vec3&, const glm::vec3&) {});
  });
  makeView();
}

void MeshObject::makeView() {
  parts_->view = std::make_unique<const detail::MeshBvhView>(
      detail::MeshBvhView{parts_->bvh.nodes.data(), parts_->bvh.root, parts_->bvh.bounds, parts_->blocks.data()});
}

ObjectRayEntry MeshObject::rayEntry() const {
  if (structure_ != MeshStructure::Bvh || !parts_->view) return {};
  const detail::MeshBvhKernels& k = detail::meshBvhKernels();
  return {k.intersect_view, k.occluded_view, parts_->view.get()};
}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, PartsTag)
    : Object(mesh->name()),
      mesh_(std::move(mesh)),
      structure_(MeshStructure::KdTree),
      parts_(std::make_unique<detail::MeshParts>()) {
  parts_->tree = std::move(tree);
  config_.structure = MeshStructure::KdTree;
  buildLeafBlocks();
}

std::shared_ptr<const MeshObject> MeshObject::fromParts(std::shared_ptr<const TriangleMesh> mesh, KdTree tree) {
  if (!mesh) throw InvalidArgument("MeshObject::fromParts: null mesh");
  checkTreeAgainstMesh(tree, *mesh);
  return std::shared_ptr<const MeshObject>(new MeshObject(std::move(mesh), std::move(tree), PartsTag{}));
}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, WideBvh bvh, PartsTag)
    : Object(mesh->name()),
      mesh_(std::move(mesh)),
      structure_(MeshStructure::Bvh),
      parts_(std::make_unique<detail::MeshParts>()) {
  parts_->bvh = std::move(bvh);
  buildBvhBlocks();
}

std::shared_ptr<const MeshObject> MeshObject::fromParts(std::shared_ptr<const TriangleMesh> mesh, WideBvh bvh) {
  if (!mesh) throw InvalidArgument("MeshObject::fromParts: null mesh");
  checkBvhAgainstMesh(bvh, *mesh);
  std::unique_ptr<MeshObject> object(new MeshObject(std::move(mesh), std::move(bvh), PartsTag{}));
  object->built_sah_ = object->parts_->bvh.sahCost(object->config_.bvh);
  return object;
}

MeshObject::~MeshObject() = default;

const KdTree& MeshObject::tree() const { return parts_->tree; }

const WideBvh& MeshObject::bvh() const { return parts_->bvh; }

double MeshObject::sahCost() const { return structure_ == MeshStructure::Bvh ? parts_->bvh.sahCost(config_.bvh) : 0.0; }

std::shared_ptr<const Object> MeshObject::deformed(std::span<const glm::vec3> positions_os) const {
  return deformedMesh(positions_os);
}

MeshObject::MeshObject(const MeshObject& from, RefitTag)
    : Object(from.name()),
      structure_(MeshStructure::Bvh),
      config_(from.config_),
      built_sah_(from.built_sah_),
      refitted_(true),
      parts_(std::make_unique<detail::MeshParts>()) {}

std::shared_ptr<const MeshObject> MeshObject::deformedMesh(std::span<const glm::vec3> positions_os) const {
  mesh_->checkPositions(positions_os);
  std::vector<glm::vec3> positions(positions_os.begin(), positions_os.end());
  // A kd-tree's clipped splits cannot be refitted; nor can a BVH whose triangles changed between
  // valid and degenerate (one that became valid is in no leaf, one that became degenerate would
  // break the structure's invariants).
  auto rebuild = [&] {
    return std::make_shared<const MeshObject>(
        std::make_shared<const TriangleMesh>(mesh_->withPositions(std::move(positions))), config_);
  };
  if (structure_ != MeshStructure::Bvh) return rebuild();
  const std::vector<TriangleMesh::Triangle>& tris = mesh_->triangles();
  for (std::size_t t = 0; mesh_->degenerateCount() > 0 && t < tris.size(); ++t) {
    if (mesh_->isValid(t)) continue;
    const TriangleMesh::Triangle& i = tris[t];
    if (TriangleMesh::hasArea(positions[i[0]], positions[i[1]], positions[i[2]])) return rebuild();
  }
  // One pass over the leaves writes the new object's blocks, takes the leaf boxes from the same
  // loads and tests that every triangle in the tree keeps an area; the nodes above are written
  // once each, with their orders, by the refit.
  std::unique_ptr<MeshObject> out(new MeshObject(*this, RefitTag{}));
  WideBvh& bvh = out->parts_->bvh;
  bvh.root = parts_->bvh.root;
  bvh.leaf_block = parts_->bvh.leaf_block;
  bvh.prim_indices = parts_->bvh.prim_indices;
  bvh.nodes.resize(parts_->bvh.nodes.size());
  out->parts_->blocks.resize(parts_->blocks.size());
  std::atomic<bool> lost_area{false};
  const std::uint32_t* refs = bvh.prim_indices.data();
  const std::size_t block_count = out->parts_->blocks.size();
  detail::TriangleBlock4* blocks = out->parts_->blocks.data();
  bvh.bounds =
      refitWideBvhNodes(parts_->bvh, bvh.nodes, [&](std::uint32_t ref) {  // indices checked when the BVH was made
        const std::uint32_t first = BvhRef::leafBlock(ref), count = BvhRef::leafCount(ref);
        Box box;
        bool flat = false;
        for (std::uint32_t b = first; b < first + (count + 3) / 4; ++b) {
          prefetchBlockCorners(refs, block_count, b, tris.data(), positions.data());
          fillBvhBlock(blocks[b], refs + std::size_t{4} * b, tris.data(), positions.data(),
                       [&](const glm::vec3& p0, const glm::vec3& p1, const glm::vec3& p2) {
                         box.extend(p0);
                         box.extend(p1);
                         box.extend(p2);
                         flat |= !TriangleMesh::hasArea(p0, p1, p2);
                       });
        }
        if (flat) lost_area.store(true, std::memory_order_relaxed);
        return box;
      });
  if (lost_area.load(std::memory_order_relaxed)) return rebuild();
  if (!(bvh.sahCost(config_.bvh) <= static_cast<double>(config_.bvh.refit_limit) * built_sah_)) return rebuild();
  // Every valid triangle is in a leaf: the refitted bounds are the mesh's.
  out->mesh_ =
      std::make_shared<const TriangleMesh>(mesh_->withPositionsOfSameValidity(std::move(positions), bvh.bounds));
  out->makeView();
  return out;
}

void MeshObject::buildLeafBlocks() {
  const TriangleMesh& m = *mesh_;
  const std::vector<glm::vec3>& positions = m.positions();
  const std::vector<std::uint32_t>& refs = parts_->tree.prim_indices;
  parts_->block_tree.bounds = parts_->tree.bounds;
  parts_->block_tree.nodes = parts_->tree.nodes;
  // Each non-empty leaf's first block, in node order (a serial pass over the nodes only); then the
  // blocks are filled leaf by leaf in parallel, each leaf writing only its own range.
  std::size_t block_count = 0;
  for (KdNode& node : parts_->block_tree.nodes) {
    if (!node.isLeaf() || node.isJump() || node.primCount() == 0) continue;
    node.setPrimOffset(static_cast<std::uint32_t>(block_count));
    block_count += (node.primCount() + 3) / 4;
  }
  parts_->blocks.resize(block_count);
  forChunks(parts_->tree.nodes.size(), kNodesPerTask, [&](std::size_t first, std::size_t last) {
    for (std::size_t n = first; n < last; ++n) {
      const KdNode& node = parts_->tree.nodes[n];
      if (!node.isLeaf() || node.isJump() || node.primCount() == 0) continue;
      const std::uint32_t begin = node.primOffset(), end = begin + node.primCount();
      detail::TriangleBlock4* block = parts_->blocks.data() + parts_->block_tree.nodes[n].primOffset();
      for (std::uint32_t i = begin; i < end; i += 4, ++block) {
        for (std::uint32_t k = 0; k < 4; ++k) {
          // Padding lanes repeat the leaf's last triangle (masked off by the leaf's count).
          const std::uint32_t prim = refs[std::min(i + k, end - 1)];
          const TriangleMesh::Triangle& t = m.triangles()[prim];
          block->set(static_cast<int>(k), positions[t[0]], positions[t[1]], positions[t[2]], prim);
        }
      }
    }
  });
}

namespace {

template <class Blocks>
detail::MeshBvhView bvhView(const WideBvh& bvh, const Blocks& blocks) {
  return {bvh.nodes.data(), bvh.root, bvh.bounds, blocks.data()};
}

// The all-hits query's leaf step: every triangle of the leaf, tested one by one.
struct AllHitsLeaf {
  const WatertightRay& wray;
  const detail::TriangleBlock4* blocks;
  float t_max;
  std::vector<Hit>& hits;

  template <int KX, int KY, int KZ>
  void test(std::uint32_t first_block, std::uint32_t count) const {
    const detail::TriangleBlock4* block = blocks + first_block;
    for (std::uint32_t i = 0; i < count; ++i) {
      const detail::TriangleBlock4& b = block[i / 4];
      const int k = static_cast<int>(i % 4);
      const glm::vec3 v0 = b.vertex(k, 0), v1 = b.vertex(k, 1), v2 = b.vertex(k, 2);
      float t, u, v;
      if (!intersectWatertight<KX, KY, KZ>(wray, v0, v1, v2, t_max, t, u, v)) continue;
      Hit h;
      h.t = t;
      h.u = u;
      h.v = v;
      h.prim_id = b.prim[k];
      h.ng = glm::cross(v1 - v0, v2 - v0);
      hits.push_back(h);
    }
  }
};

}  // namespace

bool MeshObject::intersect(const Ray& ray_os, Hit& hit) const {
  if (structure_ == MeshStructure::Bvh)
    return detail::meshBvhKernels().intersect(bvhView(parts_->bvh, parts_->blocks), ray_os, hit);
  detail::MeshRay ray;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray_os, parts_->block_tree.bounds, ray, tmin, tmax)) return false;
  float t_best = std::min(hit.t, ray_os.tfar);
  detail::ClosestHit best;
  const detail::TriangleBlock4* blocks = parts_->blocks.data();
  // The axis permutation of the triangle test is a run-time value (no dispatch per ray: the six
  // choices are a coin flip on random rays, and six copies of the traversal cost code size).
  traverseKdTreeClipped<false>(parts_->block_tree, ray.kd, tmin, tmax, t_best,
                               [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
                                 return detail::closestInLeaf(ray, blocks + begin, count, t_max, best);
                               });
  if (best.block == nullptr) return false;
  detail::fillHit(best, t_best, hit);
  return true;
}

bool MeshObject::occluded(const Ray& ray_os) const {
  if (structure_ == MeshStructure::Bvh)
    return detail::meshBvhKernels().occluded(bvhView(parts_->bvh, parts_->blocks), ray_os);
  detail::MeshRay ray;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray_os, parts_->block_tree.bounds, ray, tmin, tmax)) return false;
  float t_best = ray_os.tfar;
  const detail::TriangleBlock4* blocks = parts_->blocks.data();
  return traverseKdTreeClipped<true>(parts_->block_tree, ray.kd, tmin, tmax, t_best,
                                     [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
                                       return detail::anyInLeaf(ray, blocks + begin, count, t_max);
                                     });
}

void MeshObject::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext&) const {
  if (!isQueryable(ray_os)) return;
  const WatertightRay wray(ray_os);
  const std::size_t first = hits.size();
  dispatchPermutation(wray, [&]<int KX, int KY, int KZ>() {
    const AllHitsLeaf leaf{wray, parts_->blocks.data(), ray_os.tfar, hits};
    if (structure_ == MeshStructure::Bvh) {
      detail::meshBvhKernels().forEachLeaf(
          bvhView(parts_->bvh, parts_->blocks), ray_os,
          [](void* context, std::uint32_t block, std::uint32_t count) {
            static_cast<const AllHitsLeaf*>(context)->template test<KX, KY, KZ>(block, count);
          },
          const_cast<AllHitsLeaf*>(&leaf));
      return;
    }
    const KdRay kray(ray_os);
    float t_best = ray_os.tfar;  // never lowered: every leaf along the ray is visited
    traverseKdTree<false>(parts_->block_tree, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float&) {
      leaf.template test<KX, KY, KZ>(begin, count);
      return false;
    });
  });
  // A triangle referenced by several leaves the ray crosses is reported once; and a ray through a
  // shared edge or vertex hits every triangle around it at the same distance but crosses the
  // surface once (a sensor must not count it twice): hits within kSameCrossing of each other in
  // t merge into the one with the lowest primitive id.
  const auto begin = hits.begin() + static_cast<std::ptrdiff_t>(first);
  std::sort(begin, hits.end(),
            [](const Hit& a, const Hit& b) { return a.t != b.t ? a.t < b.t : a.prim_id < b.prim_id; });
  constexpr float kSameCrossing = 4.0f * std::numeric_limits<float>::epsilon();
  auto out = begin;
  for (auto it = begin; it != hits.end(); ++it) {
    if (out != begin && it->t - (out - 1)->t <= kSameCrossing * std::abs(it->t)) continue;
    *out++ = *it;
  }
  hits.erase(out, hits.end());
}

bool MeshObject::intersect(const Ray& ray_os, Hit& hit, QueryContext&) const { return intersect(ray_os, hit); }

namespace {

// MeshObject::closestPoint on a BVH under a similarity transform (identity included): the search
// runs in object space with squared distances (MeshClosestPoint.h), so no vertex is transformed and
// no square root is taken per box or triangle; the world distance is the object-space one times the
// transform's scale.
bool closestPointSimilar(const WideBvh& bvh, const detail::TriangleBlock4* blocks, const PointQuery& q,
                         ClosestPoint& best) {
  if (bvh.root == BvhRef::kEmpty) return false;
  const glm::dvec3 p = q.point_os;
  const double radius_os = best.distance / q.scale_ws;
  detail::ClosestPointSearch search;
  search.best2 = radius_os * radius_os;  // +inf for an unbounded query
  detail::meshClosestPointKernel()(bvh, blocks, p, search);
  const detail::TriangleBlock4* found_block = search.block;
  const int found_lane = search.lane;
  const glm::dvec3 found_point = search.point;
  const double best2 = search.best2;
  if (found_block == nullptr) return false;
  best.distance = std::sqrt(best2) * q.scale_ws;
  best.point_ws = q.world_from_object.point(found_point);
  const glm::dvec3 a(found_block->vertex(found_lane, 0)), b(found_block->vertex(found_lane, 1)),
      c(found_block->vertex(found_lane, 2));
  const glm::dvec3 normal_os = glm::cross(b - a, c - a);
  best.uv = barycentricUv(found_point, a, b, c);
  const glm::dvec3 normal = q.orientation * q.world_from_object.vector(normal_os);
  const double len = glm::length(normal);
  best.normal_ws = len > 0.0 ? normal / len : glm::dvec3(0.0);
  best.prim_id = found_block->prim[found_lane];
  return true;
}

}  // namespace

bool MeshObject::closestPoint(const PointQuery& q, ClosestPoint& best, QueryContext&) const {
  if (structure_ == MeshStructure::Bvh && q.similarity)
    return closestPointSimilar(parts_->bvh, parts_->blocks.data(), q, best);
  bool improved = false;
  // Every triangle of a leaf's blocks, mapped to world space: the distance is a world distance
  // whatever the instance's scale.
  auto testLeaf = [&](std::uint32_t first_block, std::uint32_t count) {
    const detail::TriangleBlock4* block = parts_->blocks.data() + first_block;
    for (std::uint32_t i = 0; i < count; ++i) {
      const detail::TriangleBlock4& b = block[i / 4];
      const int k = static_cast<int>(i % 4);
      const glm::dvec3 a = q.world_from_object.point(glm::dvec3(b.vertex(k, 0)));
      const glm::dvec3 v1 = q.world_from_object.point(glm::dvec3(b.vertex(k, 1)));
      const glm::dvec3 v2 = q.world_from_object.point(glm::dvec3(b.vertex(k, 2)));
      const glm::dvec3 c = closestPointOnTriangle(q.point_ws, a, v1, v2);
      const double d = glm::length(c - q.point_ws);
      if (!(d < best.distance)) continue;
      best.distance = d;
      best.point_ws = c;
      const glm::dvec3 n = glm::cross(v1 - a, v2 - a);
      const double len = glm::length(n);
      best.normal_ws = len > 0.0 ? n / len : glm::dvec3(0.0);
      best.uv = barycentricUv(c, a, v1, v2);
      best.prim_id = b.prim[k];
      improved = true;
    }
  };
  struct Entry {
    std::uint32_t node;  // BVH: a reference; kd-tree: a node index
    Box box;             // BVH: the child's box; kd-tree: the node's cell
  };
  // Bounded: a BVH path holds at most 7 pending siblings per level, a kd-tree path one per level.
  constexpr std::size_t kCapacity =
      1 + (BvhNode8::kWidth - 1) * std::max<std::size_t>(WideBvh::kMaxDepth, kKdStackSize);
  struct Stack {
    Entry items[kCapacity];
    std::size_t size = 0;
    [[nodiscard]] bool empty() const { return size == 0; }
    void push_back(const Entry& e) { items[size++] = e; }
    Entry back() const { return items[size - 1]; }
    void pop_back() { --size; }
  } stack;
  if (structure_ == MeshStructure::Bvh) {
    if (parts_->bvh.root == BvhRef::kEmpty) return false;
    stack.push_back({parts_->bvh.root, parts_->bvh.bounds});
    while (!stack.empty()) {
      const Entry e = stack.back();
      stack.pop_back();
      if (!q.mayReach(e.box, best.distance)) continue;
      if (BvhRef::isLeaf(e.node)) {
        testLeaf(BvhRef::leafBlock(e.node), BvhRef::leafCount(e.node));
        continue;
      }
      const BvhNode8& node = parts_->bvh.nodes[e.node];
      // The children that may reach, pushed farthest first so that the nearest is visited next.
      std::pair<double, int> order[BvhNode8::kWidth];
      int n = 0;
      for (int k = 0; k < BvhNode8::kWidth && node.child[k] != BvhRef::kEmpty; ++k) {
        const Box b = node.childBox(k);
        if (q.mayReach(b, best.distance))
          order[n++] = {distanceSquared(b, q.point_os), k};  // object space: the order only
      }
      for (int i = 1; i < n; ++i)  // descending by key: at most 8, an insertion sort
        for (int j = i; j > 0 && order[j - 1].first < order[j].first; --j) std::swap(order[j - 1], order[j]);
      for (int i = 0; i < n; ++i) stack.push_back({node.child[order[i].second], node.childBox(order[i].second)});
    }
    return improved;
  }
  stack.push_back({0, parts_->block_tree.bounds});
  while (!stack.empty()) {
    const Entry e = stack.back();
    stack.pop_back();
    if (!q.mayReach(e.box, best.distance)) continue;
    const KdNode& node = parts_->block_tree.nodes[e.node];
    if (node.isLeaf()) {
      if (node.primCount() > 0) testLeaf(node.primOffset(), node.primCount());
      continue;
    }
    const int axis = node.axis();
    const auto [lower, upper] = childCells(node, e.box);
    const bool below = q.point_os[axis] < double{node.split()};
    // The side holding the point last, so that it is visited first.
    if (below) {
      stack.push_back({node.upperChild(), upper});
      stack.push_back({e.node + 1, lower});
    } else {
      stack.push_back({e.node + 1, lower});
      stack.push_back({node.upperChild(), upper});
    }
  }
  return improved;
}

namespace {

// The leaves of a mesh structure whose boxes a region does not exclude, with what the boxes tell:
// visit(first_block, triangle_count, box_inside) returns true to stop the walk (the result is
// then true). BVH boxes bound their triangles' parts, so `box_inside` says those parts lie in the
// region; kd-tree cells are only space, so it is always false there.
template <class Visit>
bool forEachLeafInRegion(MeshStructure structure, const WideBvh& bvh, const KdTree& block_tree,
                         const ConvexRegion& region, Visit&& visit) {
  struct Entry {
    std::uint32_t node;
    Box box;
  };
  std::vector<Entry> stack;
  if (structure == MeshStructure::Bvh) {
    if (bvh.root == BvhRef::kEmpty) return false;
    stack.push_back({bvh.root, bvh.bounds});
    while (!stack.empty()) {
      const Entry e = stack.back();
      stack.pop_back();
      if (region.excludes(e.box)) continue;
      if (BvhRef::isLeaf(e.node)) {
        if (visit(BvhRef::leafBlock(e.node), BvhRef::leafCount(e.node), region.containsBox(e.box))) return true;
        continue;
      }
      const BvhNode8& node = bvh.nodes[e.node];
      for (int k = 0; k < BvhNode8::kWidth && node.child[k] != BvhRef::kEmpty; ++k)
        stack.push_back({node.child[k], node.childBox(k)});
    }
    return false;
  }
  if (block_tree.empty()) return false;
  stack.push_back({0, block_tree.bounds});
  while (!stack.empty()) {
    const Entry e = stack.back();
    stack.pop_back();
    if (region.excludes(e.box)) continue;
    const KdNode& node = block_tree.nodes[e.node];
    if (node.isLeaf()) {
      if (node.primCount() > 0 && visit(node.primOffset(), node.primCount(), false)) return true;
      continue;
    }
    const auto [lower, upper] = childCells(node, e.box);
    stack.push_back({node.upperChild(), upper});
    stack.push_back({e.node + 1, lower});
  }
  return false;
}

glm::dvec3 blockVertex(const detail::TriangleBlock4& b, int lane, int k) { return glm::dvec3(b.vertex(lane, k)); }

}  // namespace

std::optional<bool> MeshObject::inRegion(const ConvexRegion& region, RegionMode mode) const {
  const detail::TriangleBlock4* blocks = parts_->blocks.data();
  if (mode == RegionMode::Inside) {
    if (region.containsBox(mesh_->bounds())) return true;
    if (structure_ == MeshStructure::Bvh) {
      // Every part of the geometry lies in some child box: a box the region excludes, or a
      // triangle with a corner outside, means some geometry is outside.
      bool outside = false;
      std::vector<std::pair<std::uint32_t, Box>> stack{{parts_->bvh.root, parts_->bvh.bounds}};
      while (!stack.empty() && !outside) {
        const auto [ref, box] = stack.back();
        stack.pop_back();
        if (region.containsBox(box)) continue;
        if (region.excludes(box)) {
          outside = true;
          break;
        }
        if (BvhRef::isLeaf(ref)) {
          for (std::uint32_t i = 0; i < BvhRef::leafCount(ref) && !outside; ++i) {
            const detail::TriangleBlock4& b = blocks[BvhRef::leafBlock(ref) + i / 4];
            for (int k = 0; k < 3; ++k)
              outside = outside || !region.contains(blockVertex(b, static_cast<int>(i % 4), k));
          }
          continue;
        }
        const BvhNode8& node = parts_->bvh.nodes[ref];
        for (int k = 0; k < BvhNode8::kWidth && node.child[k] != BvhRef::kEmpty; ++k)
          stack.emplace_back(node.child[k], node.childBox(k));
      }
      return !outside;
    }
    // kd-tree cells are only space: every valid triangle's corners are checked.
    const std::vector<glm::vec3>& p = mesh_->positions();
    const std::vector<TriangleMesh::Triangle>& tris = mesh_->triangles();
    for (std::size_t t = 0; t < tris.size(); ++t) {
      if (!mesh_->isValid(t)) continue;
      for (int k = 0; k < 3; ++k)
        if (!region.contains(glm::dvec3(p[tris[t][k]]))) return false;
    }
    return true;
  }
  if (mode != RegionMode::Touching) return std::nullopt;
  return forEachLeafInRegion(
      structure_, parts_->bvh, parts_->block_tree, region,
      [&](std::uint32_t first, std::uint32_t count, bool box_inside) {
        if (box_inside) return true;  // a BVH box holds part of a triangle
        for (std::uint32_t i = 0; i < count; ++i) {
          const detail::TriangleBlock4& b = blocks[first + i / 4];
          const int lane = static_cast<int>(i % 4);
          if (region.meetsTriangle(blockVertex(b, lane, 0), blockVertex(b, lane, 1), blockVertex(b, lane, 2)))
            return true;
        }
        return false;
      });
}

bool MeshObject::trianglesInRegion(const ConvexRegion& region, std::vector<RegionTriangle>& out) const {
  const detail::TriangleBlock4* blocks = parts_->blocks.data();
  std::vector<std::uint32_t> prims;
  forEachLeafInRegion(
      structure_, parts_->bvh, parts_->block_tree, region, [&](std::uint32_t first, std::uint32_t count, bool) {
        for (std::uint32_t i = 0; i < count; ++i) {
          const detail::TriangleBlock4& b = blocks[first + i / 4];
          const int lane = static_cast<int>(i % 4);
          if (region.meetsTriangle(blockVertex(b, lane, 0), blockVertex(b, lane, 1), blockVertex(b, lane, 2)))
            prims.push_back(b.prim[lane]);
        }
        return false;
      });
  // A triangle referenced by several leaves (kd-tree, spatial splits) is reported once.
  std::sort(prims.begin(), prims.end());
  prims.erase(std::unique(prims.begin(), prims.end()), prims.end());
  const std::vector<glm::vec3>& p = mesh_->positions();
  for (const std::uint32_t prim : prims) {
    const TriangleMesh::Triangle& t = mesh_->triangles()[prim];
    RegionTriangle& r = out.emplace_back();
    r.prim_id = prim;
    for (int k = 0; k < 3; ++k) {
      r.vertex[k] = t[k];
      r.position_os[k] = p[t[k]];
    }
  }
  return true;
}

bool MeshObject::occluded(const Ray& ray_os, QueryContext&) const { return occluded(ray_os); }

std::uint32_t MeshObject::intersectPacket(std::span<const Ray> rays_os, std::span<Hit> hits, std::uint32_t active,
                                          QueryContext& ctx) const {
  if (structure_ != MeshStructure::Bvh || !packetSizeOk(rays_os.size(), hits.size()))
    return Object::intersectPacket(rays_os, hits, active, ctx);  // the kd-tree, or the default's errors
  active &= packetLanes(rays_os.size());
  return detail::meshBvhKernels().intersectPacket(bvhView(parts_->bvh, parts_->blocks), rays_os.data(), hits.data(),
                                                  active);
}

std::uint32_t MeshObject::occludedPacket(std::span<const Ray> rays_os, std::uint32_t active, QueryContext& ctx) const {
  if (structure_ != MeshStructure::Bvh || !packetSizeOk(rays_os.size(), rays_os.size()))
    return Object::occludedPacket(rays_os, active, ctx);
  active &= packetLanes(rays_os.size());
  return detail::meshBvhKernels().occludedPacket(bvhView(parts_->bvh, parts_->blocks), rays_os.data(), active);
}

std::size_t MeshObject::accelBytes() const {
  return parts_->tree.nodes.size() * sizeof(KdNode) + parts_->tree.prim_indices.size() * sizeof(std::uint32_t) +
         parts_->blocks.size() * sizeof(detail::TriangleBlock4) + parts_->block_tree.nodes.size() * sizeof(KdNode) +
         parts_->bvh.memoryBytes();
}

std::vector<ObjectFigure> MeshObject::figures() const {
  return {{"triangles", mesh_->triangleCount()}, {"degenerate_triangles", mesh_->degenerateCount()}};
}

void MeshObject::savePrepared(const std::filesystem::path& path) const { saveMeshObject(*this, path); }

std::uint64_t MeshObject::contentHash() const { return meshChecksum(*mesh_); }

std::size_t MeshObject::memoryBytes() const {
  return accelBytes() + mesh_->positions().size() * sizeof(glm::vec3) +
         mesh_->triangles().size() * sizeof(TriangleMesh::Triangle);
}

}  // namespace duplex
