#pragma once
/// \file VolumeObject.h
/// The OpenVDB volume object type: a float grid that is either a level-set surface or a fog
/// (density) medium. Its bottom-level structure is the VDB tree itself, walked with a
/// hierarchical DDA over active tiles and leaves (empty space is skipped).
///
/// OpenVDB stays out of this header: grids made in memory come in through
/// VolumeObjectVdb.h (which includes OpenVDB), files through load().
///
/// Spaces: index space is the grid's voxel lattice (voxel ijk centred at integer ijk); object space
/// is the grid's world space (the grid transform maps index to object space); the instance
/// transform is applied by the top level. Queries map the ray to index space without
/// renormalising its direction, so t means the same in object and index space.

#include "duplex/accel/Object.h"
#include "duplex/objects/VolumeQueryConfig.h"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <ostream>
#include <string>
#include <string_view>

namespace duplex {

/// What the grid's values mean.
enum class VolumeKind : std::uint8_t {
  /// From the grid class: level set when the grid says so (GRID_LEVEL_SET), fog otherwise.
  Auto,
  /// Signed distance (negative inside): role Surface, hits at the first zero crossing.
  LevelSet,
  /// Density (extinction per object-space unit length): role Medium, answered by transmittance().
  Fog,
};

/// "auto", "levelset" or "fog".
[[nodiscard]] std::string_view toString(VolumeKind kind);
/// Writes toString(kind).
std::ostream& operator<<(std::ostream& os, VolumeKind kind);

/// Options of VolumeObject::load.
struct VolumeLoadOptions {
  /// Name of the float grid to read; empty: the first float grid in OpenVDB's listing of the file
  /// (by grid name, not the order the grids were written in).
  std::string grid;
  /// Auto: from the grid class.
  VolumeKind kind = VolumeKind::Auto;
  /// The object's name; empty: "<file stem>:<grid name>".
  std::string name;
  /// How queries are answered (validated as by VolumeObject::withConfig).
  VolumeQueryConfig query;
};

/// Immutable after construction; instances share it; all queries are thread-safe (each thread's
/// OpenVDB accessor and scratch lists live in its QueryContext, see QueryContext::cached).
class VolumeObject final : public Object {
 public:
  /// The registered type name.
  static constexpr std::string_view kTypeName = "volume";

  /// Reads a float grid from a .vdb file (fully, no delayed loading: a truncated file fails here,
  /// not in a query). The file's structure (header, metadata, grid descriptors and every grid's
  /// extent) is checked against the file size before OpenVDB reads any grid data, so a truncated
  /// file is refused up front (OpenVDB 10 itself trusts block lengths it reads from a short
  /// stream). Throws FileError naming the file (and grid) for a missing, unreadable, truncated or
  /// malformed file, a file without grid offsets (written by io::Stream), a file with no float
  /// grid, or a named grid that is absent or not float; InvalidArgument naming the grid for an
  /// empty grid or a non-linear (frustum) transform, or for an invalid `options.query`.
  [[nodiscard]] static std::shared_ptr<const VolumeObject> load(const std::filesystem::path& file,
                                                                const VolumeLoadOptions& options = {});

  ~VolumeObject() override;

  [[nodiscard]] std::string_view typeName() const override { return kTypeName; }
  /// Object-space bounds of the active voxels (each voxel a unit cube around its centre in index
  /// space; level sets get one more voxel of margin for the interpolated surface).
  [[nodiscard]] Box bounds() const override;
  /// XXH64 over what the queries answer from: the kind, the grid's index-to-object transform and
  /// background, every value of the tree, active or not (tiles with their coordinates, levels and
  /// states; each leaf's origin, value mask and values), and the query options. Linear in the
  /// tree's size (a sensor run's state file fingerprints its scene with it, once per run, so a
  /// changed grid is refused on --resume).
  [[nodiscard]] std::uint64_t contentHash() const override;
  /// "active_voxels": activeVoxelCount().
  [[nodiscard]] std::vector<ObjectFigure> figures() const override;

