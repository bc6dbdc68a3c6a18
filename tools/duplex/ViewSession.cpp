#include "ViewSession.h"

#include "DemoCamera.h"
#include "Elapsed.h"

#include <duplex/accel/MemoryLimit.h>
#include <duplex/sensors/SensorObject.h>

#include <glm/geometric.hpp>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <shared_mutex>
#include <sstream>

namespace duplex::cli {

namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

// Rows per strip of a render: bounds the rays and hits held at once (about 100 bytes per pixel)
// for the largest images a request may ask for.
constexpr std::uint32_t kStripPixels = 1u << 20;
// Renderers kept for reuse: as many as frames are traced at once (the server's render pool).
constexpr std::size_t kPooledRenderers = 2;
// Picks count the edges of CAD parts' design, not those of their tessellation (as the demo).
constexpr double kPickFeatureAngleDeg = 30.0;

[[noreturn]] void refuse(const std::string& message) { throw RequestError(message); }

const json& member(const json& obj, const std::string& what, const char* key) {
  if (!obj.is_object()) refuse(what + ": expected a JSON object");
  const auto it = obj.find(key);
  if (it == obj.end()) refuse(what + ": missing \"" + key + "\"");
  return *it;
}

double number(const json& v, const std::string& what) {
  if (!v.is_number()) refuse(what + ": expected a number");
  const double d = v.get<double>();
  if (!std::isfinite(d)) refuse(what + ": not a finite number");
  return d;
}

glm::dvec3 vec3(const json& v, const std::string& what) {
  if (!v.is_array() || v.size() != 3) refuse(what + ": expected an array of 3 numbers");
  return {number(v[0], what + "[0]"), number(v[1], what + "[1]"), number(v[2], what + "[2]")};
}

std::uint32_t imageSide(const json& v, const std::string& what) {
  const double d = number(v, what);
  if (d != std::floor(d) || d < 1.0) refuse(what + ": expected a whole number of pixels >= 1, got " + json(v).dump());
  if (d > kMaxImageSide)
    refuse(what + ": " + json(v).dump() + " pixels is over the limit of " + std::to_string(kMaxImageSide));
  return static_cast<std::uint32_t>(d);
}

json vec(const glm::dvec3& v) { return json::array({v.x, v.y, v.z}); }

json changesJson(const ChangeSet& c) {
  return {{"commit", c.commit},
          {"moved", c.moved.size()},
          {"appeared", c.appeared.size()},
          {"disappeared", c.disappeared.size()},
          {"object_changed", c.object_changed.size()},
          {"mask_changed", c.mask_changed.size()},
          {"objects_changed", c.objects_changed.size()}};
}

const char* kindName(NodeKind k) {
  switch (k) {
    case NodeKind::Group: return "group";
    case NodeKind::Transform: return "transform";
    case NodeKind::Instance: return "instance";
  }
  return "group";
}

// A node and its subtree as they are now, to add again (the inverse of a removal).
struct NodeCopy {
  NodeId id = kInvalidNode;  ///< the node copied (its hit-file id goes to the node that replaces it)
  NodeKind kind = NodeKind::Group;
  std::string name;
  Affine local;
  bool visible = true;
  ObjectId object = kInvalidObject;
  std::uint32_t mask = 0xFFFFFFFFu;
  std::vector<NodeCopy> children;
};

NodeCopy copyNode(const SceneGraph& g, NodeId id) {
  const NodeInfo info = g.node(id);
  NodeCopy c{id, info.kind, std::string(info.name), info.local, info.visible, info.object, info.mask, {}};
  for (const NodeId child : g.children(id)) c.children.push_back(copyNode(g, child));
  return c;
}

// Adds `c` again under `parent`; the new instances take over the hit-file ids of the copied ones.
void addCopy(SceneGraph& g, NodeId parent, const NodeCopy& c, std::vector<std::uint32_t>& hit_ids) {
  NodeId id = kInvalidNode;
  switch (c.kind) {
    case NodeKind::Group: id = g.addGroup(parent, c.name); break;
    case NodeKind::Transform: id = g.addTransform(parent, c.local, c.name); break;
    case NodeKind::Instance: id = g.addInstance(parent, c.object, c.local, c.name, c.mask); break;
  }
  if (!c.visible) g.setVisible(id, false);
  if (c.id < hit_ids.size() && hit_ids[c.id] != kInvalidId) {
    if (id >= hit_ids.size()) hit_ids.resize(id + 1, kInvalidId);
    hit_ids[id] = hit_ids[c.id];
  }
  for (const NodeCopy& child : c.children) addCopy(g, id, child, hit_ids);
}

// The node at `path` now, for an inverse: paths survive a removal and its undo (ids do not).
NodeId nodeAt(const SceneGraph& g, const std::string& path) {
  const auto id = g.find(path);
  if (!id) refuse("cannot undo: no node at path \"" + path + "\" any more");
  return *id;
}

std::string parentPath(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  return slash == 0 || slash == std::string::npos ? "/" : path.substr(0, slash);
}

// What undoes `edit` on the graph as it is before the edit (called just before applying it).
std::function<void(SceneGraph&)> inverseOf(const SceneGraph& g, const SceneEdit& edit,
                                           std::vector<std::uint32_t>& hit_ids) {
  if (edit.kind == SceneEditKind::Deform) {
    std::shared_ptr<const Object> old = g.pendingObject(edit.object);
    return [object = edit.object, old](SceneGraph& graph) { graph.replaceObject(object, old); };
  }
  if (edit.kind == SceneEditKind::AddObject) return [](SceneGraph&) {};  // the library keeps it, unused
  const auto id = g.find(edit.node);
  if (!id) return [](SceneGraph&) {};  // applyEdit refuses it
  const NodeInfo info = g.node(*id);
  const std::string path = edit.node;
  switch (edit.kind) {
    case SceneEditKind::SetTransform:
      return [path, local = info.local](SceneGraph& graph) { graph.setTransform(nodeAt(graph, path), local); };
    case SceneEditKind::SetVisible:
      return [path, v = info.visible](SceneGraph& graph) { graph.setVisible(nodeAt(graph, path), v); };
    case SceneEditKind::SetMask:
      return [path, m = info.mask](SceneGraph& graph) { graph.setMask(nodeAt(graph, path), m); };
    case SceneEditKind::SetObject:
      return [path, o = info.object](SceneGraph& graph) { graph.setObject(nodeAt(graph, path), o); };
    case SceneEditKind::Remove:
      return [parent = parentPath(g.path(*id)), copy = copyNode(g, *id), &hit_ids](SceneGraph& graph) {
        addCopy(graph, nodeAt(graph, parent), copy, hit_ids);
      };
    case SceneEditKind::Add:  // completed after the edit, when the new node's path is known
    case SceneEditKind::Deform:
    case SceneEditKind::AddObject: break;
  }
  return [](SceneGraph&) {};
}

// The sensor results as `duplex sensor` reports them per sensor, with their maps for the page.
json sensorResults(const SensorScene& scene, const SensorRunResults& r) {
  json out = json::array();
  for (std::size_t k = 0; k < r.sensors.size(); ++k) {
    const SensorResult& s = r.sensors[k];
    const auto finite = [](double x) { return std::isfinite(x) ? json(x) : json(nullptr); };
    json j = {{"name", s.name},
              {"total_flux_w", s.total_flux_w},
              {"relative_stderr", finite(s.relative_stderr)},
              {"efficiency", s.efficiency},
              {"bins", {s.nx, s.ny}}};
    const SensorInstance& inst = scene.sensors()[k];
    switch (s.shape) {
      case SensorShape::Rectangle: j["shape"] = "rectangle"; break;
      case SensorShape::Disk: j["shape"] = "disk"; break;
      case SensorShape::Sphere: j["shape"] = "sphere"; break;
      case SensorShape::FarField: j["shape"] = "farfield"; break;
    }
    if (s.shape == SensorShape::FarField) {
      std::vector<double> c_deg, gamma_deg;
      for (std::uint32_t ic = 0; ic < s.nx; ++ic) c_deg.push_back(inst.object->farFieldC(ic));
      for (std::uint32_t ig = 0; ig < s.ny; ++ig) gamma_deg.push_back(inst.object->farFieldGamma(ig));
      j["c_deg"] = c_deg;
      j["gamma_deg"] = gamma_deg;
      j["intensity_w_sr"] = s.irradiance_w_m2;
    } else {
      j["irradiance_w_m2"] = s.irradiance_w_m2;
      j["node"] = inst.node != kInvalidNode ? json(scene.graph().path(inst.node)) : json(nullptr);
      j["size"] = {inst.object->spec().width, inst.object->spec().height};
    }
    out.push_back(std::move(j));
  }
  return out;
}

// False colour of t in [0, 1]: dark blue, cyan, yellow, red (the page's map colours).
std::array<std::uint8_t, 3> falseColour(double t) {
  static constexpr double kStops[4][3] = {{0, 0, 0.3}, {0, 0.8, 1}, {1, 1, 0}, {1, 0.1, 0}};
  const double x = std::clamp(t, 0.0, 0.9999) * 3.0;
  const int i = static_cast<int>(x);
  const double f = x - i;
  std::array<std::uint8_t, 3> c{};
  for (int k = 0; k < 3; ++k)
    c[k] = static_cast<std::uint8_t>(std::lround(255.0 * (kStops[i][k] + (kStops[i + 1][k] - kStops[i][k]) * f)));
  return c;
}

}  // namespace

