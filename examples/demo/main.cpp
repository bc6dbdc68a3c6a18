// duplex_demo: the dynamic demo. Loads a scene file (by default examples/scenes/robot_cell.json,
// four CAD robots turning their joints around a conveyor; any duplex-scene-v1 or scene-json-v1
// file, e.g. examples/scenes/car.json), renders it through a SceneTracer before the timed edits,
// plays the edits commit by commit (edits with equal times form one commit), traces every frame,
// picks the vertex, edge or face under a fixed cursor, and renders the final frame. Prints build, per-commit update and
// per-frame trace figures and picks, then one line of JSON.
//   duplex_demo [--scene S.json] [--out PNG] [--before PNG] [--frames DIR] [--width W] [--height H]
//               [--threads N] [--distance F] [--full-rebuild] [--cursor X,Y] [--pick-radius PX]
//               [--feature-angle DEG] [--probe NODE_PATH]...

#include "DemoCamera.h"
#include "DemoRenderer.h"
#include "PngWriter.h"

#include <duplex/accel/Error.h>
#include <duplex/scenegraph/SceneDocument.h>
#include <duplex/scenegraph/SceneTracer.h>
#include <duplex/sensors/SensorTypes.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <glm/geometric.hpp>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using duplex::NodeId;
using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double mraysPerSecond(std::size_t rays, double ms) { return ms > 0.0 ? static_cast<double>(rays) / (ms * 1e3) : 0.0; }

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// Figures rounded for the JSON line (microsecond resolution is plenty for milliseconds).
double round4(double x) { return std::round(x * 1e4) / 1e4; }

// The default scene: beside an installed demo, share/duplex/examples/scenes/robot_cell.json under
// the prefix (found from the executable's own path, so that a moved prefix still works); in the
// build tree, the source tree's copy.
fs::path defaultScene() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path installed =
        exe.parent_path().parent_path() / "share" / "duplex" / "examples" / "scenes" / "robot_cell.json";
    if (fs::is_regular_file(installed, ec)) return installed;
  }
  return DUPLEX_DEMO_SCENE;
}

struct Options {
  fs::path scene = defaultScene();
  fs::path out;     // final frame; default out/<stem>_after.png (out/<stem>.png without edits)
  fs::path before;  // first frame; default beside `out`: <stem>_before.png
  fs::path frames;  // every frame as frame_NNN.png when set
  duplex::demo::RenderSettings render;
  int threads = tbb::info::default_concurrency();
  double distance = 0.7;
  std::vector<std::string> probes;
  std::vector<double> cursor;  // x, y in continuous pixel coordinates; empty: kDefaultCursor of the image
  bool full_rebuild = false;   // rebuild the whole top level after every commit (the paper's method)
  duplex::PickOptions pick;    // the tolerance pick under the cursor
  Options() { pick.feature_angle_deg = 30.0; }  // CAD parts: their design edges, not the tessellation's
};

// The default cursor as fractions of the image width and height: a point right of and above the
// centre, on the middle robot of the robot cell as the demo camera frames it at any image size.
constexpr glm::dvec2 kDefaultCursor{0.52, 0.44};

// One commit of the animation: the edits of one time.
struct CommitFigures {
  double time = 0.0;
  std::size_t edits = 0;
  std::size_t instances_changed = 0;  // moved + appeared + disappeared + object changed
  std::size_t moved = 0, appeared = 0, disappeared = 0, object_changed = 0;
  std::size_t objects_changed = 0;  // library objects with new geometry (deformed)
  double update_ms = 0.0;           // wall time from the first edit call until queries see the new scene
  double tracer_ms = 0.0;           // SceneTracer::lastUpdateMs: the top-level update inside the commit
  bool full_rebuild = false;
};

