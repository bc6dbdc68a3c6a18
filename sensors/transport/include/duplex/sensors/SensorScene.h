#pragma once
/// \file SensorScene.h
/// A scene prepared for light transport: the graph and its tracer, the lights, the materials of the
/// objects and the sensor instances (each with its range of global bins).
///
/// Scene files (docs/scene-format.md, docs/sensors.md): beside the graph (either format), the
/// top-level "lights" and "sensors" lists and each object entry's "material". A "sensors" entry
/// becomes an object of type "sensor" named `sensors/<name>` with one instance under the root named
/// `<name>`; in duplex-scene-v1 files sensor objects may also be instanced in the node tree like any
/// object. Every visible instance of a SensorObject is a sensor of the run, named after its
/// instance node. Far-field sensors ("shape": "farfield") are not in the graph: they follow the
/// scene's sensors in sensors(), with node kInvalidNode.
///
/// Scene edits: everything that depends on the graph (the sensors, their world frames and bin
/// areas, the materials of the instances, the scattering media, and the lights placed at nodes) is
/// derived from the graph's last commit, again after every commit that applied edits: each
/// accessor describes the committed graph as it is now, and a SensorRun takes the scene as it is
/// when the run is made (a run refuses to go on once the graph was committed again).

#include "duplex/objects/VolumeObject.h"
#include "duplex/scenegraph/SceneDocument.h"
#include "duplex/scenegraph/SceneGraph.h"
#include "duplex/scenegraph/SceneTracer.h"
#include "duplex/sensors/Light.h"
#include "duplex/sensors/Material.h"
#include "duplex/sensors/SensorObject.h"
#include "duplex/sensors/SensorTypes.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace duplex {
// Held by pointer only: users of its members include duplex/objects/MeshObject.h.
class MeshObject;
}  // namespace duplex

namespace duplex {

/// One sensor instance of a scene.
struct SensorInstance {
  std::string name;                            ///< the instance node's name (unique among the scene's sensors)
  NodeId node = kInvalidNode;                  ///< the sensor's instance node
  std::shared_ptr<const SensorObject> object;  ///< the sensor object (object-space geometry and bins)
  /// The instance's world transform as of the graph's last commit (a far-field sensor: its rotation).
  Affine world_from_object;
  /// World area per object-space area of the sensor plane: |cross(L e_x, L e_y)| for the linear
  /// part L of world_from_object.
  double area_scale = 1.0;
  std::uint32_t first_bin = 0;  ///< offset of its bins in the run's global bin array
  /// Offset of its angular bins in the run's global angular-bin array (SensorScene::angleBinCount).
  std::uint32_t first_angle_bin = 0;
  /// \var frame_x
  /// World-space unit vector along the sensor's local x. With frame_y and normal the sensor's
  /// orthonormal frame, in which angular bins are measured.
  /// \var frame_y
  /// World-space unit vector: cross(normal, frame_x).
  /// \var normal
  /// World-space unit normal of the sensor's +z side (the frame is right-handed).
  glm::dvec3 frame_x{1.0, 0.0, 0.0}, frame_y{0.0, 1.0, 0.0}, normal{0.0, 0.0, 1.0};

