// `duplex trace` on a scene with volumes (the interchange contract): --transmittance writes exactly one
// float32 per ray (the transmittance along [tnear, tfar] through all fog volumes, 0 where a surface
// blocks), checked against exp(-sigma L) computed here by slabs; level sets give ordinary hit
// records (prim_id 0, u = v = 0) at the analytic sphere; 1 and 2 threads write identical bytes;
// bad combinations fail naming the option. Like CliCheck it drives the built program as an
// outside tool would; it links OpenVDB only to write the fixture .vdb file.
//
//   duplex_volume_cli_check <duplex> <scratch dir>

#include "CheckSupport.h"
#include "Subprocess.h"

#include <nlohmann/json.hpp>
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace duplex::clitest;

namespace {

constexpr float kSigma = 1.3f;
constexpr double kVoxel = 0.1;
constexpr int kLo = 0, kHi = 23;  // fog voxels [0, 23]^3: object box [-0.05, 2.35]^3
constexpr double kBoxLo = (kLo - 0.5) * kVoxel;
constexpr double kBoxHi = (kHi + 0.5) * kVoxel;
constexpr double kRadius = 0.5;
const double kCentre[3] = {5.0, 1.15, 1.15};  // the level-set sphere, beyond the fog along +x
constexpr float kInf = std::numeric_limits<float>::infinity();

struct RayRec {
  float o[3];
  float tnear;
  float d[3];
  float tfar;
};
static_assert(sizeof(RayRec) == 32);

struct HitRec {
  float t, u, v;
  std::uint32_t instance_id, prim_id;
};
static_assert(sizeof(HitRec) == 20);

std::string show(const RayRec& r) {
  return "{o=(" + std::to_string(r.o[0]) + ", " + std::to_string(r.o[1]) + ", " + std::to_string(r.o[2]) + "), d=(" +
         std::to_string(r.d[0]) + ", " + std::to_string(r.d[1]) + ", " + std::to_string(r.d[2]) + "), t=[" +
         std::to_string(r.tnear) + ", " + std::to_string(r.tfar) + "]}";
}

double length(const RayRec& r) {
  return std::sqrt(double(r.d[0]) * r.d[0] + double(r.d[1]) * r.d[1] + double(r.d[2]) * r.d[2]);
}

// Length (object units) of [tnear, tfar] inside the fog box.
double lengthInBox(const RayRec& r) {
  double t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    double ta = (kBoxLo - r.o[a]) / r.d[a], tb = (kBoxHi - r.o[a]) / r.d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t1 > t0 ? (t1 - t0) * length(r) : 0.0;
}

// First entry t of the ray into the sphere, and the impact parameter.
double sphereEntry(const RayRec& r, double& impact) {
  double oc[3], a = 0, b = 0, c = 0;
  for (int k = 0; k < 3; ++k) {
    oc[k] = r.o[k] - kCentre[k];
    a += double(r.d[k]) * r.d[k];
    b += oc[k] * r.d[k];
    c += oc[k] * oc[k];
  }
  impact = std::sqrt(std::max(0.0, c - b * b / a));
  const double disc = b * b - a * (c - kRadius * kRadius);
  return disc < 0.0 ? kInf : (-b - std::sqrt(disc)) / a;
}

template <class T>
void writeFile(const fs::path& p, const std::vector<T>& v) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
  expect(bool(out), "cannot write " + p.string());
}

std::vector<char> readBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  expect(bool(in), "cannot read " + p.string());
  return std::vector<char>(std::istreambuf_iterator<char>(in), {});
}

void expectFails(const std::vector<std::string>& argv, const fs::path& dir, const std::string& needle) {
  const RunResult r = run(argv, dir.string());
  expect(r.exited && r.exit_code != 0, "bad input accepted or crashed (" + describe(r) + ")");
  expect(r.err.find(needle) != std::string::npos, "stderr does not name '" + needle + "':\n" + r.err);
}

