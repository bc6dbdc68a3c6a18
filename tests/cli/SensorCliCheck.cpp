// `duplex sensor` as an outside tool drives it: output files and keys, the closed box of
// sensors registering all emitted power, bit-identical results for 1 and 2 threads, --resume equal
// to one longer run, --target-error, and clear errors for bad lights and sensors; spectral bands
// and angular bins in the sensor files; far-field sensors and their .ies files; --at and timed edits.
//   duplex_sensor_cli_check DUPLEX DIR

#include "CheckSupport.h"
#include "Subprocess.h"

#include <nlohmann/json.hpp>

#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb_image.h>

#ifdef DUPLEX_CHECK_EXR
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdlib>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <stdexcept>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace duplex::clitest;

namespace {

nlohmann::json runJson(const std::vector<std::string>& argv, const fs::path& dir) {
  const RunResult r = runOk(argv, dir);
  expect(!r.out.empty() && r.out.find('\n') == r.out.size() - 1, "stdout is not one line:\n" + r.out);
  return nlohmann::json::parse(r.out);
}

nlohmann::json readJson(const fs::path& p) {
  std::ifstream in(p);
  expect(static_cast<bool>(in), p.string() + " was not written");
  return nlohmann::json::parse(in);
}

// Six two-sided sensors closing [-1, 1]^3 (4 x 3 bins each) around a point light of `power` W.
std::string boxScene(const std::string& power) {
  const char* faces[6] = {"0,0,1,1, 0,1,0,0, -1,0,0,0",  "0,0,-1,-1, 0,1,0,0, 1,0,0,0", "1,0,0,0, 0,0,1,1, 0,-1,0,0",
                          "1,0,0,0, 0,0,-1,-1, 0,1,0,0", "1,0,0,0, 0,1,0,0, 0,0,1,1",   "1,0,0,0, 0,-1,0,0, 0,0,-1,-1"};
  std::string s = R"({"format": "scene-json-v1", "objects": [], "instances": [],
  "lights": [{"type": "point", "position": [0.1, 0.2, -0.3], "power": )" +
                  power + R"(}], "sensors": [)";
  for (int k = 0; k < 6; ++k)
    s += std::string(k ? ", " : "") + R"({"name": "face)" + std::to_string(k) +
         R"(", "shape": "rectangle", "size": [2, 2], "bins": [4, 3], "two_sided": true, "transform": [)" + faces[k] +
         "]}";
  return s + "]}";
}

void write(const fs::path& p, const std::string& text) {
  std::ofstream out(p);
  out << text;
  expect(static_cast<bool>(out), "cannot write " + p.string());
}

std::vector<std::string> sensorArgs(const std::string& duplex, const fs::path& scene, const std::string& rays,
                                    const std::string& threads, const fs::path& out) {
  return {duplex,  "sensor", "--scene", scene.string(), "--rays",     rays,         "--threads",
          threads, "--seed", "3",       "--out",        out.string(), "--progress", "lines"};
}

// The EXR copy of a map (built with OpenEXR): Y and stderr equal the JSON arrays as floats, with the
// sensor's local +y up (first scanline = last bin row), and the header names the sensor.
void expectExrMatches(const fs::path& exr, const nlohmann::json& j) {
#ifdef DUPLEX_CHECK_EXR
  const std::uint32_t nx = j["bins"][0], ny = j["bins"][1];
  Imf::InputFile file(exr.c_str());
  const Imath::Box2i w = file.header().dataWindow();
  expect(w.max.x - w.min.x + 1 == static_cast<int>(nx) && w.max.y - w.min.y + 1 == static_cast<int>(ny),
         exr.string() + ": image size is not the bins");
  const auto* name = file.header().findTypedAttribute<Imf::StringAttribute>("sensor");
  expect(name && name->value() == j["name"].get<std::string>(), exr.string() + ": header lacks the sensor's name");
  std::vector<float> y(nx * ny), e(nx * ny);
  Imf::FrameBuffer fb;
  fb.insert("Y", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(y.data()), sizeof(float), sizeof(float) * nx));
  fb.insert("stderr", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(e.data()), sizeof(float), sizeof(float) * nx));
  file.setFrameBuffer(fb);
  file.readPixels(w.min.y, w.max.y);
  for (std::uint32_t iy = 0; iy < ny; ++iy)
    for (std::uint32_t ix = 0; ix < nx; ++ix) {
      const std::size_t b = iy * nx + ix, p = (ny - 1 - iy) * nx + ix;
      expect(y[p] == static_cast<float>(j["irradiance_w_m2"][b].get<double>()) &&
                 e[p] == static_cast<float>(j["stderr_w_m2"][b].get<double>()),
             exr.string() + ": pixel of bin " + std::to_string(b) + " differs from the JSON");
    }
#else
  expect(!fs::exists(exr), exr.string() + " written by a build without OpenEXR");
  (void)j;
#endif
}

// The false-colour PNG of a map: decodes, holds the map on the left and a colour scale bar on the
// right (a column whose colours form a gradient of at least 32 steps), and the bar's top colour is
// the colour of the map's brightest bin (both the map's maximum).
void expectPngWithScaleBar(const fs::path& png) {
  int w = 0, h = 0, channels = 0;
  unsigned char* data = stbi_load(png.c_str(), &w, &h, &channels, 3);
  expect(data != nullptr, png.string() + " does not decode as a PNG");
  const auto pixel = [&](int x, int y) {
    const unsigned char* p = data + (static_cast<std::size_t>(y) * w + x) * 3;
    return (p[0] << 16) | (p[1] << 8) | p[2];
  };
  int bar_x = -1;
  for (int x = w / 2; x < w && bar_x < 0; ++x) {
    std::vector<int> column;
    for (int y = 0; y < h; ++y) column.push_back(pixel(x, y));
    std::sort(column.begin(), column.end());
    if (std::unique(column.begin(), column.end()) - column.begin() >= 32) bar_x = x;
  }
  bool top_in_map = false;
  if (bar_x >= 0) {
    int top = 0;
    while (top < h && pixel(bar_x, top) == pixel(0, 0)) ++top;  // past the background margin
    for (int y = 0; y < h && !top_in_map; ++y)
      for (int x = 0; x < bar_x - 1 && !top_in_map; ++x) top_in_map = pixel(x, y) == pixel(bar_x, top);
  }
  stbi_image_free(data);
  expect(bar_x >= 0, png.string() + ": no colour scale bar on the right half of the image");
  expect(top_in_map, png.string() + ": the scale bar's top colour (the maximum) is not the colour of any bin");
}

