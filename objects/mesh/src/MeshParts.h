#pragma once
// What a MeshObject holds behind its one pointer (MeshObject::parts_): its structure and the leaf
// data its queries walk. Private to objects/mesh/, so that MeshObject.h includes neither the BVH
// nor the kd-tree and a change to their layout recompiles only what uses them.

#include "duplex/accel/KdTree.h"
#include "duplex/accel/WideBvh.h"
#include "MeshBvh.h"
#include "TriangleBlock4.h"

#include <memory>
#include <vector>

namespace duplex::detail {

struct MeshParts {
  WideBvh bvh;  // leaf references index blocks directly (the ranges are block aligned)
  KdTree tree;  // prim_indices hold mesh triangle ids (what tests and tools inspect)
  // Each non-empty leaf's triangles copied into consecutive 4-wide blocks (structure of arrays, in
  // the leaf's reference order, the last block padded), so that a leaf is a few sequential loads
  // and its test needs neither an index list nor a transpose. A triangle referenced by several
  // leaves is copied into each (about 40 bytes per reference).
  std::vector<TriangleBlock4> blocks;
  // What queries traverse: tree's bounds and nodes, with each leaf's offset pointing at its first
  // block instead of into prim_indices (which stays empty), so reaching a leaf's triangles costs no
  // dependent load through an index list.
  KdTree block_tree;
  // The BVH kernels' view of bvh and blocks (BVH structure only), kept for the direct entry
  // (rayEntry) so that an instance visit builds none.
  std::unique_ptr<const MeshBvhView> view;
};

}  // namespace duplex::detail