  /// World-space area (square scene units) of bin `bin`.
  [[nodiscard]] double binAreaWorld(std::uint32_t bin) const { return object->binArea(bin) * area_scale; }
};

/// A far-field sensor of a scene: not in the graph (it records the rays leaving the scene), oriented
/// by a rotation.
struct FarFieldSensor {
  std::string name;                            ///< unique among the scene's sensors
  std::shared_ptr<const SensorObject> object;  ///< a SensorShape::FarField object (its grid)
  Affine world_from_sensor;                    ///< a rotation (no translation): the sensor's frame in world space
};

/// A fog instance of a scene whose media scatter (SensorScene::scatteringMedia()): light tracing
/// samples free flights through it (VolumeObject::sampleFreeFlight) instead of weighting rays by
/// its transmittance.
struct MediumInstance {
  NodeId node = kInvalidNode;                  ///< the fog's instance node
  std::shared_ptr<const VolumeObject> volume;  ///< the fog volume
  Affine object_from_world;                    ///< inverse of the instance's world transform
  /// \var world_lo
  /// Lower corner of the instance's world-space box.
  /// \var world_hi
  /// Upper corner of the instance's world-space box.
  glm::dvec3 world_lo{0.0}, world_hi{0.0};
  std::uint32_t mask = 0xFFFFFFFFu;  ///< the instance's mask (tested against the run's medium_mask)
  /// Medium (scatters with its albedo and g) or Absorber (a fog without "material": every collision
  /// absorbs, which is pure attenuation in expectation).
  Material material;
};

/// A blocking mesh instance whose material sends rays on (anything but an absorber): what a path
/// restarting from its surface needs to bound the rounding error of the hit (its triangles, in
/// object space, and the transform the top level applies to rays, as it holds it).
struct SurfaceInstance {
  std::shared_ptr<const MeshObject> mesh;  ///< null: the instance is not a mesh (or absorbs)
  Affine world_from_object;                ///< the instance's world transform (last commit)
  Affine object_from_world;                ///< its inverse, as the top level maps world rays
  bool identity = true;                    ///< object space is world space (rays are not transformed)
};

/// Illuminance meters at points: each point with the unit normal of the surface it measures
/// (world space, scene units). A run estimates the irradiance at each point by connecting every
/// emission and every diffuse reflection to it (next-event estimation), not by averaging over an
/// area, so the points may be placed anywhere, also on a surface. With a half-angle, a luminance
/// meter instead: the mean radiance arriving at the point from the directions within half_angle
/// of its normal (its axis of view), the same connections counted without the cosine, over the
/// cone's solid angle 2 pi (1 - cos half_angle).
struct PointMeter {
  std::string name;                 ///< unique among the scene's meters, non-empty
  std::vector<glm::dvec3> points;   ///< world space
  std::vector<glm::dvec3> normals;  ///< world space, unit length, one per point (luminance meters: the axis of view)
  double half_angle = 0.0;          ///< radians: 0 an illuminance meter, in (0, pi / 2] a luminance meter
  /// \var image_width
  /// Pinhole cameras (image_width > 0; made by pinholeMeter): the points are the eye repeated once
  /// per pixel, the normals each pixel's central direction, row by row from the top left. Each
  /// connection to the eye is binned into the one pixel its direction falls in (one shadow ray
  /// per event for the whole image), over that pixel's solid angle: the mean radiance over the
  /// pixel's pyramid, so the pixels tile the field of view. Luminance results (half_angle is 0).
  /// \var image_height
  /// The camera's pixel rows (0: not a camera).
  std::uint32_t image_width = 0, image_height = 0;
  /// \var image_right
  /// The camera's unit right direction (world space; right, up and forward are orthonormal).
  /// \var image_up
  /// The camera's unit up direction (world space).
  /// \var image_forward
  /// The camera's unit viewing direction (world space).
  glm::dvec3 image_right{1.0, 0.0, 0.0}, image_up{0.0, 1.0, 0.0}, image_forward{0.0, 0.0, -1.0};
  /// \var image_tan_x
  /// tan of half the horizontal field of view (the image plane at distance 1).
  /// \var image_tan_y
  /// tan of half the vertical field of view.
  double image_tan_x = 0.0, image_tan_y = 0.0;
  std::vector<double> pixel_solid_angle;  ///< sr, per pixel
};

/// A pinhole camera meter `name` at world point `eye` looking at `target`, `up` the image's up
/// (not parallel to the view), vertical field of view `fov_y` (radians, (0, pi)), width x height
/// square pixels. Throws InvalidArgument naming the meter for non-finite input, eye == target, an
/// up along the view, a field of view outside (0, pi) or a zero pixel count.
[[nodiscard]] PointMeter pinholeMeter(std::string name, const glm::dvec3& eye, const glm::dvec3& target,
                                      const glm::dvec3& up, double fov_y, std::uint32_t width, std::uint32_t height);

/// A scene prepared for light transport (see the file comment): graph and tracer, lights, materials, sensors and
/// scattering media.
class SensorScene {
 public:
  /// Reads `path` (either format) with the object types of `registry` (sensorTypeRegistry(): the
  /// built-in types and the sensor type), plus its lights, sensors and materials. Throws FileError
  /// naming the file and the JSON pointer of the first problem (a light with zero or negative power,
  /// a malformed sensor, an unknown material, ...), and InvalidArgument-derived FileErrors for
  /// duplicate sensor names.
  static SensorScene load(const std::filesystem::path& path, const SceneDocumentOptions& options = {},
                          const ObjectTypeRegistry& registry = sensorTypeRegistry());

