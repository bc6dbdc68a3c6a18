// The non-template functions of KdTreeChecks.h, compiled once into the test support library rather than
// into every test file that includes the header.
#include "KdTreeChecks.h"

namespace duplex::test {

std::vector<Box> kdcheck_detail::triangleBounds(std::span<const std::array<glm::vec3, 3>> tris,
                                                const std::vector<char>& usable) {
  std::vector<Box> bounds(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i)
    if (usable[i])
      for (const auto& v : tris[i]) bounds[i].extend(v);
  return bounds;
}

::testing::AssertionResult checkKdStructure(const KdTree& tree, std::span<const Box> prim_bounds,
                                            const std::vector<char>& usable, int max_depth, const Box* root_bounds) {
  using namespace kdcheck_detail;
  Failures f;
  const std::size_t prim_count = prim_bounds.size();
  std::size_t usable_count = 0;
  Box expected;
  for (std::size_t i = 0; i < prim_count; ++i)
    if (usable[i]) {
      ++usable_count;
      expected.extend(prim_bounds[i]);
    }
  if (usable_count == 0) {
    if (!tree.nodes.empty() || !tree.prim_indices.empty())
      f.add([&](auto& os) { os << "no usable primitive, but the tree has " << tree.nodes.size() << " nodes"; });
    return f.result("kd-tree structure");
  }
  if (tree.nodes.empty()) {
    f.add([&](auto& os) { os << usable_count << " usable primitives but the tree is empty"; });
    return f.result("kd-tree structure");
  }
  if (root_bounds) {
    if (!(tree.bounds == *root_bounds))
      f.add([&](auto& os) { os << "tree.bounds " << tree.bounds << " != the given root bounds " << *root_bounds; });
    if (!(intersection(*root_bounds, expected) == expected))
      f.add([&](auto& os) { os << "root bounds " << *root_bounds << " do not contain the primitives " << expected; });
  } else if (!(tree.bounds == expected)) {
    f.add([&](auto& os) { os << "tree.bounds " << tree.bounds << " != union of usable bounds " << expected; });
  }

  const int bound = depthBound(usable_count, max_depth);
  std::vector<char> visited(tree.nodes.size(), 0);
  std::vector<char> referenced(prim_count, 0);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> ranges;
  struct Item {
    std::uint32_t node;
    Box box;
    int depth;
  };
  std::vector<Item> stack{{0, tree.bounds, 0}};
  int max_seen = 0;
  std::vector<std::uint32_t> ids;
  std::vector<Box> walk_boxes(tree.nodes.size());
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    if (it.node >= tree.nodes.size()) {
      f.add([&](auto& os) { os << "node index " << it.node << " out of range " << tree.nodes.size(); });
      continue;
    }
    if (visited[it.node]++) {
      f.add([&](auto& os) { os << "node " << it.node << " reached twice"; });
      continue;
    }
    max_seen = std::max(max_seen, it.depth);
    walk_boxes[it.node] = it.box;
    const KdNode& n = tree.nodes[it.node];
    if (n.isLeaf()) {
      if (it.depth > bound)
        f.add([&](auto& os) { os << "leaf " << it.node << " at depth " << it.depth << " > bound " << bound; });
      const std::uint64_t end = std::uint64_t(n.primOffset()) + n.primCount();
      if (end > tree.prim_indices.size()) {
        f.add([&](auto& os) {
          os << "leaf " << it.node << " range [" << n.primOffset() << ", " << end << ") exceeds prim_indices size "
             << tree.prim_indices.size();
        });
        continue;
      }
      ranges.emplace_back(n.primOffset(), n.primCount());
      ids.assign(tree.prim_indices.begin() + n.primOffset(), tree.prim_indices.begin() + end);
      for (const std::uint32_t id : ids) {
        if (id >= prim_count || !usable[id]) {
          f.add([&](auto& os) {
            os << "leaf " << it.node << " references primitive " << id
               << (id >= prim_count ? " (out of range)" : " (not usable)");
          });
          continue;
        }
        referenced[id] = 1;
      }
      std::sort(ids.begin(), ids.end());
      if (std::adjacent_find(ids.begin(), ids.end()) != ids.end())
        f.add([&](auto& os) { os << "leaf " << it.node << " references a primitive twice"; });
      continue;
    }
    const int axis = n.axis();
    const float s = n.split();
    if (!(s > it.box.lo[axis] && s < it.box.hi[axis]))
      f.add([&](auto& os) {
        os << "node " << it.node << " splits axis " << axis << " at " << s << ", not strictly inside " << it.box;
      });
    const std::uint32_t upper = n.upperChild();
    if (!(upper > it.node + 1 && upper < tree.nodes.size() && it.node + 1 < tree.nodes.size())) {
      f.add([&](auto& os) {
        os << "node " << it.node << " has upper child " << upper << " (size " << tree.nodes.size() << ")";
      });
      continue;
    }
    Box lower_box = it.box, upper_box = it.box;
    lower_box.hi[axis] = s;
    upper_box.lo[axis] = s;
    stack.push_back({it.node + 1, lower_box, it.depth + 1});
    stack.push_back({upper, upper_box, it.depth + 1});
  }
  const auto reached = static_cast<std::size_t>(std::count(visited.begin(), visited.end(), 1));
  if (reached != tree.nodes.size())
    f.add(
        [&](auto& os) { os << "only " << reached << " of " << tree.nodes.size() << " nodes reachable from the root"; });
  std::sort(ranges.begin(), ranges.end());
  std::uint64_t total = 0;
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    total += ranges[i].second;
    if (i + 1 < ranges.size() && std::uint64_t(ranges[i].first) + ranges[i].second > ranges[i + 1].first)
      f.add([&](auto& os) { os << "leaf ranges overlap at prim offset " << ranges[i + 1].first; });
  }
  if (total != tree.prim_indices.size())
    f.add([&](auto& os) {
      os << "leaves hold " << total << " references but prim_indices has " << tree.prim_indices.size();
    });
  for (std::size_t i = 0; i < prim_count; ++i)
    if (usable[i] && !referenced[i]) f.add([&](auto& os) { os << "usable primitive " << i << " is in no leaf"; });
  // KdTree::nodeBox and KdTree::stats assume a well-formed node array: only ask them now.
  if (f.any()) return f.result("kd-tree structure");
  // nodeBox walks from the root, so asking it for every node costs O(n^2): ask for at most
  // kNodeBoxSamples nodes spread over the array (the root and the last node among them), which keeps
  // the check linear in the tree's size.
  constexpr std::size_t kNodeBoxSamples = 64;
  const std::size_t node_count = tree.nodes.size();
  const std::size_t stride = std::max<std::size_t>(1, node_count / kNodeBoxSamples);
  for (std::size_t k = 0; k < node_count; k += stride) {
    const auto i = static_cast<std::uint32_t>(k + stride >= node_count ? node_count - 1 : k);
    const Box nb = tree.nodeBox(i);
    if (!(nb == walk_boxes[i]))
      f.add([&](auto& os) { os << "nodeBox(" << i << ") = " << nb << " but walk gives " << walk_boxes[i]; });
  }
  const KdTreeStats st = tree.stats(1.0f, 1.5f);
  if (st.nodes != tree.nodes.size() || int(st.max_depth) != max_seen || st.references != tree.prim_indices.size())
    f.add([&](auto& os) {
      os << "stats() disagree: nodes " << st.nodes << ", max_depth " << st.max_depth << " (walk " << max_seen
         << "), references " << st.references;
    });
  return f.result("kd-tree structure");
}

