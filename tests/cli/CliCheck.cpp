// duplex_cli_check: the contract tests of the `duplex` tool and the demo, run from CTest.
// It drives the built programs as a tool outside the project would (fork/exec, files, stdout),
// and shares no code with the library: the expected records and camera are computed here.
//
//   duplex_cli_check fixtures DIR                      write the fixtures (QuadScene.h)
//   duplex_cli_check trace DUPLEX DIR                  closest-hit records and the JSON line
//   duplex_cli_check any-hit DUPLEX DIR                --any-hit records
//   duplex_cli_check rays DUPLEX DIR                   `duplex rays` sizes, contract, determinism
//   duplex_cli_check fails DIR NEEDLE -- PROGRAM ARGS  non-zero exit, no crash, NEEDLE in stderr
//   duplex_cli_check demo DEMO DIR                     the demo writes a PNG and prints figures
//   duplex_cli_check shared-data DUPLEX DIR DATA_DIR   real meshes (skipped, status 77, without them)
//   duplex_cli_check document DUPLEX DIR               duplex-scene-v1 vs scene-json-v1: identical hit files
//   duplex_cli_check prepare DUPLEX DIR                `duplex prepare`: structures loaded, same hits
//   duplex_cli_check prepare-koala DUPLEX DIR DATA_DIR koala in 19 objects, prepared (skipped without data)
//   duplex_cli_check bench-update DUPLEX DIR           `duplex bench update` keys and figures on tiny scenes
//   duplex_cli_check bench-update-embree BENCH DIR     the same by duplex_bench_update, with Embree's keys
//   duplex_cli_check bench-frame DUPLEX DIR            `duplex bench frame` keys, hit counts against `duplex trace`
//   duplex_cli_check bench-frame-embree BENCH DUPLEX DIR   the same by duplex_bench_frame; ours and Embree's hits agree
//   duplex_cli_check bench-deform DUPLEX DIR           `duplex bench deform` keys and figures on the quad scene
//   duplex_cli_check closest DUPLEX DIR                `duplex closest` records on the quad scene, the JSON line
//   duplex_cli_check info DUPLEX DIR                   `duplex info` of the quad scene against its hand-worked figures
//   duplex_cli_check disk-full DUPLEX DIR              record files on a full disk: an error, the old file kept
//   duplex_cli_check memory-limit DUPLEX DIR           --max-memory refusals: exit 1, one line, nothing written
// Exit status: 0 pass, 1 fail, 77 skipped.

#include "QuadScene.h"
#include "CheckSupport.h"
#include "Subprocess.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace fs = std::filesystem;
using namespace duplex::clitest;

namespace {

constexpr int kSkip = 77;

std::string show(const HitRecord& h) {
  std::ostringstream s;
  s << "{t=" << h.t << ", u=" << h.u << ", v=" << h.v << ", instance=" << h.instance_id << ", prim=" << h.prim_id
    << "}";
  return s.str();
}

std::string show(const RayRecord& r) {
  std::ostringstream s;
  s << "{o=(" << r.ox << ", " << r.oy << ", " << r.oz << "), d=(" << r.dx << ", " << r.dy << ", " << r.dz << "), t=["
    << r.tnear << ", " << r.tfar << "]}";
  return s.str();
}

// stdout must be exactly one JSON object on one line.
nlohmann::json parseOneLine(const std::string& out) {
  expect(!out.empty() && out.back() == '\n' && out.find('\n') == out.size() - 1,
         "stdout is not exactly one line:\n" + out);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(out);
  } catch (const nlohmann::json::exception& e) {
    throw Failure("stdout is not JSON (" + std::string(e.what()) + "):\n" + out);
  }
  expect(j.is_object(), "stdout is not a JSON object: " + out);
  return j;
}

double number(const nlohmann::json& j, const char* key) {
  expect(j.contains(key) && j[key].is_number(),
         std::string("JSON key \"") + key + "\" missing or not a number: " + j.dump());
  return j[key].get<double>();
}

void compareRecords(const fs::path& actual_path, const fs::path& expected_path, const std::vector<RayRecord>& rays) {
  const auto actual = readRecords<HitRecord>(actual_path);
  const auto expected = readRecords<HitRecord>(expected_path);
  expect(actual.size() == expected.size(), actual_path.string() + ": " + std::to_string(actual.size()) +
                                               " records, expected " + std::to_string(expected.size()));
  std::string errors;
  for (std::size_t i = 0; i < actual.size(); ++i)
    if (std::memcmp(&actual[i], &expected[i], sizeof(HitRecord)) != 0)
      errors += "  ray " + std::to_string(i) + " " + show(rays[i]) + ": got " + show(actual[i]) + ", expected " +
                show(expected[i]) + "\n";
  expect(errors.empty(), actual_path.string() + " differs from the analytic records:\n" + errors);
}

std::vector<std::string> traceArgs(const std::string& duplex, const fs::path& dir, const fs::path& hits) {
  return {duplex,   "trace",      "--scene", (dir / "quad.json").string(), "--rays", (dir / "rays.bin").string(),
          "--hits", hits.string()};
}

// Closest hit or --any-hit over the quad scene: exact records, the JSON line, and the same
// records with any thread count.
int checkTrace(const std::string& duplex, const fs::path& dir, bool any_hit) {
  const QuadCase c = quadCase();
  const fs::path expected = dir / (any_hit ? "expected_any.bin" : "expected_closest.bin");
  const std::string tag = any_hit ? "any" : "closest";
  std::size_t expected_hits = 0;
  for (const HitRecord& h : any_hit ? c.any_hit : c.closest) expected_hits += h.instance_id != kNone;

  // Two threads, three runs: the full report.
  const fs::path hits = dir / ("hits_" + tag + ".bin");
  auto args = traceArgs(duplex, dir, hits);
  args.insert(args.end(), {"--threads", "2", "--repeat", "3"});
  if (any_hit) args.push_back("--any-hit");
  fs::remove(hits);
  const RunResult r = runOk(args, dir);
  const nlohmann::json j = parseOneLine(r.out);
  expect(number(j, "rays") == static_cast<double>(c.rays.size()),
         "\"rays\" is not " + std::to_string(c.rays.size()) + ": " + j.dump());
  expect(number(j, "hits") == static_cast<double>(expected_hits),
         "\"hits\" is not " + std::to_string(expected_hits) + ": " + j.dump());
  expect(number(j, "threads") == 2.0, "\"threads\" is not 2: " + j.dump());
  for (const char* key : {"load_ms", "build_ms", "trace_ms", "mrays_per_s"})
    expect(number(j, key) >= 0.0, std::string("\"") + key + "\" is negative: " + j.dump());
  if (j.contains("trace_ms_all")) {
    expect(j["trace_ms_all"].is_array() && j["trace_ms_all"].size() == 3,
           "\"trace_ms_all\" does not hold 3 runs: " + j.dump());
    std::vector<double> runs = j["trace_ms_all"].get<std::vector<double>>();
    std::sort(runs.begin(), runs.end());
    expect(number(j, "trace_ms") == runs[1], "\"trace_ms\" is not the median of \"trace_ms_all\": " + j.dump());
  }
  compareRecords(hits, expected, c.rays);

  // One thread, and the default thread count: the same records.
  for (const std::vector<std::string>& extra :
       {std::vector<std::string>{"--threads", "1"}, std::vector<std::string>{}}) {
    const fs::path again = dir / ("hits_" + tag + "_again.bin");
    auto a = traceArgs(duplex, dir, again);
    a.insert(a.end(), extra.begin(), extra.end());
    if (any_hit) a.push_back("--any-hit");
    parseOneLine(runOk(a, dir).out);
    compareRecords(again, expected, c.rays);
  }
  // Streamed in blocks of 1, 2 and 3 rays (the last block short): the same records, the same counts.
  for (const std::string block : {"1", "2", "3"}) {
    const fs::path streamed = dir / ("hits_" + tag + "_block" + block + ".bin");
    auto a = traceArgs(duplex, dir, streamed);
    a.insert(a.end(), {"--block-rays", block, "--repeat", "2"});
    if (any_hit) a.push_back("--any-hit");
    const nlohmann::json jb = parseOneLine(runOk(a, dir).out);
    expect(number(jb, "hits") == static_cast<double>(expected_hits) && number(jb, "block_rays") == std::stod(block),
           "--block-rays " + block + ": wrong \"hits\" or \"block_rays\": " + jb.dump());
    compareRecords(streamed, expected, c.rays);
  }
  std::cout << "trace" << (any_hit ? " --any-hit" : "") << ": " << c.rays.size() << " records as expected; " << r.out;
  return 0;
}