  /// A scene over a committed `graph` (kept by reference: it must outlive this scene and must not
  /// be edited while a run traces it; edits committed between runs are followed, see the file
  /// comment). `materials` is indexed by ObjectId; objects beyond its end are absorbers (also
  /// objects added to the library later). `bands` names the spectral bands (empty: one radiometric
  /// band, no per-band output). Lights whose Light::node is set are placed at that node (their
  /// geometry is in its local space). `far_field` lists far-field sensors (SensorShape::FarField
  /// objects with the rotation that orients them and their names), outside the graph. Validates
  /// the lights (InvalidArgument naming the light). A scene without lights can
  /// be made (for picking or inspection), but SensorRun::run refuses it. Throws InvalidArgument
  /// naming the object or light for a reflectance or albedo outside [0, 1] or NaN, an index of
  /// refraction that is not finite and positive, a "medium" material on an object that is not a
  /// fog, a surface material on a fog, a fog that cannot be sampled (a medium of another type) in
  /// a scene whose media scatter, per-band values whose count is not the band count, or empty or
  /// repeated band names.
  ///
  /// Photometry: `band_nm` gives every band its wavelengths [lo, hi] nm (empty: none). Lights given
  /// in lumens (Light::lumens > 0) get their power_w here: lumens over their spectrum's luminous
  /// efficacy (683 lm/W times the band means of V(lambda), cieBandMean) when the bands have
  /// wavelengths, else lumens itself when every light is in lumens (luminous flux is transported
  /// directly). Throws InvalidArgument naming the light for lights in lumens beside lights in watts
  /// without wavelengths, or a light in lumens whose spectrum has no power where V(lambda) > 0; and
  /// for wavelengths not one pair per band or not 0 < lo < hi. `instance_materials` gives instance
  /// nodes materials of their own, which replace their object's (two copies of a part in different
  /// finishes); checked as the objects' materials, named by the node's path.
  SensorScene(SceneGraph& graph, std::vector<Light> lights, std::vector<Material> materials = {},
              std::vector<std::string> bands = {}, std::vector<FarFieldSensor> far_field = {},
              std::vector<std::array<double, 2>> band_nm = {},
              std::vector<std::pair<NodeId, Material>> instance_materials = {});
  /// Moves everything (the graph stays where it is: a loaded scene owns it through its document).
  SensorScene(SensorScene&&) noexcept;
  /// Moves everything, like the move constructor.
  SensorScene& operator=(SensorScene&&) noexcept;
  ~SensorScene();

  // The accessors below describe the graph as of its last commit (re-derived on the first call
  // after a commit that applied edits, SceneGraph::revision); the references they return stay
  // valid until then. They throw InvalidArgument, naming the sensor, light or object, when the
  // committed graph makes an invalid scene (a sphere sensor scaled unevenly, a light's node
  // removed, ...), or has uncommitted edits while it must be derived again.