::testing::AssertionResult checkTriangleKdTree(const KdTree& tree, std::span<const std::array<glm::vec3, 3>> tris,
                                               const std::vector<char>& usable, int max_depth) {
  using namespace kdcheck_detail;
  auto structure = checkKdStructure(tree, triangleBounds(tris, usable), usable, max_depth);
  if (!structure || tree.nodes.empty()) return structure;

  Failures f;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    if (!usable[i]) continue;
    const auto prim = static_cast<std::uint32_t>(i);
    const glm::dvec3 a(tris[i][0]), b(tris[i][1]), c(tris[i][2]);
    const double tri_area = 0.5 * glm::length(glm::cross(b - a, c - a));
    // Area coverage: descend with the triangle clipped to each node box; a plane that does not
    // cut the polygon passes it on unchanged.
    Polygon root;
    root.push(a);
    root.push(b);
    root.push(c);
    root.finish();
    struct Walker {
      const KdTree& tree;
      Failures& f;
      std::uint32_t prim;
      double tri_area;
      void visit(std::uint32_t node, const Box& box, const Polygon& poly) {
        if (poly.overflow) {
          f.add([&](auto& os) { os << "checker polygon overflow for triangle " << prim; });
          return;
        }
        const KdNode& n = tree.nodes[node];
        if (n.isLeaf()) {
          glm::dvec3 lo, hi;
          shrunk(box, lo, hi);
          Polygon cur = poly, tmp;
          for (int k = 0; k < 3 && cur.n >= 3; ++k) {
            if (cur.lo[k] < lo[k]) {
              cur.clip(k, lo[k], true, tmp);
              cur = tmp;
            }
            if (cur.n >= 3 && cur.hi[k] > hi[k]) {
              cur.clip(k, hi[k], false, tmp);
              cur = tmp;
            }
          }
          if (cur.n >= 3 && cur.area() > 1e-10 * tri_area && !leafReferences(tree, n, prim))
            f.add([&](auto& os) {
              os << "triangle " << prim << " overlaps leaf " << node << " " << box << " with area " << cur.area()
                 << " but is not referenced there";
            });
          return;
        }
        const int axis = n.axis();
        const double split = n.split();
        Box lower_box = box, upper_box = box;
        lower_box.hi[axis] = n.split();
        upper_box.lo[axis] = n.split();
        if (poly.hi[axis] < split) {
          visit(node + 1, lower_box, poly);
        } else if (poly.lo[axis] > split) {
          visit(n.upperChild(), upper_box, poly);
        } else {
          Polygon part;
          poly.clip(axis, split, false, part);
          if (part.n >= 3 && part.area() > 1e-12 * tri_area) visit(node + 1, lower_box, part);
          poly.clip(axis, split, true, part);
          if (part.n >= 3 && part.area() > 1e-12 * tri_area) visit(n.upperChild(), upper_box, part);
        }
      }
    };
    Walker{tree, f, prim, tri_area}.visit(0, tree.bounds, root);
    // Point coverage.
    const glm::dvec3 samples[7] = {a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a), (a + b + c) / 3.0};
    for (const auto& p : samples)
      if (!pointCovered(tree, p, prim)) {
        f.add([&](auto& os) {
          os << "point (" << p.x << ", " << p.y << ", " << p.z << ") of triangle " << prim
             << " lies in no leaf that references the triangle";
        });
        break;
      }
  }
  return f.result("kd-tree triangle coverage");
}