// The world box of quad.json, by hand: [0,7] x [0,2] x [-3,1].
constexpr double kBoxLo[3] = {0.0, 0.0, -3.0};
constexpr double kBoxHi[3] = {7.0, 2.0, 1.0};

struct Vec {
  double x, y, z;
  Vec operator+(const Vec& o) const { return {x + o.x, y + o.y, z + o.z}; }
  Vec operator-(const Vec& o) const { return {x - o.x, y - o.y, z - o.z}; }
  Vec operator*(double s) const { return {x * s, y * s, z * s}; }
};
double dot(const Vec& a, const Vec& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
Vec cross(const Vec& a, const Vec& b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
Vec normalize(const Vec& a) { return a * (1.0 / std::sqrt(dot(a, a))); }

bool near(double a, double b, double tol) { return std::abs(a - b) <= tol * std::max(1.0, std::abs(b)); }

// `duplex rays`: record counts, the primary camera of the contract, random rays in the world box,
// determinism per seed.
int checkRays(const std::string& duplex, const fs::path& dir) {
  const std::string scene = (dir / "quad.json").string();
  auto raysCmd = [&](const fs::path& out, std::vector<std::string> mode) {
    std::vector<std::string> a = {duplex, "rays", "--scene", scene};
    a.insert(a.end(), mode.begin(), mode.end());
    a.insert(a.end(), {"--out", out.string()});
    const nlohmann::json j = parseOneLine(runOk(a, dir).out);
    expect(j.contains("out") && j["out"] == out.string(),
           "summary does not name the output " + out.string() + ": " + j.dump());
    return number(j, "rays");
  };
  auto bytes = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };

  // Primary rays: 4 x 3, row-major from the top-left pixel, against an independent camera.
  const fs::path primary = dir / "primary.bin";
  expect(raysCmd(primary, {"--primary", "4", "3"}) == 12.0, "--primary 4 3 does not report 12 rays");
  expect(fs::file_size(primary) == 12 * 32,
         "--primary 4 3 wrote " + std::to_string(fs::file_size(primary)) + " bytes, not 384");
  const Vec lo{kBoxLo[0], kBoxLo[1], kBoxLo[2]}, hi{kBoxHi[0], kBoxHi[1], kBoxHi[2]};
  const Vec centre = (lo + hi) * 0.5;
  const Vec eye = centre + normalize({1.0, 0.6, 0.8}) * std::sqrt(dot(hi - lo, hi - lo));
  const Vec forward = normalize(centre - eye);
  const Vec right = normalize(cross(forward, {0.0, 1.0, 0.0}));
  const Vec up = cross(right, forward);
  const double half_h = std::tan(22.5 * std::numbers::pi / 180.0), half_w = half_h * 4.0 / 3.0;
  const auto p = readRecords<RayRecord>(primary);
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double px = static_cast<double>(i % 4), py = static_cast<double>(i / 4);
    const Vec d = normalize(forward + right * ((2.0 * (px + 0.5) / 4.0 - 1.0) * half_w) +
                            up * ((1.0 - 2.0 * (py + 0.5) / 3.0) * half_h));
    const bool ok = near(p[i].ox, eye.x, 1e-5) && near(p[i].oy, eye.y, 1e-5) && near(p[i].oz, eye.z, 1e-5) &&
                    near(p[i].dx, d.x, 1e-5) && near(p[i].dy, d.y, 1e-5) && near(p[i].dz, d.z, 1e-5) &&
                    p[i].tnear == 0.0f && std::isinf(p[i].tfar) && p[i].tfar > 0.0f;
    std::ostringstream expected;
    expected << "o=(" << eye.x << ", " << eye.y << ", " << eye.z << ") d=(" << d.x << ", " << d.y << ", " << d.z << ")";
    expect(ok, "primary ray " + std::to_string(i) + " is " + show(p[i]) + ", expected " + expected.str());
  }

  // Random rays: size, determinism per seed, origins in the box, unit directions.
  const fs::path r1 = dir / "random1.bin", r2 = dir / "random2.bin", r3 = dir / "random3.bin";
  expect(raysCmd(r1, {"--random", "100", "--seed", "7"}) == 100.0, "--random 100 does not report 100 rays");
  expect(fs::file_size(r1) == 3200, "--random 100 wrote " + std::to_string(fs::file_size(r1)) + " bytes, not 3200");
  raysCmd(r2, {"--random", "100", "--seed", "7"});
  expect(bytes(r1) == bytes(r2), "--random 100 --seed 7 is not deterministic");
  raysCmd(r3, {"--random", "100", "--seed", "8"});
  expect(bytes(r1) != bytes(r3), "--seed 8 gives the same rays as --seed 7");
  // Counts as people write them, the tool's -v after the command, and the default seed (1), which
  // the JSON and stderr report.
  const fs::path r4 = dir / "random4.bin", r5 = dir / "random5.bin", r6 = dir / "random6.bin";
  expect(raysCmd(r4, {"--random", "1e2", "--seed", "7", "-v"}) == 100.0 && bytes(r4) == bytes(r1),
         "--random 1e2 --seed 7 -v is not --random 100 --seed 7");
  const RunResult unseeded = runOk({duplex, "rays", "--scene", scene, "--random", "0.1k", "--out", r5.string()}, dir);
  const nlohmann::json js = parseOneLine(unseeded.out);
  expect(js.contains("seed") && js["seed"] == 1 && number(js, "rays") == 100.0,
         "--random 0.1k without --seed does not report 100 rays and \"seed\": 1: " + js.dump());
  expect(unseeded.err.find("default seed 1") != std::string::npos,
         "--random without --seed does not say on stderr which seed it used:\n" + unseeded.err);
  raysCmd(r6, {"--random", "100", "--seed", "1"});
  expect(bytes(r5) == bytes(r6), "--random without --seed is not --seed 1");
  for (const RayRecord& r : readRecords<RayRecord>(r1)) {
    const double o[3] = {r.ox, r.oy, r.oz};
    bool inside = true;
    for (int k = 0; k < 3; ++k) inside &= o[k] >= kBoxLo[k] - 1e-4 && o[k] <= kBoxHi[k] + 1e-4;
    const double len = std::sqrt(double(r.dx) * r.dx + double(r.dy) * r.dy + double(r.dz) * r.dz);
    expect(inside && near(len, 1.0, 1e-5) && r.tnear == 0.0f && std::isinf(r.tfar),
           "random ray " + show(r) + " is not in the world box with a unit direction and t in [0, inf)");
  }
  std::cout << "rays: primary 4x3 (384 bytes) and random 100 (3200 bytes, deterministic) as expected\n";
  return 0;
}

int checkFails(const fs::path& dir, const std::string& needle, const std::vector<std::string>& argv) {
  const RunResult r = run(argv, dir.string());
  std::string cmd;
  for (const std::string& a : argv) cmd += a + " ";
  expect(r.exited, "`" + cmd + "` crashed (" + describe(r) + "); stderr:\n" + r.err);
  expect(r.exit_code != 0, "`" + cmd + "` succeeded on bad input; stdout:\n" + r.out);
  expect(r.err.find(needle) != std::string::npos, "`" + cmd + "`: stderr does not name '" + needle + "':\n" + r.err);
  expect(r.out.empty(), "`" + cmd + "` printed on stdout:\n" + r.out);
  std::cout << describe(r) << ", stderr: " << r.err;
  return 0;
}

// A full disk, made by a file-size limit (ulimit -f: writes past it fail with EFBIG): each command
// that writes a record file fails with an error naming the file, the file keeps what it held
// before, and no temporary file is left beside it.
int checkDiskFull(const std::string& duplex, const fs::path& dir) {
  const fs::path big_rays = dir / "full_disk_rays.bin";
  runOk({duplex, "rays", "--scene", (dir / "quad.json").string(), "--random", "2000", "--seed", "3", "--out",
         big_rays.string()},
        dir);
  const fs::path points = dir / "full_disk_points.bin";
  {
    std::vector<float> p(4 * 2000, 0.5f);
    std::ofstream out(points, std::ios::binary);
    out.write(reinterpret_cast<const char*>(p.data()), static_cast<std::streamsize>(p.size() * sizeof(float)));
  }
  const std::string scene = (dir / "quad.json").string();
  const fs::path out = dir / "full_disk_out.bin";
  struct Case {
    std::string what;
    std::vector<std::string> args;
  };
  const std::vector<Case> cases = {
      {"trace --hits", {duplex, "trace", "--scene", scene, "--rays", big_rays.string(), "--hits", out.string()}},
      {"trace --any-hit",
       {duplex, "trace", "--scene", scene, "--rays", big_rays.string(), "--hits", out.string(), "--any-hit"}},
      {"trace --block-rays",
       {duplex, "trace", "--scene", scene, "--rays", big_rays.string(), "--hits", out.string(), "--block-rays", "7"}},
      {"rays --random", {duplex, "rays", "--scene", scene, "--random", "2000", "--seed", "1", "--out", out.string()}},
      {"closest", {duplex, "closest", "--scene", scene, "--points", points.string(), "--out", out.string()}},
  };
  for (const Case& c : cases) {
    {
      std::ofstream before(out, std::ios::binary | std::ios::trunc);
      before << "the previous output";
    }
    std::vector<std::string> argv = {"/bin/sh", "-c", "ulimit -f 4 && exec \"$0\" \"$@\""};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    const RunResult r = run(argv, dir.string());
    expect(r.exited, c.what + " on a full disk crashed (" + describe(r) + "); stderr:\n" + r.err);
    expect(r.exit_code != 0, c.what + " on a full disk exited 0; stdout:\n" + r.out);
    expect(r.err.find(out.string()) != std::string::npos,
           c.what + ": stderr does not name " + out.string() + ":\n" + r.err);
    std::ifstream in(out, std::ios::binary);
    const std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    expect(kept == "the previous output", c.what + " on a full disk changed " + out.string());
    fs::path tmp = out;
    tmp += ".tmp";
    expect(!fs::exists(tmp), c.what + " on a full disk left " + tmp.string());
    std::cout << c.what << ": " << r.err;
  }
  return 0;
}

