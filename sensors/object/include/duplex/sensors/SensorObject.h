#pragma once
/// \file SensorObject.h
/// A light sensor: a flat rectangle or disk (or a sphere) with a grid of bins that never blocks or changes a ray
/// and reports every crossing (ObjectRole::Crossing). Crossings are found by the top level's
/// crossing query (TopLevel::intersectWithCrossings) and turned into deposited power by SensorRun.
///
/// Geometry (object space, the scene file's convention): the sensor lies in the plane
/// z = 0, centred at the origin, normal +z; width w along x, height h along y (a disk has diameter
/// w = h). Bins form an nx x ny grid over [-w/2, w/2] x [-h/2, h/2]; bin (0, 0) is at (-w/2, -h/2),
/// bin index = iy * nx + ix (x fastest).
///
/// Edge rules (documented in docs/sensors.md, tested in SensorObjectTest):
/// - The border is closed: a crossing exactly on the border counts (x = +-w/2 or y = +-h/2; for a
///   disk x^2 + y^2 <= r^2).
/// - A crossing on an inner bin edge goes to the bin above it (ix = floor((x + w/2) * nx / w));
///   a crossing on the upper border goes to the last bin.
/// - A ray parallel to the plane (dir.z == 0 in object space), including one lying in it, never
///   crosses.
/// - A one-sided sensor records rays that arrive at its front face (travelling against the normal,
///   dir.z < 0); a two-sided sensor records both directions.
///
/// Sphere sensors (flux through a sphere, by direction): the sphere of diameter w = h centred at
/// the origin. Bins are equal-area cells of the outward normal n at the crossing point: nx azimuth
/// steps of phi = atan2(n.y, n.x) in [0, 360) degrees from +x towards +y, times ny steps of n.z in
/// [-1, 1] (equal steps of z cut equal areas, Archimedes); bin index iy * nx + ix. Every crossing
/// of the ray's line in [tnear, tfar] counts (up to two: in and out); a one-sided sphere records
/// the rays entering it (travelling against the outward normal), a two-sided sphere both. A ray
/// tangent to the sphere (one touching point) does not cross it. Instances must be similarities
/// (rotation and uniform scale: SensorScene checks), and spheres take no angular bins.
///
/// Far-field sensors (SensorShape::FarField) have no geometry and are never placed in a scene
/// graph: a sensor run bins the direction of every ray that leaves the scene (SensorScene.h). Bins
/// form an IES type C grid of nx = n_c C-planes times ny = n_gamma vertical angles, bin index
/// ic * n_gamma + ig (gamma fastest), in the sensor's frame: C = atan2(y, x) from local +x towards
/// +y, gamma the angle from local -z (the nadir). The grid's angles are C_c = c 360 / n_c and
/// gamma_g = g 180 / (n_gamma - 1), 0 and 180 included; each bin is the cell around its angles,
/// [C_c - dC/2, C_c + dC/2) x [gamma_g - dg/2, gamma_g + dg/2) clipped to [0, 180] (the cells at
/// gamma 0 and 180 are polar caps of half height), an angle on an inner edge in the cell above it.

#include "duplex/accel/Object.h"

#include <glm/vec3.hpp>

#include <cstdint>
#include <string_view>
#include <vector>

namespace duplex {

/// The form of a sensor (see the file comment).
enum class SensorShape : std::uint8_t {
  Rectangle,  ///< w x h rectangle in the plane z = 0
  Disk,       ///< disk of diameter w = h in the plane z = 0
  Sphere,     ///< sphere of diameter w = h, bins by outward normal
  FarField    ///< directions of the rays leaving the scene, on a C-gamma grid (never in a scene graph)
};

/// What a sensor looks like. Lengths in object-space units.
struct SensorSpec {
  SensorShape shape = SensorShape::Rectangle;  ///< rectangle, disk or sphere
  double width = 1.0;                          ///< along x (a disk's or sphere's diameter)
  double height = 1.0;                         ///< along y (a disk or sphere: equal to width)
  std::uint32_t nx = 1;   ///< bins along x (a sphere: azimuth steps; far field: C-planes n_c), >= 1
  std::uint32_t ny = 1;   ///< bins along y (a sphere: steps of n.z; far field: vertical angles n_gamma, >= 2), >= 1
  bool two_sided = true;  ///< records rays arriving at both faces (else only the front face, travelling towards -z)
  /// Optional angular bins of the incoming direction (per sensor, not per spatial bin): 0 = none.
  /// theta: the angle between the incoming direction (towards where the light came from) and the
  /// normal of the face it arrives at, [0, 90] degrees in theta_bins equal steps; phi: its azimuth
  /// in the sensor's frame (from local +x towards +y, [0, 360) degrees) in phi_bins equal steps.
  /// Angular bin index: iphi * theta_bins + itheta (theta fastest); an angle on an inner edge goes
  /// to the bin above it, 90 degrees to the last theta bin.
  std::uint32_t theta_bins = 0;
  std::uint32_t phi_bins = 1;  ///< azimuth bins (>= 1 when theta_bins > 0)

