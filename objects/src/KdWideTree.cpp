#include "KdWideTree.h"

#include "duplex/accel/Error.h"

#include <limits>
#include <string>

namespace duplex::detail {

namespace {

class WideBuilder {
 public:
  explicit WideBuilder(const KdTree& tree, KdWideTree& out) : tree_(tree), out_(out) {}

  /// The child word of binary node `index` (a leaf word, or a new wide node); `empty` is set for
  /// an empty leaf.
  std::uint32_t childWord(std::uint32_t index, bool& empty) {
    const KdNode& node = tree_.nodes.at(index);
    empty = false;
    if (node.isJump()) throw Error("buildKdWideTree: jump node " + std::to_string(index) + " in a mesh tree");
    if (!node.isLeaf()) return buildNode(index);
    if (node.primCount() == 0) {
      empty = true;
      return 0;
    }
    const std::uint32_t offset = node.primOffset(), blocks = (node.primCount() + 3) / 4;
    if (offset <= KdWideNode::kOffsetMask && blocks <= KdWideNode::kMaxCount)
      return KdWideNode::kLeafBit | blocks << KdWideNode::kOffsetBits | offset;
    const auto big = static_cast<std::uint32_t>(out_.big_leaves.size());
    if (big > KdWideNode::kOffsetMask) throw Error("buildKdWideTree: too many large leaves");
    out_.big_leaves.emplace_back(offset, blocks);
    return KdWideNode::kLeafBit | big;
  }

 private:
  std::uint32_t buildNode(std::uint32_t index) {
    const auto slot = static_cast<std::uint32_t>(out_.nodes.size());
    if (slot >= KdWideNode::kLeafBit) throw Error("buildKdWideTree: too many nodes");
    out_.nodes.emplace_back();
    const KdNode& top = tree_.nodes[index];
    KdWideNode n{};
    n.plane[0] = top.split();
    n.axis16[0] = static_cast<std::uint8_t>(16 * top.axis());
    unsigned mask = 0;
    const std::uint32_t halves[2] = {index + 1, top.upperChild()};
    for (int h = 0; h < 2; ++h) {
      const KdNode& half = tree_.nodes.at(halves[h]);
      std::uint32_t grand[2];
      bool has_lower = true;
      if (!half.isLeaf()) {
        n.plane[1 + h] = half.split();
        n.axis16[1 + h] = static_cast<std::uint8_t>(16 * half.axis());
        grand[0] = halves[h] + 1;
        grand[1] = half.upperChild();
      } else {
        // A leaf half: a plane at -inf whose lower side is empty; the leaf is the upper side.
        n.plane[1 + h] = -std::numeric_limits<float>::infinity();
        has_lower = false;
        grand[0] = grand[1] = halves[h];
      }
      for (int s = 0; s < 2; ++s) {
        if (s == 0 && !has_lower) continue;
        bool empty = false;
        const std::uint32_t word = childWord(grand[s], empty);
        if (empty) continue;
        n.child[2 * h + s] = word;
        mask |= 1u << (2 * h + s);
      }
    }
    n.child_mask = static_cast<std::uint8_t>(mask);
    out_.nodes[slot] = n;
    return slot;
  }

  const KdTree& tree_;
  KdWideTree& out_;
};

}  // namespace

KdWideTree buildKdWideTree(const KdTree& block_tree) {
  KdWideTree out;
  out.bounds = block_tree.bounds;
  if (block_tree.nodes.empty()) return out;
  out.nodes.reserve(block_tree.nodes.size() / 3 + 1);
  WideBuilder builder(block_tree, out);
  bool empty = false;
  const std::uint32_t root = builder.childWord(0, empty);
  out.root_word = empty ? KdWideTree::kEmptyRoot : root;
  return out;
}

}  // namespace duplex::detail