::testing::AssertionResult checkBoxKdTree(const KdTree& tree, std::span<const Box> boxes, int max_depth,
                                          const Box* root_bounds) {
  using namespace kdcheck_detail;
  std::vector<char> usable(boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const Box& b = boxes[i];
    bool ok = !b.empty();
    for (int k = 0; k < 3; ++k) ok = ok && std::isfinite(b.lo[k]) && std::isfinite(b.hi[k]);
    usable[i] = ok;
  }
  auto structure = checkKdStructure(tree, boxes, usable, max_depth, root_bounds);
  if (!structure || tree.nodes.empty()) return structure;

  Failures f;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (!usable[i]) continue;
    const auto prim = static_cast<std::uint32_t>(i);
    std::function<void(std::uint32_t, const Box&)> visit = [&](std::uint32_t node, const Box& box) {
      if (intersection(box, boxes[i]).empty()) return;
      const KdNode& n = tree.nodes[node];
      if (n.isLeaf()) {
        glm::dvec3 lo, hi;
        shrunk(box, lo, hi);
        bool overlap = true;
        for (int k = 0; k < 3; ++k)
          overlap = overlap && std::max(lo[k], double(boxes[i].lo[k])) <= std::min(hi[k], double(boxes[i].hi[k]));
        if (overlap && !leafReferences(tree, n, prim))
          f.add([&](auto& os) {
            os << "box " << prim << " " << boxes[i] << " overlaps leaf " << node << " " << box
               << " but is not referenced";
          });
        return;
      }
      Box lower_box = box, upper_box = box;
      lower_box.hi[n.axis()] = n.split();
      upper_box.lo[n.axis()] = n.split();
      visit(node + 1, lower_box);
      visit(n.upperChild(), upper_box);
    };
    visit(0, tree.bounds);
    const glm::dvec3 lo(boxes[i].lo), hi(boxes[i].hi);
    for (int k = 0; k < 9; ++k) {
      if (!pointCovered(tree, boxSamplePoint(lo, hi, k), prim)) {
        f.add([&](auto& os) {
          os << "point of box " << prim << " " << boxes[i] << " lies in no leaf that references it";
        });
        break;
      }
    }
  }
  return f.result("kd-tree box coverage");
}

::testing::AssertionResult checkMeshTree(const MeshObject& object, int max_depth) {
  const CheckedTriangles t(object.mesh());
  return checkTriangleKdTree(object.tree(), t.tris, t.usable, max_depth);
}

std::vector<ConfigCase> allConfigCases() {
  std::vector<ConfigCase> cases;
  for (const KdHeuristic h : {KdHeuristic::Sah, KdHeuristic::Median, KdHeuristic::SpatialMiddle})
    for (const bool clip : {true, false}) {
      KdBuildConfig c;
      c.heuristic = h;
      c.clip_primitives = clip;
      cases.push_back({std::string(toString(h)) + (clip ? "_clip" : "_noclip"), c});
    }
  KdBuildConfig parallel;
  parallel.parallel_threshold = 16;  // TBB subtrees almost everywhere
  cases.push_back({"sah_parallel16", parallel});
  KdBuildConfig serial;
  serial.parallel_threshold = 0;
  cases.push_back({"sah_serial", serial});
  KdBuildConfig shallow;
  shallow.max_depth = 5;  // big leaves
  cases.push_back({"sah_depth5", shallow});
  KdBuildConfig small_leaves;
  small_leaves.heuristic = KdHeuristic::SpatialMiddle;
  small_leaves.max_leaf_size = 2;
  small_leaves.parallel_threshold = 64;
  cases.push_back({"middle_leaf2_parallel64", small_leaves});
  KdBuildConfig deep;
  deep.traversal_cost = 0.1f;  // node cost 1 triangle test: small leaves, whatever the default
  deep.intersection_cost = 0.1f;
  deep.empty_bonus = 0.9f;
  cases.push_back({"sah_deep", deep});
  return cases;
}

}  // namespace duplex::test