ViewCamera readCamera(const json& value, const std::string& what) {
  if (!value.is_object())
    refuse(what +
           ": expected a camera object {\"eye\", \"target\", \"up\", \"fov_deg\", "
           "\"width\", \"height\"}");
  const glm::dvec3 eye = vec3(member(value, what, "eye"), what + ".eye");
  const glm::dvec3 target = vec3(member(value, what, "target"), what + ".target");
  const glm::dvec3 up = vec3(member(value, what, "up"), what + ".up");
  const double fov = number(member(value, what, "fov_deg"), what + ".fov_deg");
  ViewCamera c;
  c.width = imageSide(member(value, what, "width"), what + ".width");
  c.height = imageSide(member(value, what, "height"), what + ".height");
  if (!(fov > 0.0 && fov < 180.0)) refuse(what + ".fov_deg: expected degrees in (0, 180), got " + std::to_string(fov));
  const glm::dvec3 view = target - eye;
  const double distance = glm::length(view);
  if (!(distance > 0.0) || !std::isfinite(distance)) refuse(what + ": eye and target coincide");
  // The construction of PinholeCamera::looking_at_box, so that its camera given back as eye,
  // target and up gives the same rays bit for bit (`duplex rays --primary`).
  c.camera.eye = eye;
  c.camera.forward = glm::normalize(target - eye);
  const glm::dvec3 side = glm::cross(c.camera.forward, up);
  if (!(glm::length(side) > 1e-9 * glm::length(up)) || !(glm::length(up) > 0.0))
    refuse(what + ".up: zero or parallel to the view direction");
  c.camera.right = glm::normalize(side);
  c.camera.up = glm::cross(c.camera.right, c.camera.forward);
  c.camera.vertical_fov_deg = fov;
  return c;
}

