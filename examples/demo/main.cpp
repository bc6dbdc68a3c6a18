// duplex_demo: renders a scene shipped with the repository (examples/scenes/demo.json) to a PNG
// and prints how long loading, building and tracing took.
//   duplex_demo [--scene S.json] [--out out/demo.png] [--width W] [--height H] [--threads N]

#include "DemoRenderer.h"
#include "PngWriter.h"

#include <duplex/accel/Error.h>
#include <duplex/accel/TopLevel.h>
#include <duplex/scenegraph/SceneFile.h>

#include <CLI/CLI.hpp>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <chrono>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <optional>

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double mraysPerSecond(std::size_t rays, double ms) { return ms > 0.0 ? static_cast<double>(rays) / (ms * 1e3) : 0.0; }

}  // namespace

int main(int argc, char** argv) {
  std::filesystem::path scene_path = DUPLEX_DEMO_SCENE;
  std::filesystem::path out_path = "out/demo.png";
  duplex::demo::RenderSettings settings;
  int threads = tbb::info::default_concurrency();

  CLI::App app{"Renders a scene-json-v1 scene to a PNG (Lambert shading and shadow rays) and prints the figures.",
               "duplex_demo"};
  app.add_option("--scene", scene_path, "Scene to render")->capture_default_str();
  app.add_option("--out", out_path, "PNG to write (folders are created)")->capture_default_str();
  app.add_option("--width", settings.width, "Image width in pixels")->check(CLI::Range(1u, 16384u))->capture_default_str();
  app.add_option("--height", settings.height, "Image height in pixels")->check(CLI::Range(1u, 16384u))->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (default: all hardware threads)")->check(CLI::Range(1, 4096));
  CLI11_PARSE(app, argc, argv);

  try {
    tbb::global_control thread_limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    tbb::task_arena arena(threads);

    duplex::SceneLoadReport load;
    std::optional<duplex::Scene> scene;
    duplex::TopLevel top;
    double top_build_ms = 0.0;
    duplex::demo::RenderStats stats;
    duplex::demo::RgbImage image;
    arena.execute([&] {
      scene.emplace(duplex::loadScene(scene_path, {}, &load));
      if (scene->instances().empty()) throw duplex::InvalidArgument(scene_path.string() + ": scene has no instances");
      const auto t0 = Clock::now();
      top.build(scene->instanceDescs());
      top_build_ms = msSince(t0);
      image = duplex::demo::render(*scene, top, settings, stats);
    });
    duplex::demo::writePng(out_path, image);

    const double hit_percent = 100.0 * static_cast<double>(stats.primary_hits) / static_cast<double>(stats.primary_rays);
    std::printf("Duplex demo: %s\n", scene_path.string().c_str());
    std::printf("  scene    %zu objects, %zu instances, %zu triangles in the library\n", scene->objectCount(),
                scene->instances().size(), load.triangles);
    std::printf("  load     %8.2f ms  (scene parse + mesh files)\n", load.load_ms);
    std::printf("  build    %8.2f ms  (bottom levels %.2f ms + top level %.2f ms)\n", load.build_ms + top_build_ms,
                load.build_ms, top_build_ms);
    std::printf("  primary  %8.2f ms  %zu rays, %.2f Mrays/s, %.1f%% hit\n", stats.primary_ms, stats.primary_rays,
                mraysPerSecond(stats.primary_rays, stats.primary_ms), hit_percent);
    std::printf("  shadow   %8.2f ms  %zu rays, %.2f Mrays/s, %zu blocked\n", stats.shadow_ms, stats.shadow_rays,
                mraysPerSecond(stats.shadow_rays, stats.shadow_ms), stats.shadowed);
    std::printf("  threads  %d\n", threads);
    std::printf("  image    %s (%u x %u)\n", out_path.string().c_str(), image.width, image.height);
    return 0;
  } catch (const duplex::Error& e) {
    std::cerr << "duplex_demo: error: " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "duplex_demo: internal error: " << e.what() << '\n';
    return 3;
  }
}
