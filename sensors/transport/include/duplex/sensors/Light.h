#pragma once
/// \file Light.h
/// Light sources of a sensor run, each with a total power in watts (radiometric; in spectral scenes
/// shared among the bands by `spectrum`).
/// Positions and directions are in world space (scene units; irradiance is reported per square
/// scene unit, W/m^2 when the scene is in metres), or, for a light placed at a scene-graph node
/// (Light::node), in that node's local space: the scene places it (placeLight) at every commit.

#include "duplex/accel/Affine.h"
#include "duplex/scenegraph/NodeId.h"
#include "duplex/sensors/CieSky.h"
#include "duplex/sensors/IesProfile.h"

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include <array>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace duplex {

/// Kinds of light source.
enum class LightType : std::uint8_t {
  Point,        ///< isotropic point: intensity P / (4 pi) W/sr in every direction
  Spot,         ///< point emitting uniformly into a cone of half-angle cone_angle about direction
  Directional,  ///< parallel rays along direction, uniform over a disk of `radius` centred at position
  /// Lambertian rectangle (local z = 0, width x height centred at the origin), the disk inscribed in
  /// it, or a polygon of that plane (Light::polygon); emits towards +z
  Area,
  /// Point with a goniometric intensity table (IES LM-63): intensity P * profile(d_lf) / integral,
  /// d_lf the direction in the luminaire frame (world_from_light's rotation; nadir = local -z).
  Goniometric,
  /// A CIE standard sky (Light::sky) lighting the sphere of `radius` about `position` from every
  /// direction above the horizon (+z up): rays enter from a disk of that radius across their
  /// direction, upstream of the sphere, so that every point inside it receives the sky's radiance
  /// L_z relativeLuminance from every unobstructed direction. power_w = L_z radianceIntegral pi r^2.
  Sky,
};

/// One light. Only the fields of its type are used; validate() checks them.
struct Light {
  LightType type = LightType::Point;     ///< kind of light (which fields below apply)
  std::string name;                      ///< for messages (the scene file's "name", or "lights/<k>")
  double power_w = 1.0;                  ///< total emitted power, > 0
  glm::dvec3 position{0.0};              ///< Point, Spot; Directional: the centre of its disk; Sky: of its sphere
  glm::dvec3 direction{0.0, 0.0, -1.0};  ///< Spot (cone axis), Directional (ray direction); any length > 0
  double cone_angle = 0.5;               ///< Spot: half-angle in radians, in (0, pi]
  double radius = 1.0;                   ///< Directional: disk radius; Sky: the lit sphere's radius; > 0
  double width = 1.0;                    ///< Area: along local x, > 0
  double height = 1.0;                   ///< Area: along local y, > 0
  Affine world_from_light;  ///< Area: placement of the local rectangle; Goniometric: its rotation orients the luminaire
  std::shared_ptr<const IesProfile> profile;  ///< Goniometric: the intensity table (its shape; power_w scales it)
  std::shared_ptr<const CieSky> sky;          ///< Sky: the luminance distribution (its shape; power_w scales it)
  bool two_sided = false;                     ///< Area: also emits towards -z (half the power each side)
  /// Area: the disk of radius width / 2 (width == height) inscribed in the rectangle instead of the
  /// rectangle itself (a scene file's "disk" light).
  bool disk = false;
  /// Area: a polygon of the local z = 0 plane (x, y in local units; at least 3 vertices, simple,
  /// either winding, convex or not) instead of the rectangle (a scene file's "polygon" light);
  /// empty: the rectangle or disk. Set with setPolygon, which also fills the two members below.
  std::vector<glm::dvec2> polygon;
  /// Area polygons: the triangles that cover the polygon (indices into `polygon`) ...
  std::vector<std::array<std::uint32_t, 3>> polygon_triangles;
  /// ... and their cumulative share of its area (the last is 1), for sampling by area; for an
  /// emissive mesh, the triangles' cumulative share of the mesh's area.
  std::vector<double> polygon_cdf;
  /// Area: the triangles of an emissive mesh (light-local space; each emits from its front face,
  /// the side of cross(b - a, c - a)) instead of the rectangle (a scene file's "mesh" light); set
  /// with setTriangles.
  std::vector<std::array<glm::dvec3, 3>> triangles;
  /// Spectral scenes: relative power per band (>= 0, not all 0; normalised by the scene); empty:
  /// the power is shared equally among the bands. Its length must be the scene's band count.
  std::vector<double> spectrum;
  /// The scene-graph node the light is attached to (kInvalidNode: none, world space). Its position,
  /// direction and transform are then in the node's local space and follow the node's world
  /// transform (moves, rotations, scales, re-parenting); the light is off while the node is hidden.
  NodeId node = kInvalidNode;
  /// > 0: the light was given in lumens (luminous flux), and the scene sets power_w from it: by the
  /// luminous efficacy of its spectrum when the bands have wavelengths, else power_w = lumens (a
  /// scene whose lights are all in lumens and whose bands have no wavelengths transports luminous
  /// flux directly). 0: given in watts.
  double lumens = 0.0;

  /// Throws InvalidArgument naming the light for non-finite values, power <= 0, a zero direction,
  /// a cone angle outside (0, pi], or a non-positive size or radius, or a singular transform; a
  /// goniometric light without a profile or whose transform's linear part is not a rotation, a
  /// spectrum with a negative or non-finite entry or without a positive one, lumens negative or
  /// not finite.
  void validate() const;
  /// Makes the light a polygon area light of `vertices` (local x, y): triangulates it (ear
  /// clipping) and sets width and height to the origin-centred box that holds it (what the
  /// rectangle's corners stand for in outward checks). Throws InvalidArgument naming the light for
  /// fewer than 3 vertices, a non-finite one, edges that cross or touch other than at their shared
  /// vertex, or a zero area.
  void setPolygon(std::vector<glm::dvec2> vertices);
  /// Makes the light an emissive mesh of `tris` (light-local space): keeps each triangle's
  /// cumulative share of the area in polygon_cdf, and sets width = height to twice the largest
  /// vertex coordinate (what the rectangle's corners stand for in outward checks). Throws
  /// InvalidArgument naming the light for no triangles, a non-finite vertex or a zero area.
  void setTriangles(std::vector<std::array<glm::dvec3, 3>> tris);
  /// Area: the emitting area in local units (the rectangle, the inscribed disk or the polygon);
  /// the transform scales it.
  [[nodiscard]] double localArea() const;
  /// Radiant intensity (W/sr) of a Point, Spot or Goniometric light towards world direction
  /// `dir_ws` (any length); 0 outside a spot's cone. For analytic checks.
  [[nodiscard]] double intensity(const glm::dvec3& dir_ws) const;
};

/// `light` (its geometry in a node's local space) placed by that node's world transform
/// `world_from_node`: positions map as points, directions as vectors, an area light's rectangle
/// through the whole transform (its size scales with it); a directional light's radius and a
/// goniometric light's orientation take the similarity's scale out (a goniometric light keeps its
/// table's solid angles). Throws InvalidArgument naming the light when a directional or
/// goniometric light's node transform is not a similarity (rotation and uniform scale), or the
/// placed light is invalid (validate()). The result's node is kept.
[[nodiscard]] Light placeLight(const Light& light, const Affine& world_from_node);

/// One emitted ray: world-space origin and unit direction.
struct EmittedRay {
  glm::dvec3 origin{0.0};         ///< world space, scene units
  glm::dvec3 dir{0.0, 0.0, 1.0};  ///< world space, unit length
  /// Power of this ray relative to the light's mean ray power (1 for all but goniometric lights and
  /// skies, whose directions are importance-sampled from a table with weights of mean 1).
  double weight = 1.0;
  /// Emissive meshes: the world unit normal of the front face of the triangle the ray leaves
  /// (before a two-sided light picks a face); zero for other lights.
  glm::dvec3 normal{0.0};
};

/// Samples a ray leaving `light` from four uniform numbers in [0, 1) (power-proportional over the
/// light's emission: every ray of a light carries the same power).
[[nodiscard]] EmittedRay sampleLight(const Light& light, const double u[4]);

}  // namespace duplex
