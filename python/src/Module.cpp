// The `duplex` Python module: duplex.Scene (PyScene.h), duplex.primary_rays / random_rays and
// duplex.run_sensors (PySensors.h). Errors of the library become ValueError (bad arguments and
// input, duplex::InvalidArgument and duplex::Error), OSError (files, duplex::FileError),
// MemoryError (duplex::ResourceError: more than the memory limit, duplex.set_max_memory) and
// duplex.Cancelled, each carrying the library's message.

#include "PyScene.h"
#include "PySensors.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/MemoryLimit.h>
#include <duplex/accel/WorkControl.h>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <glm/geometric.hpp>

#include <array>
#include <cmath>

namespace py = pybind11;
using namespace pybind11::literals;

namespace duplex::python {
namespace {

using Vec = std::array<double, 3>;

// A pinhole camera at `eye` looking at `target`, `up` the image's up direction (world space).
PinholeCamera cameraFrom(const Vec& eye, const Vec& target, const Vec& up, double fov_deg) {
  const glm::dvec3 e(eye[0], eye[1], eye[2]), t(target[0], target[1], target[2]), u(up[0], up[1], up[2]);
  if (!(std::isfinite(fov_deg) && fov_deg > 0.0 && fov_deg < 180.0))
    throw InvalidArgument("fov_deg must be in (0, 180) degrees, got " + std::to_string(fov_deg));
  const glm::dvec3 forward = t - e;
  if (!(glm::length(forward) > 0.0)) throw InvalidArgument("eye and target must differ (and be finite)");
  PinholeCamera c;
  c.eye = e;
  c.forward = glm::normalize(forward);
  const glm::dvec3 right = glm::cross(c.forward, u);
  if (!(glm::length(right) > 1e-12 * glm::length(u)) || !(glm::length(u) > 0.0))
    throw InvalidArgument("up must be a non-zero direction not parallel to target - eye");
  c.right = glm::normalize(right);
  c.up = glm::cross(c.right, c.forward);
  c.vertical_fov_deg = fov_deg;
  return c;
}

RegionMode regionMode(const std::string& mode) {
  if (mode == "touching") return RegionMode::Touching;
  if (mode == "inside") return RegionMode::Inside;
  if (mode == "boxes") return RegionMode::Boxes;
  throw InvalidArgument("mode: expected \"touching\", \"inside\" or \"boxes\", got \"" + mode + "\"");
}

constexpr const char* kModuleDoc = R"doc(Duplex: two-level ray tracing of scenes that change.

A duplex.Scene holds an object library (meshes, OpenVDB volumes, sensors), a scene graph of
groups, transform nodes and instances, and the tracer whose top level follows each commit. Rays,
points and transforms are NumPy arrays in world space; results are dicts of arrays shaped like
the input's leading axes. Every query and build releases the GIL and uses all hardware threads
unless `nthreads` says otherwise.

Errors: ValueError for bad arguments and bad input (the message names the argument, node or
object), OSError for files that cannot be read or are malformed (the message names the file),
MemoryError for an input that needs more memory than duplex.max_memory() (checked before it is
allocated), duplex.Cancelled for work stopped on request.
)doc";

constexpr const char* kSceneDoc = R"doc(An object library, a scene graph and its tracer.

Node ids (what add_group and add_instance return) address nodes in edits. Instance ids number
the instances in the order they entered the scene: a loaded file's first (for scene-json-v1 the
position in "instances", as in the hit files of `duplex trace`), then each add_instance. Hits,
commits, selections and closest points report instance ids; instance_node(id) and
instance_id(node) convert. Edits take effect for queries at the next commit(); a query with
edits pending commits them first (pending="commit", the default), raises naming them ("raise") or
answers from the last commit ("snapshot").
)doc";

constexpr const char* kRaysDoc =
    R"doc(rays: float32 or float64 array (..., 6) [ox, oy, oz, dx, dy, dz] (t from 0 to +inf) or
