#include "FeatureEdges.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

namespace duplex {

namespace {

constexpr std::uint32_t kLeafEdges = 4;

glm::dvec3 unitNormal(const RegionTriangle& t) {
  const glm::dvec3 a(t.position_os[0]), b(t.position_os[1]), c(t.position_os[2]);
  const glm::dvec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  return len > 0.0 ? n / len : n;
}

// Whether segment [a, b] shares a point with the region: what is left after clipping it by every plane.
bool segmentMeets(const ConvexRegion& region, const glm::dvec3& a, const glm::dvec3& b) {
  double t0 = 0.0, t1 = 1.0;
  for (const glm::dvec4& p : region.planes()) {
    const glm::dvec3 n(p);
    const double fa = glm::dot(n, a) - p.w, fb = glm::dot(n, b) - p.w;
    if (fa > 0.0 && fb > 0.0) return false;
    if (fa > 0.0) t0 = std::max(t0, fa / (fa - fb));
    else if (fb > 0.0) t1 = std::min(t1, fa / (fa - fb));
    if (t0 > t1) return false;
  }
  return true;
}

}  // namespace

std::shared_ptr<const FeatureEdges> FeatureEdges::build(const Object& object, double feature_angle_deg) {
  std::vector<RegionTriangle> tris;
  if (!object.trianglesInRegion(ConvexRegion(), tris)) return nullptr;
  // Every triangle's three edges keyed by (lower, higher vertex index): an edge's faces side by side.
  struct Side {
    std::uint64_t key;
    std::uint32_t triangle;  // index into tris
    bool operator<(const Side& o) const { return key != o.key ? key < o.key : triangle < o.triangle; }
  };
  std::vector<Side> sides;
  sides.reserve(3 * tris.size());
  for (std::uint32_t i = 0; i < tris.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = tris[i].vertex[k], b = tris[i].vertex[(k + 1) % 3];
      if (a == b) continue;
      sides.push_back({(std::uint64_t{std::min(a, b)} << 32) | std::max(a, b), i});
    }
  std::sort(sides.begin(), sides.end());
  const double cos_feature = std::cos(feature_angle_deg * std::numbers::pi / 180.0);
  auto out = std::make_shared<FeatureEdges>();
  std::vector<Edge> edges;
  for (std::size_t i = 0; i < sides.size();) {
    std::size_t j = i + 1;
    while (j < sides.size() && sides[j].key == sides[i].key) ++j;
    const bool feature =
        feature_angle_deg <= 0.0 || j - i != 2 ||
        glm::dot(unitNormal(tris[sides[i].triangle]), unitNormal(tris[sides[i + 1].triangle])) < cos_feature;
    if (feature) {
      Edge e;
      e.low = static_cast<std::uint32_t>(sides[i].key >> 32);
      e.high = static_cast<std::uint32_t>(sides[i].key);
      e.prim = tris[sides[i].triangle].prim_id;
      for (std::size_t k = i; k < j; ++k) e.prim = std::min(e.prim, tris[sides[k].triangle].prim_id);
      const RegionTriangle& t = tris[sides[i].triangle];
      for (int k = 0; k < 3; ++k) {
        if (t.vertex[k] == e.low) e.p[0] = t.position_os[k];
        if (t.vertex[k] == e.high) e.p[1] = t.position_os[k];
      }
      edges.push_back(e);
    }
    i = j;
  }
  if (edges.empty()) return out;
  std::vector<std::uint32_t> order(edges.size());
  std::vector<glm::vec3> centre(edges.size());
  for (std::uint32_t i = 0; i < edges.size(); ++i) {
    order[i] = i;
    centre[i] = 0.5f * (edges[i].p[0] + edges[i].p[1]);
  }
  out->edges_ = std::move(edges);
  out->nodes_.reserve(2 * out->edges_.size() / kLeafEdges + 1);
  out->buildNode(order, centre, 0, static_cast<std::uint32_t>(order.size()));
  std::vector<Edge> sorted(out->edges_.size());
  for (std::size_t i = 0; i < order.size(); ++i) sorted[i] = out->edges_[order[i]];
  out->edges_ = std::move(sorted);
  return out;
}

std::uint32_t FeatureEdges::buildNode(std::vector<std::uint32_t>& order, std::vector<glm::vec3>& centre,
                                      std::uint32_t begin, std::uint32_t end) {
  const auto index = static_cast<std::uint32_t>(nodes_.size());
  nodes_.emplace_back();
  Box box, centres;
  for (std::uint32_t i = begin; i < end; ++i) {
    box.extend(edges_[order[i]].p[0]);
    box.extend(edges_[order[i]].p[1]);
    centres.extend(centre[order[i]]);
  }
  nodes_[index].box = box;
  if (end - begin <= kLeafEdges) {
    nodes_[index].first = begin;
    nodes_[index].count = end - begin;
    return index;
  }
  // Median split along the widest axis of the centres.
  const glm::vec3 extent = centres.hi - centres.lo;
  const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
  const std::uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(order.begin() + begin, order.begin() + mid, order.begin() + end,
                   [&](std::uint32_t a, std::uint32_t b) { return centre[a][axis] < centre[b][axis]; });
  buildNode(order, centre, begin, mid);
  const std::uint32_t right = buildNode(order, centre, mid, end);
  nodes_[index].first = right;
  return index;
}

void FeatureEdges::query(const ConvexRegion& region_os, std::vector<std::uint32_t>& out) const {
  if (nodes_.empty()) return;
  std::uint32_t stack[64];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    if (region_os.excludes(n.box)) continue;
    if (n.count > 0) {
      for (std::uint32_t i = n.first; i < n.first + n.count; ++i)
        if (segmentMeets(region_os, glm::dvec3(edges_[i].p[0]), glm::dvec3(edges_[i].p[1]))) out.push_back(i);
      continue;
    }
    const auto self = static_cast<std::uint32_t>(&n - nodes_.data());
    stack[top++] = n.first;
    stack[top++] = self + 1;
  }
}

std::size_t FeatureEdges::memoryBytes() const {
  return sizeof(*this) + edges_.capacity() * sizeof(Edge) + nodes_.capacity() * sizeof(Node);
}

}  // namespace duplex