ViewSession::ViewSession(const std::filesystem::path& scene, int threads)
    : threads_(threads), workers_(std::make_unique<WorkerThreads>(threads)), arena_(&workers_->arena) {
  arena_->execute([&] { scene_.emplace(SensorScene::load(scene)); });
  doc_ = scene_->document();
  deriveSensorScene();
  const InstanceIds ids(*doc_);
  for (const NodeId node : doc_->instances) {
    if (node >= hit_ids_.size()) hit_ids_.resize(static_cast<std::size_t>(node) + 1, kInvalidId);
    hit_ids_[node] = ids.of(node);
  }
  // The picks' feature-edge indices now, so that the first hover over a large part does not wait.
  arena_->execute([&] { scene_->tracer().preparePicking(kPickFeatureAngleDeg); });
}

ViewSession::~ViewSession() {
  {
    std::lock_guard lock(sensor_mutex_);
    if (run_) run_->cancel();
  }
  joinSensorThread();
}

void ViewSession::joinSensorThread() {
  if (sensor_thread_.joinable()) sensor_thread_.join();
}

json ViewSession::scene() const {
  std::shared_lock lock(mutex_);
  const SceneGraph& g = *doc_->graph;
  json nodes = json::array();
  std::vector<NodeId> stack = {kRootNode};
  while (!stack.empty()) {
    const NodeId id = stack.back();
    stack.pop_back();
    const NodeInfo info = g.node(id);
    json children = json::array();
    const std::vector<NodeId> kids = g.children(id);
    for (const NodeId c : kids) children.push_back(g.path(c));
    json n = {{"path", g.path(id)}, {"kind", kindName(info.kind)}, {"children", children}, {"visible", info.visible}};
    if (info.kind == NodeKind::Instance) n["object"] = g.library().name(info.object);
    // Transforms (row-major 3x4) for the page's drags: a move in world space becomes a new local.
    if (info.kind != NodeKind::Group) {
      n["local"] = info.local.toRowMajor3x4();
      n["world"] = g.worldTransform(id).toRowMajor3x4();
    }
    nodes.push_back(std::move(n));
    for (auto it = kids.rbegin(); it != kids.rend(); ++it) stack.push_back(*it);
  }
  json objects = json::array();
  const ObjectLibrary& lib = g.library();
  for (ObjectId id = 0; id < lib.size(); ++id) {
    if (!lib.contains(id)) continue;
    std::size_t triangles = 0, memory = 0;
    if (lib.isBuilt(id)) {
      for (const ObjectFigure& f : lib.get(id)->figures())
        if (f.name == "triangles") triangles = f.value;
      memory = lib.memoryBytes(id);
    }
    objects.push_back({{"name", lib.name(id)},
                       {"type", lib.typeName(id)},
                       {"triangles", triangles},
                       {"memory_bytes", memory},
                       {"built", lib.isBuilt(id)}});
  }
  json out = {{"file", doc_->file.string()}, {"format", doc_->format}, {"nodes", nodes}, {"objects", objects}};
  const Box bounds = visibleWorldBounds(*doc_);
  if (!bounds.empty()) {
    out["bounds"] = {{"min", vec(glm::dvec3(bounds.lo))}, {"max", vec(glm::dvec3(bounds.hi))}};
    // The default view frames the parts as the demo does (flat instances such as a floor left out,
    // 0.7 diagonals away); "rays_camera" is the camera of `duplex rays --primary` for the bounds.
    const auto cameraJson = [](const PinholeCamera& cam, const glm::dvec3& target) {
      return json{{"eye", vec(cam.eye)},
                  {"target", vec(target)},
                  {"up", json::array({0.0, 1.0, 0.0})},
                  {"fov_deg", cam.vertical_fov_deg},
                  {"width", 640},
                  {"height", 400}};
    };
    // A subject much smaller than the scene (a block in a room of sensors) would fill the view
    // alone: then the whole scene is framed, as `duplex rays --primary` does.
    Box subject = demo::subjectBounds(g);
    double distance = 0.7;
    if (glm::length(subject.extent()) < 0.25f * glm::length(bounds.extent())) {
      subject = bounds;
      distance = 1.0;
    }
    out["camera"] = cameraJson(demo::frameCamera(subject, distance), glm::dvec3(subject.center()));
    out["rays_camera"] =
        cameraJson(PinholeCamera::looking_at_box(bounds), 0.5 * (glm::dvec3(bounds.lo) + glm::dvec3(bounds.hi)));
  } else {
    out["bounds"] = nullptr;
    out["camera"] = nullptr;
    out["rays_camera"] = nullptr;
  }
  if (!doc_->edits.empty()) {
    json times = json::array();
    for (const SceneEdit& e : doc_->edits)
      if (times.empty() || times.back().get<double>() != e.time) times.push_back(e.time);
    out["timeline"] = times;
    out["time"] = time_;
  }
  json sensors = json::array();
  try {
    for (const SensorInstance& s : scene_->sensors()) sensors.push_back(s.name);
    out["lights"] = scene_->lights().size();
  } catch (const Error& e) {
    out["sensor_problem"] = e.what();
  }
  out["sensors"] = sensors;
  out["commit"] = g.commitCount();
  out["instances"] = g.instances().size();
  out["memory_bytes"] = lib.memoryBytes();
  out["threads"] = threads_;
  return out;
}