// A camera's EXR (built with OpenEXR): its pixels are the JSON's luminance and standard error as
// floats, the camera's top row first, and the header names the camera and the units.
void expectCameraExr(const fs::path& exr, const nlohmann::json& cam) {
#ifdef DUPLEX_CHECK_EXR
  const int w = cam["image_size"][0], h = cam["image_size"][1];
  Imf::InputFile file(exr.c_str());
  const Imath::Box2i win = file.header().dataWindow();
  expect(win.max.x - win.min.x + 1 == w && win.max.y - win.min.y + 1 == h,
         exr.string() + ": image size is not the camera's");
  const auto* name = file.header().findTypedAttribute<Imf::StringAttribute>("sensor");
  const auto* units = file.header().findTypedAttribute<Imf::StringAttribute>("units");
  expect(name && name->value() == cam["name"].get<std::string>() && units && units->value() == "cd/m^2",
         exr.string() + ": header lacks the camera's name or the units cd/m^2");
  std::vector<float> y(static_cast<std::size_t>(w) * h), e(y.size());
  Imf::FrameBuffer fb;
  fb.insert("Y", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(y.data()), sizeof(float), sizeof(float) * w));
  fb.insert("stderr", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(e.data()), sizeof(float), sizeof(float) * w));
  file.setFrameBuffer(fb);
  file.readPixels(win.min.y, win.max.y);
  for (std::size_t p = 0; p < y.size(); ++p)
    expect(y[p] == static_cast<float>(cam["luminance_cd_m2"][p].get<double>()) &&
               e[p] == static_cast<float>(cam["luminance_stderr_cd_m2"][p].get<double>()),
           exr.string() + ": pixel " + std::to_string(p) + " differs from run.json");
  expect(cam["exr"] == exr.string(), "run.json names " + cam.dump() + " instead of " + exr.string());
#else
  expect(!fs::exists(exr) && !cam.contains("exr"), exr.string() + " written by a build without OpenEXR");
#endif
}

void expectSameMaps(const fs::path& a, const fs::path& b, const std::string& what) {
  for (int k = 0; k < 6; ++k) {
    const std::string name = "face" + std::to_string(k) + ".json";
    const nlohmann::json ja = readJson(a / name), jb = readJson(b / name);
    for (const char* key : {"irradiance_w_m2", "stderr_w_m2", "total_flux_w", "rays"})
      expect(ja[key] == jb[key], what + ": " + name + " differs in \"" + key + "\"");
  }
}