int checkDemo(const std::string& demo, const fs::path& dir) {
  const fs::path png = dir / "demo_out" / "demo.png";
  fs::remove_all(dir / "demo_out");
  const RunResult r = runOk({demo, "--width", "64", "--height", "36", "--threads", "2", "--out", png.string()}, dir);
  std::ifstream in(png, std::ios::binary);
  char signature[8] = {};
  in.read(signature, 8);
  expect(in && std::memcmp(signature, "\x89PNG\r\n\x1a\n", 8) == 0, png.string() + " is not a PNG");
  for (const char* word : {"Mrays/s", "build", "load", "instances", "triangles"})
    expect(r.out.find(word) != std::string::npos, std::string("demo output lacks '") + word + "':\n" + r.out);
  std::cout << r.out;
  return 0;
}

void expectSameFile(const fs::path& a, const fs::path& b);

// Real meshes from ../shared/data: three instances of spot.obj, primary rays, closest and any-hit
// agree on which rays hit, and thread counts and --single (no packets) do not change the records.
int checkSharedData(const std::string& duplex, const fs::path& dir, const fs::path& data) {
  const fs::path spot = data / "meshes" / "spot.obj";
  if (!fs::exists(spot)) {
    std::cout << "skipped: " << spot.string() << " not found (the shared data folder is not beside the repository)\n";
    return kSkip;
  }
  const fs::path scene = dir / "spot_scene.json";
  {
    std::ofstream out(scene);
    out << R"({"format": "scene-json-v1", "objects": [{"name": "spot", "mesh": {"file": )"
        << nlohmann::json(spot.string()).dump() << R"(}}], "instances": [
      {"object": "spot", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]},
      {"object": "spot", "transform": [0,0,1,1.5, 0,1,0,0, -1,0,0,0]},
      {"object": "spot", "transform": [0.5,0,0,-1.2, 0,0.5,0,0.3, 0,0,0.5,0.4]}]})";
  }
  const fs::path rays = dir / "spot_rays.bin";
  runOk({duplex, "rays", "--scene", scene.string(), "--primary", "64", "48", "--out", rays.string()}, dir);
  auto trace = [&](const fs::path& hits, std::vector<std::string> extra) {
    std::vector<std::string> a = {duplex,   "trace",       "--scene", scene.string(),
                                  "--rays", rays.string(), "--hits",  hits.string()};
    a.insert(a.end(), extra.begin(), extra.end());
    return parseOneLine(runOk(a, dir).out);
  };
  const nlohmann::json closest = trace(dir / "spot_hits1.bin", {"--threads", "1"});
  trace(dir / "spot_hits2.bin", {"--threads", "2"});
  const nlohmann::json any = trace(dir / "spot_any.bin", {"--any-hit"});
  const nlohmann::json single = trace(dir / "spot_single.bin", {"--single"});
  const nlohmann::json any_single = trace(dir / "spot_any_single.bin", {"--any-hit", "--single"});
  expect(closest.value("packets", false) && !single.value("packets", true),
         "\"packets\" is not true by default and false with --single: " + closest.dump() + " / " + single.dump());
  expectSameFile(dir / "spot_hits1.bin", dir / "spot_single.bin");
  expectSameFile(dir / "spot_any.bin", dir / "spot_any_single.bin");
  (void)any_single;
  expect(number(closest, "hits") > 0.0, "no primary ray hits spot: " + closest.dump());
  expect(number(closest, "hits") == number(any, "hits"),
         "closest hit and --any-hit disagree on the number of hits: " + closest.dump() + " vs " + any.dump());
  const auto h1 = readRecords<HitRecord>(dir / "spot_hits1.bin"), h2 = readRecords<HitRecord>(dir / "spot_hits2.bin");
  expect(h1.size() == 64 * 48 && std::memcmp(h1.data(), h2.data(), h1.size() * sizeof(HitRecord)) == 0,
         "1 and 2 threads write different hit files");
  std::cout << "shared data: " << closest.dump() << "\n";
  return 0;
}

// ---- duplex-scene-v1, prepared structures and the update benchmark ----

// A row-major 3x4 matrix [r00 r01 r02 t0 r10 ... t2], world_from_object, composed by hand here.
using Mat34 = std::array<double, 12>;

Mat34 compose(const Mat34& a, const Mat34& b) {  // a * b: b first
  Mat34 m{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      double v = c == 3 ? a[r * 4 + 3] : 0.0;
      for (int k = 0; k < 3; ++k) v += a[r * 4 + k] * b[k * 4 + c];
      m[r * 4 + c] = v;
    }
  }
  return m;
}
Mat34 translate(double x, double y, double z) { return {1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z}; }
Mat34 scale(double x, double y, double z) { return {x, 0, 0, 0, 0, y, 0, 0, 0, 0, z, 0}; }

// The same five instances twice: doc_tree.json (duplex-scene-v1: groups, transform nodes given as
// translate/scale/matrix, an empty group, a mask, and a hidden group last, whose instance has id 5
// and is never hit) and doc_flat.json (scene-json-v1: the world matrices, in depth-first order).
// Every number is a small dyadic rational and rotations are permutations, so both give the same
// world matrices bit for bit and must give byte-identical hit files.
void writeDocumentFixtures(const fs::path& dir) {
  fs::create_directories(dir);
  {
    std::ofstream obj(dir / "doc_tet.obj");
    obj << "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  }
  const std::string objects = R"([
    {"name": "quad", "mesh": {"positions": [0,0,0, 1,0,0, 1,1,0, 0,1,0], "indices": [0,1,2, 0,2,3]}},
    {"name": "tet", "mesh": {"file": "doc_tet.obj"}},
    {"name": "tri", "mesh": {"positions": [0,0,0, 1,0,0, 0,1,0], "indices": [0,1,2]}}])";
  {
    std::ofstream tree(dir / "doc_tree.json");
    tree << R"({"format": "duplex-scene-v1", "objects": )" << objects << R"(,
 "nodes": [
  {"instance": "floor", "object": "quad", "transform": {"scale": [8, 8, 1], "translate": [-4, -4, 0]}},
  {"group": "rig", "translate": [1, 2, 3], "children": [
    {"instance": "a", "object": "tet", "transform": {"scale": 2}},
    {"group": "arm", "matrix": [0,0,1,0.5, 0,1,0,0, -1,0,0,0], "children": [
      {"instance": "b", "object": "tet", "transform": [1,0,0,0.25, 0,1,0,0, 0,0,1,-1]},
      {"instance": "c", "object": "tri", "transform": {"scale": [0.5, 2, 1], "translate": [0, 1, 0]}, "mask": 2}]},
    {"group": "empty"}]},
  {"instance": "d", "object": "quad", "transform": {"matrix": [1,0,0,-2, 0,0,-1,1, 0,1,0,0]}},
  {"group": "hidden", "visible": false, "children": [{"instance": "h", "object": "tet"}]}]})";
  }
  const Mat34 rig = translate(1, 2, 3), arm = {0, 0, 1, 0.5, 0, 1, 0, 0, -1, 0, 0, 0};
  const std::vector<std::pair<std::string, Mat34>> instances = {
      {"quad", compose(translate(-4, -4, 0), scale(8, 8, 1))},
      {"tet", compose(rig, scale(2, 2, 2))},
      {"tet", compose(compose(rig, arm), {1, 0, 0, 0.25, 0, 1, 0, 0, 0, 0, 1, -1})},
      {"tri", compose(compose(rig, arm), compose(translate(0, 1, 0), scale(0.5, 2, 1)))},
      {"quad", {1, 0, 0, -2, 0, 0, -1, 1, 0, 1, 0, 0}}};
  nlohmann::json list = nlohmann::json::array();
  for (const auto& [object, m] : instances) list.push_back({{"object", object}, {"transform", m}});
  std::ofstream flat(dir / "doc_flat.json");
  flat << R"({"format": "scene-json-v1", "objects": )" << objects << R"(, "instances": )" << list.dump() << "}";
}