  /// Number of angular bins: theta_bins * phi_bins (0: none).
  [[nodiscard]] std::uint32_t angleBinCount() const { return theta_bins * phi_bins; }
};

/// Where a crossing lands on a sensor (object space).
struct SensorCell {
  std::uint32_t bin = 0;  ///< iy * nx + ix
  float x = 0.0f;         ///< local position of the crossing
  float y = 0.0f;         ///< local y of the crossing (spheres: n.z)
};

/// The sensor object type (ObjectRole::Crossing): see the file comment for its geometry and rules.
class SensorObject final : public Object {
 public:
  /// The registered type name.
  static constexpr std::string_view kTypeName = "sensor";
  /// Throws InvalidArgument (naming `name`) for non-finite or non-positive sizes, zero bins, more
  /// than 2^26 bins, or a disk or sphere whose width and height differ; phi_bins 0 with theta
  /// bins, more than 2^20 angular bins, or angular bins on a sphere.
  SensorObject(std::string name, const SensorSpec& spec);

  [[nodiscard]] std::string_view typeName() const override { return kTypeName; }
  /// Shape, size (object-space units) and bins, as validated.
  [[nodiscard]] const SensorSpec& spec() const { return spec_; }
  /// Number of spatial bins: nx * ny.
  [[nodiscard]] std::uint32_t binCount() const { return spec_.nx * spec_.ny; }
  /// Object-space area of bin `bin` that belongs to the sensor (for a disk, the exact area of the
  /// bin's square inside the circle; zero for bins outside it; a far-field sensor: the cell's
  /// solid angle in sr, dC (cos gamma0 - cos gamma1)). Precondition: bin < binCount()
  /// (not checked: used per deposit).
  [[nodiscard]] double binArea(std::uint32_t bin) const { return bin_area_[bin]; }
  /// Angular bin of an incoming direction given by the cosine of its angle to the crossed face's
  /// normal (sign ignored) and its azimuth phi (radians, any real number); kInvalidId without
  /// angular bins.
  [[nodiscard]] std::uint32_t angleBinAt(double cos_theta, double phi) const;
  /// Solid angle (sr) of angular bin `bin` on one face: (cos theta0 - cos theta1) (phi1 - phi0).
  [[nodiscard]] double angleBinSolidAngle(std::uint32_t bin) const;
  /// Object-space area of the whole sensor (w h, pi w^2 / 4, or a sphere's pi w^2).
  [[nodiscard]] double area() const;

  /// The flat box [-w/2, w/2] x [-h/2, h/2] x [0, 0]; a sphere's cube [-w/2, w/2]^3.
  [[nodiscard]] Box bounds() const override;
  /// Sensors never block: always false (the top level never asks).
  bool intersect(const Ray& ray_os, Hit& hit, QueryContext& ctx) const override;
  [[nodiscard]] bool occluded(const Ray& ray_os, QueryContext& ctx) const override;
  /// Appends the crossing of `ray_os` with t in [tnear, tfar], if any (at most one): t, u = local
  /// x, v = local y, prim_id = bin, ng = (0, 0, 1). Spheres: up to two crossings in order of t,
  /// u = azimuth phi (radians), v = n.z, ng = the outward normal.
  void intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext& ctx) const override;
  [[nodiscard]] std::size_t memoryBytes() const override;
  /// Rectangles and disks: the rectangle of bounds() (a disk's bounding square), front_only for a
  /// one-sided sensor; spheres: none.
  [[nodiscard]] std::optional<FlatCrossings> flatCrossings() const override;

  /// The crossing test itself: whether `ray_os` crosses the sensor within [tnear, tfar] (with the
  /// side and border rules above); fills t (units of ray_os.dir) and the cell. Spheres: the first
  /// crossing, cell x = azimuth (radians), y = n.z.
  [[nodiscard]] bool cross(const Ray& ray_os, float& t, SensorCell& cell) const;
  /// The bin of local point (x, y), or kInvalidId outside the sensor (border rules above).
  [[nodiscard]] std::uint32_t binAt(double x, double y) const;
  /// Sphere sensors: the bin of a point with outward unit normal n (object space).
  [[nodiscard]] std::uint32_t sphereBinAt(const glm::dvec3& n) const;
  /// Far-field sensors: the bin of direction `d` (the sensor's frame, any length > 0; see the file
  /// comment for the grid); kInvalidId for a zero or non-finite vector.
  [[nodiscard]] std::uint32_t farFieldBinAt(const glm::dvec3& d) const;
  /// Far-field sensors: the C angle (degrees) of C-plane `ic`, ic * 360 / n_c.
  [[nodiscard]] double farFieldC(std::uint32_t ic) const { return ic * 360.0 / spec_.nx; }
  /// Far-field sensors: the vertical angle (degrees from the nadir) of row `ig`, ig * 180 / (n_gamma - 1).
  [[nodiscard]] double farFieldGamma(std::uint32_t ig) const { return ig * 180.0 / (spec_.ny - 1); }

 private:
  SensorSpec spec_;
  std::vector<double> bin_area_;
};

/// Area of the disk of radius r centred at the origin inside the rectangle [x0, x1] x [y0, y1]
/// (exact, closed form). For disk sensors' bin areas; exposed for tests.
[[nodiscard]] double diskRectangleArea(double r, double x0, double x1, double y0, double y1);

}  // namespace duplex