int check(const std::string& duplex, const fs::path& dir) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path scene = dir / "box.json";
  write(scene, boxScene("7"));

  // Output keys and files; plain progress lines on a stderr that is not a terminal.
  const RunResult first = runOk(sensorArgs(duplex, scene, "20000", "1", dir / "one"), dir);
  expect(first.err.find("progress: 20000 / 20000 rays (100.0%)") != std::string::npos,
         "--progress lines printed no final progress line:\n" + first.err);
  const nlohmann::json report = nlohmann::json::parse(first.out);
  expect(report["rays"] == 20000 && report["status"] == "completed", "report: " + report.dump());
  expect(report["sensors"].size() == 6, "six sensors expected: " + report.dump());
  double total = 0.0;
  for (int k = 0; k < 6; ++k) {
    const std::string name = "face" + std::to_string(k);
    const nlohmann::json j = readJson(dir / "one" / (name + ".json"));
    for (const char* key : {"rays", "total_flux_w", "irradiance_w_m2", "stderr_w_m2", "efficiency"})
      expect(j.contains(key), name + ".json lacks \"" + std::string(key) + "\"");
    expect(j["rays"] == 20000, name + ".json: rays is not the emitted count");
    expect(j["irradiance_w_m2"].size() == 12 && j["stderr_w_m2"].size() == 12,
           name + ".json: arrays are not nx * ny = 12");
    total += j["total_flux_w"].get<double>();
    expect(std::abs(j["efficiency"].get<double>() - j["total_flux_w"].get<double>() / 7.0) <= 1e-12,
           name + ".json: efficiency is not total_flux_w / emitted power (7 W)");
    std::ifstream csv(dir / "one" / (name + ".csv"));
    std::string line;
    int lines = 0;
    while (std::getline(csv, line)) {
      if (++lines == 1) {
        expect(line == "ix,iy,x,y,flux_w,irradiance_w_m2,stderr_w_m2,ray_count,world_x,world_y,world_z",
               name + ".csv: header " + line);
        continue;
      }
      // The bin centre in world coordinates lies on the face of the cube [-1, 1]^3 (one coordinate
      // +-1) and the other two are the local centre's, up to sign and order.
      std::vector<double> v;
      std::stringstream ss(line);
      for (std::string cell; std::getline(ss, cell, ',');) v.push_back(std::stod(cell));
      if (v.size() != 11) {
        expect(false, name + ".csv: row of " + std::to_string(v.size()) + " cells: " + line);
        continue;
      }
      std::vector<double> world = {std::abs(v[8]), std::abs(v[9]), std::abs(v[10])},
                          local = {std::abs(v[2]), std::abs(v[3]), 1.0};
      std::sort(world.begin(), world.end());
      std::sort(local.begin(), local.end());
      for (int c = 0; c < 3; ++c)
        expect(std::abs(world[c] - local[c]) < 1e-6, name + ".csv: world centre not on the face: " + line);
    }
    expect(lines == 13, name + ".csv: expected a header and 12 rows, got " + std::to_string(lines) + " lines");
    std::ifstream png(dir / "one" / (name + ".png"), std::ios::binary);
    char sig[8] = {};
    png.read(sig, 8);
    expect(std::string(sig + 1, 3) == "PNG", name + ".png is not a PNG file");
    expectPngWithScaleBar(dir / "one" / (name + ".png"));
    expectExrMatches(dir / "one" / (name + ".exr"), j);
  }
  // Sensors never block: the closed box registers all the emitted power.
  expect(std::abs(total - 7.0) < 1e-9, "the box's sensors registered " + std::to_string(total) + " W of 7 W");

  // Bit-identical for 2 threads; --resume from 8,000 rays equals the 20,000-ray run.
  (void)runJson(sensorArgs(duplex, scene, "20000", "2", dir / "two"), dir);
  expectSameMaps(dir / "one", dir / "two", "1 vs 2 threads");

  // Maps above --text-map-limit bins: NumPy files named in "map_files" instead of JSON arrays and
  // CSV rows, holding the same values bit for bit.
  {
    std::vector<std::string> args = sensorArgs(duplex, scene, "20000", "1", dir / "npy");
    args.insert(args.end(), {"--text-map-limit", "11"});
    (void)runJson(args, dir);
    for (int k = 0; k < 6; ++k) {
      const std::string name = "face" + std::to_string(k);
      const nlohmann::json text = readJson(dir / "one" / (name + ".json"));
      const nlohmann::json j = readJson(dir / "npy" / (name + ".json"));
      expect(!j.contains("irradiance_w_m2") && j.contains("map_files") && j["total_flux_w"] == text["total_flux_w"],
             name + ".json above the limit: expected map_files, no arrays, the same totals: " + j.dump());
      expect(!fs::exists(dir / "npy" / (name + ".csv")), name + ".csv written above the limit");
      for (const char* key : {"irradiance_w_m2", "stderr_w_m2", "flux_w", "bin_area_m2"}) {
        const fs::path file = dir / "npy" / j["map_files"][key].get<std::string>();
        std::ifstream in(file, std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        expect(bytes.size() > 10 && bytes.compare(0, 6, "\x93NUMPY") == 0, file.string() + " is not a .npy file");
        const std::size_t header =
            10 + static_cast<unsigned char>(bytes[8]) + 256u * static_cast<unsigned char>(bytes[9]);
        const std::string dict = bytes.substr(10, header - 10);
        expect(header % 64 == 0 && dict.find("'descr': '<f8'") != std::string::npos &&
                   dict.find("'shape': (3, 4)") != std::string::npos && bytes.size() == header + 12 * 8,
               file.string() + ": header " + dict);
        const std::vector<double> expected = text[key].get<std::vector<double>>();
        expect(std::memcmp(bytes.data() + header, expected.data(), 12 * 8) == 0,
               file.string() + " differs from the JSON array of the same run");
      }
    }
  }
  (void)runJson(sensorArgs(duplex, scene, "8000", "2", dir / "resumed"), dir);
  std::vector<std::string> resume = sensorArgs(duplex, scene, "20000", "1", dir / "resumed");
  resume.push_back("--resume");
  const nlohmann::json resumed = runJson(resume, dir);
  expect(resumed["resumed_from"] == 8000, "resume did not start from the saved rays: " + resumed.dump());
  expectSameMaps(dir / "one", dir / "resumed", "resumed run");

  // SIGTERM while the scene loads (many objects, each built in turn) stops the load: exit 143,
  // nothing on stdout, nothing written.
  {
    std::ostringstream objects, nodes;
    for (int k = 0; k < 400; ++k) {
      objects << (k ? ", " : "") << R"({"name": "s)" << k << R"(", "sphere": {"radius": )" << 1.0 + 0.001 * k
              << R"(, "subdivisions": 6}})";
      nodes << (k ? ", " : "") << R"({"instance": "s)" << k << R"("})";
    }
    const fs::path slow = dir / "slow_load.json";
    write(slow, R"({"format": "duplex-scene-v1", "objects": [)" + objects.str() + R"(], "nodes": [)" + nodes.str() +
                    R"(], "lights": [{"type": "point", "position": [0, 0, 5], "power": 1}],
                        "sensors": [{"name": "s", "shape": "rectangle", "size": [1, 1], "bins": [2, 2]}]})");
    const RunResult stopped =
        runAndSignal(sensorArgs(duplex, slow, "1000", "1", dir / "slow"), dir.string(), SIGTERM, "loading ", 60.0);
    expect(stopped.exited && stopped.exit_code == 143,
           "SIGTERM while loading: expected exit 143, got " + describe(stopped) + "\n" + stopped.err);
    expect(stopped.out.empty() && stopped.err.find("stopped while loading the scene") != std::string::npos,
           "SIGTERM while loading: " + stopped.out + stopped.err);
    expect(!fs::exists(dir / "slow" / "run.json") && !fs::exists(dir / "slow" / "run_state.bin"),
           "SIGTERM while loading: files were written");
  }

  // SIGINT stops a run after the chunks in flight: its rays are saved and written, the exit status
  // is 128 + 2, and resuming to N rays gives the files of one run of N rays.
  {
    const RunResult stopped = runAndSignal(sensorArgs(duplex, scene, "2000000000", "2", dir / "stopped"), dir.string(),
                                           SIGINT, "progress: ", 120.0);
    expect(stopped.exited && stopped.exit_code == 130,
           "SIGINT: expected exit 130, got " + describe(stopped) + "\n" + stopped.err);
    const nlohmann::json j = nlohmann::json::parse(stopped.out);
    const std::uint64_t done = j["rays"].get<std::uint64_t>();
    expect(j["status"] == "interrupted" && j["signal"] == SIGINT && done > 0 && done < 2000000000,
           "SIGINT: report " + stopped.out);
    expect(readJson(dir / "stopped" / "face0.json")["rays"] == done, "SIGINT: face0.json does not hold the rays done");
    const std::string total_rays = std::to_string(done + 3000);
    std::vector<std::string> resume_stopped = sensorArgs(duplex, scene, total_rays, "2", dir / "stopped");
    resume_stopped.push_back("--resume");
    const nlohmann::json continued = runJson(resume_stopped, dir);
    expect(continued["resumed_from"] == done && continued["status"] == "completed",
           "resume after SIGINT: " + continued.dump());
    (void)runJson(sensorArgs(duplex, scene, total_rays, "1", dir / "straight"), dir);
    expectSameMaps(dir / "straight", dir / "stopped", "run stopped by SIGINT and resumed");
  }

  // A run killed outright (SIGKILL: no handler runs, nothing is saved at the end) resumes from its
  // last periodic checkpoint and ends with the files of one uninterrupted run of the same total.
  {
    std::vector<std::string> args = sensorArgs(duplex, scene, "2000000000", "2", dir / "killed");
    for (const char* a : {"--checkpoint", "0.05"}) args.push_back(a);
    const RunResult killed = runAndSignal(args, dir.string(), SIGKILL, "checkpoint: ", 120.0);
    expect(!killed.exited && killed.signal == SIGKILL, "SIGKILL: expected death by signal 9, got " + describe(killed));
    // The last checkpoint line on stderr; a later save may have landed before the kill.
    const std::string marker = "checkpoint: ";
    const std::size_t at = killed.err.rfind(marker);
    expect(at != std::string::npos, "SIGKILL: no checkpoint line on stderr:\n" + killed.err);
    const std::uint64_t saved = std::stoull(killed.err.substr(at + marker.size()));
    expect(saved > 0 && std::filesystem::exists(dir / "killed" / "run_state.bin"),
           "SIGKILL: no saved state after a checkpoint line:\n" + killed.err);
    const std::string total_rays = std::to_string(saved + 300000);
    std::vector<std::string> resume_killed = sensorArgs(duplex, scene, total_rays, "2", dir / "killed");
    resume_killed.push_back("--resume");
    const nlohmann::json continued = runJson(resume_killed, dir);
    expect(continued["resumed_from"].get<std::uint64_t>() >= saved && continued["status"] == "completed",
           "resume after SIGKILL: " + continued.dump());
    (void)runJson(sensorArgs(duplex, scene, total_rays, "1", dir / "straight_killed"), dir);
    expectSameMaps(dir / "straight_killed", dir / "killed", "run killed by SIGKILL and resumed from its checkpoint");
  }

  // Stop on a target relative error.
  std::vector<std::string> target = sensorArgs(duplex, scene, "50000000", "2", dir / "target");
  for (const char* a : {"--target-error", "0.05", "--target-sensor", "face4"}) target.push_back(a);
  const nlohmann::json stopped = runJson(target, dir);
  expect(stopped["status"] == "target_reached" && stopped["rays"].get<double>() < 5e7,
         "target not reached: " + stopped.dump());
  expect(stopped["sensors"][4]["relative_stderr"].get<double>() <= 0.05,
         "relative error above target: " + stopped.dump());

  // Bad input: a clear message naming the file and the JSON pointer, a non-zero exit.
  struct Bad {
    const char* file;
    std::string text;
    const char* needle;
  };
  std::vector<Bad> bad = {
      {"zero_power.json", boxScene("0"), "/lights/0/power"},
      {"negative_power.json", boxScene("-3"), "power must be > 0"},
      {"bad_bins.json",
       R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [{"type": "point", "position": [0,0,0], "power": 1}],
        "sensors": [{"name": "s", "shape": "rectangle", "size": [1, 1], "bins": [0, 3]}]})",
       "/sensors/0/bins/0"},
      {"no_lights.json",
       R"({"format": "scene-json-v1", "objects": [], "instances": [], "sensors": [{"name": "s", "size": 1}]})",
       "no lights"}};
  // Sensors whose output files would collide: refused before the run, like the bad entries above.
  const auto twoSensors = [](const std::string& a, const std::string& b) {
    const auto sensor = [](const std::string& name) {
      return R"({"name": ")" + name + R"(", "shape": "rectangle", "size": [1, 1], "bins": [1, 1]})";
    };
    return R"({"format": "scene-json-v1", "objects": [], "instances": [],
               "lights": [{"type": "point", "position": [0, 0, 0], "power": 1}], "sensors": [)" +
           sensor(a) + ", " + sensor(b) + "]}";
  };
  bad.push_back({"same_file.json", twoSensors("a b", "a_b"), "would both write a_b.json"});
  bad.push_back({"run_name.json", twoSensors("x", "run"), "would write run.json"});
  bad.push_back({"long_name.json", twoSensors("x", std::string(300, 'n')), "too long for its output files' names"});
  {
    std::vector<std::string> args = sensorArgs(duplex, scene, "100", "1", dir / "bad");
    for (const char* a : {"--target-error", "0.1", "--target-sensor", "no-such-face"}) args.push_back(a);
    const RunResult r = run(args, dir.string());
    expect(r.exited && r.exit_code != 0 && r.err.find("no-such-face") != std::string::npos,
           "unknown --target-sensor: " + describe(r) + "\n" + r.err);
    args = sensorArgs(duplex, scene, "100", "1", dir / "fresh");
    args.push_back("--resume");
    const RunResult rr = run(args, dir.string());
    expect(rr.exited && rr.exit_code != 0 && rr.err.find("run_state.bin") != std::string::npos,
           "--resume without a saved state: " + describe(rr) + "\n" + rr.err);
    // A directory where the run state goes: refused before the run (with and without --resume).
    fs::create_directories(dir / "state_dir" / "run_state.bin");
    for (const bool resume : {false, true}) {
      args = sensorArgs(duplex, scene, "100", "1", dir / "state_dir");
      args.push_back(resume ? "--resume" : "--overwrite");
      const RunResult rd = run(args, dir.string());
      expect(rd.exited && rd.exit_code == 1 && rd.err.find("a directory, not a file") != std::string::npos &&
                 rd.out.empty(),
             "run_state.bin a directory: " + describe(rd) + "\n" + rd.err);
    }
  }
  for (const Bad& b : bad) {
    write(dir / b.file, b.text);
    const RunResult r = run(sensorArgs(duplex, dir / b.file, "100", "1", dir / "bad"), dir.string());
    expect(r.exited && r.exit_code != 0, std::string(b.file) + ": expected a non-zero exit, got " + describe(r));
    expect(r.err.find((dir / b.file).string()) != std::string::npos && r.err.find(b.needle) != std::string::npos,
           std::string(b.file) + ": message does not name the file and '" + b.needle + "':\n" + r.err);
  }
  std::cout << "duplex sensor: files, keys, progress lines, efficiency, closed box " << total
            << " W of 7 W, 1 = 2 threads, resume, SIGINT and resume, target, errors, colliding names: ok\n";
  return 0;
}

