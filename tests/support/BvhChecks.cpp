// The non-template functions of BvhChecks.h, compiled once into the test support library rather than
// into every test file that includes the header.
#include "BvhChecks.h"

namespace duplex::test {

::testing::AssertionResult checkBvhStructure(const WideBvh& bvh, std::span<const Box> prim_bounds,
                                             const std::vector<char>& usable, const BvhCheckOptions& opt) {
  using namespace bvhcheck_detail;
  Failures f;
  const std::size_t prim_count = prim_bounds.size();
  const bool tight = opt.tight && !opt.spatial_splits;
  std::size_t usable_count = 0;
  Box expected;
  for (std::size_t i = 0; i < prim_count; ++i)
    if (usable[i]) {
      ++usable_count;
      expected.extend(prim_bounds[i]);
    }
  if (bvh.leaf_block != opt.leaf_block)
    f.add([&](auto& os) { os << "leaf_block " << bvh.leaf_block << ", expected " << opt.leaf_block; });
  if (f.any()) return f.result("BVH structure");
  if (bvh.root == BvhRef::kEmpty) {
    if (usable_count != 0) f.add([&](auto& os) { os << "empty root but " << usable_count << " usable primitives"; });
    if (!bvh.nodes.empty() || !bvh.prim_indices.empty())
      f.add([&](auto& os) {
        os << "empty root with " << bvh.nodes.size() << " nodes and " << bvh.prim_indices.size() << " indices";
      });
    if (!bvh.bounds.empty()) f.add([&](auto& os) { os << "empty root with bounds " << bvh.bounds; });
    return f.result("BVH structure");
  }
  if (usable_count == 0) {
    f.add([&](auto& os) { os << "no usable primitive, but the root is " << bvh.root; });
    return f.result("BVH structure");
  }
  if (!(bvh.bounds == expected))
    f.add([&](auto& os) { os << "bounds " << bvh.bounds << " != union of usable bounds " << expected; });
  if (BvhRef::isLeaf(bvh.root) && !bvh.nodes.empty())
    f.add([&](auto& os) { os << "leaf root with " << bvh.nodes.size() << " nodes"; });
  if (BvhRef::isInner(bvh.root) && bvh.root != 0) f.add([&](auto& os) { os << "inner root " << bvh.root << " != 0"; });
  if (f.any()) return f.result("BVH structure");

  std::vector<std::uint32_t> references(prim_count, 0);
  std::vector<char> block_owned(bvh.prim_indices.size() / std::max<std::uint32_t>(1, bvh.leaf_block), 0);
  if (bvh.prim_indices.size() % bvh.leaf_block != 0)
    f.add([&](auto& os) { os << "prim_indices size " << bvh.prim_indices.size() << " not a multiple of leaf_block"; });
  std::size_t total_refs = 0;
  std::vector<std::uint32_t> ids;
  auto checkLeaf = [&](std::uint32_t ref, const Box& box, const std::string& where) {
    const std::uint32_t count = BvhRef::leafCount(ref);
    const std::size_t first = std::size_t{bvh.leaf_block} * BvhRef::leafBlock(ref);
    const std::size_t blocks = (count + bvh.leaf_block - 1) / bvh.leaf_block;
    if (count > opt.max_leaf_size)
      f.add([&](auto& os) { os << where << ": leaf of " << count << " > max_leaf_size " << opt.max_leaf_size; });
    if (first + blocks * bvh.leaf_block > bvh.prim_indices.size()) {
      f.add([&](auto& os) {
        os << where << ": leaf range [" << first << ", " << first + blocks * bvh.leaf_block
           << ") beyond prim_indices size " << bvh.prim_indices.size();
      });
      return;
    }
    for (std::size_t b = BvhRef::leafBlock(ref); b < BvhRef::leafBlock(ref) + blocks; ++b)
      if (block_owned[b]++) f.add([&](auto& os) { os << where << ": block " << b << " belongs to two leaves"; });
    for (std::size_t i = first + count; i < first + blocks * bvh.leaf_block; ++i)
      if (bvh.prim_indices[i] != WideBvh::kPadding)
        f.add([&](auto& os) { os << where << ": prim_indices[" << i << "] after the leaf is not padding"; });
    ids.assign(bvh.prim_indices.begin() + static_cast<std::ptrdiff_t>(first),
               bvh.prim_indices.begin() + static_cast<std::ptrdiff_t>(first + count));
    Box held;
    for (const std::uint32_t id : ids) {
      if (id >= prim_count || !usable[id]) {
        f.add([&](auto& os) {
          os << where << ": references primitive " << id
             << (id == WideBvh::kPadding ? " (padding inside the leaf)"
                                         : (id >= prim_count ? " (out of range)" : " (not usable)"));
        });
        continue;
      }
      ++references[id];
      ++total_refs;
      held.extend(prim_bounds[id]);
      if (!opt.spatial_splits && !inside(prim_bounds[id], box))
        f.add([&](auto& os) {
          os << where << ": box " << box << " does not contain primitive " << id << " " << prim_bounds[id];
        });
      if (opt.spatial_splits && intersection(box, prim_bounds[id]).empty())
        f.add([&](auto& os) {
          os << where << ": box " << box << " does not overlap primitive " << id << " " << prim_bounds[id];
        });
    }
    if (tight && !(held == box))
      f.add([&](auto& os) { os << where << ": box " << box << " != union of its primitives " << held; });
    std::sort(ids.begin(), ids.end());
    if (std::adjacent_find(ids.begin(), ids.end()) != ids.end())
      f.add([&](auto& os) { os << where << ": a primitive twice in one leaf"; });
  };

  if (BvhRef::isLeaf(bvh.root)) {
    checkLeaf(bvh.root, bvh.bounds, "root leaf");
  } else {
    struct Item {
      std::uint32_t node;
      std::uint32_t parent;
      Box box;  // the parent's slot box (bvh.bounds for the root)
      int depth;
    };
    std::vector<Item> stack{{0, BvhRef::kEmpty, bvh.bounds, 1}};
    std::vector<char> visited(bvh.nodes.size(), 0);
    std::uint32_t order = 0;
    while (!stack.empty()) {
      const Item it = stack.back();
      stack.pop_back();
      const std::string at = "node " + std::to_string(it.node);
      if (it.node >= bvh.nodes.size()) {
        f.add([&](auto& os) { os << at << " out of range (" << bvh.nodes.size() << " nodes)"; });
        continue;
      }
      if (visited[it.node]++) {
        f.add([&](auto& os) { os << at << " reached twice"; });
        continue;
      }
      if (it.parent != BvhRef::kEmpty && it.node <= it.parent)
        f.add([&](auto& os) { os << at << " is a child of node " << it.parent << ": children come after parents"; });
      if (it.node != order)
        f.add([&](auto& os) { os << at << " visited at depth-first position " << order << ": not depth-first"; });
      ++order;
      if (it.depth > WideBvh::kMaxDepth)
        f.add([&](auto& os) { os << at << " at depth " << it.depth << " > kMaxDepth " << WideBvh::kMaxDepth; });
      const BvhNode8& node = bvh.nodes[it.node];
      int used = 0;
      while (used < BvhNode8::kWidth && node.child[used] != BvhRef::kEmpty) ++used;
      if (used < 2) f.add([&](auto& os) { os << at << " has " << used << " children (at least 2)"; });
      if (!node.orderValid()) {
        f.add([&](auto& os) { os << at << ": child order is not a permutation of the slots per octant"; });
      } else if (opt.tight) {
        BvhNode8 sorted = node;
        sorted.computeOrder();
        if (!std::equal(std::begin(node.order), std::end(node.order), std::begin(sorted.order)))
          f.add([&](auto& os) { os << at << ": child order differs from the boxes' (computeOrder)"; });
      }
      Box all;
      for (int k = 0; k < BvhNode8::kWidth; ++k) {
        const Box b = node.childBox(k);
        const std::string slot = at + " slot " + std::to_string(k);
        if (k >= used) {
          if (node.child[k] != BvhRef::kEmpty)
            f.add([&](auto& os) { os << slot << ": used slot " << node.child[k] << " after an empty one"; });
          if (!isEmptySlotBox(b))
            f.add([&](auto& os) { os << slot << ": empty slot with box " << b << " (not [+inf, -inf])"; });
          continue;
        }
        if (!b.finite() || b.empty()) {
          f.add([&](auto& os) { os << slot << ": box " << b << " not finite and non-empty"; });
          continue;
        }
        if (!inside(b, it.box))
          f.add([&](auto& os) { os << slot << ": box " << b << " outside the parent's box " << it.box; });
        all.extend(b);
        if (BvhRef::isLeaf(node.child[k])) checkLeaf(node.child[k], b, slot);
      }
      if (tight && !(all == it.box))
        f.add([&](auto& os) { os << at << ": parent's box " << it.box << " != union of the children " << all; });
      // Reverse slot order, so that slot 0 is visited next (depth-first in slot order).
      for (int k = used - 1; k >= 0; --k)
        if (BvhRef::isInner(node.child[k])) stack.push_back({node.child[k], it.node, node.childBox(k), it.depth + 1});
    }
    if (order != bvh.nodes.size())
      f.add([&](auto& os) { os << "only " << order << " of " << bvh.nodes.size() << " nodes reached from the root"; });
  }
  const auto owned = static_cast<std::size_t>(std::count(block_owned.begin(), block_owned.end(), 1));
  if (owned != block_owned.size())
    f.add([&](auto& os) { os << block_owned.size() - owned << " blocks of prim_indices belong to no leaf"; });
  for (std::size_t i = 0; i < prim_count; ++i) {
    if (!usable[i]) continue;
    if (references[i] == 0) f.add([&](auto& os) { os << "usable primitive " << i << " is in no leaf"; });
    else if (references[i] > 1 && !opt.spatial_splits)
      f.add([&](auto& os) { os << "primitive " << i << " in " << references[i] << " leaves without spatial splits"; });
  }
  if (opt.spatial_splits && double(total_refs) > (1.0 + double(opt.spatial_split_budget)) * double(usable_count) + 1.0)
    f.add([&](auto& os) {
      os << total_refs << " references for " << usable_count << " primitives exceed the budget "
         << opt.spatial_split_budget;
    });
  return f.result("BVH structure");
}

std::vector<char> usableBoxes(std::span<const Box> boxes) {
  std::vector<char> usable(boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) usable[i] = !boxes[i].empty() && boxes[i].finite();
  return usable;
}

::testing::AssertionResult checkBoxBvh(const WideBvh& bvh, std::span<const Box> boxes, const BvhCheckOptions& opt) {
  using namespace bvhcheck_detail;
  const std::vector<char> usable = usableBoxes(boxes);
  auto structure = checkBvhStructure(bvh, boxes, usable, opt);
  if (!structure || !opt.spatial_splits) return structure;
  Failures f;
  const auto leaves = leafBoxesByPrimitive(bvh, boxes.size());
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (!usable[i]) continue;
    const glm::dvec3 lo(boxes[i].lo), hi(boxes[i].hi);
    for (int k = 0; k < 9; ++k) {
      if (!coveredByLeaves(kdcheck_detail::boxSamplePoint(lo, hi, k), leaves[i])) {
        f.add([&](auto& os) { os << "a point of box " << i << " " << boxes[i] << " is in no leaf referencing it"; });
        break;
      }
    }
  }
  return f.result("BVH box coverage");
}