int check(const std::string& duplex, const fs::path& dir) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  openvdb::initialize();
  // Fixture: a fog box (tiles where whole nodes fit, voxels elsewhere) and a level-set sphere.
  auto fog = openvdb::FloatGrid::create(0.0f);
  fog->tree().fill(openvdb::CoordBBox(openvdb::Coord(kLo), openvdb::Coord(kHi)), kSigma, true);
  fog->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  fog->setGridClass(openvdb::GRID_FOG_VOLUME);
  fog->setName("density");
  auto ball = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
      float(kRadius), openvdb::Vec3f(float(kCentre[0]), float(kCentre[1]), float(kCentre[2])), 0.02f);
  ball->setName("ball");
  {
    openvdb::io::File out((dir / "vol.vdb").string());
    out.write({fog, ball});
    out.close();
  }
  std::ofstream(dir / "scene.json") << R"({"format": "scene-json-v1",
    "objects": [{"name": "fog", "volume": {"file": "vol.vdb", "grid": "density", "kind": "fog"}},
                {"name": "ball", "volume": {"file": "vol.vdb", "grid": "ball"}}],
    "instances": [{"object": "fog", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]},
                  {"object": "ball", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}]})";

  // Rays: fixed cases, then random rays through the fog towards (or past) the sphere.
  std::vector<RayRec> rays = {
      {{-1.0f, 1.15f, 1.15f}, 0.0f, {1, 0, 0}, 3.5f},    // through the fog, stops before the sphere
      {{-1.0f, 1.15f, 1.15f}, 0.0f, {1, 0, 0}, kInf},    // then blocked by the sphere
      {{0.0f, 10.0f, 0.0f}, 0.0f, {1, 0, 0}, kInf},      // misses everything
      {{-1.0f, 1.0f, 1.0f}, 1.0f, {1, 0, 0}, 2.0f},      // starts inside the fog
      {{-1.0f, -1.0f, 0.5f}, 0.0f, {2, 2, 0.2f}, 1.5f},  // diagonal, direction not unit
  };
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int k = 0; k < 200; ++k) {
    const float o[3] = {-1.0f, 2.3f * u(rng), 2.3f * u(rng)};
    const float target[3] = {6.0f, 1.15f + 1.2f * (u(rng) - 0.5f), 1.15f + 1.2f * (u(rng) - 0.5f)};
    const float scale = 0.3f + u(rng);
    RayRec r{{o[0], o[1], o[2]}, 0.0f, {}, kInf};
    for (int a = 0; a < 3; ++a) r.d[a] = (target[a] - o[a]) * scale / 7.0f;
    if (k % 2 == 0) r.tfar = (3.0f + 5.0f * u(rng)) / scale;  // ends at x in [2, 7]: before, in or past the sphere
    rays.push_back(r);
  }
  writeFile(dir / "rays.bin", rays);

  // --transmittance, 1 and 2 threads.
  const fs::path t1 = dir / "t1.bin", t2 = dir / "t2.bin";
  const RunResult r1 = runOk({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays",
                              (dir / "rays.bin").string(), "--transmittance", t1.string(), "--threads", "1"},
                             dir);
  runOk({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays", (dir / "rays.bin").string(),
         "--transmittance", t2.string(), "--threads", "2"},
        dir);
  const std::vector<char> b1 = readBytes(t1), b2 = readBytes(t2);
  expect(b1.size() == rays.size() * 4, "transmittance file has " + std::to_string(b1.size()) + " bytes for " +
                                           std::to_string(rays.size()) + " rays (want 4 per ray)");
  expect(b1 == b2, "1 and 2 threads wrote different transmittance files");
  const nlohmann::json report = nlohmann::json::parse(r1.out);
  expect(report.value("transmittance", false) && report.value("rays", 0) == int(rays.size()),
         "report lacks transmittance / rays: " + r1.out);
  std::vector<float> t(rays.size());
  std::memcpy(t.data(), b1.data(), b1.size());
  int blocked = 0, checked = 0;
  double worst = 0.0;
  for (std::size_t k = 0; k < rays.size(); ++k) {
    const RayRec& r = rays[k];
    double impact = 0.0;
    const double entry = sphereEntry(r, impact);
    // Rays grazing the sphere (within 2 voxels of the level set) are left out: the discrete
    // surface may differ from the analytic one there.
    if (std::abs(impact - kRadius) < 0.04 || std::abs(entry - double(r.tfar)) * length(r) < 0.04) continue;
    ++checked;
    const bool hits_sphere = std::isfinite(entry) && entry >= r.tnear && entry <= r.tfar;
    const double expected = hits_sphere ? 0.0 : std::exp(-double(kSigma) * lengthInBox(r));
    blocked += hits_sphere;
    worst = std::max(worst, std::abs(t[k] - expected));
    expect(std::abs(t[k] - expected) < 2e-5 + 1e-5 * expected, "ray " + std::to_string(k) + " " + show(r) +
                                                                   ": transmittance " + std::to_string(t[k]) +
                                                                   ", expected " + std::to_string(expected));
  }
  expect(t[0] > 0.0f && t[0] < 1.0f && t[1] == 0.0f && t[2] == 1.0f, "fixed cases wrong");
  expect(blocked > 20 && checked - blocked > 20, "too few blocked or free rays: " + std::to_string(blocked));

  // Ordinary hit records: the level set hits at the analytic sphere with prim 0, u = v = 0; the fog
  // never hits.
  const fs::path hits = dir / "hits.bin";
  runOk({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays", (dir / "rays.bin").string(), "--hits",
         hits.string()},
        dir);
  const std::vector<char> hb = readBytes(hits);
  expect(hb.size() == rays.size() * sizeof(HitRec), "hit file size");
  std::vector<HitRec> h(rays.size());
  std::memcpy(h.data(), hb.data(), hb.size());
  int sphere_hits = 0;
  for (std::size_t k = 0; k < rays.size(); ++k) {
    const RayRec& r = rays[k];
    double impact = 0.0;
    const double entry = sphereEntry(r, impact);
    if (std::abs(impact - kRadius) < 0.04 || std::abs(entry - double(r.tfar)) * length(r) < 0.04) continue;
    const bool hits_sphere = std::isfinite(entry) && entry >= r.tnear && entry <= r.tfar;
    if (!hits_sphere) {
      expect(h[k].instance_id == 0xFFFFFFFFu && h[k].prim_id == 0xFFFFFFFFu,
             "ray " + std::to_string(k) + " should miss");
      continue;
    }
    ++sphere_hits;
    const double len = length(r);
    expect(h[k].instance_id == 1 && h[k].prim_id == 0 && h[k].u == 0.0f && h[k].v == 0.0f,
           "ray " + std::to_string(k) + ": level-set hit record is not {instance 1, prim 0, u 0, v 0}");
    expect(std::abs(h[k].t - entry) * len < 0.25 * 0.02,
           "ray " + std::to_string(k) + ": hit t " + std::to_string(h[k].t) + ", sphere at " + std::to_string(entry));
  }
  expect(sphere_hits > 20, "too few sphere hits");

  // Bad combinations name the options.
  expectFails({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays", (dir / "rays.bin").string(),
               "--transmittance", t1.string(), "--any-hit"},
              dir, "--any-hit");
  expectFails({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays", (dir / "rays.bin").string(),
               "--transmittance", t1.string(), "--hits", hits.string()},
              dir, "--hits");
  expectFails({duplex, "trace", "--scene", (dir / "scene.json").string(), "--rays", (dir / "rays.bin").string(),
               "--transmittance", (dir / "no_such_dir" / "t.bin").string()},
              dir, "no_such_dir");

  // duplex sensor's path limits act on fog: light from the fog's far side is attenuated
  // (transmittance down to exp(-sigma 2.4) ~ 0.04 across the box), crosses a sensor wall and is
  // reflected by a white wall behind it, where roulette is decided on the power left.
  // --roulette 0 plays no roulette (roulette_w exactly 0), --roulette 0.5 does; with a scattering
  // fog, --max-scatterings 0 cuts every path at its first collision (depth_limited_w > 0), the
  // default never.
  auto sensorScene = [&](const fs::path& file, const char* material) {
    std::ofstream(file) << R"({"format": "scene-json-v1",
      "objects": [{"name": "fog", "volume": {"file": "vol.vdb", "grid": "density", "kind": "fog"})"
                        << material << R"(},
                  {"name": "back", "mesh": {"positions": [4,-10,-10, 4,12,-10, 4,12,12, 4,-10,12], "indices": [0,1,2, 0,2,3]},
                   "material": {"type": "lambertian", "reflectance": 0.9}}],
      "instances": [{"object": "fog", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]},
                    {"object": "back", "transform": [1,0,0,0, 0,1,0,0, 0,0,1,0]}],
      "lights": [{"type": "point", "position": [-0.5, 1.15, 1.15], "power": 1}],
      "sensors": [{"name": "wall", "shape": "rectangle", "size": [20, 20], "bins": [2, 2],
                   "transform": [0,0,1,3, 0,1,0,1.15, -1,0,0,1.15]}]})";
  };
  // Each run replaces the previous one's results (--overwrite): only the reports are compared.
  auto sensorRun = [&](const fs::path& scene, const std::vector<std::string>& extra) {
    std::vector<std::string> argv = {duplex,       "sensor", "--scene",   scene.string(),
                                     "--rays",     "4000",   "--threads", "1",
                                     "--progress", "none",   "--out",     (dir / "sensor_out").string(),
                                     "--overwrite"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return nlohmann::json::parse(runOk(argv, dir).out);
  };
  sensorScene(dir / "fog_sensor.json", "");
  const nlohmann::json no_rr = sensorRun(dir / "fog_sensor.json", {"--roulette", "0"});
  const nlohmann::json rr = sensorRun(dir / "fog_sensor.json", {"--roulette", "0.5"});
  expect(no_rr["roulette_threshold"] == 0.0 && no_rr["energy"]["roulette_w"] == 0.0,
         "--roulette 0 still played roulette: " + no_rr.dump());
  expect(rr["roulette_threshold"] == 0.5 && rr["energy"]["roulette_w"].get<double>() != 0.0,
         "--roulette 0.5 played no roulette in the fog: " + rr.dump());
  sensorScene(dir / "fog_scatter.json", R"(, "material": {"type": "medium", "albedo": 0.9})");
  // A cut above --failure-threshold of the emitted power is said on stderr, with the options that remove it.
  const RunResult cut_run =
      runOk({duplex, "sensor", "--scene", (dir / "fog_scatter.json").string(), "--rays", "4000", "--threads", "1",
             "--progress", "none", "--out", (dir / "sensor_out").string(), "--overwrite", "--max-scatterings", "0"},
            dir);
  const nlohmann::json cut = nlohmann::json::parse(cut_run.out);
  expect(cut_run.err.find("path limits cut") != std::string::npos &&
             cut_run.err.find("% of the emitted power") != std::string::npos &&
             cut_run.err.find("--max-scatterings") != std::string::npos,
         "--max-scatterings 0: no warning of the cut energy on stderr:\n" + cut_run.err);
  // A depth cap likewise names --max-depth none; the default (no cap) says nothing.
  const RunResult capped =
      runOk({duplex, "sensor", "--scene", (dir / "fog_sensor.json").string(), "--rays", "4000", "--threads", "1",
             "--progress", "none", "--out", (dir / "sensor_out").string(), "--overwrite", "--max-depth", "0"},
            dir);
  expect(
      nlohmann::json::parse(capped.out)["max_depth"] == 0 && capped.err.find("--max-depth none") != std::string::npos,
      "--max-depth 0: no warning naming --max-depth none:\n" + capped.err);
  const nlohmann::json full = sensorRun(dir / "fog_scatter.json", {});
  expect(cut["max_scatterings"] == 0 && cut["energy"]["depth_limited_w"].get<double>() > 0.1,
         "--max-scatterings 0 did not cut the paths at their first collision: " + cut.dump());
  expect(full["max_scatterings"] == 100000 && full["energy"]["depth_limited_w"] == 0.0 &&
             full["scatterings"].get<double>() > 0,
         "default max_scatterings: " + full.dump());
  expectFails({duplex, "sensor", "--scene", (dir / "fog_sensor.json").string(), "--rays", "10", "--roulette", "1"}, dir,
              "--roulette");

  std::cout
      << "volumes: " << rays.size() << " rays, " << checked << " checked against exp(-sigma L) (worst error " << worst
      << ", " << blocked << " blocked by the level set), 1 and 2 threads byte-identical; " << sphere_hits
      << " level-set hit records at the analytic sphere; sensor runs: --roulette and --max-scatterings act on fog\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: duplex_volume_cli_check <duplex> <scratch dir>\n";
    return 2;
  }
  return reportFailures([&] { return check(argv[1], argv[2]); });
}