// A point of the scene picked before and after the edits: the centre of an instance's world box as
// loaded, carried to the end by the motion of the instance's top-level ancestor (the child of the
// root it belongs to, e.g. /car), not by the instance's own motion. With a door as the probe, the
// pick changes from the door to what is behind it once the door has opened, wherever the car drove.
struct Probe {
  std::string path;
  NodeId anchor = duplex::kInvalidNode;
  duplex::Affine anchor_from_world;  // at the start
  glm::dvec3 point_ws{0.0};          // at the start
  std::optional<glm::dvec2> pixel_before, pixel_after;
  std::string hit_before, hit_after;  // node paths of the nearest hits; "" for a miss
};

std::string pickPath(const duplex::SceneTracer& tracer, const duplex::PinholeCamera& camera,
                     const std::optional<glm::dvec2>& pixel, const duplex::demo::RenderSettings& s) {
  if (!pixel) return {};
  const std::vector<duplex::SceneHit> hits = tracer.pick(camera, pixel->x, pixel->y, s.width, s.height);
  return hits.empty() ? std::string() : tracer.graph().path(hits.front().instance);
}

// What lies under the cursor in one frame.
struct CursorPick {
  double time = 0.0;
  std::string path;                     // node path of the instance; "" for a miss
  std::string element;                  // "vertex", "edge" or "face"; "" for a miss
  std::uint32_t prim_id = 0;            // the triangle (a face; for a vertex or an edge, a triangle that has it)
  std::vector<std::uint32_t> vertices;  // a vertex: its index; an edge: its two vertex indices
  double distance_px = 0.0;             // screen distance from the cursor to the element
  double distance = 0.0;                // world distance from the camera to the element
  double ms = 0.0;                      // wall time of the pick
};

// The pick under the cursor: SceneTracer::pickElement's vertex, else edge, within the pick radius,
// else the face under the cursor.
CursorPick pickUnderCursor(const duplex::SceneTracer& tracer, const duplex::PinholeCamera& camera,
                           const glm::dvec2& cursor, const Options& opt, double time) {
  CursorPick pick;
  pick.time = time;
  const auto t0 = Clock::now();
  const duplex::ElementPick e =
      tracer.pickElement(camera, cursor.x, cursor.y, opt.render.width, opt.render.height, opt.pick);
  pick.ms = msSince(t0);
  if (!e.valid()) return pick;
  pick.path = tracer.graph().path(e.instance);
  pick.prim_id = e.prim_id;
  pick.distance_px = e.distance_px;
  pick.distance = e.depth;
  switch (e.kind) {
    case duplex::PickElement::Vertex:
      pick.element = "vertex";
      pick.vertices = {e.vertex};
      break;
    case duplex::PickElement::Edge:
      pick.element = "edge";
      pick.vertices = {e.edge[0], e.edge[1]};
      break;
    default: pick.element = "face"; break;
  }
  return pick;
}

std::string describe(const CursorPick& pick) {
  if (pick.path.empty()) return "(miss)";
  std::string out = pick.path + " " + pick.element + " ";
  if (pick.element == "face") return out + std::to_string(pick.prim_id);
  out += std::to_string(pick.vertices[0]);
  if (pick.vertices.size() == 2) out.append("-").append(std::to_string(pick.vertices[1]));
  return out;
}

Probe startProbe(const duplex::SceneGraph& graph, const std::string& path) {
  const std::optional<NodeId> id = graph.find(path);
  if (!id || graph.node(*id).kind != duplex::NodeKind::Instance)
    throw duplex::InvalidArgument("--probe " + path + ": no instance node with that path in the scene");
  Probe p;
  p.path = path;
  p.anchor = graph.pathIds(*id).front();
  p.anchor_from_world = graph.worldTransform(p.anchor).inverse();
  const duplex::Box box_ws = graph.worldTransform(*id).apply(graph.library().get(graph.node(*id).object)->bounds());
  p.point_ws = glm::dvec3(box_ws.center());
  return p;
}