// Spectral bands and angular bins: the per-band arrays and angular bins are added beside the
// exact keys, which hold the sums over the bands; a floor that reflects no red sends no red to a
// sensor that sees only the floor; the angular bins hold the sensor's whole flux. A sphere sensor
// around a light sees all its power.
void checkBandsAndAngles(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  write(dir / "bands.json", R"({"format": "scene-json-v1", "bands": ["blue", "red"],
    "objects": [{"name": "floor", "mesh": {"positions": [-2,-2,0, 2,-2,0, 2,2,0, -2,2,0], "indices": [0,1,2, 0,2,3]},
                 "material": {"type": "lambertian", "reflectance": [0.5, 0]}}],
    "instances": [{"object": "floor", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
    "lights": [{"type": "point", "position": [0, 0, 0.2], "power": 2, "spectrum": [1, 3]}],
    "sensors": [{"name": "looks_down", "size": [2, 2], "bins": [2, 2], "two_sided": false, "angular_bins": [3, 4],
                 "transform": [1,0,0,0, 0,-1,0,0, 0,0,-1,0.1]}]})");
  const nlohmann::json report = runJson(sensorArgs(duplex, dir / "bands.json", "20000", "2", dir / "bands"), dir);
  expect(report["bands"] == nlohmann::json({"blue", "red"}), "run.json lacks the bands");
  expect(std::abs(report["band_emitted_w"][0].get<double>() - 0.5) < 1e-12 &&
             std::abs(report["band_emitted_w"][1].get<double>() - 1.5) < 1e-12,
         "band_emitted_w is not the spectrum's share of 2 W: " + report["band_emitted_w"].dump());
  const nlohmann::json j = readJson(dir / "bands" / "looks_down.json");
  for (const char* key : {"rays", "total_flux_w", "irradiance_w_m2", "stderr_w_m2"})
    expect(j.contains(key), std::string("looks_down.json lacks the exact key ") + key);
  const double total = j["total_flux_w"];
  expect(total > 0.0, "the sensor under the light saw nothing of the floor");
  expect(j["band_total_flux_w"][1].get<double>() == 0.0, "red arrived from a floor that reflects no red");
  expect(std::abs(j["band_total_flux_w"][0].get<double>() - total) <= 1e-12 * total,
         "the bands do not sum to total_flux_w");
  for (std::size_t b = 0; b < 4; ++b) {
    const double e = j["irradiance_w_m2"][b], blue = j["band_irradiance_w_m2"][0][b],
                 red = j["band_irradiance_w_m2"][1][b];
    expect(red == 0.0 && std::abs(blue - e) <= 1e-12 * e,
           "bin " + std::to_string(b) + ": bands do not sum to the irradiance");
  }
  expect(j["angular_bins"] == nlohmann::json({3, 4}) && j["angular_flux_w"].size() == 12 &&
             j["angular_solid_angle_sr"].size() == 12,
         "looks_down.json lacks its 3 x 4 angular bins");
  double angular = 0.0;
  for (const auto& x : j["angular_flux_w"]) angular += x.get<double>();
  expect(std::abs(angular - total) <= 1e-12 * total, "the angular bins do not hold the sensor's flux");

  // --roulette and --max-scatterings act on fog paths: VolumeCliCheck. Here: they are reported,
  // and a threshold outside [0, 1) is refused with a message naming the option.
  // No depth cap by default (null), the deep roulette after 32 interactions.
  expect(report["roulette_threshold"] == 0.05 && report["max_scatterings"] == 100000 && report["max_depth"].is_null() &&
             report["roulette_depth"] == 32,
         "run.json lacks the default path limits: " + report.dump());
  for (const char* bad_value : {"1", "-0.1", "nan"}) {
    std::vector<std::string> args = sensorArgs(duplex, dir / "bands.json", "100", "1", dir / "bad_roulette");
    args.push_back("--roulette");
    args.push_back(bad_value);
    const RunResult r = run(args, dir.string());
    expect(r.exited && r.exit_code != 0 && r.err.find("--roulette") != std::string::npos,
           std::string("--roulette ") + bad_value + ": expected an error naming the option, got " + describe(r));
  }

  // A sphere sensor around a point light: all the power leaves through it, by direction.
  write(dir / "sphere.json", R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 0], "power": 3}],
    "sensors": [{"name": "far", "shape": "sphere", "size": 4, "bins": [8, 4]}]})");
  (void)runJson(sensorArgs(duplex, dir / "sphere.json", "5000", "1", dir / "sphere"), dir);
  const nlohmann::json sj = readJson(dir / "sphere" / "far.json");
  expect(sj["shape"] == "sphere" && sj["irradiance_w_m2"].size() == 32, "far.json is not a 8 x 4 sphere");
  expect(std::abs(sj["total_flux_w"].get<double>() - 3.0) < 1e-12, "the sphere around the light did not see all 3 W");
}