ViewFrame ViewSession::render(const json& body, bool ids) const {
  const ViewCamera cam = readCamera(member(body, "request body", "camera"), "camera");
  const std::uint64_t pixels = static_cast<std::uint64_t>(cam.width) * cam.height;
  requireMemory(pixels * (ids ? 11 : 3) + 100ull * std::min<std::uint64_t>(pixels, kStripPixels),
                "a " + std::to_string(cam.width) + " x " + std::to_string(cam.height) + " render");
  ViewFrame frame;
  frame.image = {cam.width, cam.height, std::vector<std::uint8_t>(pixels * 3)};
  if (ids) frame.ids.resize(pixels * 2);
  std::shared_lock lock(mutex_);
  const SceneGraph& g = *doc_->graph;
  NodeId highlight = kInvalidNode;
  if (body.contains("highlight") && !body["highlight"].is_null()) {
    if (!body["highlight"].is_string()) refuse("highlight: expected a node path (a string) or null");
    const auto id = g.find(body["highlight"].get<std::string>());
    if (!id) refuse("highlight: no node at path " + body["highlight"].dump());
    highlight = *id;
  }
  // "edges" (default true): feature edges and silhouettes drawn as lines.
  bool edges = true;
  if (body.contains("edges") && !body["edges"].is_null()) {
    if (!body["edges"].is_boolean()) refuse("edges: expected true or false");
    edges = body["edges"].get<bool>();
  }
  frame.commit = g.commitCount();
  // "sensors": true draws the last sensor run's maps on the sensors' surfaces.
  std::vector<SensorOverlay> overlays;
  if (body.contains("sensors") && !body["sensors"].is_null()) {
    if (!body["sensors"].is_boolean()) refuse("sensors: expected true or false");
    if (body["sensors"].get<bool>()) {
      std::lock_guard sensor_lock(sensor_mutex_);
      overlays = overlays_;
    }
  }
  // A renderer of the pool: its ray, hit and shading buffers are reused from frame to frame.
  std::unique_ptr<demo::DemoRenderer> taken;
  {
    std::lock_guard pool_lock(pool_mutex_);
    if (!renderers_.empty()) {
      taken = std::move(renderers_.back());
      renderers_.pop_back();
    }
  }
  if (!taken) taken = std::make_unique<demo::DemoRenderer>(scene_->tracer(), demo::RenderSettings{});
  struct GiveBack {
    const ViewSession& session;
    std::unique_ptr<demo::DemoRenderer>& renderer;
    ~GiveBack() {
      std::lock_guard pool_lock(session.pool_mutex_);
      if (session.renderers_.size() < kPooledRenderers) session.renderers_.push_back(std::move(renderer));
    }
  } give_back{*this, taken};
  demo::DemoRenderer& renderer = *taken;
  renderer.setHighlight(highlight);
  renderer.setEdges(edges);
  const std::uint32_t strip_rows = std::max<std::uint32_t>(1, kStripPixels / cam.width);
  for (std::uint32_t r0 = 0; r0 < cam.height; r0 += strip_rows) {
    const std::uint32_t r1 = std::min(cam.height, r0 + strip_rows);
    renderer.setView(cam.camera, cam.width, cam.height, r0, r1);
    demo::FrameStats stats;
    const demo::RgbImage strip = arena_->execute([&] { return renderer.render(stats); });
    frame.trace_ms += stats.traceMs();
    frame.rays += stats.rays();
    std::copy(strip.pixels.begin(), strip.pixels.end(),
              frame.image.pixels.begin() + static_cast<std::ptrdiff_t>(r0) * cam.width * 3);
    if (!overlays.empty()) drawOverlays(overlays, cam, renderer, r0, r1, frame.image);
    if (!ids) continue;
    const std::size_t n = static_cast<std::size_t>(cam.width) * (r1 - r0);
    for (std::size_t p = 0; p < n; ++p) {
      const Hit& h = renderer.hitOfPixel(p);
      const std::size_t out = (static_cast<std::size_t>(r0) * cam.width + p) * 2;
      if (!h.valid()) {
        frame.ids[out] = frame.ids[out + 1] = kInvalidId;
        continue;
      }
      const std::uint32_t id = hitId(h.instance_id);
      frame.ids[out] = id == kInvalidId ? kInvalidId - 1 : id;
      frame.ids[out + 1] = h.prim_id;
    }
  }
  return frame;
}