  /// Level sets: the first zero crossing of the trilinearly interpolated distance along
  /// [tnear, min(tfar, hit.t)], found by stepping half a voxel through the active spans of the
  /// tree and refining by bisection. A ray starting inside finds its exit. On a hit: t (object
  /// space units of the ray's direction), prim_id = 0, u = v = 0, ng = unit object-space normal
  /// from the distance gradient (pointing outwards, towards positive distance).
  /// Fog: never hits.
  bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const override;
  [[nodiscard]] bool occluded(const Ray& ray_os, QueryContext& ctx) const override;
  /// Level sets: every zero crossing in [tnear, tfar] (entries and exits). Fog: none.
  void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const override;
  /// Fog: exp(-optical depth) along [tnear, tfar] of the piecewise-constant density (each active
  /// voxel the unit cube around its centre in index space; extinction per object-space unit
  /// length, lengths measured in object space: |dir_os| per unit t), by config().transmittance:
  /// exact by default; stochastic methods seed from a hash of the ray and config().seed, so a
  /// ray's estimate is the same on every thread and run. An infinite tfar is clipped to the
  /// bounds. Level sets: 0 when occluded, else 1.
  [[nodiscard]] float transmittance(const Ray& ray_os, QueryContext& ctx) const override;
  /// Fog: one transmittance estimate by `method` (samples, step and majorant level from config())
  /// from the random stream `seed` (ignored by Exact and RayMarching). Level sets: as above.
  [[nodiscard]] float transmittance(const Ray& ray_os, QueryContext& ctx, FogMethod method, std::uint64_t seed) const;
  /// Fog: a free-flight distance by delta tracking with the node majorants of
  /// config().majorant_level: the t (object-space ray units) of the first real collision in
  /// [tnear, tfar], distributed with density sigma(t) |dir| T(tnear, t); nullopt when the flight
  /// leaves the segment (probability T(tnear, tfar)). Deterministic for a given `seed`.
  /// Level sets: nullopt.
  [[nodiscard]] std::optional<float> sampleFreeFlight(const Ray& ray_os, QueryContext& ctx, std::uint64_t seed) const;
  /// Fog picking: the t where the ray first enters a voxel whose density exceeds `threshold`
  /// (>= tnear, <= tfar), nullopt if none. Nodes whose maximum is at most `threshold` are skipped
  /// whole. Level sets: the first zero crossing, as intersect().
  [[nodiscard]] std::optional<float> firstDensityAbove(const Ray& ray_os, float threshold, QueryContext& ctx) const;

  /// Level sets: the point of the zero crossing (the surface rays hit) nearest to the query point,
  /// in world distance through the instance's transform. The nearest of the points where the
  /// interpolated distance changes sign along a lattice edge (made on the first query and kept)
  /// is refined on the surface until the offset to the query point is normal to it (Newton
  /// projections in index space, tangential steps in world space: any affine instance transform).
  /// prim_id 0, the normal from the distance's gradient. Fog: none (media have no surface).
  bool closestPoint(const PointQuery& query, ClosestPoint& best, QueryContext& ctx) const override;

  /// Bytes of the grid, the fog's density ranges and, once a closest-point query has made them, the
  /// level set's surface points.
  [[nodiscard]] std::size_t memoryBytes() const override;

  /// LevelSet or Fog (never Auto: resolved at construction).
  [[nodiscard]] VolumeKind kind() const;
  /// The grid's name in its file (or as made).
  [[nodiscard]] const std::string& gridName() const;
  /// Object-space size of a voxel along index x (the grid's voxel size; uniform scale assumed for
  /// this figure only, queries handle any linear transform).
  [[nodiscard]] double voxelSize() const;
  /// Active voxels, tiles counted by the voxels they cover.
  [[nodiscard]] std::uint64_t activeVoxelCount() const;
  /// Fog: the largest effective density (0 for level sets).
  [[nodiscard]] float maxDensity() const;

  /// How queries are answered.
  [[nodiscard]] const VolumeQueryConfig& config() const { return config_; }
  /// The same volume (the grid is shared, not copied) answering queries with `config`, under the
  /// same name. Throws InvalidArgument for samples 0, a non-positive or non-finite march_step, a
  /// majorant_level outside [0, 2], levelset_step outside (0, 1] or refine_steps outside [0, 60].
  [[nodiscard]] std::shared_ptr<const VolumeObject> withConfig(const VolumeQueryConfig& config) const;

  /// The OpenVDB side (defined in src/VolumeGrid.h; VolumeObjectVdb.h builds one).
  struct Grid;
  /// Keeps the constructor below to load(), withConfig() and makeVolumeObject().
  struct ConstructTag {};
  /// For load(), withConfig() and makeVolumeObject() only (public for std::make_shared; ConstructTag keeps other
  /// callers out): `grid` as given, `config` already validated.
  VolumeObject(std::string name, ObjectRole role, std::shared_ptr<const Grid> grid, const VolumeQueryConfig& config,
               ConstructTag);
  /// The OpenVDB side (a complete type only in the volume sources).
  [[nodiscard]] const Grid& grid() const { return *grid_; }

 private:
  std::shared_ptr<const Grid> grid_;
  VolumeQueryConfig config_;
};

}  // namespace duplex