// The numbers of an IES LM-63 file after its TILT=NONE line (read here, not by the library).
std::vector<double> iesNumbers(const fs::path& p, std::string& header) {
  std::ifstream in(p);
  expect(static_cast<bool>(in), p.string() + " was not written");
  std::stringstream text;
  text << in.rdbuf();
  header = text.str();
  const std::size_t tilt = header.find("TILT=NONE\n");
  expect(tilt != std::string::npos, p.string() + " has no TILT=NONE line");
  std::istringstream numbers(header.substr(tilt + 10));
  std::vector<double> out;
  for (std::string token; numbers >> token;) out.push_back(std::strtod(token.c_str(), nullptr));
  header.resize(tilt);
  return out;
}

// A far-field sensor: its keys (gamma fastest), intensity x solid angle summing to the escaped
// power, an isotropic source's P / (4 pi) per cell, and the .ies file holding the JSON's numbers.
// Timed edits: --at T applies those up to T (run.json's at and edits_applied; the scene's sensor
// and light follow them: the same files as a scene written with the edits done), stderr says
// which edits a run leaves out.
void checkFarFieldAndEdits(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  write(dir / "far.json", R"({"format": "scene-json-v1",
    "objects": [{"name": "floor", "mesh": {"positions": [-1,-1,0, 1,-1,0, 1,1,0, -1,1,0], "indices": [0,1,2, 0,2,3]}}],
    "instances": [{"object": "floor", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
    "lights": [{"type": "point", "position": [0, 0, 0.5], "power": 12.566370614359172}],
    "sensors": [{"name": "far", "shape": "farfield", "bins": [6, 5]}]})");
  const nlohmann::json report = runJson(sensorArgs(duplex, dir / "far.json", "60000", "2", dir / "far"), dir);
  const nlohmann::json j = readJson(dir / "far" / "far.json");
  for (const char* key : {"rays", "total_flux_w", "c_deg", "gamma_deg", "intensity_w_sr", "intensity_stderr_w_sr"})
    expect(j.contains(key), std::string("far.json lacks the exact key ") + key);
  expect(j["shape"] == "farfield" && j["bins"] == nlohmann::json({6, 5}), "far.json is not a 6 x 5 far field");
  expect(j["c_deg"] == nlohmann::json({0, 60, 120, 180, 240, 300}) &&
             j["gamma_deg"] == nlohmann::json({0, 45, 90, 135, 180}),
         "far.json's angles are not the IES grid: " + j["c_deg"].dump() + " " + j["gamma_deg"].dump());
  const double escaped = report["energy"]["escaped_w"], total = j["total_flux_w"];
  expect(std::abs(total - escaped) <= 1e-12 * escaped, "the far field did not see the escaped power");
  // Every path ends one way: escaped (through the far field) or absorbed by the floor, each with
  // the power it was emitted with; no numerical failure.
  const nlohmann::json& e = report["energy"];
  for (const char* key : {"escaped_rays", "absorbed_rays", "medium_absorbed_rays", "depth_limited_rays",
                          "roulette_rays", "failed_w", "failed_rays"})
    expect(e.contains(key), std::string("run.json's energy lacks ") + key);
  expect(report["failure_threshold"] == 0.001, "run.json lacks the default failure_threshold 0.001");
  const std::uint64_t escaped_rays = e["escaped_rays"], absorbed_rays = e["absorbed_rays"];
  expect(escaped_rays + absorbed_rays == 60000 && e["failed_rays"] == 0,
         "the ray counts do not sum to the rays: " + e.dump());
  expect(std::abs(escaped - 12.566370614359172 * static_cast<double>(escaped_rays) / 60000.0) <= 1e-12 * escaped,
         "escaped_w is not its ray count times the ray power: " + e.dump());
  double sum = 0.0;
  for (std::size_t b = 0; b < 30; ++b) {
    const double i = j["intensity_w_sr"][b], se = j["intensity_stderr_w_sr"][b], omega = j["solid_angle_sr"][b];
    sum += i * omega;
    const std::size_t g = b % 5;  // gamma fastest: cells of gamma 0 (and 45) look at the floor
    if (g == 0) expect(i == 0.0, "a ray through the floor reached the nadir cell " + std::to_string(b));
    if (g >= 3)
      expect(std::abs(i - 1.0) < 4.5 * se,
             "cell " + std::to_string(b) + ": I = " + std::to_string(i) + " W/sr, not the source's 1 W/sr");
  }
  expect(std::abs(sum - total) <= 1e-9 * total, "intensity x solid angle does not sum to total_flux_w");
  std::string header;
  const std::vector<double> ies = iesNumbers(dir / "far" / "far.ies", header);
  expect(header.rfind("IESNA:LM-63-2002\n", 0) == 0 && header.find("[_UNITS] W/sr") != std::string::npos,
         "far.ies is not an LM-63-2002 file that says its values are W/sr:\n" + header);
  // 1 lamp, -1 lm, x1, 5 vertical, 7 horizontal (0 ... 360), type C, metres, 0 0 0, 1 1 0.
  const std::vector<double> counts = {1, -1, 1, 5, 7, 1, 2, 0, 0, 0, 1, 1, 0};
  expect(ies.size() == 13 + 5 + 7 + 35 && std::equal(counts.begin(), counts.end(), ies.begin()),
         "far.ies's counts are not those of a 5 x 7 type C table");
  expect(ies[13 + 5 + 6] == 360.0, "far.ies's last C-plane is not 360");
  for (std::size_t b = 0; b < 35; ++b)
    expect(ies[25 + b] == j["intensity_w_sr"][b % 30].get<double>(),
           "far.ies value " + std::to_string(b) + " is not the JSON's intensity");

  // Timed edits: the sensor moves at t = 1 and shrinks at t = 2, the lamp's node moves at t = 3.
  const std::string objects = R"({"format": "duplex-scene-v1",
    "objects": [{"name": "plate", "sensor": {"size": [1, 1], "bins": [2, 2]}},
                {"name": "floor", "plane": {"size": 4}, "material": {"type": "lambertian", "reflectance": 0.5}}],
    "lights": [{"type": "point", "node": "/lamp", "position": [0, 0, 0], "power": 10}],)";
  auto nodes = [](const char* sensor, const char* lamp) {
    return std::string(R"("nodes": [{"instance": "floor", "object": "floor"},
      {"group": "rig", "translate": [0, 0, 1], "children": [{"instance": "plate", "object": "plate", "transform": )") +
           sensor + R"(}]}, {"group": "lamp", "translate": )" + lamp + "}]";
  };
  write(dir / "edits.json", objects + nodes(R"({"translate": [0, 0, 0]})", "[0, 0, 2]") + R"(, "edits": [
      {"time": 1, "node": "/rig/plate", "set_transform": {"translate": [0.3, 0, 0]}},
      {"time": 2, "node": "/rig/plate", "set_transform": {"translate": [0.3, 0, 0], "scale": 0.5}},
      {"time": 3, "node": "/lamp", "set_transform": {"translate": [0, 0, 3]}}]})");
  write(dir / "at2.json", objects + nodes(R"({"translate": [0.3, 0, 0], "scale": 0.5})", "[0, 0, 2]") + "}");
  std::vector<std::string> args = sensorArgs(duplex, dir / "edits.json", "20000", "1", dir / "none");
  RunResult r = runOk(args, dir);
  expect(r.err.find("3 timed edit(s)") != std::string::npos && r.err.find("none is applied") != std::string::npos,
         "a run without --at did not say that the scene's 3 edits are not applied:\n" + r.err);
  expect(!nlohmann::json::parse(r.out).contains("at"), "run.json has \"at\" without --at");
  args = sensorArgs(duplex, dir / "edits.json", "20000", "1", dir / "at2");
  args.insert(args.end(), {"--at", "2"});
  r = runOk(args, dir);
  const nlohmann::json at2 = nlohmann::json::parse(r.out);
  expect(at2["at"] == 2.0 && at2["edits_applied"] == 2, "run.json lacks at 2, edits_applied 2: " + at2.dump());
  expect(r.err.find("applied 2, the 1 after it are not applied") != std::string::npos,
         "--at 2 did not say that one edit is left out:\n" + r.err);
  (void)runJson(sensorArgs(duplex, dir / "at2.json", "20000", "1", dir / "baked"), dir);
  const nlohmann::json edited = readJson(dir / "at2" / "plate.json"), baked = readJson(dir / "baked" / "plate.json");
  for (const char* key : {"flux_w", "irradiance_w_m2", "bin_area_m2", "ray_count", "stderr_w_m2"})
    expect(edited[key] == baked[key], std::string("--at 2: ") + key + " differs from the scene with the edits done");
  expect(std::abs(edited["bin_area_m2"][0].get<double>() - 0.0625) < 1e-15, "the shrunk sensor kept its bin areas");
  args = sensorArgs(duplex, dir / "edits.json", "20000", "1", dir / "at9");
  args.insert(args.end(), {"--at", "9"});
  r = runOk(args, dir);
  expect(nlohmann::json::parse(r.out)["edits_applied"] == 3 && r.err.find("timed edit") == std::string::npos,
         "--at 9 did not apply all 3 edits silently: " + r.out + r.err);
  const nlohmann::json at9 = readJson(dir / "at9" / "plate.json");
  expect(at9["total_flux_w"].get<double>() < edited["total_flux_w"].get<double>(),
         "the lamp moved up, yet the sensor saw no less");
  args = sensorArgs(duplex, dir / "edits.json", "100", "1", dir / "bad_at");
  args.insert(args.end(), {"--at", "-1"});
  const RunResult bad = run(args, dir.string());
  expect(bad.exited && bad.exit_code != 0 && bad.err.find("--at") != std::string::npos,
         "--at -1: expected an error naming the option, got " + describe(bad));
}

// Every file of a folder, name -> bytes.
std::map<std::string, std::string> folderFiles(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const fs::directory_entry& e : fs::directory_iterator(dir)) {
    std::ifstream in(e.path(), std::ios::binary);
    files[e.path().filename().string()] =
        std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  return files;
}

// The output folder: an earlier run's results are refused without --overwrite / --resume and left
// as they were; --overwrite removes the files of sensors the new run does not have and keeps the
// user's own files; a failure while writing the results (a full disk, made by a file-size limit
// that the run state fits under and one result file does not) keeps the earlier files byte for
// byte, leaves no staging folder, and --resume then writes the run's results.
void checkOutputFolderRules(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  const std::string sensors = R"("sensors": [{"name": "big", "shape": "rectangle", "size": [2, 2], "bins": [64, 64]},
                                             {"name": "small", "shape": "rectangle", "size": [2, 2], "bins": [2, 2]}]})";
  const std::string light = R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 5}], )";
  write(dir / "two.json", light + sensors);
  write(dir / "one.json",
        light + R"("sensors": [{"name": "other", "shape": "rectangle", "size": [1, 1], "bins": [3, 3]}]})");
  const fs::path out = dir / "out";
  (void)runJson(sensorArgs(duplex, dir / "two.json", "2000", "1", out), dir);
  write(out / "notes.txt", "the user's own file");
  const std::map<std::string, std::string> earlier = folderFiles(out);

  // Refused, naming the earlier report and the way out; nothing changed.
  const RunResult again = run(sensorArgs(duplex, dir / "two.json", "3000", "1", out), dir.string());
  expect(again.exited && again.exit_code == 1 && again.err.find("run.json") != std::string::npos &&
             again.err.find("--overwrite") != std::string::npos && again.out.empty(),
         "a second run into the same --out: " + describe(again) + "\n" + again.err);
  expect(folderFiles(out) == earlier, "a refused run changed the output folder");
  std::vector<std::string> both = sensorArgs(duplex, dir / "two.json", "3000", "1", out);
  both.insert(both.end(), {"--overwrite", "--resume"});
  const RunResult conflict = run(both, dir.string());
  expect(conflict.exited && conflict.exit_code != 0 && folderFiles(out) == earlier,
         "--overwrite with --resume accepted: " + describe(conflict));
  // A folder holding only other files (here the scenes) is not refused.
  fs::create_directories(dir / "plain");
  write(dir / "plain" / "scene.json", light + sensors);
  (void)runJson(sensorArgs(duplex, dir / "plain" / "scene.json", "1000", "1", dir / "plain"), dir);

  // A full disk while the results are written: the earlier files stay, the run is saved.
  std::vector<std::string> limited = {"/bin/sh", "-c", "ulimit -f 500 && exec \"$0\" \"$@\""};
  const std::vector<std::string> big = sensorArgs(duplex, dir / "two.json", "200000", "1", out);
  limited.insert(limited.end(), big.begin(), big.end());
  limited.push_back("--overwrite");
  const RunResult full = run(limited, dir.string());
  expect(full.exited && full.exit_code == 1 && full.err.find("keeps the files it held before") != std::string::npos &&
             full.err.find("--resume") != std::string::npos,
         "results on a full disk: " + describe(full) + "\n" + full.err);
  std::map<std::string, std::string> after = folderFiles(out);
  expect(!after.count(".duplex-sensor-staging"), "a failed write left the staging folder");
  after.erase("run_state.bin");
  std::map<std::string, std::string> earlier_results = earlier;
  earlier_results.erase("run_state.bin");
  expect(after == earlier_results, "a failed write of the results changed the earlier results");
  std::vector<std::string> resume = sensorArgs(duplex, dir / "two.json", "200000", "1", out);
  resume.push_back("--resume");
  const nlohmann::json resumed = runJson(resume, dir);
  expect(resumed["resumed_from"] == 200000 && resumed["rays"] == 200000,
         "--resume after the failed write: " + resumed.dump());
  (void)runJson(sensorArgs(duplex, dir / "two.json", "200000", "1", dir / "direct"), dir);
  for (const char* name : {"big.json", "small.json", "big.csv"})
    expect(folderFiles(out)[name] == folderFiles(dir / "direct")[name],
           std::string(name) + " written by --resume differs from the uninterrupted run's");

  // --overwrite with other sensors: the earlier run's sensor files go, the user's file stays.
  std::vector<std::string> other = sensorArgs(duplex, dir / "one.json", "1000", "1", out);
  other.push_back("--overwrite");
  (void)runJson(other, dir);
  const std::map<std::string, std::string> now = folderFiles(out);
  for (const char* gone : {"big.json", "big.csv", "big.png", "small.json", "small.csv"})
    expect(!now.count(gone), std::string("--overwrite left the earlier run's ") + gone);
  expect(now.count("other.json") && now.count("run.json") && now.at("notes.txt") == "the user's own file",
         "--overwrite: expected other.json, run.json and the user's notes.txt");
}

}  // namespace