std::vector<SensorOverlay> sensorOverlays(const SensorScene& scene, const SensorRunResults& r) {
  std::vector<SensorOverlay> out;
  for (std::size_t k = 0; k < r.sensors.size(); ++k) {
    const SensorResult& s = r.sensors[k];
    if (s.shape == SensorShape::FarField) continue;  // no surface: a polar plot on the page
    SensorOverlay o;
    const SensorInstance& inst = scene.sensors()[k];
    o.object_from_world = inst.world_from_object.inverse();
    o.disk = s.shape == SensorShape::Disk;
    if (s.shape == SensorShape::Sphere) o.sphere = inst.object;
    o.width = inst.object->spec().width;
    o.height = inst.object->spec().height;
    o.nx = s.nx;
    o.ny = s.ny;
    o.values = s.irradiance_w_m2;
    o.max = 0.0;
    for (const double v : o.values)
      if (std::isfinite(v)) o.max = std::max(o.max, v);
    if (o.max > 0.0) out.push_back(std::move(o));
  }
  return out;
}

void drawOverlays(const std::vector<SensorOverlay>& overlays, const ViewCamera& cam, const demo::DemoRenderer& renderer,
                  std::uint32_t r0, std::uint32_t r1, demo::RgbImage& image) {
  // Per pixel, the nearest sensor surface the primary ray crosses before its hit (sensors never
  // block rays, so the frame shows what lies behind them): its bin's irradiance in false colour,
  // 75% over the shaded pixel.
  tbb::parallel_for(r0, r1, [&](std::uint32_t y) {
    for (std::uint32_t x = 0; x < cam.width; ++x) {
      const Hit& h = renderer.hitOfPixel(static_cast<std::size_t>(y - r0) * cam.width + x);
      const glm::dvec3 dir = cam.camera.directionAt(x + 0.5, y + 0.5, cam.width, cam.height);
      double best = h.valid() ? static_cast<double>(h.t) : std::numeric_limits<double>::infinity();
      double value = -1.0;
      for (const SensorOverlay& o : overlays) {
        const glm::dvec3 org = o.object_from_world.point(cam.camera.eye);
        const glm::dvec3 d = o.object_from_world.linear * dir;
        if (o.sphere) {
          // The first crossing in front of the eye of the sphere |p| = width / 2 (t in units of the
          // world direction, as the hit's: the object-space ray is its image).
          const double r = 0.5 * o.width, a = glm::dot(d, d), b = glm::dot(org, d);
          const double disc = b * b - a * (glm::dot(org, org) - r * r);
          if (!(disc > 0.0)) continue;
          const double root = std::sqrt(disc), t0 = (-b - root) / a, t1 = (-b + root) / a;
          const double t = t0 > 0.0 ? t0 : t1;
          if (!(t > 0.0 && t < best)) continue;
          const std::uint32_t bin = o.sphere->sphereBinAt(glm::normalize(org + t * d));
          if (bin >= o.values.size()) continue;
          best = t;
          value = o.values[bin] / o.max;
          continue;
        }
        if (!(std::abs(d.z) > 0.0)) continue;
        const double t = -org.z / d.z;
        if (!(t > 0.0 && t < best)) continue;
        const glm::dvec3 p = org + t * d;
        const double u = (p.x + 0.5 * o.width) / o.width, v = (p.y + 0.5 * o.height) / o.height;
        if (!(u >= 0.0 && u < 1.0 && v >= 0.0 && v < 1.0)) continue;
        if (o.disk && (2 * u - 1) * (2 * u - 1) + (2 * v - 1) * (2 * v - 1) > 1.0) continue;
        const auto ix = std::min(o.nx - 1, static_cast<std::uint32_t>(u * o.nx));
        const auto iy = std::min(o.ny - 1, static_cast<std::uint32_t>(v * o.ny));
        best = t;
        value = o.values[static_cast<std::size_t>(iy) * o.nx + ix] / o.max;
      }
      if (value < 0.0) continue;
      const std::array<std::uint8_t, 3> c = falseColour(value);
      std::uint8_t* px = &image.pixels[(static_cast<std::size_t>(y) * cam.width + x) * 3];
      for (int k = 0; k < 3; ++k) px[k] = static_cast<std::uint8_t>((px[k] + 3 * c[k] + 2) / 4);
    }
  });
}