nlohmann::json pixelJson(const std::optional<glm::dvec2>& px) {
  return px ? nlohmann::json::array({round4(px->x), round4(px->y)}) : nlohmann::json(nullptr);
}

// An "add_object" edit reads its prepared structure only when it is applied, mid-run: check up front
// that the files exist, so that a missing one stops the demo before the first frame with a hint.
void checkPreparedStructures(const duplex::SceneDocument& doc) {
  if (!doc.parsed || !doc.parsed->contains("edits") || !(*doc.parsed)["edits"].is_array()) return;
  for (const nlohmann::json& edit : (*doc.parsed)["edits"]) {
    if (!edit.is_object() || !edit.contains("add_object")) continue;
    const nlohmann::json& entry = edit["add_object"];
    if (!entry.is_object() || !entry.contains("structure") || !entry["structure"].is_string()) continue;
    const fs::path structure = entry["structure"].get<std::string>();
    const std::string extension = structure.extension().string();
    if (extension != ".dbvh" && extension != ".dkdt") continue;  // a structure choice such as "bvh"
    const fs::path file = structure.is_absolute() ? structure : doc.file.parent_path() / structure;
    if (!fs::exists(file))
      throw duplex::FileError(doc.file.string() + ": the prepared structure " + file.string() +
                              " of an add_object edit does not exist; write it with `duplex prepare` (scripts/demo "
                              "prepares the robot cell's spare parts)");
  }
}