// A one-sided sensor turned away from the only light records nothing and stderr says so; the same
// sensor facing the light records it and nothing is said.
void checkBackFacingWarning(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  const std::string head = R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 5}], "sensors": [{"name": "desk", "size": [1, 1],
    "bins": [2, 2], "two_sided": false, "transform": )";
  write(dir / "away.json", head + R"([1,0,0,0, 0,-1,0,0, 0,0,-1,0]}]})");
  write(dir / "facing.json", head + R"([1,0,0,0, 0,1,0,0, 0,0,1,0]}]})");
  const RunResult away = runOk(sensorArgs(duplex, dir / "away.json", "2000", "1", dir / "away"), dir);
  expect(away.err.find("one-sided sensor 'desk' recorded nothing") != std::string::npos &&
             away.err.find("two_sided") != std::string::npos,
         "a one-sided sensor facing away from every light: no warning:\n" + away.err);
  const RunResult facing = runOk(sensorArgs(duplex, dir / "facing.json", "2000", "1", dir / "facing"), dir);
  expect(facing.err.find("recorded nothing") == std::string::npos &&
             nlohmann::json::parse(facing.out)["sensors"][0]["total_flux_w"].get<double>() > 0.0,
         "a one-sided sensor facing the light: " + facing.out + facing.err);
}