json ViewSession::pick(const json& body) const {
  const ViewCamera cam = readCamera(member(body, "request body", "camera"), "camera");
  const double x = number(member(body, "request body", "x"), "x");
  const double y = number(member(body, "request body", "y"), "y");
  PickOptions options;
  options.feature_angle_deg = kPickFeatureAngleDeg;
  if (body.contains("radius_px")) options.radius_px = number(body["radius_px"], "radius_px");
  if (options.radius_px < 0.0 || options.radius_px > 1000.0)
    refuse("radius_px: expected pixels in [0, 1000], got " + std::to_string(options.radius_px));
  std::shared_lock lock(mutex_);
  const SceneTracer& tracer = scene_->tracer();
  const auto t0 = Clock::now();
  const ElementPick e =
      arena_->execute([&] { return tracer.pickElement(cam.camera, x, y, cam.width, cam.height, options); });
  if (!e.valid()) return {{"path", nullptr}, {"pick_ms", msSince(t0)}};
  // The surface normal: the face under the cursor when it belongs to the picked instance.
  json normal = nullptr;
  const std::vector<SceneHit> under = tracer.pick(cam.camera, x, y, cam.width, cam.height);
  if (!under.empty() && under.front().instance == e.instance) normal = vec(under.front().normal_ws);
  const double ms = msSince(t0);
  json j;
  j["path"] = doc_->graph->path(e.instance);
  switch (e.kind) {
    case PickElement::Vertex:
      j["element"] = "vertex";
      j["vertices"] = {e.vertex};
      break;
    case PickElement::Edge:
      j["element"] = "edge";
      j["vertices"] = {e.edge[0], e.edge[1]};
      break;
    default:
      j["element"] = "face";
      j["vertices"] = json::array();
      break;
  }
  const std::uint32_t id = hitId(e.instance);
  j["instance_id"] = id == kInvalidId ? json(nullptr) : json(id);
  j["prim_id"] = e.prim_id;
  j["point"] = vec(e.point_ws);
  j["normal"] = normal;
  j["distance_px"] = e.distance_px;
  j["distance"] = e.depth;
  j["pick_ms"] = ms;
  return j;
}

void ViewSession::deriveSensorScene() {
  // SensorScene derives its lights and sensors lazily on the first call after a commit: done here,
  // under the exclusive lock, so that readers sharing the lock never derive at the same time.
  try {
    (void)scene_->revision();
  } catch (const Error&) {
    // A scene the commit made invalid for light transport: /api/scene and sensor runs say so.
  }
}