std::string fileBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

nlohmann::json traceJson(const std::string& duplex, const fs::path& dir, const fs::path& scene, const fs::path& rays,
                         const fs::path& hits, std::vector<std::string> extra) {
  std::vector<std::string> a = {duplex,   "trace",       "--scene", scene.string(),
                                "--rays", rays.string(), "--hits",  hits.string()};
  a.insert(a.end(), extra.begin(), extra.end());
  return parseOneLine(runOk(a, dir).out);
}

void expectSameFile(const fs::path& a, const fs::path& b) {
  expect(fs::exists(a) && fs::exists(b) && fileBytes(a) == fileBytes(b),
         a.string() + " and " + b.string() + " differ (expected byte-identical hit files)");
}

// duplex-scene-v1 against scene-json-v1: the same rays (bounds of the visible instances), and
// byte-identical closest-hit and --any-hit files, with 1 and 2 threads.
// Each of these checks writes its own subfolder of the fixtures (CTest runs them in parallel).
int checkDocument(const std::string& duplex, const fs::path& fixtures) {
  const fs::path dir = fixtures / "document";
  writeDocumentFixtures(dir);
  const fs::path tree = dir / "doc_tree.json", flat = dir / "doc_flat.json";
  for (const auto& [name, mode] : std::vector<std::pair<std::string, std::vector<std::string>>>{
           {"random", {"--random", "4000", "--seed", "5"}}, {"primary", {"--primary", "48", "32"}}}) {
    const fs::path rays_tree = dir / ("doc_" + name + "_tree.bin"), rays_flat = dir / ("doc_" + name + ".bin");
    for (const auto& [scene, out] : {std::pair{tree, rays_tree}, std::pair{flat, rays_flat}}) {
      std::vector<std::string> a = {duplex, "rays", "--scene", scene.string()};
      a.insert(a.end(), mode.begin(), mode.end());
      a.insert(a.end(), {"--out", out.string()});
      parseOneLine(runOk(a, dir).out);
    }
    expectSameFile(rays_tree, rays_flat);

    for (const bool any_hit : {false, true}) {
      const std::string tag = name + (any_hit ? "_any" : "");
      std::vector<std::string> extra = {"--threads", "2"};
      if (any_hit) extra.push_back("--any-hit");
      const nlohmann::json jt = traceJson(duplex, dir, tree, rays_flat, dir / ("doc_hits_" + tag + "_tree.bin"), extra);
      const nlohmann::json jf = traceJson(duplex, dir, flat, rays_flat, dir / ("doc_hits_" + tag + "_flat.bin"), extra);
      extra[1] = "1";
      traceJson(duplex, dir, tree, rays_flat, dir / ("doc_hits_" + tag + "_tree1.bin"), extra);
      expectSameFile(dir / ("doc_hits_" + tag + "_tree.bin"), dir / ("doc_hits_" + tag + "_flat.bin"));
      expectSameFile(dir / ("doc_hits_" + tag + "_tree.bin"), dir / ("doc_hits_" + tag + "_tree1.bin"));
      expect(jt.value("format", "") == "duplex-scene-v1" && jf.value("format", "") == "scene-json-v1",
             "\"format\" does not name the scene formats: " + jt.dump() + " / " + jf.dump());
      expect(number(jt, "instances") == 6.0 && number(jf, "instances") == 5.0,
             "\"instances\" is not 6 (tree, hidden one included) and 5 (flat): " + jt.dump() + " / " + jf.dump());
      expect(number(jt, "hits") == number(jf, "hits") && number(jt, "hits") > 0.0,
             "hit counts differ or are 0: " + jt.dump());
      if (!any_hit) {
        std::vector<int> per_instance(5, 0);
        for (const HitRecord& h : readRecords<HitRecord>(dir / ("doc_hits_" + tag + "_tree.bin"))) {
          if (h.instance_id == kNone) continue;
          expect(h.instance_id < 5, "a hit names instance " + std::to_string(h.instance_id) + " (hidden or unknown)");
          ++per_instance[h.instance_id];
        }
        if (name == "random")
          for (std::size_t i = 0; i < 5; ++i)
            expect(per_instance[i] > 0,
                   "no random ray hits instance " + std::to_string(i) + " (the fixture misses its point)");
      }
      std::cout << "document " << tag << ": identical hit files; " << jt.dump() << "\n";
    }
  }
  return 0;
}

// `duplex prepare`: both formats; the copies load every structure instead of building it, give
// the same hits, and a damaged structure is refused with its file named.
int checkPrepare(const std::string& duplex, const fs::path& fixtures) {
  const fs::path dir = fixtures / "prepare";
  writeDocumentFixtures(dir);
  const fs::path rays = dir / "prep_rays.bin";
  runOk({duplex, "rays", "--scene", (dir / "doc_flat.json").string(), "--random", "3000", "--seed", "9", "--out",
         rays.string()},
        dir);
  for (const std::string name : {"doc_tree", "doc_flat"}) {
    const fs::path source = dir / (name + ".json"), out = dir / ("prepared_" + name);
    fs::remove_all(out);
    const nlohmann::json p =
        parseOneLine(runOk({duplex, "prepare", "--scene", source.string(), "--out", out.string()}, dir).out);
    const fs::path prepared = out / (name + ".json");
    expect(
        p.value("scene", "") == prepared.string() && number(p, "structures") == 3.0 && number(p, "mesh_objects") == 3.0,
        "prepare report: " + p.dump());
    const nlohmann::json copy = nlohmann::json::parse(fileBytes(prepared));
    expect(copy.value("format", "") == "duplex-scene-v1", prepared.string() + " is not duplex-scene-v1");
    for (const nlohmann::json& object : copy["objects"])
      expect(object.contains("structure") && fs::exists(out / object["structure"].get<std::string>()),
             prepared.string() + ": object without an existing structure file: " + object.dump());

    const nlohmann::json built = traceJson(duplex, dir, source, rays, dir / ("prep_hits_" + name + ".bin"), {});
    const nlohmann::json loaded =
        traceJson(duplex, dir, prepared, rays, dir / ("prep_hits_" + name + "_prepared.bin"), {});
    expect(number(built, "structures_loaded") == 0.0 && number(loaded, "structures_loaded") == 3.0,
           "structures_loaded is not 0 (source) and 3 (prepared): " + built.dump() + " / " + loaded.dump());
    expectSameFile(dir / ("prep_hits_" + name + ".bin"), dir / ("prep_hits_" + name + "_prepared.bin"));

    // A damaged structure: the load fails and names the file.
    const fs::path bad = dir / ("prepared_bad_" + name);
    fs::remove_all(bad);
    fs::copy(out, bad);
    const fs::path damaged = bad / copy["objects"][1]["structure"].get<std::string>();
    std::string bytes = fileBytes(damaged);
    bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x5A);
    std::ofstream(damaged, std::ios::binary | std::ios::trunc) << bytes;
    const RunResult r = run({duplex, "trace", "--scene", (bad / (name + ".json")).string(), "--rays", rays.string(),
                             "--hits", (dir / "prep_bad_hits.bin").string()},
                            dir.string());
    expect(r.exited && r.exit_code == 1 && r.err.find(damaged.filename().string()) != std::string::npos,
           "a damaged structure was not refused with its file named (" + describe(r) + "): " + r.err);
    std::cout << "prepare " << name << ": " << p.dump() << "\n  built " << built.dump() << "\n  loaded "
              << loaded.dump() << "\n";
  }
  return 0;
}