// Lights in lumens (no wavelengths): run.json and the sensor files give the photometric keys
// (emitted_flux_lm, total_flux_lm, the energy's "_lm" keys, flux_lm, illuminance_lx, the CSV's
// appended luminous columns) and leave the "_w" keys null or empty, since the transported unit is the
// lumen; --per-light gives each light's share, which adds up to the totals. The same scene in
// watts keeps its "_w" keys and gets no "_lm" key.
void checkPhotometricKeysAndPerLight(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  const auto scene = [](const std::string& unit) {
    return R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
      {"type": "point", "name": "left", "position": [-0.5, 0, 1.5], ")" +
           unit + R"(": 400}, {"type": "point", "name": "right", "position": [0.5, 0.2, 2], ")" + unit +
           R"(": 1200}], "sensors": [{"name": "desk", "size": [1, 1], "bins": [2, 2], "two_sided": false}],
      "meters": [{"name": "grid", "points": [[0, 0, 0], [0, 0, 0]], "normals": [[0, 0, 1], [0, 0, -1]]}]})";
  };
  write(dir / "lumens.json", scene("lumens"));
  write(dir / "watts.json", scene("power"));
  std::vector<std::string> args = sensorArgs(duplex, dir / "lumens.json", "20000", "2", dir / "lumens");
  args.push_back("--per-light");
  const nlohmann::json r = runJson(args, dir);
  expect(r["emitted_flux_lm"] == 1600.0 && r["emitted_luminous_flux_lm"] == 1600.0,
         "lumens: emitted_flux_lm " + r.dump());
  expect(
      r["emitted_power_w"].is_null() && r["energy"]["escaped_w"].is_null() && r["sensors"][0]["total_flux_w"].is_null(),
      "lumens: a \"_w\" key holds lumens: " + r.dump());
  // Sensors absorb nothing: every lumen escapes this scene.
  expect(std::abs(r["energy"]["escaped_lm"].get<double>() - 1600.0) < 1e-9 &&
             r["sensors"][0]["total_flux_lm"].get<double>() > 0.0,
         "lumens: escaped_lm is not the emitted 1600 lm, or the desk got nothing: " + r.dump());
  expect(r["lights"].size() == 2 && r["lights"][0]["name"] == "left" && r["lights"][1]["emitted_flux_lm"] == 1200.0 &&
             r["lights"][1]["emitted_power_w"].is_null(),
         "lumens: run.json lights " + r["lights"].dump());
  // The meter's first point (facing up) against the inverse-square cosine law of both lights; the
  // second faces away from them.
  const double pi = 3.14159265358979323846;
  const double exact = 400 / (4 * pi) * (1.5 / std::sqrt(2.5)) / 2.5 + 1200 / (4 * pi) * (2 / std::sqrt(4.29)) / 4.29;
  const nlohmann::json& meter = r["meters"][0];
  expect(meter["name"] == "grid" && meter["irradiance_w_m2"].is_null() &&
             std::abs(meter["illuminance_lx"][0].get<double>() - exact) <=
                 4.5 * meter["illuminance_stderr_lx"][0].get<double>() + 1e-9 * exact &&
             meter["illuminance_lx"][1] == 0.0 && meter["lights"].size() == 2,
         "lumens: meter " + meter.dump() + ", expected " + std::to_string(exact) + " lx at the first point");
  const nlohmann::json j = readJson(dir / "lumens" / "desk.json");
  expect(j["irradiance_w_m2"].is_null() && j["flux_w"].is_null() && j["total_flux_w"].is_null(),
         "lumens: desk.json holds lumens under a \"_w\" key");
  expect(j["illuminance_lx"].size() == 4 && j["flux_lm"].size() == 4 && j["total_flux_lm"] == j["luminous_flux_lm"],
         "lumens: desk.json's luminous keys");
  expect(j["lights"].size() == 2, "lumens: desk.json has no per-light entries");
  double total = 0.0;
  for (int b = 0; b < 4; ++b) {
    double sum = 0.0;
    for (int l = 0; l < 2; ++l) sum += j["lights"][l]["illuminance_lx"][b].get<double>();
    const double all = j["illuminance_lx"][b].get<double>();
    expect(all > 0.0 && std::abs(sum - all) <= 1e-9 * all,
           "lumens: per-light illuminances do not sum to bin " + std::to_string(b) + "'s");
  }
  for (int l = 0; l < 2; ++l) total += j["lights"][l]["total_flux_lm"].get<double>();
  expect(std::abs(total - j["total_flux_lm"].get<double>()) <= 1e-9 * total, "lumens: per-light totals");
  std::ifstream csv(dir / "lumens" / "desk.csv");
  std::string line;
  std::getline(csv, line);
  expect(line ==
             "ix,iy,x,y,flux_w,irradiance_w_m2,stderr_w_m2,ray_count,world_x,world_y,world_z,flux_lm,illuminance_lx,"
             "illuminance_stderr_lx",
         "lumens: desk.csv header " + line);
  for (int b = 0; std::getline(csv, line); ++b) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) cells.push_back(cell);
    expect(cells.size() == 14 && cells[4].empty() && cells[5].empty() && cells[6].empty() &&
               std::abs(std::stod(cells[12]) - j["illuminance_lx"][b].get<double>()) <=
                   1e-12 * j["illuminance_lx"][b].get<double>(),
           "lumens: desk.csv row " + line);
  }
  const nlohmann::json w = runJson(sensorArgs(duplex, dir / "watts.json", "20000", "2", dir / "watts"), dir);
  expect(w["meters"][0]["irradiance_w_m2"][0].get<double>() > 0.0 && !w["meters"][0].contains("illuminance_lx"),
         "watts: meter " + w["meters"].dump());
  expect(w["emitted_power_w"] == 1600.0 && !w.contains("emitted_flux_lm") && !w["energy"].contains("escaped_lm") &&
             !w.contains("lights") && w["sensors"][0]["total_flux_w"].get<double>() > 0.0,
         "watts: " + w.dump());
}