void ViewSession::refuseWhileSensorsRun(const char* what) const {
  if (sensor_running_.load())
    refuse(std::string(what) + ": refused while a sensor run traces the scene (POST /api/sensors/cancel first)");
}

json ViewSession::applyAndCommit(const std::vector<SceneEdit>& edits, std::vector<Inverse>* inverses) {
  SceneGraph& g = *doc_->graph;
  const auto t0 = Clock::now();
  ChangeSet changes;
  try {
    for (const SceneEdit& e : edits) {
      Inverse inv = inverses ? inverseOf(g, e, hit_ids_) : Inverse();
      const std::vector<NodeId> added = applyEdit(*doc_, e);
      if (inverses) {
        if (e.kind == SceneEditKind::Add && !added.empty())
          inv = [path = g.path(added.front())](SceneGraph& graph) { graph.remove(nodeAt(graph, path)); };
        inverses->push_back(std::move(inv));
      }
    }
    changes = arena_->execute([&] { return g.commit(); });
  } catch (const Error& e) {
    g.rollback();
    refuse(e.what());
  }
  const double ms = msSince(t0);
  deriveSensorScene();
  return {{"update_ms", ms}, {"top_update_ms", scene_->tracer().lastUpdateMs()}, {"changes", changesJson(changes)}};
}

json ViewSession::revert(const std::vector<Inverse>& inverses) {
  SceneGraph& g = *doc_->graph;
  const auto t0 = Clock::now();
  ChangeSet changes;
  try {
    for (auto it = inverses.rbegin(); it != inverses.rend(); ++it) (*it)(g);
    changes = arena_->execute([&] { return g.commit(); });
  } catch (const Error& e) {
    g.rollback();
    refuse(e.what());
  }
  deriveSensorScene();
  return {{"update_ms", msSince(t0)},
          {"top_update_ms", scene_->tracer().lastUpdateMs()},
          {"changes", changesJson(changes)}};
}

json ViewSession::edits(const json& body) {
  const json& list = member(body, "request body", "edits");
  if (!list.is_array() || list.empty()) refuse("edits: expected a non-empty array of edits");
  std::unique_lock lock(mutex_);
  refuseWhileSensorsRun("edits");
  std::vector<SceneEdit> parsed;
  try {
    parsed = parseLiveEdits(*doc_, list, "edits", sensorTypeRegistry());
  } catch (const Error& e) {
    refuse(e.what());
  }
  // "group": consecutive commits with the same group id (the steps of one drag) are undone as one.
  std::string group;
  if (body.contains("group")) {
    if (!body["group"].is_string()) refuse("group: expected a string");
    group = body["group"].get<std::string>();
  }
  std::vector<Inverse> inverses;
  json out = applyAndCommit(parsed, &inverses);
  if (!group.empty() && group == undo_group_ && !undo_.empty())
    undo_.back().insert(undo_.back().end(), inverses.begin(), inverses.end());
  else undo_.push_back(std::move(inverses));
  undo_group_ = group;
  out["undo_depth"] = undo_.size();
  return out;
}

json ViewSession::undo() {
  std::unique_lock lock(mutex_);
  refuseWhileSensorsRun("undo");
  if (undo_.empty()) refuse("undo: no edit made through this interface to roll back");
  json out = revert(undo_.back());
  undo_.pop_back();
  undo_group_.clear();
  out["undo_depth"] = undo_.size();
  return out;
}

json ViewSession::time(const json& body) {
  const double t = number(member(body, "request body", "t"), "t");
  if (t < 0.0) refuse("t: expected a time >= 0 (seconds), got " + std::to_string(t));
  std::unique_lock lock(mutex_);
  refuseWhileSensorsRun("time");
  const std::vector<SceneEdit>& edits = doc_->edits;
  std::size_t target = 0;
  while (target < edits.size() && edits[target].time <= t) ++target;
  std::size_t applied = timeline_end_.empty() ? 0 : timeline_end_.back();
  json out = {{"update_ms", 0.0}, {"changes", changesJson(ChangeSet{})}};
  const auto t0 = Clock::now();
  if (target < applied) {
    // Back: the inverses of the groups after t, last first, as one commit.
    std::vector<Inverse> back;
    std::size_t keep = timeline_.size();
    while (keep > 0 && timeline_end_[keep - 1] > target) --keep;
    for (std::size_t k = keep; k < timeline_.size(); ++k)
      back.insert(back.end(), timeline_[k].begin(), timeline_[k].end());
    out = revert(back);
    timeline_.resize(keep);
    timeline_end_.resize(keep);
    applied = timeline_end_.empty() ? 0 : timeline_end_.back();
  }
  // Forward: one commit per group of equal times, as applyEditsUntil (and `duplex sensor --at`) play them.
  while (applied < target) {
    std::size_t end = applied;
    while (end < edits.size() && edits[end].time == edits[applied].time) ++end;
    std::vector<SceneEdit> group(edits.begin() + static_cast<std::ptrdiff_t>(applied),
                                 edits.begin() + static_cast<std::ptrdiff_t>(end));
    std::vector<Inverse> inverses;
    out = applyAndCommit(group, &inverses);
    timeline_.push_back(std::move(inverses));
    timeline_end_.push_back(end);
    applied = end;
  }
  time_ = t;
  out["update_ms"] = msSince(t0);
  out["t"] = t;
  out["edits_applied"] = applied;
  return out;
}