// --structure: the default structure of the entries that choose none, on every command that loads
// a scene. The BVH (default, and a preset with parameters) and the kd-tree give the same hits (the
// same watertight triangle test behind either structure); the JSON reports the structures built;
// `duplex prepare` writes each structure's own files, and a prepared file decides over --structure.
int checkStructure(const std::string& duplex, const fs::path& fixtures) {
  const fs::path dir = fixtures / "structure";
  writeDocumentFixtures(dir);
  const fs::path tree = dir / "doc_tree.json", rays = dir / "st_rays.bin";
  runOk({duplex, "rays", "--scene", tree.string(), "--random", "4000", "--seed", "3", "--out", rays.string()}, dir);
  const fs::path rays_kd = dir / "st_rays_kd.bin";
  runOk({duplex, "rays", "--scene", tree.string(), "--random", "4000", "--seed", "3", "--out", rays_kd.string(),
         "--structure", "kdtree"},
        dir);
  expectSameFile(rays, rays_kd);
  const std::vector<std::pair<std::string, std::string>> choices = {
      {"", "bvh"}, {"bvh", "bvh"}, {"kdtree", "kdtree"}, {"bvh:fast,leaf=2", "bvh"}};
  for (const bool any_hit : {false, true}) {
    fs::path first;
    for (std::size_t k = 0; k < choices.size(); ++k) {
      const auto& [choice, structure] = choices[k];
      std::vector<std::string> extra;
      if (!choice.empty()) extra = {"--structure", choice};
      if (any_hit) extra.push_back("--any-hit");
      const fs::path hits = dir / ("st_hits_" + std::to_string(k) + (any_hit ? "_any" : "") + ".bin");
      const nlohmann::json j = traceJson(duplex, dir, tree, rays, hits, extra);
      // doc_tree.json has three mesh objects (two entries share the tet's file).
      expect(j.contains("mesh_structures") && j["mesh_structures"] == nlohmann::json{{structure, 3}},
             "--structure '" + choice + "': mesh_structures is not {\"" + structure + "\": 3}: " + j.dump());
      expect(number(j, "hits") > 0.0, "no hits: " + j.dump());
      if (first.empty()) {
        first = hits;
      } else {
        expectSameFile(first, hits);
      }
    }
  }
  std::cout << "structure: bvh, kdtree and bvh:fast,leaf=2 give identical hit files\n";

  // prepare: the files of the structure built; the copy loads them whatever --structure says.
  for (const auto& [choice, ext] : {std::pair<std::string, std::string>{"", ".dbvh"}, {"kdtree", ".dkdt"}}) {
    const fs::path out = dir / ("prepared_" + (choice.empty() ? std::string("default") : choice));
    fs::remove_all(out);
    std::vector<std::string> a = {duplex, "prepare", "--scene", tree.string(), "--out", out.string()};
    if (!choice.empty()) a.insert(a.end(), {"--structure", choice});
    const nlohmann::json p = parseOneLine(runOk(a, dir).out);
    const std::string structure = ext == ".dbvh" ? "bvh" : "kdtree";
    expect(p["mesh_structures"] == nlohmann::json{{structure, 3}}, "prepare report: " + p.dump());
    const nlohmann::json copy = nlohmann::json::parse(fileBytes(out / "doc_tree.json"));
    for (const nlohmann::json& object : copy["objects"])
      expect(fs::path(object["structure"].get<std::string>()).extension() == ext,
             "prepared with --structure '" + choice + "': " + object.dump() + " is not a " + ext + " file");
    const std::string other = structure == "bvh" ? "kdtree" : "bvh";
    const nlohmann::json loaded = traceJson(duplex, dir, out / "doc_tree.json", rays,
                                            dir / ("st_prepared_" + structure + ".bin"), {"--structure", other});
    expect(number(loaded, "structures_loaded") == 3.0 && loaded["mesh_structures"] == nlohmann::json{{structure, 3}},
           "the prepared " + ext + " files did not decide the structure: " + loaded.dump());
    expectSameFile(dir / "st_hits_0.bin", dir / ("st_prepared_" + structure + ".bin"));
  }

  // The other commands that load scenes take it too.
  const nlohmann::json b =
      parseOneLine(runOk({duplex, "bench", "update", "--scene", tree.string(), "--moves", "1", "--repeat", "2",
                          "--build-repeat", "1", "--primary", "16", "--structure", "kdtree"},
                         dir)
                       .out);
  expect(number(b, "update_ms_median") > 0.0, "bench update --structure kdtree: " + b.dump());
  const RunResult help = run({duplex, "sensor", "--help"}, dir.string());
  expect(help.out.find("--structure") != std::string::npos, "duplex sensor --help has no --structure");
  return 0;
}

// The paper's first scene: koala split into 19 objects, prepared; load + build of both.
int checkPrepareKoala(const std::string& duplex, const fs::path& dir, const fs::path& data) {
  const fs::path koala = data / "meshes" / "koala.obj";
  if (!fs::exists(koala)) {
    std::cout << "skipped: " << koala.string() << " not found\n";
    return kSkip;
  }
  fs::create_directories(dir);
  const fs::path scene = dir / "koala19.json", out = dir / "koala19_prepared", rays = dir / "koala19_rays.bin";
  fs::remove_all(out);
  runOk({duplex, "scene", "split", "--mesh", koala.string(), "--objects", "19", "--out", scene.string()}, dir);
  runOk({duplex, "prepare", "--scene", scene.string(), "--out", out.string()}, dir);
  runOk({duplex, "rays", "--scene", scene.string(), "--primary", "128", "128", "--out", rays.string()}, dir);
  const nlohmann::json built = traceJson(duplex, dir, scene, rays, dir / "koala19_hits.bin", {});
  const nlohmann::json loaded =
      traceJson(duplex, dir, out / "koala19.json", rays, dir / "koala19_hits_prepared.bin", {});
  expect(number(loaded, "structures_loaded") == 19.0, "prepared koala did not load 19 structures: " + loaded.dump());
  expectSameFile(dir / "koala19_hits.bin", dir / "koala19_hits_prepared.bin");
  for (const auto& [what, j] : {std::pair{"original", built}, std::pair{"prepared", loaded}})
    std::cout << "koala 19 objects, " << what << ": load_ms " << number(j, "load_ms") << ", bottom_build_ms "
              << number(j, "bottom_build_ms") << ", build_ms " << number(j, "build_ms") << ", load+build ms "
              << number(j, "load_ms") + number(j, "build_ms") << "\n";
  return 0;
}

// `duplex bench update` on tiny scenes: the documented keys and positive times. The installed
// tool has no Embree baseline: no Embree figure, ratio or version in its JSON, and no source
// revision (it never reads the checkout it was built from). duplex_bench_update built with Embree
// (`embree`) has them all, and ours and Embree's hits agree after the same edits.
int checkBenchUpdate(const std::vector<std::string>& command, const fs::path& fixtures, bool embree) {
  const fs::path dir = fixtures / (embree ? "bench_update_embree" : "bench_update");
  writeDocumentFixtures(dir);
  for (const fs::path& scene : {fixtures / "quad.json", dir / "doc_tree.json"}) {
    std::vector<std::string> args = command;
    args.insert(args.end(), {"--scene", scene.string(), "--moves", "2", "--repeat", "3", "--seed", "4", "--threads",
                             "2", "--primary", "48"});
    const nlohmann::json j = parseOneLine(runOk(args, dir).out);
    expect(number(j, "moves") == 2.0 && number(j, "repeat") == 3.0, "moves/repeat not as given: " + j.dump());
    for (const char* key : {"update_ms_median", "full_rebuild_ms_median", "add_ms_median", "remove_ms_median",
                            "build_ms", "mrays_per_s", "prepared_build_ms_median", "prepared_library_bytes"})
      expect(number(j, key) > 0.0, std::string("\"") + key + "\" is not positive: " + j.dump());
    expect(j.contains("machine") && j["machine"].is_object(), "no \"machine\" object: " + j.dump());
    const nlohmann::json& machine = j["machine"];
    if (embree) {
      expect(number(j, "embree_update_ms_median") > 0.0, "\"embree_update_ms_median\" is not positive: " + j.dump());
      expect(number(j, "agreement_with_embree") >= 0.99, "ours and Embree disagree after the same edits: " + j.dump());
      expect(number(j, "hits") == number(j, "embree_hits"), "ours and Embree hit different ray counts: " + j.dump());
      expect(number(j, "embree_dynamic_low_update_ms_median") > 0.0,
             "\"embree_dynamic_low_update_ms_median\" is not positive: " + j.dump());
      // The full builds' interleaved rounds (7 by default): per-round ratios ours / Embree.
      expect(number(j, "embree_high_build_ms") > 0.0, "\"embree_high_build_ms\" is not positive: " + j.dump());
      for (const std::string key : {"full_build_ratio", "prepared_build_ratio", "full_build_ratio_vs_embree_high"})
        expect(number(j, (key + "_min").c_str()) > 0.0 &&
                   number(j, (key + "_min").c_str()) <= number(j, (key + "_median").c_str()) &&
                   number(j, (key + "_median").c_str()) <= number(j, (key + "_max").c_str()),
               "\"" + key + "\" min / median / max out of order: " + j.dump());
      expect(machine.value("embree_version", nlohmann::json()).is_string(),
             "machine.embree_version is not a string: " + machine.dump());
    } else {
      for (const auto& [key, value] : j.items())
        expect(key.find("embree") == std::string::npos && key.find("ratio") == std::string::npos,
               "the tool, built without Embree, reports \"" + key + "\": " + j.dump());
      for (const char* key : {"embree_version", "duplex_git_revision", "duplex_library_dirty"})
        expect(machine.contains(key) && machine[key].is_null(),
               std::string("machine.") + key + " is not null in the tool: " + machine.dump());
    }
    expect(number(j, "full_build_rounds") == 7.0, "\"full_build_rounds\" is not the default 7: " + j.dump());
    std::cout << "bench update " << scene.filename().string() << ": " << j.dump() << "\n";
  }
  return 0;
}

