#include "duplex/objects/MeshObject.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/KdTraversal.h"
#include "duplex/accel/KdTreeBuilder.h"
#include "duplex/accel/TriangleClip.h"
#include "duplex/objects/WatertightTriangle.h"
#include "WatertightTriangle4.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

namespace duplex {

namespace {

// One 4-wide group of a leaf: the references [i, i + min(4, end - i)) of `refs` (padded, so the
// extra lanes read valid triangles and are masked off).
template <int KX, int KY, int KZ, class TriangleVertices>
inline detail::Watertight4 testGroup(const WatertightRay& wray, const TriangleVertices* tris, const std::uint32_t* refs,
                                     std::uint32_t i, int n, float t_max) {
  const float* lane[4];
  for (int k = 0; k < 4; ++k) lane[k] = &tris[refs[i + k]].v0.x;
  return detail::intersectWatertight4<KX, KY, KZ>(wray, lane, n, t_max);
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
      if (depth + 1 >= kKdStackSize) fail(at() + "deeper than the traversal stack (" + std::to_string(kKdStackSize) + ")");
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
  // Degenerate triangles get an empty box, which the builder leaves out.
  std::vector<Box> bounds(m.triangleCount());
  for (std::size_t i = 0; i < m.triangleCount(); ++i) {
    if (!m.isValid(i)) continue;
    const auto v = m.vertices(i);
    Box b;
    for (const auto& p : v) b.extend(p);
    bounds[i] = b;
  }
  tree_ = buildKdTree(
      bounds,
      [&m](std::uint32_t prim, const Box& box) {
        const auto v = m.vertices(prim);
        return clipTriangleToBox(v[0], v[1], v[2], box);
      },
      config);
  orderTrianglesByLeaves();
}

MeshObject::MeshObject(std::shared_ptr<const TriangleMesh> mesh, KdTree tree, PartsTag)
    : Object(mesh->name()), mesh_(std::move(mesh)), tree_(std::move(tree)) {
  orderTrianglesByLeaves();
}

std::shared_ptr<const MeshObject> MeshObject::fromParts(std::shared_ptr<const TriangleMesh> mesh, KdTree tree) {
  if (!mesh) throw InvalidArgument("MeshObject::fromParts: null mesh");
  checkTreeAgainstMesh(tree, *mesh);
  return std::shared_ptr<const MeshObject>(new MeshObject(std::move(mesh), std::move(tree), PartsTag{}));
}

void MeshObject::orderTrianglesByLeaves() {
  const TriangleMesh& m = *mesh_;
  const std::vector<glm::vec3>& positions = m.positions();
  std::vector<std::uint32_t> renumbered(m.triangleCount(), kInvalidId);
  leaf_refs_.reserve(tree_.prim_indices.size() + 3);
  prim_ids_.reserve(m.triangleCount());
  triangles_.reserve(m.triangleCount() + 1);
  for (const std::uint32_t prim : tree_.prim_indices) {
    if (renumbered[prim] == kInvalidId) {
      renumbered[prim] = static_cast<std::uint32_t>(prim_ids_.size());
      prim_ids_.push_back(prim);
      const TriangleMesh::Triangle& t = m.triangles()[prim];
      triangles_.push_back({positions[t[0]], positions[t[1]], positions[t[2]]});
    }
    leaf_refs_.push_back(renumbered[prim]);
  }
  // Three spare references so that a 4-wide group never reads past the list (the extra lanes
  // are masked off), and one spare triangle: the 4-wide test reads 12 floats from each start.
  leaf_refs_.insert(leaf_refs_.end(), 3, 0u);
  leaf_refs_.shrink_to_fit();
  triangles_.push_back(triangles_.empty() ? TriangleVertices{} : triangles_.back());
  triangles_.shrink_to_fit();
  prim_ids_.shrink_to_fit();
}

bool MeshObject::intersect(const Ray& ray_os, Hit& hit) const {
  if (!isQueryable(ray_os)) return false;
  const KdRay kray(ray_os);
  const WatertightRay wray(ray_os);
  float t_best = std::min(hit.t, ray_os.tfar);
  std::uint32_t best = kInvalidId;
  const TriangleVertices* tris = triangles_.data();
  const std::uint32_t* refs = leaf_refs_.data();
  // One dispatch per ray on the axis permutation; traversal and triangle tests below are
  // instantiated for each of the six permutations.
  dispatchPermutation(wray, [&]<int KX, int KY, int KZ>() {
    traverseKdTree<false>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
      bool found = false;
      // Four triangles per step; lanes are resolved in order with the scalar interval test so
      // that the result equals testing them one by one.
      for (std::uint32_t i = begin, end = begin + count; i < end; i += 4) {
        const int n = static_cast<int>(std::min<std::uint32_t>(4, end - i));
        const detail::Watertight4 r = testGroup<KX, KY, KZ>(wray, tris, refs, i, n, t_max);
        if ((r.fast | r.exact) == 0) continue;
        for (int k = 0; k < n; ++k) {
          float t, u, v;
          bool hit = false;
          if (r.exact >> k & 1) {
            const TriangleVertices& tri = tris[refs[i + k]];
            hit = intersectWatertight<KX, KY, KZ>(wray, tri.v0, tri.v1, tri.v2, t_max, t, u, v);
          } else if ((r.fast >> k & 1) && !(r.sT[k] > t_max * r.abs_det[k])) {
            t = r.T[k] * (1.0f / r.det[k]);  // the scalar test's final step
            hit = true;
          }
          if (hit) {
            t_max = t;
            best = refs[i + k];
            found = true;
          }
        }
      }
      return found;
    });
  });
  if (best == kInvalidId) return false;
  const TriangleVertices& tri = tris[best];
  // Barycentrics only for the winner, from the scalar test (its arithmetic is the 4-wide one).
  float t, u = 0.0f, v = 0.0f;
  (void)intersectWatertight(wray, tri.v0, tri.v1, tri.v2, std::numeric_limits<float>::infinity(), t, u, v);
  hit.t = t_best;
  hit.u = u;
  hit.v = v;
  hit.prim_id = prim_ids_[best];
  hit.ng = glm::cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
  return true;
}