json ViewSession::sensorsRun(const json& body) {
  const double rays = number(member(body, "request body", "rays"), "rays");
  if (rays < 1.0 || rays != std::floor(rays) || rays > 1e12)
    refuse("rays: expected a whole number of rays in [1, 1e12]");
  double seed = 1.0;
  if (body.contains("seed")) seed = number(body["seed"], "seed");
  if (seed < 0.0 || seed != std::floor(seed) || seed > 9007199254740992.0)
    refuse("seed: expected a whole number >= 0 (at most 2^53)");
  std::unique_lock lock(mutex_);  // no commit while the run is made
  std::lock_guard sensor_lock(sensor_mutex_);
  if (sensor_running_.load()) refuse("sensors/run: a run is already in progress");
  try {
    if (scene_->lights().empty()) refuse("sensors/run: the scene has no lights");
    if (scene_->sensors().empty()) refuse("sensors/run: the scene has no sensors");
  } catch (const RequestError&) {
    throw;
  } catch (const Error& e) {
    refuse(std::string("sensors/run: ") + e.what());
  }
  joinSensorThread();
  SensorRunConfig cfg;
  cfg.seed = static_cast<std::uint64_t>(seed);
  cfg.threads = static_cast<unsigned>(threads_);
  try {
    run_ = std::make_unique<SensorRun>(*scene_, cfg);
  } catch (const Error& e) {
    refuse(std::string("sensors/run: ") + e.what());
  }
  sensor_target_ = static_cast<std::uint64_t>(rays);
  sensor_done_ = 0;
  sensor_state_ = "running";
  sensor_error_.clear();
  sensor_results_ = nullptr;
  sensor_cancel_ = false;
  sensor_running_ = true;
  sensor_thread_ = std::thread([this] {
    std::string state, error;
    json results;
    std::vector<SensorOverlay> overlays;
    try {
      // runUntil forgets a cancel() that came before it started: a cancel asked for then is
      // passed on after the first batch.
      const SensorRunStatus status = run_->runUntil(sensor_target_, [this](const SensorProgress& p) {
        sensor_done_ = p.rays_done;
        if (sensor_cancel_.load()) run_->cancel();
      });
      state = status == SensorRunStatus::Cancelled ? "cancelled" : "completed";
      const SensorRunResults r = run_->results();
      results = sensorResults(*scene_, r);
      overlays = sensorOverlays(*scene_, r);
    } catch (const std::exception& e) {
      state = "failed";
      error = e.what();
    }
    std::lock_guard l(sensor_mutex_);
    sensor_state_ = state;
    sensor_error_ = error;
    sensor_results_ = std::move(results);
    overlays_ = std::move(overlays);
    sensor_done_ = run_->raysDone();
    sensor_running_ = false;
  });
  return {{"state", "running"}, {"rays", sensor_target_}, {"seed", cfg.seed}};
}

json ViewSession::sensorsStatus() const {
  std::lock_guard lock(sensor_mutex_);
  const std::uint64_t done = sensor_done_.load();
  json j = {{"state", sensor_state_},
            {"rays_done", done},
            {"rays", sensor_target_},
            {"progress", sensor_target_ ? static_cast<double>(done) / static_cast<double>(sensor_target_) : 0.0}};
  if (!sensor_error_.empty()) j["error"] = sensor_error_;
  j["sensors"] = sensor_results_.is_null() ? json::array() : sensor_results_;
  return j;
}

json ViewSession::sensorsCancel() {
  std::lock_guard lock(sensor_mutex_);
  if (!sensor_running_.load()) refuse("sensors/cancel: no run in progress");
  sensor_cancel_ = true;
  run_->cancel();
  return {{"state", "cancelling"}};
}

}  // namespace duplex::cli