// `duplex bench frame` on tiny scenes and frames. Every run starts from the loaded scene, so its
// untimed first frame hits as many primary rays as `duplex trace` on `duplex rays --primary W H`
// (the same pixels); frames without moves keep that count; ours replays the same frames with 1 and
// 2 threads, so its per-frame counts agree between them. duplex_bench_frame (`embree`) adds
// Embree's sides, whose per-frame hit counts must agree with ours (hits_agree), and the ratios.
int checkBenchFrame(const std::vector<std::string>& command, const std::string& duplex, const fs::path& fixtures,
                    bool embree) {
  const fs::path dir = fixtures / (embree ? "bench_frame_embree" : "bench_frame");
  writeDocumentFixtures(dir);
  for (const fs::path& scene : {fixtures / "quad.json", dir / "doc_tree.json"}) {
    const std::string stem = scene.stem().string();
    const fs::path rays = dir / (stem + "_frame_rays.bin"), hits = dir / (stem + "_frame_hits.bin");
    runOk({duplex, "rays", "--scene", scene.string(), "--primary", "40", "30", "--out", rays.string()}, dir);
    (void)traceJson(duplex, dir, scene, rays, hits, {"--threads", "1"});
    std::uint64_t expected_hits = 0;
    for (const HitRecord& h : readRecords<HitRecord>(hits)) expected_hits += h.instance_id != kNone ? 1 : 0;
    expect(expected_hits > 0, scene.string() + ": the check's camera sees nothing");

    std::vector<std::string> args = command;
    args.insert(args.end(), {"--scene", scene.string(), "--moves", "0,1,50%", "--threads", "1,2", "--frames", "3",
                             "--size", "40", "30", "--seed", "4"});
    const nlohmann::json j = parseOneLine(runOk(args, dir).out);
    expect(number(j, "primary_rays") == 1200.0 && number(j, "frames") == 3.0, "rays/frames not as given: " + j.dump());
    expect(j.contains("runs") && j["runs"].is_array() && j["runs"].size() == 6, "expected 6 runs: " + j.dump());
    expect(j.contains("sides") && j["sides"].is_array() && !j["sides"].empty() && j["sides"][0] == "ours",
           "\"sides\" does not start with ours: " + j.dump());
    expect(j.contains("machine") && j["machine"].is_object(), "no \"machine\" object: " + j.dump());
    const nlohmann::json& runs = j["runs"];
    for (std::size_t r = 0; r < runs.size(); ++r) {
      const nlohmann::json& run = runs[r];
      expect(number(run, "threads") == (r < 3 ? 1.0 : 2.0), "runs not ordered by threads, then moves: " + j.dump());
      for (const auto& name : j["sides"]) {
        expect(run.contains(name.get<std::string>()), "run without side " + name.dump() + ": " + run.dump());
        const nlohmann::json& side = run[name.get<std::string>()];
        for (const char* key : {"frame_ms_median", "trace_ms_median", "primary_ms_median"})
          expect(number(side, key) > 0.0, std::string("\"") + key + "\" is not positive: " + side.dump());
        expect(number(side, "edit_commit_ms_median") >= 0.0 && number(side, "shadow_ms_median") >= 0.0,
               "negative times: " + side.dump());
        expect(number(side, "frame_ms_min") <= number(side, "frame_ms_median") &&
                   number(side, "frame_ms_median") <= number(side, "frame_ms_max"),
               "frame_ms min / median / max out of order: " + side.dump());
        for (const char* key :
             {"frame_ms", "edit_commit_ms", "trace_ms", "primary_hits", "shadow_rays", "shadow_blocked"})
          expect(side.contains(key) && side[key].is_array() && side[key].size() == 3,
                 std::string("\"") + key + "\" is not an array of 3 frames: " + side.dump());
        expect(number(side, "static_primary_hits") == static_cast<double>(expected_hits),
               scene.string() + ": the first frame's hits differ from `duplex trace` (" +
                   std::to_string(expected_hits) + "): " + side.dump());
        if (run["moves"] == 0)
          for (std::size_t f = 0; f < 3; ++f)
            expect(side["primary_hits"][f] == side["static_primary_hits"] &&
                       side["shadow_blocked"][f] == side["static_shadow_blocked"] &&
                       side["shadow_rays"][f] == side["static_primary_hits"],
                   "frames without moves changed the hits: " + side.dump());
      }
      // The same frames with 1 and 2 threads.
      if (r >= 3)
        for (const char* key : {"primary_hits", "shadow_blocked"})
          expect(run["ours"][key] == runs[r - 3]["ours"][key],
                 std::string("ours: \"") + key + "\" differs between 1 and 2 threads: " + j.dump());
      if (embree) {
        expect(run.value("hits_agree", false) == true, "ours and Embree's hit counts disagree: " + run.dump());
        for (const char* key : {"ratio_frame", "ratio_trace", "embree_frame_ms_median"})
          expect(number(run, key) > 0.0, std::string("\"") + key + "\" is not positive: " + run.dump());
        expect(run.contains("embree_best") && run.contains(run["embree_best"].get<std::string>()),
               "\"embree_best\" names no side: " + run.dump());
      } else {
        for (const auto& [key, value] : run.items())
          expect(key.find("embree") == std::string::npos && key.find("ratio") == std::string::npos,
                 "the tool, built without Embree, reports \"" + key + "\": " + run.dump());
      }
    }
    // 50% of 4 instances (quad.json) and of 5 visible ones (doc_tree.json, rounded half up).
    expect(runs[1]["moves"] == 1 && runs[2]["moves"] == (stem == "doc_tree" ? 3 : 2),
           "--moves 1 and 50% not resolved as expected: " + j.dump());
    if (embree)
      expect(j["machine"].value("embree_version", nlohmann::json()).is_string(),
             "machine.embree_version is not a string: " + j["machine"].dump());
    std::cout << "bench frame " << scene.filename().string() << ": " << runs[1].dump() << "\n";
  }
  return 0;
}

// `duplex bench deform` on the quad scene: the documented keys, positive times, every step either
// a refit or a counted rebuild, and the refitted object tracing the same hits as a fresh one.
int checkBenchDeform(const std::string& duplex, const fs::path& fixtures) {
  const nlohmann::json j =
      parseOneLine(runOk({duplex, "bench", "deform", "--scene", (fixtures / "quad.json").string(), "--object", "quad",
                          "--steps", "6", "--seed", "3", "--primary", "40", "--trace-rounds", "2", "--threads", "2"},
                         fixtures)
                       .out);
  expect(number(j, "steps") == 6.0 && number(j, "triangles") == 2.0, "steps/triangles not as expected: " + j.dump());
  for (const char* key : {"rebuild_ms_median", "commit_ms_median", "mrays_per_s_refitted", "mrays_per_s_fresh",
                          "sah_cost_fresh", "sah_cost_refitted"})
    expect(number(j, key) > 0.0, std::string("\"") + key + "\" is not positive: " + j.dump());
  const double rebuilds = number(j, "rebuilds");
  expect(rebuilds >= 0.0 && rebuilds <= 6.0 && rebuilds == std::floor(rebuilds), "bad \"rebuilds\": " + j.dump());
  // Refitted steps have a time and a speedup; the guard's rebuilds have theirs.
  expect((rebuilds == 6.0) == j["refit_ms_median"].is_null(), "refit_ms_median and rebuilds disagree: " + j.dump());
  expect((rebuilds == 0.0) == j["guard_rebuild_ms_median"].is_null(),
         "guard_rebuild_ms_median and rebuilds disagree: " + j.dump());
  if (rebuilds < 6.0) expect(number(j, "refit_speedup") > 0.0, "\"refit_speedup\" is not positive: " + j.dump());
  expect(j.contains("trace_slowdown_after_refits") && j["trace_slowdown_after_refits"].is_number(),
         "no trace_slowdown_after_refits: " + j.dump());
  expect(number(j, "agreement_refit_vs_fresh") >= 0.99, "refitted and fresh trees disagree: " + j.dump());
  expect(number(j, "primary_rays") == 1600.0, "primary_rays is not 40 x 40: " + j.dump());
  std::cout << "bench deform: " << j.dump() << "\n";
  return 0;
}