::testing::AssertionResult checkTriangleBvh(const WideBvh& bvh, std::span<const std::array<glm::vec3, 3>> tris,
                                            const std::vector<char>& usable, const BvhCheckOptions& opt) {
  using namespace bvhcheck_detail;
  // Without spatial splits, leaf boxes containing the triangle boxes contain all three vertices.
  auto structure = checkBvhStructure(bvh, kdcheck_detail::triangleBounds(tris, usable), usable, opt);
  if (!structure || !opt.spatial_splits) return structure;
  Failures f;
  const auto leaves = leafBoxesByPrimitive(bvh, tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i) {
    if (!usable[i]) continue;
    const glm::dvec3 a(tris[i][0]), b(tris[i][1]), c(tris[i][2]);
    // Every referencing leaf box meets the triangle itself, not only its bounding box.
    for (const Box& box : leaves[i]) {
      glm::dvec3 lo, hi;
      grown(box, lo, hi);
      kdcheck_detail::Polygon cur, tmp;
      cur.push(a);
      cur.push(b);
      cur.push(c);
      cur.finish();
      for (int k = 0; k < 3 && cur.n > 0; ++k) {
        cur.clip(k, lo[k], true, tmp);
        cur = tmp;
        if (cur.n == 0) break;
        cur.clip(k, hi[k], false, tmp);
        cur = tmp;
      }
      if (cur.n == 0)
        f.add([&](auto& os) { os << "triangle " << i << " referenced by leaf " << box << " which it does not meet"; });
    }
    // The referencing leaves together cover the triangle.
    const glm::dvec3 samples[10] = {a,
                                    b,
                                    c,
                                    0.5 * (a + b),
                                    0.5 * (b + c),
                                    0.5 * (c + a),
                                    (a + b + c) / 3.0,
                                    0.7 * a + 0.2 * b + 0.1 * c,
                                    0.1 * a + 0.7 * b + 0.2 * c,
                                    0.2 * a + 0.1 * b + 0.7 * c};
    for (const auto& p : samples)
      if (!coveredByLeaves(p, leaves[i])) {
        f.add([&](auto& os) {
          os << "point (" << p.x << ", " << p.y << ", " << p.z << ") of triangle " << i
             << " lies in no leaf that references it";
        });
        break;
      }
  }
  return f.result("BVH triangle coverage");
}

::testing::AssertionResult checkMeshBvh(const MeshObject& object, const BvhCheckOptions& opt) {
  if (object.structure() != MeshStructure::Bvh)
    return ::testing::AssertionFailure() << "mesh '" << object.mesh().name() << "' has no BVH";
  const CheckedTriangles t(object.mesh());
  return checkTriangleBvh(object.bvh(), t.tris, t.usable, opt);
}

}  // namespace duplex::test