bool MeshObject::occluded(const Ray& ray_os) const {
  if (!isQueryable(ray_os)) return false;
  const KdRay kray(ray_os);
  const WatertightRay wray(ray_os);
  float t_best = ray_os.tfar;
  const TriangleVertices* tris = triangles_.data();
  const std::uint32_t* refs = leaf_refs_.data();
  return dispatchPermutation(wray, [&]<int KX, int KY, int KZ>() {
    return traverseKdTree<true>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
      for (std::uint32_t i = begin, end = begin + count; i < end; i += 4) {
        const int n = static_cast<int>(std::min<std::uint32_t>(4, end - i));
        const detail::Watertight4 r = testGroup<KX, KY, KZ>(wray, tris, refs, i, n, t_max);
        if (r.fast) return true;
        for (int k = 0; k < n; ++k) {
          if (!(r.exact >> k & 1)) continue;
          const TriangleVertices& tri = tris[refs[i + k]];
          float t, u, v;
          if (intersectWatertight<KX, KY, KZ>(wray, tri.v0, tri.v1, tri.v2, t_max, t, u, v)) return true;
        }
      }
      return false;
    });
  });
}

void MeshObject::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext&) const {
  if (!isQueryable(ray_os)) return;
  const KdRay kray(ray_os);
  const WatertightRay wray(ray_os);
  float t_best = ray_os.tfar;  // never lowered: every leaf along the ray is visited
  const std::size_t first = hits.size();
  dispatchPermutation(wray, [&]<int KX, int KY, int KZ>() {
    traverseKdTree<false>(tree_, kray, t_best, [&](std::uint32_t begin, std::uint32_t count, float& t_max) {
      for (std::uint32_t i = begin; i < begin + count; ++i) {
        const std::uint32_t ref = leaf_refs_[i];
        const TriangleVertices& tri = triangles_[ref];
        float t, u, v;
        if (!intersectWatertight<KX, KY, KZ>(wray, tri.v0, tri.v1, tri.v2, t_max, t, u, v)) continue;
        Hit h;
        h.t = t;
        h.u = u;
        h.v = v;
        h.prim_id = prim_ids_[ref];
        h.ng = glm::cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
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
  std::sort(begin, hits.end(), [](const Hit& a, const Hit& b) { return a.t != b.t ? a.t < b.t : a.prim_id < b.prim_id; });
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
         leaf_refs_.size() * sizeof(std::uint32_t) +
         triangles_.size() * (sizeof(TriangleVertices) + sizeof(std::uint32_t));
}

std::size_t MeshObject::memoryBytes() const {
  return accelBytes() + mesh_->positions().size() * sizeof(glm::vec3) +
         mesh_->triangles().size() * sizeof(TriangleMesh::Triangle);
}

}  // namespace duplex