// `duplex closest` on the quad scene (QuadScene.cpp): each point's nearest instance, triangle,
// point and distance worked out by hand; nothing within a short max_distance or for a NaN point.
int checkClosest(const std::string& duplex, const fs::path& dir) {
  using PointIn = PointRecord;
  using ClosestOut = ClosestRecord;
  const float inf = std::numeric_limits<float>::infinity();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<PointIn> points{
      {0.75f, 0.25f, 0.5f, inf},    // above instance 0, triangle 0 (x > y)
      {0.25f, 0.75f, 2.0f, inf},    // above instance 0, triangle 1
      {4.5f, 0.5f, -0.5f, inf},     // above the scaled instance 1 (z = -1), object point (0.75, 0.25)
      {0.75f, 0.25f, 0.5f, 0.25f},  // the quad is 0.5 away: nothing within 0.25
      {6.75f, 2.0f, 0.25f, inf},    // in front of the standing instance 3 (y = 0), object point (0.75, 0.25)
      {nan, 0.0f, 0.0f, inf},       // not a point
      {0.5f, 0.25f, 0.0f, inf},     // on instance 0
  };
  const std::vector<ClosestOut> want{{0.75f, 0.25f, 0.0f, 0.5f, 0, 0}, {0.25f, 0.75f, 0.0f, 2.0f, 0, 1},
                                     {4.5f, 0.5f, -1.0f, 0.5f, 1, 0},  {0.0f, 0.0f, 0.0f, inf, kNone, kNone},
                                     {6.75f, 0.0f, 0.25f, 2.0f, 3, 0}, {0.0f, 0.0f, 0.0f, inf, kNone, kNone},
                                     {0.5f, 0.25f, 0.0f, 0.0f, 0, 0}};
  const fs::path in = dir / "closest_points.bin", out = dir / "closest_out.bin";
  writeRecords(in, points);
  for (const char* threads : {"1", "2"}) {
    const nlohmann::json j = parseOneLine(runOk({duplex, "closest", "--scene", (dir / "quad.json").string(), "--points",
                                                 in.string(), "--out", out.string(), "--threads", threads},
                                                dir)
                                              .out);
    expect(number(j, "points") == 7.0 && number(j, "found") == 5.0, "points/found wrong: " + j.dump());
    expect(number(j, "threads") == std::stod(threads), "threads not as given: " + j.dump());
    for (const char* key : {"load_ms", "build_ms", "query_ms"})
      expect(number(j, key) >= 0.0, std::string("\"") + key + "\" is negative: " + j.dump());
    const auto got = readRecords<ClosestOut>(out);
    expect(got.size() == want.size(), "closest file has " + std::to_string(got.size()) + " records");
    for (std::size_t i = 0; i < want.size(); ++i) {
      const ClosestOut& g = got[i];
      const ClosestOut& w = want[i];
      const bool same_point =
          std::abs(g.x - w.x) <= 1e-6f && std::abs(g.y - w.y) <= 1e-6f && std::abs(g.z - w.z) <= 1e-6f;
      const bool same_distance =
          std::isinf(w.distance) ? g.distance == w.distance : std::abs(g.distance - w.distance) <= 1e-6f;
      expect(same_point && same_distance && g.instance_id == w.instance_id && g.prim_id == w.prim_id,
             "point " + std::to_string(i) + ": got (" + std::to_string(g.x) + ", " + std::to_string(g.y) + ", " +
                 std::to_string(g.z) + ") at " + std::to_string(g.distance) + ", instance " +
                 std::to_string(g.instance_id) + ", prim " + std::to_string(g.prim_id));
    }
  }
  std::cout << "closest: 7 points, records as worked out\n";
  return 0;
}

