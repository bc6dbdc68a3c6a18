#include "duplex/objects/MeshObject.h"
#include "duplex/objects/MeshObjectFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/objects/TriangleClip.h"
#include "duplex/objects/WatertightTriangle.h"
#include "MeshRay.h"
#include "TriangleBlock4.h"
#include "WatertightTriangle4.h"

#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
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

// Lane masks of a block holding n (1..4) of the leaf's triangles.
constexpr int kLaneMask[5] = {0x0, 0x1, 0x3, 0x7, 0xF};

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

}  // namespace

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, const KdBuildConfig& config)
    : Object(mesh ? mesh->name() : std::string()), mesh_(std::move(mesh)) {
  if (!mesh_) throw InvalidArgument("MeshObject: null mesh");
  const TriangleMesh& m = *mesh_;
  // Degenerate triangles get an empty box, which the builder leaves out. In parallel: on its own
  // this pass would hold the other threads idle before the build (as the leaf blocks after it).
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
  try {
    tree_ = buildKdTree(
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

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, PartsTag)
    : Object(mesh->name()), mesh_(std::move(mesh)), tree_(std::move(tree)) {
  buildLeafBlocks();
}

std::shared_ptr<const MeshObject> MeshObject::fromParts(std::shared_ptr<const TriangleMesh> mesh, KdTree tree) {
  if (!mesh) throw InvalidArgument("MeshObject::fromParts: null mesh");
  checkTreeAgainstMesh(tree, *mesh);
  return std::shared_ptr<const MeshObject>(new MeshObject(std::move(mesh), std::move(tree), PartsTag{}));
}

MeshObject::~MeshObject() = default;

void MeshObject::buildLeafBlocks() {
  const TriangleMesh& m = *mesh_;
  const std::vector<glm::vec3>& positions = m.positions();
  const std::vector<std::uint32_t>& refs = tree_.prim_indices;
  block_tree_.bounds = tree_.bounds;
  block_tree_.nodes = tree_.nodes;
  // Each non-empty leaf's first block, in node order (a serial pass over the nodes only); then the
  // blocks are filled leaf by leaf in parallel, each leaf writing only its own range.
  std::size_t block_count = 0;
  for (KdNode& node : block_tree_.nodes) {
    if (!node.isLeaf() || node.isJump() || node.primCount() == 0) continue;
    node.setPrimOffset(static_cast<std::uint32_t>(block_count));
    block_count += (node.primCount() + 3) / 4;
  }
  blocks_.resize(block_count);
  forChunks(tree_.nodes.size(), kNodesPerTask, [&](std::size_t first, std::size_t last) {
    for (std::size_t n = first; n < last; ++n) {
      const KdNode& node = tree_.nodes[n];
      if (!node.isLeaf() || node.isJump() || node.primCount() == 0) continue;
      const std::uint32_t begin = node.primOffset(), end = begin + node.primCount();
      detail::TriangleBlock4* block = blocks_.data() + block_tree_.nodes[n].primOffset();
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

bool MeshObject::intersect(const Ray& ray_os, Hit& hit) const {
  detail::MeshRay ray;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray_os, block_tree_.bounds, ray, tmin, tmax)) return false;
  float t_best = std::min(hit.t, ray_os.tfar);
  const detail::TriangleBlock4* best_block = nullptr;
  int best_lane = 0;
  float best_u = 0.0f, best_v = 0.0f;
  const detail::TriangleBlock4* blocks = blocks_.data();
  // The axis permutation of the triangle test is a run-time value (no dispatch per ray: the six
  // choices are a coin flip on random rays, and six copies of the traversal cost code size).
  traverseKdTreeClipped<false>(
      block_tree_, ray.kd, tmin, tmax, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
        bool found = false;
        // Four triangles per block; lanes are resolved in order with the scalar interval test so
        // that the result equals testing them one by one.
        const detail::TriangleBlock4* block = blocks + begin;
        for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
          const detail::Watertight4 r =
              detail::intersectWatertight4(ray.wray4, *block, kLaneMask[std::min(left, 4)], t_max);
          for (int lanes = r.fast | r.exact; lanes != 0; lanes &= lanes - 1) {
            const int k = std::countr_zero(static_cast<unsigned>(lanes));
            float t, u, v;
            if (r.exact >> k & 1) {
              if (!intersectWatertight(ray.wray, block->vertex(k, 0), block->vertex(k, 1), block->vertex(k, 2), t_max,
                                       t, u, v))
                continue;
            } else {
              if (r.sT[k] > t_max * r.abs_det[k]) continue;
              const float inv = 1.0f / r.det[k];  // the scalar test's final step
              t = r.T[k] * inv;
              u = r.V[k] * inv;
              v = r.W[k] * inv;
            }
            t_max = t;
            best_block = block;
            best_lane = k;
            best_u = u;
            best_v = v;
            found = true;
          }
        }
        return found;
      });
  if (best_block == nullptr) return false;
  const glm::vec3 v0 = best_block->vertex(best_lane, 0);
  hit.t = t_best;
  hit.u = best_u;
  hit.v = best_v;
  hit.prim_id = best_block->prim[best_lane];
  hit.ng = glm::cross(best_block->vertex(best_lane, 1) - v0, best_block->vertex(best_lane, 2) - v0);
  return true;
}

bool MeshObject::occluded(const Ray& ray_os) const {
  detail::MeshRay ray;
  float tmin, tmax;
  if (!detail::setupMeshRay(ray_os, block_tree_.bounds, ray, tmin, tmax)) return false;
  float t_best = ray_os.tfar;
  const detail::TriangleBlock4* blocks = blocks_.data();
  return traverseKdTreeClipped<true>(
      block_tree_, ray.kd, tmin, tmax, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
        const detail::TriangleBlock4* block = blocks + begin;
        for (int left = static_cast<int>(count); left > 0; left -= 4, ++block) {
          const detail::Watertight4 r =
              detail::intersectWatertight4(ray.wray4, *block, kLaneMask[std::min(left, 4)], t_max);
          if (r.fast) return true;
          for (int lanes = r.exact; lanes != 0; lanes &= lanes - 1) {
            const int k = std::countr_zero(static_cast<unsigned>(lanes));
            float t, u, v;
            if (intersectWatertight(ray.wray, block->vertex(k, 0), block->vertex(k, 1), block->vertex(k, 2), t_max, t,
                                    u, v))
              return true;
          }
        }
        return false;
      });
}

void MeshObject::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext&) const {
  if (!isQueryable(ray_os)) return;
  const KdRay kray(ray_os);
  const WatertightRay wray(ray_os);
  float t_best = ray_os.tfar;  // never lowered: every leaf along the ray is visited
  const std::size_t first = hits.size();
  dispatchPermutation(wray, [&]<int KX, int KY, int KZ>() {
    traverseKdTree<false>(block_tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
      const detail::TriangleBlock4* block = blocks_.data() + begin;
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
bool MeshObject::occluded(const Ray& ray_os, QueryContext&) const { return occluded(ray_os); }

std::size_t MeshObject::accelBytes() const {
  return tree_.nodes.size() * sizeof(KdNode) + tree_.prim_indices.size() * sizeof(std::uint32_t) +
         blocks_.size() * sizeof(detail::TriangleBlock4) + block_tree_.nodes.size() * sizeof(KdNode);
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