// A CIE overcast sky of 10,000 lx with a sun of 50,000 lx at altitude 40 (`--per-light`): the sky
// and the sun are listed apart; an illuminance meter facing up reads 10,000 + 50,000 sin 40, a
// luminance meter looking at the zenith through 10 degrees reads L_z (2 + cos 10) / 3 (L_z =
// 10,000 / (7 pi / 9)) under the luminance keys and has no illuminance keys.
void checkSkyAndLuminanceMeter(const std::string& duplex, const fs::path& dir) {
  fs::create_directories(dir);
  write(dir / "sky.json", R"({"format": "scene-json-v1", "objects": [], "instances": [], "lights": [
    {"type": "sky", "name": "day", "model": "overcast", "horizontal_illuminance": 10000,
     "sun": {"altitude": 40, "azimuth": 120, "normal_illuminance": 50000}, "centre": [0, 0, 0], "radius": 2}],
    "meters": [{"name": "desk", "points": [[0, 0, 0]], "normal": [0, 0, 1]},
               {"name": "eye", "points": [[0, 0, 0]], "normal": [0, 0, 1], "half_angle": 10},
               {"name": "cam", "camera": {"eye": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov": 10,
                                          "pixels": [2, 2]}}]})");
  std::vector<std::string> args = sensorArgs(duplex, dir / "sky.json", "100000", "2", dir / "sky");
  args.push_back("--per-light");
  const nlohmann::json r = runJson(args, dir);
  const double pi = 3.14159265358979323846;
  expect(r["lights"].size() == 2 && r["lights"][0]["name"] == "day" && r["lights"][1]["name"] == "day/sun",
         "sky: run.json lights " + r["lights"].dump());
  const nlohmann::json& desk = r["meters"][0];
  const double e = 10000 + 50000 * std::sin(40 * pi / 180);
  expect(std::abs(desk["illuminance_lx"][0].get<double>() - e) <= 4.5 * desk["illuminance_stderr_lx"][0].get<double>(),
         "sky: desk " + desk.dump() + ", expected " + std::to_string(e) + " lx");
  const nlohmann::json& eye = r["meters"][1];
  const double l = 10000 / (7 * pi / 9) * (2 + std::cos(10 * pi / 180)) / 3;
  expect(!eye.contains("illuminance_lx") && !eye.contains("irradiance_w_m2") &&
             std::abs(eye["half_angle_deg"].get<double>() - 10.0) < 1e-12 &&
             std::abs(eye["luminance_cd_m2"][0].get<double>() - l) <=
                 4.5 * eye["luminance_stderr_cd_m2"][0].get<double>() &&
             eye["lights"].size() == 2 && eye["lights"][1]["luminance_cd_m2"][0] == 0.0,
         "sky: eye " + eye.dump() + ", expected " + std::to_string(l) + " cd/m^2");
  // The camera's four pixels about the zenith (5 degrees): close to L_z, each within 4.5 SE + 1%
  // of the 10 degree cone's mean (they differ by less than 0.2%).
  const nlohmann::json& cam = r["meters"][2];
  bool pixels = cam["image_size"] == nlohmann::json::array({2, 2}) && cam["luminance_cd_m2"].size() == 4 &&
                !cam.contains("illuminance_lx") && cam["points"].size() == 4;
  for (int k = 0; pixels && k < 4; ++k)
    pixels = std::abs(cam["luminance_cd_m2"][k].get<double>() - l) <=
             4.5 * cam["luminance_stderr_cd_m2"][k].get<double>() + 0.01 * l;
  expect(pixels, "sky: camera " + cam.dump());
  // Its image files: the PNG in false colour with a scale bar, the EXR with run.json's values.
  expectPngWithScaleBar(dir / "sky" / "cam.png");
  expect(cam["png"] == (dir / "sky" / "cam.png").string(), "sky: camera's png key " + cam.dump());
  expectCameraExr(dir / "sky" / "cam.exr", cam);

  // A camera named as a sensor would write over its image: refused before any ray, naming both.
  write(dir / "clash.json", R"({"format": "scene-json-v1", "objects": [], "instances": [],
    "lights": [{"type": "point", "position": [0, 0, 1], "power": 5}],
    "sensors": [{"name": "cam", "shape": "rectangle", "size": [1, 1], "bins": [2, 2]}],
    "meters": [{"name": "cam", "camera": {"eye": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov": 10,
                                          "pixels": [2, 2]}}]})");
  const RunResult clash = run(sensorArgs(duplex, dir / "clash.json", "1000", "1", dir / "clash"), dir.string());
  expect(clash.exited && clash.exit_code == 1 && clash.err.find("sensor 'cam' and camera 'cam'") != std::string::npos &&
             !fs::exists(dir / "clash" / "run.json"),
         "a camera named as a sensor: " + describe(clash) + "\n" + clash.err);
}

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: duplex_sensor_cli_check DUPLEX DIR\n";
    return 2;
  }
  return reportFailures([&] {
    const int status = check(argv[1], argv[2]);  // clears DIR first
    checkBandsAndAngles(argv[1], fs::path(argv[2]) / "spectral");
    checkFarFieldAndEdits(argv[1], fs::path(argv[2]) / "farfield");
    checkOutputFolderRules(argv[1], fs::path(argv[2]) / "output");
    checkSkyAndLuminanceMeter(argv[1], fs::path(argv[2]) / "sky");
    checkBackFacingWarning(argv[1], fs::path(argv[2]) / "back_facing");
    checkPhotometricKeysAndPerLight(argv[1], fs::path(argv[2]) / "photometric");
    return status;
  });
}