// --max-memory: inputs that need more than the limit are refused before they are allocated, with
// exit status 1, one line "duplex <cmd>: error: ..." naming the file (or option) and the option to
// raise it, and no output written; sizes are read as 4G, 512M, 1.5GiB or bytes, anything else is a
// usage error; under a large limit the same runs give the same files.
int checkMemoryLimit(const std::string& duplex, const fs::path& dir) {
  const fs::path work = dir / "memory_limit";
  fs::remove_all(work);
  fs::create_directories(work);
  // 5000 instances of a triangle: 0.3 MB of text, several MB as a JSON document.
  const fs::path many = work / "many.json";
  {
    std::ofstream out(many);
    out << R"({"format": "scene-json-v1", "objects": [{"name": "tri", "mesh": {"positions": [0, 0, 0, 1, 0, 0, 0, 1, 0],)"
        << R"( "indices": [0, 1, 2]}}], "instances": [)";
    for (int i = 0; i < 5000; ++i)
      out << (i ? ",\n" : "") << R"({"object": "tri", "transform": [1, 0, 0, )" << i << R"(, 0, 1, 0, 0, 0, 0, 1, 0]})";
    out << "]}";
  }
  const fs::path points = work / "points.bin";
  writeRecords(points, std::vector<PointRecord>(100000, PointRecord{0.5f, 0.5f, 1.0f, 10.0f}));
  const fs::path rays = work / "rays.bin";
  runOk({duplex, "rays", "--scene", (dir / "quad.json").string(), "--random", "2000", "--seed", "1", "--out",
         rays.string()},
        work);
  const auto sensorScene = [&](const std::string& name, const std::string& bins) {
    const fs::path file = work / name;
    std::ofstream(file) << R"({"format": "scene-json-v1", "objects": [], "instances": [],
      "lights": [{"type": "point", "position": [0, 0, 1], "power": 1}],
      "sensors": [{"name": "screen", "size": [1, 1], "bins": )"
                        << bins << "}]}";
    return file;
  };
  const fs::path big_sensor = sensorScene("big_sensor.json", "[4096, 4096]");
  const fs::path sensor = sensorScene("sensor.json", "[256, 256]");
  const fs::path mesh = work / "tri.obj";
  std::ofstream(mesh) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  const fs::path overflow_sensor = sensorScene("overflow_sensor.json", "[2147483648, 2147483648]");
  const fs::path out = work / "out.bin", out_dir = work / "sensor_out";

  struct Case {
    std::string command;               // "duplex <command>: error: " starts the line
    std::vector<std::string> args;     // after the tool's path
    std::vector<std::string> needles;  // in the message
    fs::path output;                   // must not appear
  };
  const std::vector<Case> cases = {
      {"trace",
       {"trace", "--scene", many.string(), "--rays", rays.string(), "--hits", out.string(), "--max-memory", "1M"},
       {"scene file '" + many.string() + "' (its text and its", "more than the memory limit of 1.00 MiB",
        "--max-memory"},
       out},
      {"trace",
       {"trace", "--scene", many.string(), "--rays", rays.string(), "--hits", out.string(), "--max-memory", "64K"},
       {"--block-rays 2000 (blocks of the ray file '" + rays.string() + "')", "memory limit of 64.0 KiB"},
       out},
      {"closest",
       {"closest", "--scene", (dir / "quad.json").string(), "--points", points.string(), "--out", out.string(),
        "--max-memory", "1.5MiB"},
       {"point file '" + points.string() + "' (100000 points)", "memory limit of 1.50 MiB"},
       out},
      {"rays",
       {"rays", "--scene", many.string(), "--random", "10", "--seed", "1", "--out", out.string(), "--max-memory",
        "1048576"},
       {"scene file '" + many.string() + "'", "memory limit of 1.00 MiB"},
       out},
      {"prepare",
       {"prepare", "--scene", many.string(), "--out", (work / "prepared").string(), "--max-memory", "1M"},
       {"scene file '" + many.string() + "'"},
       work / "prepared"},
      {"scene instances",
       {"scene", "instances", "--mesh", mesh.string(), "--count", "100000", "--seed", "1", "--out", out.string(),
        "--max-memory", "1M"},
       {"--count 100000 (the instances of '" + mesh.string() + "')"},
       out},
      {"sensor",
       {"sensor", "--scene", big_sensor.string(), "--rays", "10", "--out", out_dir.string(), "--progress", "none",
        "--max-memory", "64M"},
       {big_sensor.string() + ": /sensors/0: sensor 'screen' (4096 x 4096 bins) needs 128 MiB",
        "memory limit of 64.0 MiB"},
       out_dir},
      {"sensor",
       {"sensor", "--scene", sensor.string(), "--rays", "10", "--out", out_dir.string(), "--progress", "none",
        "--max-memory", "4M"},
       {"the sensor run of '" + sensor.string() + "' (sensors: 1, the largest 'screen' with 256 x 256 bins",
        "memory limit of 4.00 MiB"},
       out_dir},
      {"sensor",
       {"sensor", "--scene", overflow_sensor.string(), "--rays", "10", "--out", out_dir.string(), "--progress", "none"},
       {overflow_sensor.string(), "/sensors/0/bins/0", "expected a bin count"},
       out_dir},
  };
  for (const Case& c : cases) {
    std::vector<std::string> argv = {duplex};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    const RunResult r = run(argv, work.string());
    const std::string what = "duplex " + c.command + " (" + c.args.back() + ")";
    expect(r.exited && r.exit_code == 1, what + " ended with " + describe(r) + "; stderr:\n" + r.err);
    const std::string head = "duplex " + c.command + ": error: ";
    expect(r.err.rfind(head, 0) == 0 && std::count(r.err.begin(), r.err.end(), '\n') == 1,
           what + ": stderr is not one line starting '" + head + "':\n" + r.err);
    for (const std::string& needle : c.needles)
      expect(r.err.find(needle) != std::string::npos, what + ": stderr does not say '" + needle + "':\n" + r.err);
    expect(r.out.empty(), what + " printed on stdout:\n" + r.out);
    expect(!fs::exists(c.output), what + " wrote " + c.output.string());
    std::cout << r.err;
  }

  // Sizes the option refuses: a usage error naming the option, before anything runs.
  for (const char* bad : {"abc", "0", "-1", "1.5", "4 G", "1e9", "99999999999999999999"}) {
    const RunResult r = run({duplex, "trace", "--scene", (dir / "quad.json").string(), "--rays", rays.string(),
                             "--hits", out.string(), "--max-memory", bad},
                            work.string());
    expect(r.exited && r.exit_code != 0 && r.exit_code != 1 && r.exit_code != 3,
           std::string("--max-memory ") + bad + " ended with " + describe(r));
    expect(r.err.find("--max-memory") != std::string::npos,
           std::string("--max-memory ") + bad + ": stderr does not name the option:\n" + r.err);
    expect(!fs::exists(out), std::string("--max-memory ") + bad + " wrote " + out.string());
  }

  // Under a limit that holds them, the same commands give the same files as without one.
  const fs::path plain = work / "plain.bin";
  runOk({duplex, "trace", "--scene", many.string(), "--rays", rays.string(), "--hits", plain.string()}, work);
  for (const char* size : {"1G", "1.5GiB", "4294967296"}) {
    runOk({duplex, "trace", "--scene", many.string(), "--rays", rays.string(), "--hits", out.string(), "--max-memory",
           size},
          work);
    expectSameFile(out, plain);
  }
  runOk({duplex, "sensor", "--scene", sensor.string(), "--rays", "10", "--out", out_dir.string(), "--max-memory", "64M",
         "--progress", "none"},
        work);
  expect(fs::exists(out_dir / "run.json"), "duplex sensor --max-memory 64M wrote no run.json");
  std::cout << "memory-limit: " << cases.size() << " refusals, bad sizes refused, runs under the limit unchanged\n";
  return 0;
}

// `duplex info` of the quad scene: one object of 2 triangles, placed by 4 instances (QuadScene.cpp),
// whose world boxes, worked out by hand from the transforms, span [0, 7] x [0, 2] x [-3, 1].
int checkInfo(const std::string& duplex, const fs::path& dir) {
  for (const char* threads : {"1", "2"}) {
    const nlohmann::json j =
        parseOneLine(runOk({duplex, "info", "--scene", (dir / "quad.json").string(), "--threads", threads}, dir).out);
    expect(j.value("format", "") == "scene-json-v1", "\"format\" is not scene-json-v1: " + j.dump());
    expect(number(j, "objects") == 1.0 && number(j, "instances") == 4.0 && number(j, "visible_instances") == 4.0,
           "objects / instances wrong: " + j.dump());
    expect(number(j, "triangles") == 2.0 && number(j, "instanced_triangles") == 8.0,
           "triangle counts wrong: " + j.dump());
    expect(j["mesh_structures"] == nlohmann::json{{"bvh", 1}}, "\"mesh_structures\" is not {bvh: 1}: " + j.dump());
    expect(number(j, "edits") == 0.0 && number(j, "structures_loaded") == 0.0, "edits / loaded wrong: " + j.dump());
    expect(number(j, "threads") == std::stod(threads), "threads not as given: " + j.dump());
    // World boxes are rounded outward (conservative), so each bound may lie a few float ulps out.
    const double want_min[3] = {0.0, 0.0, -3.0}, want_max[3] = {7.0, 2.0, 1.0};
    const nlohmann::json& bounds = j["world_bounds"];
    bool bounds_ok = bounds.is_object() && bounds.contains("min") && bounds.contains("max");
    for (int a = 0; bounds_ok && a < 3; ++a) {
      const double lo = bounds["min"].at(a).get<double>(), hi = bounds["max"].at(a).get<double>();
      const double lo_slack = 1e-6 * std::max(1.0, std::abs(want_min[a]));
      const double hi_slack = 1e-6 * std::max(1.0, std::abs(want_max[a]));
      bounds_ok =
          lo <= want_min[a] && lo >= want_min[a] - lo_slack && hi >= want_max[a] && hi <= want_max[a] + hi_slack;
    }
    expect(bounds_ok, "\"world_bounds\" is not [0, 7] x [0, 2] x [-3, 1] (rounded outward): " + j.dump());
    for (const char* key : {"load_ms", "build_ms", "graph_ms"})
      expect(number(j, key) >= 0.0, std::string("\"") + key + "\" is negative: " + j.dump());
  }
  std::cout << "info: the quad scene's counts and world bounds\n";
  return 0;
}

int usage() {
  std::cerr
      << "usage: duplex_cli_check fixtures DIR | trace DUPLEX DIR | any-hit DUPLEX DIR | rays DUPLEX DIR |\n"
         "       fails DIR NEEDLE -- PROGRAM ARGS... | demo DEMO DIR | shared-data DUPLEX DIR DATA_DIR |\n"
         "       document DUPLEX DIR | prepare DUPLEX DIR | structure DUPLEX DIR |\n"
         "       prepare-koala DUPLEX DIR DATA_DIR |\n"
         "       bench-update DUPLEX DIR | bench-update-embree DUPLEX_BENCH_UPDATE DIR | bench-deform DUPLEX DIR |\n"
         "       bench-frame DUPLEX DIR | bench-frame-embree DUPLEX_BENCH_FRAME DUPLEX DIR |\n"
         "       closest DUPLEX DIR | disk-full DUPLEX DIR | memory-limit DUPLEX DIR | info DUPLEX DIR\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> args(argv + 1, argv + argc);
  return reportFailures([&] {
    if (args.size() == 2 && args[0] == "fixtures") {
      writeFixtures(args[1]);
      std::cout << "fixtures written to " << args[1] << "\n";
      return 0;
    }
    if (args.size() == 3 && args[0] == "trace") return checkTrace(args[1], args[2], false);
    if (args.size() == 3 && args[0] == "any-hit") return checkTrace(args[1], args[2], true);
    if (args.size() == 3 && args[0] == "rays") return checkRays(args[1], args[2]);
    if (args.size() >= 5 && args[0] == "fails" && args[3] == "--")
      return checkFails(args[1], args[2], std::vector<std::string>(args.begin() + 4, args.end()));
    if (args.size() == 3 && args[0] == "demo") return checkDemo(args[1], args[2]);
    if (args.size() == 4 && args[0] == "shared-data") return checkSharedData(args[1], args[2], args[3]);
    if (args.size() == 3 && args[0] == "document") return checkDocument(args[1], args[2]);
    if (args.size() == 3 && args[0] == "prepare") return checkPrepare(args[1], args[2]);
    if (args.size() == 3 && args[0] == "structure") return checkStructure(args[1], args[2]);
    if (args.size() == 4 && args[0] == "prepare-koala") return checkPrepareKoala(args[1], args[2], args[3]);
    if (args.size() == 3 && args[0] == "bench-update")
      return checkBenchUpdate({args[1], "bench", "update"}, args[2], false);
    if (args.size() == 3 && args[0] == "bench-update-embree") return checkBenchUpdate({args[1]}, args[2], true);
    if (args.size() == 3 && args[0] == "bench-frame")
      return checkBenchFrame({args[1], "bench", "frame"}, args[1], args[2], false);
    if (args.size() == 4 && args[0] == "bench-frame-embree") return checkBenchFrame({args[1]}, args[2], args[3], true);
    if (args.size() == 3 && args[0] == "bench-deform") return checkBenchDeform(args[1], args[2]);
    if (args.size() == 3 && args[0] == "closest") return checkClosest(args[1], args[2]);
    if (args.size() == 3 && args[0] == "info") return checkInfo(args[1], args[2]);
    if (args.size() == 3 && args[0] == "disk-full") return checkDiskFull(args[1], args[2]);
    if (args.size() == 3 && args[0] == "memory-limit") return checkMemoryLimit(args[1], args[2]);
    return usage();
  });
}