fs::path framePath(const fs::path& dir, std::size_t frame) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%03zu.png", frame);
  return dir / name;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CLI::App app{
      "Plays a scene's timed edits through a SceneTracer: renders PNGs before and after them (Lambert "
      "shading, shadow rays) and prints build, update and trace figures, then one JSON line.",
      "duplex_demo"};
  app.add_option("--scene", opt.scene, "Scene file (duplex-scene-v1 or scene-json-v1)")->capture_default_str();
  app.add_option("--out", opt.out,
                 "PNG of the final frame (default out/<scene>_after.png; out/<scene>.png without edits)");
  app.add_option("--before", opt.before,
                 "PNG of the first frame, before the edits (default: <scene>_before.png beside --out)");
  app.add_option("--frames", opt.frames, "Also write every frame to DIR/frame_NNN.png");
  app.add_option("--width", opt.render.width, "Image width in pixels")
      ->check(CLI::Range(1u, 16384u))
      ->capture_default_str();
  app.add_option("--height", opt.render.height, "Image height in pixels")
      ->check(CLI::Range(1u, 16384u))
      ->capture_default_str();
  app.add_option("--threads", opt.threads, "Worker threads (default: all hardware threads)")
      ->check(CLI::Range(1, 4096));
  app.add_option("--distance", opt.distance, "Camera distance in diagonals of the (non-flat) scene as loaded")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_flag("--full-rebuild", opt.full_rebuild,
               "Rebuild the whole top level after every commit (baseline: update time and trace speed)");
  app.add_option("--cursor", opt.cursor,
                 "Pick under this image point every frame: X,Y in pixels from the top-left corner "
                 "(default: 52% of the width, 44% of the height)")
      ->delimiter(',')
      ->expected(2);
  app.add_option("--pick-radius", opt.pick.radius_px,
                 "Pick radius around the cursor in pixels: the nearest visible vertex, else edge, within it, "
                 "else the face under the cursor")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--feature-angle", opt.pick.feature_angle_deg,
                 "Pick only edges whose faces meet at more than this angle (degrees; 0: every edge), and "
                 "vertices at their ends")
      ->check(CLI::Range(0.0, 179.9))
      ->capture_default_str();
  app.add_option("--probe", opt.probes, "Instance node path: pick its centre before and after the edits (repeatable)");
  CLI11_PARSE(app, argc, argv);

  try {
    tbb::global_control thread_limit(tbb::global_control::max_allowed_parallelism,
                                     static_cast<std::size_t>(opt.threads));
    tbb::task_arena arena(opt.threads);

    duplex::SceneDocument doc;
    std::optional<duplex::SceneTracer> tracer;
    double top_build_ms = 0.0;
    arena.execute([&] {
      // Sensor objects of duplex-scene-v1 files are read as by every `duplex` command (they never
      // block a ray, so they do not show in the frames).
      doc = duplex::loadSceneDocument(opt.scene, duplex::sensorTypeRegistry());
      checkPreparedStructures(doc);
      const auto t0 = Clock::now();
      tracer.emplace(*doc.graph);
      top_build_ms = msSince(t0);
      // The tolerance picks' feature-edge indices now, so that the first frame's pick does not
      // build them (its pick_ms would count it).
      tracer->preparePicking(opt.pick.feature_angle_deg);
    });
    duplex::SceneGraph& graph = *doc.graph;
    if (graph.visibleInstances().empty())
      throw duplex::InvalidArgument(opt.scene.string() + ": scene has no visible instances");

    const bool animated = !doc.edits.empty();
    const std::string stem = opt.scene.stem().string();
    if (opt.out.empty()) opt.out = fs::path("out") / (animated ? stem + "_after.png" : stem + ".png");
    if (opt.before.empty()) opt.before = opt.out.parent_path() / (stem + "_before.png");

    const duplex::PinholeCamera camera = duplex::demo::frameCamera(duplex::demo::subjectBounds(graph), opt.distance);
    const glm::dvec2 cursor = opt.cursor.empty() ? kDefaultCursor * glm::dvec2(opt.render.width, opt.render.height)
                                                 : glm::dvec2(opt.cursor[0], opt.cursor[1]);
    if (!std::isfinite(cursor.x) || !std::isfinite(cursor.y))
      throw duplex::InvalidArgument("--cursor: the coordinates must be finite numbers");
    std::vector<Probe> probes;
    for (const std::string& path : opt.probes) {
      probes.push_back(startProbe(graph, path));
      Probe& p = probes.back();
      p.pixel_before = duplex::demo::project(camera, p.point_ws, opt.render.width, opt.render.height);
      p.hit_before = pickPath(*tracer, camera, p.pixel_before, opt.render);
    }

    std::printf("Duplex demo: %s (%s)\n", opt.scene.string().c_str(), doc.format.c_str());
    std::printf("  scene    %zu objects, %zu instances (%zu nodes), %zu triangles in the library, %zu timed edits\n",
                doc.figures.objects, doc.figures.instances, doc.figures.nodes, doc.figures.count("triangles"),
                doc.edits.size());
    std::printf("  load     %8.3f ms  (scene parse + mesh files)\n", doc.figures.load_ms);
    std::printf("  build    %8.3f ms  (bottom levels %.3f ms + top level %.3f ms; graph %.3f ms)\n",
                doc.figures.build_ms + top_build_ms, doc.figures.build_ms, top_build_ms, doc.figures.graph_ms);
    std::printf(
        "  render   %u x %u, %d threads, camera at %.2f diagonals, cursor at (%.1f, %.1f), pick radius %.1f px, "
        "feature edges above %.0f deg\n",
        opt.render.width, opt.render.height, opt.threads, opt.distance, cursor.x, cursor.y, opt.pick.radius_px,
        opt.pick.feature_angle_deg);

    duplex::demo::DemoRenderer renderer(*tracer, camera, opt.render);
    std::vector<duplex::demo::FrameStats> frames;
    std::vector<CommitFigures> commits;
    std::vector<CursorPick> picks;
    duplex::demo::RgbImage image;

    // Traces the current frame, picks under the cursor, writes the PNGs asked for, prints its line.
    const auto traceFrame = [&](const CommitFigures* commit) {
      duplex::demo::FrameStats stats;
      arena.execute([&] { image = renderer.render(stats); });
      picks.push_back(pickUnderCursor(*tracer, camera, cursor, opt, commit ? commit->time : 0.0));
      const std::size_t index = frames.size();
      frames.push_back(stats);
      if (!opt.frames.empty()) duplex::demo::writePng(framePath(opt.frames, index), image);
      if (commit) {
        std::printf("  frame %3zu t=%5.2f s  %2zu edits %3zu instances  update %7.3f ms (top level %6.3f ms%s)", index,
                    commit->time, commit->edits, commit->instances_changed, commit->update_ms, commit->tracer_ms,
                    commit->full_rebuild ? ", full rebuild" : "");
      } else {
        std::printf("  frame %3zu t= 0.00 s  as loaded %48s", index, "");
      }
      std::printf("  trace %7.2f ms  %6.2f Mrays/s  pick %s (%.3f ms)\n", stats.traceMs(),
                  mraysPerSecond(stats.rays(), stats.traceMs()), describe(picks.back()).c_str(), picks.back().ms);
    };

    traceFrame(nullptr);
    if (animated) duplex::demo::writePng(opt.before, image);

    // Play the edits: one commit per distinct time, then one frame.
    for (std::size_t i = 0; i < doc.edits.size();) {
      CommitFigures c;
      c.time = doc.edits[i].time;
      const auto t0 = Clock::now();
      const std::size_t j = duplex::applyEditGroup(doc, i);
      c.edits = j - i;
      duplex::ChangeSet changes;
      double rebuild_ms = 0.0;
      arena.execute([&] {
        changes = graph.commit();  // the tracer updates inside commit()
        if (opt.full_rebuild) {
          const auto r0 = Clock::now();
          tracer->rebuild();
          rebuild_ms = msSince(r0);
        }
      });
      c.update_ms = msSince(t0);
      c.tracer_ms = tracer->lastUpdateMs() + rebuild_ms;
      c.full_rebuild = opt.full_rebuild || tracer->stats().last_commit_full_rebuild;
      c.moved = changes.moved.size();
      c.appeared = changes.appeared.size();
      c.disappeared = changes.disappeared.size();
      c.object_changed = changes.object_changed.size();
      c.objects_changed = changes.objects_changed.size();
      c.instances_changed = c.moved + c.appeared + c.disappeared + c.object_changed;
      commits.push_back(c);
      traceFrame(&commits.back());
      i = j;
    }
    duplex::demo::writePng(opt.out, image);

    for (Probe& p : probes) {
      if (graph.contains(p.anchor)) {
        const glm::dvec3 point_ws = (graph.worldTransform(p.anchor) * p.anchor_from_world).point(p.point_ws);
        p.pixel_after = duplex::demo::project(camera, point_ws, opt.render.width, opt.render.height);
        p.hit_after = pickPath(*tracer, camera, p.pixel_after, opt.render);
      }
    }

    // Summary.
    std::vector<double> update_ms, tracer_ms, trace_ms;
    std::size_t rays = 0;
    double all_trace_ms = 0.0;
    for (const CommitFigures& c : commits) {
      update_ms.push_back(c.update_ms);
      tracer_ms.push_back(c.tracer_ms);
    }
    for (const auto& f : frames) {
      trace_ms.push_back(f.traceMs());
      rays += f.rays();
      all_trace_ms += f.traceMs();
    }
    const double update_max = update_ms.empty() ? 0.0 : *std::max_element(update_ms.begin(), update_ms.end());
    const double mrays = mraysPerSecond(rays, all_trace_ms);
    if (!commits.empty())
      std::printf(
          "  update   median %.3f ms, max %.3f ms per commit (first edit call until queries see it); "
          "top level median %.3f ms\n",
          median(update_ms), update_max, median(tracer_ms));
    std::printf("  trace    median %.2f ms per frame over %zu frames, %.2f Mrays/s (primary + shadow rays)\n",
                median(trace_ms), frames.size(), mrays);
    for (const Probe& p : probes)
      std::printf("  probe    %s: before %s, after %s\n", p.path.c_str(),
                  p.hit_before.empty() ? "(miss)" : p.hit_before.c_str(),
                  p.hit_after.empty() ? "(miss)" : p.hit_after.c_str());
    if (animated) std::printf("  image    %s (before), ", opt.before.string().c_str());
    else std::printf("  image    ");
    std::printf("%s (%u x %u)\n", opt.out.string().c_str(), image.width, image.height);

    nlohmann::json j;
    j["scene"] = opt.scene.string();
    j["format"] = doc.format;
    j["width"] = opt.render.width;
    j["height"] = opt.render.height;
    j["threads"] = opt.threads;
    j["full_rebuild"] = opt.full_rebuild;
    j["objects"] = doc.figures.objects;
    j["instances"] = doc.figures.instances;
    j["triangles"] = doc.figures.count("triangles");
    j["load_ms"] = round4(doc.figures.load_ms);
    j["bottom_build_ms"] = round4(doc.figures.build_ms);
    j["top_build_ms"] = round4(top_build_ms);
    j["build_ms"] = round4(doc.figures.build_ms + top_build_ms);
    j["edits"] = doc.edits.size();
    j["commits"] = commits.size();
    j["frames"] = frames.size();
    j["update_ms_median"] = round4(median(update_ms));
    j["update_ms_max"] = round4(update_max);
    j["top_update_ms_median"] = round4(median(tracer_ms));
    j["update_ms"] = nlohmann::json::array();
    for (const double ms : update_ms) j["update_ms"].push_back(round4(ms));
    // Per commit: what changed (ChangeSet counts) and the update time.
    j["changes"] = nlohmann::json::array();
    for (const CommitFigures& c : commits)
      j["changes"].push_back({{"time", c.time},
                              {"edits", c.edits},
                              {"moved", c.moved},
                              {"appeared", c.appeared},
                              {"disappeared", c.disappeared},
                              {"object_changed", c.object_changed},
                              {"objects_changed", c.objects_changed},
                              {"update_ms", round4(c.update_ms)}});
    j["cursor"] = nlohmann::json::array({round4(cursor.x), round4(cursor.y)});
    // Per frame (the first as loaded, at time 0): the pick under the cursor; path null for a miss.
    j["picks"] = nlohmann::json::array();
    for (const CursorPick& p : picks)
      j["picks"].push_back({{"time", p.time},
                            {"path", p.path.empty() ? nlohmann::json(nullptr) : nlohmann::json(p.path)},
                            {"element", p.path.empty() ? nlohmann::json(nullptr) : nlohmann::json(p.element)},
                            {"prim_id", p.path.empty() ? nlohmann::json(nullptr) : nlohmann::json(p.prim_id)},
                            {"vertices", p.vertices},
                            {"distance_px", round4(p.distance_px)},
                            {"pick_ms", round4(p.ms)},
                            {"distance", round4(p.distance)}});
    j["trace_ms_median"] = round4(median(trace_ms));
    j["rays"] = rays;
    j["mrays_per_s"] = round4(mrays);
    j["before"] = animated ? nlohmann::json(opt.before.string()) : nlohmann::json(nullptr);
    j["after"] = opt.out.string();
    j["probes"] = nlohmann::json::array();
    for (const Probe& p : probes)
      j["probes"].push_back({{"node", p.path},
                             {"pixel_before", pixelJson(p.pixel_before)},
                             {"pixel_after", pixelJson(p.pixel_after)},
                             {"hit_before", p.hit_before},
                             {"hit_after", p.hit_after}});
    std::cout << j.dump() << std::endl;
    return 0;
  } catch (const duplex::Error& e) {
    std::cerr << "duplex_demo: error: " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "duplex_demo: internal error: " << e.what() << '\n';
    return 3;
  }
}