(..., 8) with tnear, tfar at the end; world space, t in units of the direction (any non-zero
length). Rays are traced in float32 (float64 input is rounded). A ray with a non-finite or zero
direction, or tnear > tfar, misses. nthreads: worker threads (0: all). mask: only instances whose
mask meets it count.)doc";

}  // namespace
}  // namespace duplex::python

// The extension is duplex._duplex inside the package duplex (python/duplex/__init__.py checks the
// interpreter and NumPy before importing it, and adds the Open3D-style RaycastingScene).
PYBIND11_MODULE(_duplex, m) {
  using namespace duplex;
  using namespace duplex::python;
  // Classes take their __module__ from the module's name when they are created: name them after
  // the package that re-exports them, so that help(), repr() and pickling say duplex.Scene.
  const py::object extension_name = m.attr("__name__");
  m.attr("__name__") = "duplex";
  m.doc() = kModuleDoc;
  m.attr("INVALID_ID") = py::int_(kInvalidId);
  m.attr("__version__") = "0.1.0";

  static py::exception<Cancelled> cancelled(m, "Cancelled", PyExc_RuntimeError);
  cancelled.doc() = "Raised when long work (a build, a query, a run) was stopped on request.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ResourceError& e) {  // more memory than duplex.max_memory()
      PyErr_SetString(PyExc_MemoryError, e.what());
    } catch (const FileError& e) {
      PyErr_SetString(PyExc_OSError, e.what());
    } catch (const Error& e) {  // InvalidArgument and the other bad-input errors
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const Cancelled& e) {
      PyErr_SetString(cancelled.ptr(), e.what());
    }
  });

  py::class_<PyScene> scene(m, "Scene", kSceneDoc);
  scene.def(py::init([](const std::string& pending) { return std::make_unique<PyScene>(pendingPolicy(pending)); }),
            "pending"_a = "commit",
            R"doc(An empty scene (the root group only). pending: what a query does while edits wait
for a commit: "commit" (default: commit them first, as commit() would; its change lists are not
reported), "raise" (ValueError naming the pending edits) or "snapshot" (answer from the last
commit: for edits made in one thread while others query).)doc");
  scene.def_static(
      "load",
      [](const std::filesystem::path& path, const std::string& structure, const std::string& pending) {
        return PyScene::load(path, structure, pendingPolicy(pending));
      },
      "path"_a, "structure"_a = "", "pending"_a = "commit",
      R"doc(Reads a scene file: scene-json-v1 or duplex-scene-v1 (sensors included; lights and
timed edits are read by run_sensors and the tool, not applied here). Bottom-level structures are
built in parallel, or read from the prepared files the scene names. structure: the choice for
meshes that make none ("bvh", "kdtree", "bvh:fast", ...; "" = the default BVH). Raises OSError
naming the file and the JSON pointer of the first problem.)doc");

  // ---- objects ----
  scene.def("add_mesh", &PyScene::addMesh, "positions"_a, "triangles"_a, "name"_a = py::none(), "structure"_a = "",
            "nthreads"_a = 0,
            R"doc(Adds a triangle mesh to the library and builds its structure; returns its object id.
positions: (N, 3) float32 or float64, object space (stored as float32). triangles: (M, 3) integer
vertex indices. Degenerate triangles keep their index (primitive ids are row numbers of
`triangles`) but are never hit. name: unique in the library (None: "mesh", made unique).
structure: "bvh" (default), "kdtree", "bvh:fast", "bvh:high,leaf=4", ... nthreads: worker
threads of the build (0: all). The object is not hit until add_instance places it.
Raises ValueError for bad shapes, dtypes, indices out of range or no valid triangle.)doc");
  scene.def("load_mesh", &PyScene::loadMesh, "path"_a, "name"_a = py::none(), "structure"_a = "",
            R"doc(Reads a mesh file (OBJ, PLY, STL, OFF, OM: any format of the C++ loader; polygons are
fan-triangulated) and adds it; returns its object id. name: None takes the file's stem. Raises
OSError naming the file.)doc");
  scene.def("load_volume", &PyScene::loadVolume, "path"_a, "grid"_a = py::none(), "kind"_a = py::none(),
            "name"_a = py::none(),
            R"doc(Reads a float grid of an OpenVDB file and adds it; returns its object id. grid: its name
(None: the first float grid). kind: None or "auto" (from the grid class), "levelset" (a surface at
the zero crossing) or "fog" (a medium: attenuates, never blocks cast_rays).)doc");
  scene.def("deform_object", &PyScene::deformObject, "object"_a, "positions"_a,
            R"doc(Moves the vertices of a mesh object (same triangles; (N, 3), object space) at the next
commit: its BVH is refitted (rebuilt when the refit degraded it) and every instance follows.)doc");
  scene.def("remove_object", &PyScene::removeObject, "object"_a,
            "Removes a library object that no instance uses (ValueError naming the users otherwise).");
  scene.def("object_count", &PyScene::objectCount, "Number of library objects (not removed).");
  scene.def("find_object", &PyScene::findObject, "name"_a, "The object id of `name`, or None.");

  // ---- nodes ----
  scene.def("add_group", &PyScene::addGroup, "parent"_a = py::none(), "transform"_a = py::none(), "name"_a = py::none(),
            R"doc(Adds a group under `parent` (a node id; None: the root); returns its node id. With a
transform ((3, 4) or (4, 4), float64, local -> parent space) it is a transform node.)doc");
  scene.def("add_instance", &PyScene::addInstance, "obj"_a, "transform"_a = py::none(), "parent"_a = py::none(),
            "name"_a = py::none(), "mask"_a = 0xFFFFFFFFu,
            R"doc(Adds an instance of library object `obj` under `parent` (None: the root) with its
object -> parent transform ((3, 4) or (4, 4); None: identity) and a 32-bit mask; returns its node
id: node ids address edits; hits, commits and closest points report the instance id, which
instance_id(node) gives (the next number: the instances in the order they were added).)doc");
  scene.def("set_transform", &PyScene::setTransform, "node"_a, "T"_a,
            "Sets a node's local transform T: (3, 4) or (4, 4), object (local) -> parent space, float64.");
  scene.def("set_visible", &PyScene::setVisible, "node"_a, "flag"_a,
            "Shows or hides a node (hidden: it and its subtree are never hit).");
  scene.def("set_mask", &PyScene::setMask, "node"_a, "mask"_a, "Sets an instance's 32-bit mask.");
  scene.def("remove", &PyScene::remove, "node"_a,
            "Removes a node and its subtree (its instances keep their ids, never hit again).");
  scene.def("commit", &PyScene::commit,
            R"doc(Applies the edits since the last commit to the tracer (the top level is updated
where they touch it). Returns a dict of instance-id arrays: "appeared", "disappeared", "moved",
"object_changed", "mask_changed"; "objects_changed" (library ids with new geometry) and "commit"
(the commit's number).)doc");
  scene.def("rollback", &PyScene::rollback, "Undoes every edit since the last commit.");

  // ---- queries ----
  scene.def("cast_rays", &PyScene::castRays, "rays"_a, "nthreads"_a = 0, "mask"_a = 0xFFFFFFFFu,
            (std::string("Closest hits. ") + kRaysDoc + R"doc(

Returns a dict of arrays shaped like rays[..., 0]: "t_hit" (float32, +inf on a miss),
"instance_ids" and "primitive_ids" (uint32, duplex.INVALID_ID on a miss), "primitive_uvs" (..., 2:
barycentric u, v of the triangle's second and third vertex), "primitive_normals" (..., 3: unit
world-space geometric normals, 0 on a miss).)doc")
                .c_str());
  scene.def("test_occlusions", &PyScene::testOcclusions, "rays"_a, "nthreads"_a = 0, "mask"_a = 0xFFFFFFFFu,
            (std::string("Whether anything blocks each ray within [tnear, tfar] (bool array shaped like "
                         "rays[..., 0]). ") +
             kRaysDoc)
                .c_str());
  scene.def("list_intersections", &PyScene::listIntersections, "rays"_a, "nthreads"_a = 0, "mask"_a = 0xFFFFFFFFu,
            (std::string("Every hit along each ray, sorted by t per ray (sensors too when the mask selects "
                         "them). ") +
             kRaysDoc + R"doc(

Returns a dict: "ray_splits" (int64, num_rays + 1: the hits of ray i are [ray_splits[i],
ray_splits[i + 1])), "ray_ids" (int64), "t_hit" (float32), "instance_ids", "primitive_ids"
(uint32), "primitive_uvs" (k, 2); rays in the flattened order of rays[..., 0].)doc")
                .c_str());
  scene.def("compute_closest_points", &PyScene::computeClosestPoints, "points"_a, "max_distance"_a = py::none(),
            "nthreads"_a = 0, "mask"_a = 0xFFFFFFFFu,
            R"doc(The nearest surface point of the visible instances to each query point.
points: (..., 3) float32 or float64, world space. max_distance: None (no limit), a number or an
array broadcasting to points[..., 0] (world units, inclusive). Meshes answer with their triangles,
level sets with their zero crossing; fog volumes and sensors are not surfaces and are ignored.
Returns a dict: "points" (..., 3 float64), "distances" (float64, +inf when nothing is within
reach), "instance_ids", "primitive_ids" (uint32, duplex.INVALID_ID when none), "primitive_normals"
(..., 3 float64, unit, world space), "primitive_uvs" (..., 2 float64: the point's barycentric (u, v)
on its triangle, point = (1 - u - v) a + u b + v c; 0 for level sets and misses).)doc");
  scene.def(
      "pick",
      [](const PyScene& s, const Vec& eye, const Vec& target, const Vec& up, double fov_deg, std::uint32_t width,
         std::uint32_t height, double x, double y,
         std::uint32_t mask) { return s.pick(cameraFrom(eye, target, up, fov_deg), width, height, x, y, mask); },
      "eye"_a, "target"_a, "up"_a, "fov_deg"_a, "width"_a, "height"_a, "x"_a, "y"_a, "mask"_a = 0xFFFFFFFFu,
      R"doc(The surface under pixel (x, y) of a width x height image seen from `eye` looking at
`target` (world space) with `up` and a vertical field of view of fov_deg degrees. x, y are
continuous pixel coordinates: (0, 0) the top-left corner, (width, height) the bottom-right; the
centre of pixel (i, j) is (i + 0.5, j + 0.5). The ray is traced in double precision.
Returns a dict: "hit" (bool), "t" (distance along the unit view ray), "instance_id", "node",
"node_path" (node ids from below the root down to the instance), "path" (the node's path of
names), "primitive_id", "uv", "point" and "normal" (float64 (3,), world space; NaN on a miss).)doc");
  scene.def(
      "pick_element",
      [](const PyScene& s, const Vec& eye, const Vec& target, const Vec& up, double fov_deg, std::uint32_t width,
         std::uint32_t height, double x, double y, double radius_px, bool vertices, bool edges, bool faces,
         double feature_angle_deg, std::uint32_t mask) {
        PickOptions o;
        o.radius_px = radius_px;
        o.vertices = vertices;
        o.edges = edges;
        o.faces = faces;
        o.feature_angle_deg = feature_angle_deg;
        o.mask = mask;
        return s.pickElement(cameraFrom(eye, target, up, fov_deg), width, height, x, y, o);
      },
      "eye"_a, "target"_a, "up"_a, "fov_deg"_a, "width"_a, "height"_a, "x"_a, "y"_a, "radius_px"_a = 5.0,
      "vertices"_a = true, "edges"_a = true, "faces"_a = true, "feature_angle_deg"_a = 0.0, "mask"_a = 0xFFFFFFFFu,
      R"doc(Tolerance picking as CAD applications do it: the visible vertex, else edge, within
radius_px pixels of (x, y), else the face under the cursor (camera and pixels as pick()).
feature_angle_deg > 0 keeps only edges whose faces meet at more than that angle (and boundary
edges). Returns a dict: "kind" ("vertex", "edge", "face" or "none"), "instance_id", "node",
"node_path", "path", "primitive_id", "vertex", "edge" (two vertex indices, ascending), "point"
(float64 (3,), world space), "distance_px", "depth" (world distance from the eye).)doc");
  scene.def(
      "select_rectangle",
      [](const PyScene& s, const Vec& eye, const Vec& target, const Vec& up, double fov_deg, std::uint32_t width,
         std::uint32_t height, double x0, double y0, double x1, double y1, std::uint32_t mask,
         const std::string& mode) {
        return s.selectRectangle(cameraFrom(eye, target, up, fov_deg), width, height, x0, y0, x1, y1, mask,
                                 regionMode(mode));
      },
      "eye"_a, "target"_a, "up"_a, "fov_deg"_a, "width"_a, "height"_a, "x0"_a, "y0"_a, "x1"_a, "y1"_a,
      "mask"_a = 0xFFFFFFFFu, "mode"_a = "touching",
      R"doc(The visible instances selected by the pixel rectangle [x0, x1] x [y0, y1] (camera and
pixels as pick()), as a sorted uint32 array of instance ids. mode: "touching" (some of the
geometry meets the frustum, exact for meshes), "inside" (all of it lies within) or "boxes" (the
world box meets it). Occlusion plays no part.)doc");

  // ---- introspection ----
  scene.def_property_readonly("instances", &PyScene::instances,
                              "Node id of every instance id (uint32 array; removed instances keep their place).");
  scene.def("instance_id", &PyScene::instanceId, "node"_a, "The instance id of an instance node.");
  scene.def("instance_node", &PyScene::instanceNode, "instance_id"_a, "The node id of an instance id.");
  scene.def("find", &PyScene::find, "path"_a, "The node id at a path of names (\"/robot/link_1\"), or None.");
  scene.def("path", &PyScene::path, "node"_a, "The path of names of a node.");
  scene.def("node", &PyScene::node, "node"_a,
            R"doc(A node as a dict: "id", "kind" ("group", "transform", "instance"), "parent", "name",
"path", "transform" (3, 4: local -> parent), "visible", "children"; instances also "object",
"mask", "instance_id", "world_transform" (3, 4: object -> world, as of the last commit).)doc");
  scene.def("bounds", &PyScene::bounds,
            "World box of the visible instances as of the last commit: (2, 3) float64 [min, max], None when empty.");
  scene.def_property_readonly("format", &PyScene::format,
                              "\"scene-json-v1\" or \"duplex-scene-v1\" for a loaded scene, \"\" otherwise.");
  scene.def_property_readonly("file", &PyScene::file, "The scene file it was loaded from (\"\" otherwise).");
  scene.def_property_readonly("pending", &PyScene::pending,
                              "What a query does with uncommitted edits: \"commit\", \"raise\" or \"snapshot\".");
  scene.def("pending_edits", &PyScene::pendingEdits,
            "The edits since the last commit, as calls (\"set_transform(node=3)\", ...; the first 8, then a count).");

  m.def(
      "set_max_memory", [](std::uint64_t bytes) { setMemoryLimit(bytes); }, "bytes"_a,
      R"doc(Sets the memory limit (bytes) that loads and runs are checked against before they
allocate: a scene file, mesh, sensor run or ray array that needs more raises MemoryError naming
it. 0 restores the default: the smaller of the machine's physical memory and the memory limit of
the process's control group (cgroup). The limit is the process's (the C++ library's too).)doc");
  m.def(
      "set_max_memory",
      [](const std::string& size) {
        const std::optional<std::uint64_t> bytes = parseByteSize(size);
        if (!bytes) throw InvalidArgument("set_max_memory: '" + size + "' is no size (e.g. 4G, 512M, 1.5GiB, 1000000)");
        setMemoryLimit(*bytes);
      },
      "size"_a, "The same with a size as text: \"4G\", \"512M\", \"1.5GiB\" (powers of 1024) or plain bytes.");
  m.def("max_memory", &memoryLimit, "The memory limit in bytes (set_max_memory's, or the default).");

  m.def("primary_rays", &PyScene::primaryRays, "scene"_a, "width"_a, "height"_a,
        R"doc(The camera rays of `duplex rays --primary`: the camera at 1.0 x the diagonal of the
visible instances' world box from its centre along normalize(1, 0.6, 0.8), looking at the centre,
up +y, 45 degrees vertical field of view. Returns float32 (height, width, 8) rays [ox, oy, oz, dx,
dy, dz, tnear, tfar], row-major from the top-left pixel, unit directions.)doc");
  m.def("random_rays", &PyScene::randomRays, "scene"_a, "count"_a, "seed"_a,
        R"doc(The rays of `duplex rays --random N --seed X`: origins uniform in the visible
instances' world box, directions uniform on the sphere. Returns float32 (count, 8).)doc");

  // run_sensors and run_lighting: the same run and parameters, two shapes of result.
  const auto runWith = [](bool lighting) {
    return
        [lighting](const std::filesystem::path& scene_file, std::uint64_t rays, std::uint64_t seed, int threads,
                   const py::object& progress, std::optional<std::uint32_t> max_depth, std::uint32_t max_scatterings,
                   double roulette, double target_error, const std::string& target_sensor, const std::string& structure,
                   std::optional<double> at, double failure_threshold, bool per_light) {
          SensorRunOptions o;
          o.at = at;
          o.failure_threshold = failure_threshold;
          o.max_depth = max_depth.value_or(kNoDepthLimit);
          o.max_scatterings = max_scatterings;
          o.roulette_threshold = roulette;
          o.target_error = target_error;
          o.target_sensor = target_sensor;
          o.structure = structure;
          o.per_light = per_light;
          return runScene(scene_file, rays, seed, threads, progress, o, lighting);
        };
  };
  m.def("run_lighting", runWith(true), "scene"_a, "rays"_a = 1000000, "seed"_a = 1, "threads"_a = 0,
        "progress"_a = py::none(), "max_depth"_a = py::none(), "max_scatterings"_a = SensorRunOptions{}.max_scatterings,
        "roulette"_a = SensorRunOptions{}.roulette_threshold, "target_error"_a = 0.0, "target_sensor"_a = "",
        "structure"_a = "", "at"_a = py::none(), "failure_threshold"_a = SensorRunOptions{}.failure_threshold,
        "per_light"_a = false,
        R"doc(The run of run_sensors (same parameters and numbers), returning the sensors and the meters:
{"sensors": what run_sensors returns, "meters": meter name -> dict, and the run's "rays", "seed",
"status", "emitted_power", "energy", "edits_applied", "emitted_luminous_flux" (photometric),
"light_names", "light_emitted_power", "light_emitted_luminous_flux" (per_light)}. A scene may
have meters and no sensors. A meter's dict: "points", "normals" (N, 3), "ray_count" (N); an
illuminance meter "irradiance", "stderr" (W per square scene unit), in photometric scenes
"illuminance", "illuminance_stderr" (lx); a luminance meter ("half_angle" in the scene) instead
"half_angle_deg" (a camera "image_size" (w, h), its pixels row by row from the top left),
"radiance", "radiance_stderr" (W/(m^2 sr)), "luminance", "luminance_stderr" (cd/m^2); with per_light "light_names" and (lights, N) arrays "light_irradiance", "light_stderr",
"light_illuminance" (luminance meters "light_radiance", "light_radiance_stderr",
"light_luminance").)doc");
  m.def("run_sensors", runWith(false), "scene"_a, "rays"_a = 1000000, "seed"_a = 1, "threads"_a = 0,
        "progress"_a = py::none(), "max_depth"_a = py::none(), "max_scatterings"_a = SensorRunOptions{}.max_scatterings,
        "roulette"_a = SensorRunOptions{}.roulette_threshold, "target_error"_a = 0.0, "target_sensor"_a = "",
        "structure"_a = "", "at"_a = py::none(), "failure_threshold"_a = SensorRunOptions{}.failure_threshold,
        "per_light"_a = false,
        R"doc(A light-tracing run of a scene file's lights and sensors, as `duplex sensor` runs it:
the same seed gives the same numbers, for any thread count. progress: None or a callable
(done, total) called from the calling thread between batches of rays; an exception raised in it
(or Ctrl-C) stops the run and is raised again. target_error > 0 stops once the target sensor's
relative standard error is at most it. at: None, or a time (seconds): the scene's timed edits
with time <= at are applied before the run (`duplex sensor --at`); the result's "edits_applied"
counts them, and a UserWarning says how many edits the run leaves out. failure_threshold: a
UserWarning when numerical failures ("energy"'s "failed_w"), or the path limits ("depth_limited_w"),
carry more than this fraction of the emitted power (`duplex sensor --failure-threshold`). max_depth:
None (no cap, unbiased) or the surface interactions after which a path is cut.
Returns a dict sensor name -> dict: "irradiance", "stderr" (W per square scene unit), "flux",
"flux_stderr" (W), "ray_count", "bin_area", each (ny, nx) with bin (0, 0) at local (-w/2, -h/2);
"total_flux", "total_flux_stderr" (W), "relative_stderr" (None before any power arrived),
"efficiency", "shape", "bins" (nx, ny), "two_sided", "node"; with angular bins "angular_flux",
"angular_stderr", "angular_solid_angle", "angular_ray_count" (phi, theta); in spectral scenes
"bands", "band_irradiance", "band_stderr", "band_flux" (band, ny, nx), "band_total_flux",
"band_total_flux_stderr"; and the run's "rays", "seed", "status" ("completed",
"target_reached"), "emitted_power" (W), "energy" (where the power went, W, with the paths that
ended each way: "escaped_rays", ..., "failed_w", "failed_rays"), "edits_applied"; in photometric
scenes (lights in lumens, or bands with wavelengths) "luminous_flux", "luminous_flux_stderr" (lm),
"illuminance", "illuminance_stderr" (lm per square scene unit; far field "intensity_cd",
"intensity_cd_stderr"), "emitted_luminous_flux"; with wavelengths "cie_xyz" (ny, nx, 3),
"chromaticity_xy" (ny, nx, 2; NaN where no light arrived), "total_cie_xyz",
"total_chromaticity_xy", "band_nm".
A far-field sensor ("shape" "farfield", "bins" (n_c, n_gamma)) has instead of the (ny, nx)
arrays "intensity", "intensity_stderr" (W/sr), "flux", "ray_count", "solid_angle" (sr), each
(n_c, n_gamma), and "c_deg", "gamma_deg" (the grid's angles).
per_light: each light's contribution beside the totals, from the same rays: "light_names",
"light_emitted_power" (W) and "light_emitted_luminous_flux" (photometric), (lights, ny, nx)
arrays "light_irradiance", "light_stderr", "light_flux", "light_flux_stderr" (far field
"light_intensity", "light_intensity_stderr"), "light_total_flux", "light_total_flux_stderr",
and where every ray has one luminous weight "light_illuminance", "light_illuminance_stderr" (far
field "light_intensity_cd", ...), "light_luminous_flux", "light_luminous_flux_stderr".)doc");

  m.attr("__name__") = extension_name;
}