  /// The lights that shine (those at hidden nodes are off), validated; positions and directions in
  /// world space.
  [[nodiscard]] const std::vector<Light>& lights() const { return current().lights; }
  /// Sum of the lights' power (W).
  [[nodiscard]] double totalPower() const { return current().total_power; }
  /// Sensor instances, sorted by node id, then the far-field sensors in their given order.
  [[nodiscard]] const std::vector<SensorInstance>& sensors() const { return current().sensors; }
  /// The illuminance meters (setMeters), in their given order.
  [[nodiscard]] const std::vector<PointMeter>& meters() const { return meters_; }
  /// The meters' points over all meters.
  [[nodiscard]] std::uint32_t meterPointCount() const { return meter_points_; }
  /// Sets the illuminance meters. Throws InvalidArgument naming the meter for an empty or repeated
  /// name, no points, a point or normal that is not finite, a zero normal (normals are normalised),
  /// normals not one per point, a half-angle outside [0, pi / 2], or more than 2^24 points in all.
  void setMeters(std::vector<PointMeter> meters);
  /// Throws InvalidArgument naming the first material a run with meters cannot connect through:
  /// meters see the lights and diffuse (Lambertian) reflections directly, so a mirror, coating,
  /// dielectric, rough lobe or fog, whose light would reach a meter only along paths a connection
  /// cannot make, is refused rather than silently missed.
  void checkMeterMaterials() const;
  /// Index into sensors() of the sensor with this name, or -1.
  [[nodiscard]] int findSensor(const std::string& name) const;
  /// Total number of bins over all sensors.
  [[nodiscard]] std::uint32_t binCount() const { return current().bin_count; }
  /// Total number of angular bins over all sensors.
  [[nodiscard]] std::uint32_t angleBinCount() const { return current().angle_bin_count; }
  /// Material of instance `node` (absorber when none was given).
  [[nodiscard]] const Material& materialOf(NodeId node) const {
    const Derived& d = current();
    return node < d.material_of_node.size() ? d.material_of_node[node] : kAbsorber;
  }
  /// The mesh of instance `node` and its transforms, or nullptr when the instance is not a mesh
  /// or its material absorbs (no path restarts from it).
  [[nodiscard]] const SurfaceInstance* surfaceOf(NodeId node) const {
    const Derived& d = current();
    return node < d.surface_of_node.size() && d.surface_of_node[node].mesh ? &d.surface_of_node[node] : nullptr;
  }
  /// The graph's revision (SceneGraph::revision: its commits that applied edits) that the accessors
  /// describe, derived now if needed.
  [[nodiscard]] std::uint64_t revision() const { return current().revision; }
  /// Spectral band names (empty: a single radiometric band).
  [[nodiscard]] const std::vector<std::string>& bands() const { return bands_; }
  /// Number of bands transported (1 when the scene has no "bands").
  [[nodiscard]] std::uint32_t bandCount() const {
    return bands_.empty() ? 1u : static_cast<std::uint32_t>(bands_.size());
  }
  /// The bands' wavelengths [lo, hi] nm (empty: the bands have none).
  [[nodiscard]] const std::vector<std::array<double, 2>>& bandWavelengths() const { return band_nm_; }
  /// Whether the run reports photometric quantities: some light was given in lumens, or the bands
  /// have wavelengths.
  [[nodiscard]] bool photometric() const { return photometric_; }
  /// Whether the run reports CIE XYZ and chromaticities: the bands have wavelengths.
  [[nodiscard]] bool colorimetric() const { return !band_nm_.empty(); }
  /// Lumens per transported unit of band `band` (< bandCount()) of a photometric scene: 683 lm/W
  /// times the band's mean V(lambda), or 1 when luminous flux is transported directly.
  [[nodiscard]] double luminousWeight(std::uint32_t band) const { return band_lm_[band]; }
  /// 683 lm/W times the band's means of x-bar, y-bar, z-bar (colorimetric scenes only).
  [[nodiscard]] const glm::dvec3& tristimulusWeight(std::uint32_t band) const { return band_xyz_[band]; }
  /// Cumulative normalised spectrum of light `light` (bandCount() entries, the last 1); `light`
  /// must be < lights().size() (not checked: the run's hot loop).
  [[nodiscard]] const std::vector<double>& bandCdf(std::size_t light) const { return current().band_cdf[light]; }
  /// Whether `linear` is a rotation (or reflection) times a uniform scale, to relative 1e-9: the
  /// transforms a sphere sensor accepts (its bins keep equal areas only under these).
  [[nodiscard]] static bool isSimilarity(const glm::dmat3& linear);
  /// Whether some fog scatters (has a "medium" material); then every fog instance is listed in
  /// scatteringMedia() and transported by free flights, else fogs only attenuate.
  [[nodiscard]] bool scatters() const { return !current().media.empty(); }
  /// The fog instances transported by free flights (empty unless scatters()).
  [[nodiscard]] const std::vector<MediumInstance>& scatteringMedia() const { return current().media; }
  /// The tracer over the graph.
  [[nodiscard]] const SceneTracer& tracer() const { return *tracer_; }
  /// The graph (owned by the document of a loaded scene, else the caller's).
  [[nodiscard]] const SceneGraph& graph() const { return *graph_; }
  /// The document when the scene was loaded from a file, else nullptr.
  [[nodiscard]] const SceneDocument* document() const { return doc_.get(); }
  /// The document, to apply its timed edits (applyEditsUntil) before a run; nullptr when the scene
  /// was not loaded from a file.
  [[nodiscard]] SceneDocument* document() { return doc_.get(); }

 private:
  // What the scene derives from one commit of the graph.
  struct Derived {
    std::uint64_t revision = 0;
    std::vector<Light> lights;
    double total_power = 0.0;
    std::vector<std::vector<double>> band_cdf;
    std::vector<SensorInstance> sensors;
    std::uint32_t bin_count = 0;
    std::uint32_t angle_bin_count = 0;
    std::vector<Material> material_of_node;
    std::vector<SurfaceInstance> surface_of_node;
    std::vector<MediumInstance> media;
  };
  struct Cache;
  static inline const Material kAbsorber{};
  [[nodiscard]] const Derived& current() const;
  [[nodiscard]] std::unique_ptr<Derived> derive() const;
  // Photometric scenes: the bands' luminous and tristimulus weights, the power of lights in lumens.
  void resolvePhotometry();
  std::unique_ptr<SceneDocument> doc_;
  SceneGraph* graph_ = nullptr;
  std::unique_ptr<SceneTracer> tracer_;
  std::vector<Light> given_lights_;  // as given (at a node: in its local space)
  std::vector<Material> materials_;  // by object id
  std::vector<std::string> bands_;
  std::vector<FarFieldSensor> far_field_;
  std::vector<std::array<double, 2>> band_nm_;               // per band [lo, hi] nm, or empty
  std::unordered_map<NodeId, Material> instance_materials_;  // instances' own materials
  bool photometric_ = false;
  std::vector<double> band_lm_;       // per band: lumens per transported unit (photometric scenes)
  std::vector<glm::dvec3> band_xyz_;  // per band: 683 x (mean x-bar, y-bar, z-bar) (colorimetric scenes)
  std::unique_ptr<Cache> cache_;      // the Derived of the last commit (a mutex guards its renewal)
  std::vector<PointMeter> meters_;
  std::uint32_t meter_points_ = 0;
};

}  // namespace duplex
