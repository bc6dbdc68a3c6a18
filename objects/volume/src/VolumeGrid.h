#pragma once
// Private to objects/volume/src (includes OpenVDB): the data behind a VolumeObject and the per-thread
// state of its queries, shared by VolumeObject.cpp (construction, files, level sets) and
// VolumeFog.cpp (fog media). Spaces as in VolumeObject.h: times are in units of the object-space
// ray's direction everywhere, index-space rays are never renormalised.

#include "duplex/objects/VolumeObjectVdb.h"

#include "duplex/accel/Box.h"
#include "duplex/accel/QueryContext.h"
#include "duplex/accel/Ray.h"

#include <openvdb/math/DDA.h>
#include <openvdb/math/Ray.h>

#include <array>
#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace duplex {

namespace volume_detail {

namespace vdb = openvdb;

using TreeT = vdb::FloatTree;
using RootT = TreeT::RootNodeType;
using Upper = RootT::ChildNodeType;   // 4096^3 voxels (level 2)
using Lower = Upper::ChildNodeType;   // 128^3 voxels (level 1)
using LeafT = Lower::ChildNodeType;   // 8^3 voxels (level 0)
using RayI = vdb::math::Ray<double>;  // index space, direction not normalised
using TimeSpan = RayI::TimeSpan;
using AccessorT = vdb::tree::ValueAccessor<const TreeT, /*IsSafe=*/false>;
// (min, max) of the effective density of each node, keyed by the node origin >> log2(node size).
// Small nodes (8^3 per level): the keys are already node-coarse, and huge sparse grids must not pay
// for 32^3 upper-node tables per range tree.
using RangeTree = vdb::tree::Tree4<vdb::Vec2s, 3, 3, 3>::Type;
using RangeAccessor = vdb::tree::ValueAccessor<const RangeTree, /*IsSafe=*/false>;

inline constexpr int kLevels = 3;
// log2 of the node size in voxels, per level (leaf, lower internal, upper internal).
inline constexpr int kLog2Size[kLevels] = {static_cast<int>(LeafT::TOTAL), static_cast<int>(Lower::TOTAL),
                                           static_cast<int>(Upper::TOTAL)};

void initializeOpenVdb();

// Points on a level set's zero crossing: where the interpolated distance changes sign along an
// edge of the voxel lattice (exactly on the trilinear surface the rays hit, at most one voxel
// apart), in object space, ordered by the leaves of a small BVH over them.
struct SurfacePoints {
  struct Node {
    Box box;                  // object space
    std::uint32_t first = 0;  // leaf: first point; inner: the right child (the left is next)
    std::uint32_t count = 0;  // points of a leaf; 0 for an inner node
  };
  std::vector<glm::vec3> points_os;
  std::vector<Node> nodes;  // nodes[0] is the root; empty when the grid has no crossing
  [[nodiscard]] std::size_t memoryBytes() const {
    return points_os.size() * sizeof(glm::vec3) + nodes.size() * sizeof(Node);
  }
};

}  // namespace volume_detail

struct VolumeObject::Grid {
  volume_detail::vdb::FloatGrid::ConstPtr grid;
  VolumeKind kind = VolumeKind::Fog;
  std::string grid_name;
  // Continuous index-space box that queries clip rays to (voxel ijk is centred at ijk): the active
  // voxels' cells, plus one voxel for level sets (the interpolated surface reaches that far).
  volume_detail::vdb::Vec3d clip_min_is, clip_max_is;
  Box bounds_os;
  // Fog only: density range of every leaf, lower and upper internal node (the majorants and
  // minorants of delta and ratio tracking). Built once; inactive voxels count as 0.
  std::array<volume_detail::RangeTree::Ptr, volume_detail::kLevels> ranges;
  // Level sets: points of the zero crossing for closest-point queries, made on the first such
  // query (most scenes never ask, and the points cost memory in proportion to the surface).
  mutable std::once_flag surface_once;
  mutable std::shared_ptr<const volume_detail::SurfacePoints> surface;
  mutable std::atomic<std::size_t> surface_bytes{0};  // for memoryBytes(), which may run meanwhile
};

namespace volume_detail {

// The density the fog methods integrate: active voxel values, negatives clamped to 0.
inline float effectiveDensity(float value) { return value > 0.0f ? value : 0.0f; }

// Per-thread state of one volume object, kept in the QueryContext. Holds the grid data so that the
// accessors never outlive their trees, and so that a new object at a dead object's address is
// recognised.
struct ThreadState {
  std::shared_ptr<const VolumeObject::Grid> data;
  AccessorT acc;
  std::array<std::unique_ptr<RangeAccessor>, kLevels> range_acc;
  std::vector<TimeSpan> spans;  // scratch for the HDDA
  explicit ThreadState(const std::shared_ptr<const VolumeObject::Grid>& g) : data(g), acc(g->grid->constTree()) {
    for (int l = 0; l < kLevels; ++l)
      if (g->ranges[l]) range_acc[l] = std::make_unique<RangeAccessor>(*g->ranges[l]);
  }
};

ThreadState& threadState(const void* key, const std::shared_ptr<const VolumeObject::Grid>& g, QueryContext& ctx);

// `ray_os` in index space (origin shifted by `shift` voxels on each axis), clipped to [tmin, tmax]
// and to the clip box. False when nothing is left. Times are unchanged by the mapping.
bool indexRay(const VolumeObject::Grid& g, const Ray& ray_os, double tmin, double tmax, double shift, RayI& out);

// The spans [t0, t1] of `ray` that cross active leaves or tiles, in order.
const std::vector<TimeSpan>& activeSpans(const RayI& ray, ThreadState& s);

}  // namespace volume_detail

}  // namespace duplex
