// The CIE 171:2006 cases Duplex can express, built as sensor scenes and compared with exact
// references (see CieCases.h for each case's geometry and reference).

#include "CieCases.h"

#include "OpticsReference.h"
#include "SensorFixture.h"
#include "SlabRuns.h"

#include "duplex/objects/ProceduralMesh.h"
#include "duplex/sensors/CieSky.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>

namespace duplex::validation {

using namespace duplex::test;

namespace {

constexpr double kLumens = 1000.0;

std::uint64_t scaled(std::uint64_t rays, const CaseOptions& o) {
  return std::max<std::uint64_t>(1000, static_cast<std::uint64_t>(static_cast<double>(rays) * o.scale));
}

// A sensor frame: local x along ex, local y along ey, its normal (the side it records rays
// arriving on) ex x ey, the plane's centre at `at`.
Affine frame(const glm::dvec3& at, const glm::dvec3& ex, const glm::dvec3& ey) {
  Affine a;
  a.linear = glm::dmat3(ex, ey, glm::cross(ex, ey));
  a.translation = at;
  return a;
}

struct Timed {
  SensorRunResults results;
  double seconds = 0.0;
};

Timed run(const SensorScene& scene, std::uint64_t rays, const CaseOptions& o, SensorRunConfig cfg = {}) {
  cfg.seed = 171;
  cfg.threads = o.threads;
  const auto t0 = std::chrono::steady_clock::now();
  SensorRun r(scene, cfg);
  (void)r.runUntil(rays);
  Timed t{r.results(), 0.0};
  t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return t;
}

// Runs case c's scene for its rays and records the run's seconds in it.
Timed runCase(CaseResult& c, const SensorScene& scene, const CaseOptions& o) {
  Timed t = run(scene, c.rays, o);
  c.seconds = t.seconds;
  return t;
}

// A case's description, its rays scaled by the options.
CaseResult describe(std::string name, std::string title, std::string reference, std::string unit, std::uint64_t rays,
                    const CaseOptions& o) {
  CaseResult c;
  c.name = std::move(name);
  c.title = std::move(title);
  c.reference = std::move(reference);
  c.unit = std::move(unit);
  c.rays = scaled(rays, o);
  return c;
}

// Rows of a grid sensor of w x h (nx x ny cells) against `exact(x0, x1, y0, y1)`, the exact mean
// illuminance of the cell [x0, x1] x [y0, y1] in the sensor's local coordinates.
template <class Exact>
void gridRows(CaseResult& out, const std::string& what, const SensorResult& s, double w, double h, Exact exact) {
  for (std::uint32_t iy = 0; iy < s.ny; ++iy)
    for (std::uint32_t ix = 0; ix < s.nx; ++ix) {
      const std::size_t b = std::size_t{iy} * s.nx + ix;
      const double x0 = -w / 2 + w * ix / s.nx, x1 = -w / 2 + w * (ix + 1) / s.nx;
      const double y0 = -h / 2 + h * iy / s.ny, y1 = -h / 2 + h * (iy + 1) / s.ny;
      CaseRow row;
      row.label = what + " (" + std::to_string(ix) + ", " + std::to_string(iy) + ")";
      row.reference = exact(x0, x1, y0, y1);
      row.value = s.irradiance_w_m2[b];
      row.stderr_value = s.stderr_w_m2[b];
      row.other = std::nan("");
      out.rows.push_back(row);
    }
}

// The faces of a cube centred at the origin: their names, outward normals and sensor frames.
constexpr const char* kFaceNames[6] = {"+x", "-x", "+y", "-y", "+z", "-z"};
glm::dvec3 faceNormal(int k) {
  const glm::dvec3 axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  return axes[k / 2] * (k % 2 ? -1.0 : 1.0);
}
Affine faceFrame(int k, double a, double inset) {
  const glm::dvec3 axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const glm::dvec3 n = faceNormal(k), ex = axes[(k / 2 + 1) % 3], ey = glm::cross(-n, ex);
  return frame(n * (a / 2 - inset), ex, ey);  // recording the light arriving from inside
}

// One sensor of bins x bins cells per face of a cube of edge a, `inset` inside it.
void addFaceSensors(Fixture& f, double a, double inset, std::uint32_t bins) {
  for (int k = 0; k < 6; ++k)
    f.add(sensor(a, a, bins, bins, false, kFaceNames[k]), faceFrame(k, a, inset), kFaceNames[k]);
}

}  // namespace

double CaseRow::z() const { return stderr_value > 0.0 ? (value - reference) / stderr_value : 0.0; }

bool CaseRow::passes() const {
  return std::abs(value - reference) <= 4.0 * stderr_value + relative_tolerance * std::abs(reference);
}

CaseResult pointSourceCase(const CaseOptions& o) {
  const double h = 3.0, half = 2.0;
  Fixture f;
  // The source at (0, 0, 3); the floor z = 0 seen from above; the wall x = 2 (from z = 0 to 3) seen
  // from the room (local x along -y, local y along +z, normal -x).
  f.add(sensor(4.0, 4.0, 8, 8, false, "floor"), frame({0, 0, 0}, {1, 0, 0}, {0, 1, 0}), "floor");
  f.add(sensor(4.0, 3.0, 8, 6, false, "wall"), frame({half, 0, 1.5}, {0, -1, 0}, {0, 0, 1}), "wall");
  const SensorScene scene = f.scene({pointLight({0, 0, h}, kLumens)});
  CaseResult c = describe(
      "point-source", "Isotropic point source of 1000 lm 3 m above a 4 m x 4 m floor and a 4 m x 3 m wall 2 m away",
      "I x solid angle of each cell / its area (inverse-square cosine law integrated over the cell)", "lx", 400000, o);
  const Timed t = runCase(c, scene, o);
  const double intensity = kLumens / (4.0 * std::numbers::pi);
  gridRows(c, "floor", t.results.sensors[scene.findSensor("floor")], 4.0, 4.0,
           [&](double x0, double x1, double y0, double y1) {
             return intensity * rectangleSolidAngleFrom(x0, x1, y0, y1, h) / ((x1 - x0) * (y1 - y0));
           });
  // Wall cell: local x = -y_world, local y = z_world - 1.5; the source's foot on the wall plane is at
  // local (0, 1.5), distance 2.
  gridRows(c, "wall", t.results.sensors[scene.findSensor("wall")], 4.0, 3.0,
           [&](double x0, double x1, double y0, double y1) {
             return intensity * rectangleSolidAngleFrom(x0, x1, y0 - 1.5, y1 - 1.5, half) / ((x1 - x0) * (y1 - y0));
           });
  return c;
}

CaseResult areaSourceCase(const CaseOptions& o) {
  const double h = 3.0, luminance = 1000.0;
  Fixture f;
  f.add(sensor(4.0, 4.0, 8, 8, false, "floor"), frame({0, 0, 0}, {1, 0, 0}, {0, 1, 0}), "floor");
  Light panel;
  panel.type = LightType::Area;
  panel.name = "panel";
  panel.width = 1.0;
  panel.height = 1.0;
  panel.world_from_light = frame({0, 0, h}, {1, 0, 0}, {0, -1, 0});  // emits towards -z
  panel.power_w = std::numbers::pi * luminance * 1.0;                // M = pi L over 1 m^2
  const SensorScene scene = f.scene({panel});
  CaseResult c =
      describe("area-source", "Lambertian panel of 1 m^2 and 1000 cd/m^2, 3 m above a 4 m x 4 m floor",
               "pi L x exchange area between the cell and the panel (parallel rectangles, closed form) / cell area",
               "lx", 400000, o);
  const Timed t = runCase(c, scene, o);
  gridRows(c, "floor", t.results.sensors[0], 4.0, 4.0, [&](double x0, double x1, double y0, double y1) {
    return std::numbers::pi * luminance * parallelRectanglesExchange(x0, x1, y0, y1, -0.5, 0.5, -0.5, 0.5, h) /
           ((x1 - x0) * (y1 - y0));
  });
  return c;
}

CaseResult diffuseCubeCase(double rho, const CaseOptions& o, bool also_capped) {
  const double a = 4.0, inset = 1e-3;
  Fixture f;
  f.add(std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(makeBox({a, a, a}, "room"))),
        Affine::identity(), "room", Material{Lambertian{rho}});
  addFaceSensors(f, a, inset, 1);
  const SensorScene scene = f.scene({pointLight({0, 0, 0}, kLumens)});
  CaseResult c = describe("diffuse-cube-" + std::to_string(static_cast<int>(std::lround(rho * 100))),
                          "Closed 4 m cube of Lambertian reflectance " + std::to_string(rho).substr(0, 4) +
                              ", 1000 lm isotropic source at its centre",
                          "Phi / (6 a^2 (1 - rho)) per face (closed-enclosure balance and the cube's symmetry)", "lx",
                          rho > 0.9 ? 60000 : 100000, o);
  const Timed t = runCase(c, scene, o);
  const double expected = kLumens / (6.0 * a * a * (1.0 - rho));
  for (int k = 0; k < 6; ++k) {
    const SensorResult& s = t.results.sensors[scene.findSensor(kFaceNames[k])];
    c.rows.push_back(
        {std::string("face ") + kFaceNames[k], expected, s.irradiance_w_m2[0], s.stderr_w_m2[0], std::nan(""), 0.005});
  }
  const EnergyBalance& e = t.results.energy;
  c.notes.push_back("energy cut by path limits: " + std::to_string(e.depth_limited_w / e.emitted_w * 100.0) +
                    "% of the emitted flux; failures " + std::to_string(e.failed_rays) + " paths");
  if (also_capped) {
    SensorRunConfig capped;
    capped.max_depth = 1000;
    const Timed u = run(scene, c.rays, o, capped);
    c.notes.push_back("seconds, default options: " + std::to_string(t.seconds) + "; with max_depth 1000: " +
                      std::to_string(u.seconds) + "; ratio: " + std::to_string(t.seconds / u.seconds));
  }
  return c;
}

CaseResult clearGlassCase(const CaseOptions& o) {
  const double n = 1.52, d = 0.006;
  // The absorption that makes the slab transmit the CIE curve's value at normal incidence.
  const double t0 = cieClearGlassTransmittance(1.0);
  double lo = 0.0, hi = 100.0;
  for (int k = 0; k < 200; ++k) {
    const double mid = 0.5 * (lo + hi);
    (slabUnpolarised(n, d, mid, 0.0).t > t0 ? lo : hi) = mid;
  }
  const double alpha = 0.5 * (lo + hi);
  const Material glass = Dielectric{n, alpha};
  CaseResult c = describe("clear-glass",
                          "6 mm clear glass (n = 1.52, absorption " + std::to_string(alpha).substr(0, 6) +
                              " /m: the CIE curve's 0.8788 at normal incidence), collimated beam at 0-85 degrees",
                          "two-polarisation slab formulas with all internal reflections (s and p averaged); "
                          "'other' = the CIE 171 clear-glass curve (a fit)",
                          "fraction", 100000, o);
  const auto start = std::chrono::steady_clock::now();
  for (const double deg : {0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 75.0, 80.0, 85.0}) {
    const double th = deg * std::numbers::pi / 180.0;
    const Measured m = slabRun({{0, 0, 0}, {0, 0, 1}, {1, 0, 0}}, d, glass, th, false, {}, c.rays, 171);
    const SlabResponse ref = slabUnpolarised(n, d, alpha, th);
    const std::string at = std::to_string(static_cast<int>(deg)) + " deg";
    c.rows.push_back({"T at " + at, ref.t, m.value.t, m.se.t, cieClearGlassTransmittance(std::cos(th)), 0.002});
    c.rows.push_back({"R at " + at, ref.r, m.value.r, m.se.r, std::nan(""), 0.002});
  }
  c.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return c;
}

namespace {

// An n x n grid of floor points `step` apart centred at the origin, facing up, row by row (x
// fastest).
PointMeter floorGrid(int n, double step) {
  PointMeter m{"floor", {}, {}};
  const double first = -0.5 * (n - 1) * step;
  for (int iy = 0; iy < n; ++iy)
    for (int ix = 0; ix < n; ++ix) {
      m.points.push_back({first + step * ix, first + step * iy, 0.0});
      m.normals.push_back({0, 0, 1});
    }
  return m;
}

// The 8 x 8 centres of the 0.5 m cells of the 4 m x 4 m floor.
PointMeter floorPoints() { return floorGrid(8, 0.5); }

// Rows of a meter against `exact(point)`.
template <class Exact>
void meterRows(CaseResult& out, const MeterResult& m, Exact exact) {
  for (std::size_t i = 0; i < m.points.size(); ++i) {
    CaseRow row;
    row.label = m.name + " point (" + std::to_string(m.points[i].x).substr(0, 5) + ", " +
                std::to_string(m.points[i].y).substr(0, 5) + ")";
    row.reference = exact(m.points[i]);
    row.value = m.irradiance_w_m2[i];
    row.stderr_value = m.stderr_w_m2[i];
    row.other = std::nan("");
    out.rows.push_back(row);
  }
}

}  // namespace

CaseResult areaSourcePointsCase(const CaseOptions& o) {
  const double h = 3.0, luminance = 1000.0;
  Fixture f;
  SensorScene scene = f.scene({areaLight(1.0, 1.0, frame({0, 0, h}, {1, 0, 0}, {0, -1, 0}),
                                         std::numbers::pi * luminance * 1.0)});  // M = pi L over 1 m^2
  scene.setMeters({floorPoints()});
  CaseResult c = describe("area-source-points",
                          "Lambertian panel of 1 m^2 and 1000 cd/m^2, 3 m above the floor: illuminance at 64 points",
                          "pi L x configuration factor from the point to the panel (closed form)", "lx", 100000, o);
  const Timed t = runCase(c, scene, o);
  meterRows(c, t.results.meters[0], [&](const glm::dvec3& p) {
    return std::numbers::pi * luminance * pointToParallelRectangle(-0.5 - p.x, 0.5 - p.x, -0.5 - p.y, 0.5 - p.y, h);
  });
  return c;
}

CaseResult obstructionCase(const CaseOptions& o) {
  const double h = 3.0, zo = 1.5;
  Fixture f;
  f.add(quad(0.5, "obstruction"), translate(0, 0, zo), "obstruction");  // black: an absorber
  SensorScene scene = f.scene({pointLight({0, 0, h}, kLumens)});
  scene.setMeters({floorPoints()});
  CaseResult c =
      describe("obstruction",
               "Point source of 1000 lm 3 m above the floor, a black 1 m x 1 m square 1.5 m above the floor's centre: "
               "illuminance at 64 points",
               "I cos / d^2 outside the obstruction's shadow (|x|, |y| > 1 m), 0 inside", "lx", 20000, o);
  const Timed t = runCase(c, scene, o);
  const double intensity = kLumens / (4.0 * std::numbers::pi), shadow = 0.5 * h / (h - zo);
  meterRows(c, t.results.meters[0], [&](const glm::dvec3& p) {
    if (std::abs(p.x) < shadow && std::abs(p.y) < shadow) return 0.0;
    const double d2 = p.x * p.x + p.y * p.y + h * h;
    return intensity * h / (d2 * std::sqrt(d2));
  });
  return c;
}

CaseResult blackCubeCase(const CaseOptions& o) {
  const double a = 4.0, inset = 1e-3;
  const glm::dvec3 source{0.5, -0.3, 0.2};
  Fixture f;
  f.add(std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(makeBox({a, a, a}, "room"))),
        Affine::identity(), "room");  // black: an absorber
  addFaceSensors(f, a, inset, 4);
  const SensorScene scene = f.scene({pointLight(source, kLumens)});
  CaseResult c = describe(
      "black-cube", "Closed 4 m cube with black (absorbing) faces, 1000 lm isotropic source at (0.5, -0.3, 0.2) m",
      "I x solid angle of each cell seen from the source / its area (direct light only)", "lx", 200000, o);
  const Timed t = runCase(c, scene, o);
  const double intensity = kLumens / (4.0 * std::numbers::pi);
  for (int k = 0; k < 6; ++k) {
    // The source in the face's sensor frame: local x, y and its height above the face.
    const Affine fr = faceFrame(k, a, inset);
    const glm::dvec3 d = source - fr.translation;
    const double sx = glm::dot(d, fr.linear[0]), sy = glm::dot(d, fr.linear[1]), hz = glm::dot(d, fr.linear[2]);
    gridRows(c, std::string("face ") + kFaceNames[k], t.results.sensors[scene.findSensor(kFaceNames[k])], a, a,
             [&](double x0, double x1, double y0, double y1) {
               return intensity * rectangleSolidAngleFrom(x0 - sx, x1 - sx, y0 - sy, y1 - sy, hz) /
                      ((x1 - x0) * (y1 - y0));
             });
  }
  return c;
}

namespace {

// The CIE sky luminance relative to the zenith, written out here from ISO 15469 / CIE S 011 apart
// from the library's CieSky: type 0 the standard overcast sky, else general sky type 8 or 12 (the
// two these cases use) with the sun towards unit `sun`; 0 below the horizon.
double skyRelative(int type, const glm::dvec3& sun, const glm::dvec3& d) {
  if (d.z <= 0.0) return 0.0;
  if (type == 0) return (1.0 + 2.0 * d.z) / 3.0;
  const double a = type == 8 ? 0.0 : -1.0, b = type == 8 ? -1.0 : -0.32, c = 10.0, dd = -3.0, e = 0.45;
  const auto f = [&](double chi) {
    return 1.0 + c * (std::exp(dd * chi) - std::exp(dd * std::numbers::pi / 2)) + e * std::cos(chi) * std::cos(chi);
  };
  const auto phi = [&](double cos_z) { return 1.0 + a * std::exp(b / cos_z); };
  const double chi = std::acos(std::clamp(glm::dot(d, sun), -1.0, 1.0));
  return f(chi) * phi(d.z) / (f(std::acos(sun.z)) * phi(1.0));
}

// The horizontal illuminance per zenith luminance of that sky: the midpoint rule in (zenith angle,
// azimuth), 800 x 1600 (7 pi / 9 for the overcast sky).
double skyHorizontal(int type, const glm::dvec3& sun) {
  const int nz = 800, na = 1600;
  double sum = 0.0;
  for (int i = 0; i < nz; ++i) {
    const double z = (i + 0.5) * (std::numbers::pi / 2) / nz;
    for (int j = 0; j < na; ++j) {
      const double az = (j + 0.5) * 2 * std::numbers::pi / na;
      const glm::dvec3 d(std::sin(z) * std::sin(az), std::sin(z) * std::cos(az), std::cos(z));
      sum += skyRelative(type, sun, d) * std::cos(z) * std::sin(z);
    }
  }
  return sum * (std::numbers::pi / 2) / nz * 2 * std::numbers::pi / na;
}

// The sun's direction from its altitude and azimuth (degrees; azimuth from north, +y, towards east).
glm::dvec3 sunAt(double altitude_deg, double azimuth_deg) {
  const double h = altitude_deg * std::numbers::pi / 180, a = azimuth_deg * std::numbers::pi / 180;
  return {std::cos(h) * std::sin(a), std::cos(h) * std::cos(a), std::sin(h)};
}

// A black (absorbing) rectangle w x h centred at `at`, spanned by unit ex, ey.
void blackRectangle(Fixture& f, const std::string& name, double w, double h, const glm::dvec3& at, const glm::dvec3& ex,
                    const glm::dvec3& ey) {
  f.add(std::make_shared<const MeshObject>(std::make_shared<const TriangleMesh>(makePlane({w, h}, name))),
        frame(at, ex, ey), name);
}

// The black room of the daylight cases: 4 m x 4 m, 3 m high, floor z = 0 (no floor surface: the
// meters lie on it), with a 2 m x 2 m opening centred in the roof (`roof`) or a 2 m wide, 1.5 m
// high window with its sill at 1 m centred in the south wall y = -2 (facade).
void blackRoom(Fixture& f, bool roof) {
  const glm::dvec3 x(1, 0, 0), y(0, 1, 0), z(0, 0, 1);
  blackRectangle(f, "wall_n", 4, 3, {0, 2, 1.5}, x, z);
  blackRectangle(f, "wall_e", 4, 3, {2, 0, 1.5}, y, z);
  blackRectangle(f, "wall_w", 4, 3, {-2, 0, 1.5}, y, z);
  if (roof) {
    blackRectangle(f, "wall_s", 4, 3, {0, -2, 1.5}, x, z);
    blackRectangle(f, "roof_n", 4, 1, {0, 1.5, 3}, x, y);
    blackRectangle(f, "roof_s", 4, 1, {0, -1.5, 3}, x, y);
    blackRectangle(f, "roof_e", 1, 2, {1.5, 0, 3}, x, y);
    blackRectangle(f, "roof_w", 1, 2, {-1.5, 0, 3}, x, y);
  } else {
    blackRectangle(f, "roof", 4, 4, {0, 0, 3}, x, y);
    blackRectangle(f, "wall_s_low", 4, 1, {0, -2, 0.5}, x, z);
    blackRectangle(f, "wall_s_high", 4, 0.5, {0, -2, 2.75}, x, z);
    blackRectangle(f, "wall_s_e", 1, 1.5, {1.5, -2, 1.75}, x, z);
    blackRectangle(f, "wall_s_w", 1, 1.5, {-1.5, -2, 1.75}, x, z);
  }
}

// The 5 x 5 floor points of the daylight cases (0.8 m apart).
PointMeter daylightFloor() { return floorGrid(5, 0.8); }

std::string pointLabel(const glm::dvec3& p) {
  char s[48];
  std::snprintf(s, sizeof s, "(%.1f, %.1f)", p.x, p.y);
  return s;
}

// The sky component at floor point p (facing up) through the opening {o + s ex + t ey : |s| <= w/2,
// |t| <= h/2}: L_z times the integral of the relative luminance cos_p cos_o / d^2 over the opening
// (midpoint rule, 300 x 300).
double skyThrough(int type, const glm::dvec3& sun, double lz, const glm::dvec3& p, const glm::dvec3& o,
                  const glm::dvec3& ex, const glm::dvec3& ey, double w, double h) {
  const glm::dvec3 n = glm::cross(ex, ey);
  const int k = 300;
  double sum = 0.0;
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) {
      const glm::dvec3 q = o + ((i + 0.5) / k - 0.5) * w * ex + ((j + 0.5) / k - 0.5) * h * ey;
      const glm::dvec3 v = q - p;
      const double d2 = glm::dot(v, v);
      const glm::dvec3 u = v / std::sqrt(d2);
      sum += skyRelative(type, sun, u) * u.z * std::abs(glm::dot(u, n)) / d2;
    }
  return lz * sum * w * h / (k * k);
}

constexpr double kSkyLux = 10000.0;  // the unobstructed sky's horizontal illuminance

}  // namespace

CaseResult daylightOpeningCase(bool roof, const CaseOptions& o) {
  CaseResult c = describe(
      roof ? "daylight-roof-opening" : "daylight-facade-opening",
      roof ? "Sky component on the floor of a black 4 m x 4 m x 3 m room under a 2 m x 2 m unglazed roof opening: "
             "CIE overcast sky and CIE skies 8 and 12 (sun at altitude 30, azimuth 180, not itself emitted), 10,000 lx "
             "horizontal"
           : "Sky component on the floor of a black 4 m x 4 m x 3 m room with a 2 m x 1.5 m unglazed window (sill "
             "1 m) in its south wall: the same skies",
      "L_z x integral of the sky's relative luminance (ISO 15469 formulas written out apart from the library) x cos "
      "cos / d^2 over the opening, 300 x 300 midpoint rule; L_z = 10,000 lx / the sky's horizontal integral (800 x "
      "1600 midpoint rule)",
      "lx", 100000, o);
  const glm::dvec3 sun = sunAt(30, 180);
  const PointMeter floor = daylightFloor();
  const std::vector<glm::dvec3>& points = floor.points;
  for (const int type : {0, 8, 12}) {
    Fixture f;
    blackRoom(f, roof);
    Light sky;
    sky.type = LightType::Sky;
    sky.name = "sky";
    sky.sky = std::make_shared<const CieSky>(type == 0 ? CieSky::overcast() : CieSky::general(type, sun));
    sky.position = {0, 0, 1.5};
    sky.radius = 3.5;  // holds the room (its corners are 3.2 m from the centre)
    sky.power_w = kSkyLux / sky.sky->horizontalIntegral() * sky.sky->radianceIntegral() * std::numbers::pi *
                  sky.radius * sky.radius;
    SensorScene scene = f.scene({sky});
    scene.setMeters({floor});
    const Timed t = run(scene, c.rays, o);
    c.seconds += t.seconds;
    const MeterResult& m = t.results.meters[0];
    const double lz = kSkyLux / skyHorizontal(type, sun);
    const std::string name = type == 0 ? "overcast" : "type " + std::to_string(type);
    for (std::size_t k = 0; k < points.size(); ++k) {
      const double ref = roof ? skyThrough(type, sun, lz, points[k], {0, 0, 3}, {1, 0, 0}, {0, 1, 0}, 2, 2)
                              : skyThrough(type, sun, lz, points[k], {0, -2, 1.75}, {1, 0, 0}, {0, 0, 1}, 2, 1.5);
      c.rows.push_back(
          {name + " " + pointLabel(points[k]), ref, m.irradiance_w_m2[k], m.stderr_w_m2[k], std::nan(""), 0.005});
    }
  }
  return c;
}

CaseResult daylightSunCase(const CaseOptions& o) {
  // The sun at altitude 60, azimuth 180 through the roof opening: its beam travels north and down,
  // the opening's patch on the floor is the opening shifted 3 / tan 60 = 1.732 m north (y from
  // 0.732 to 2.732, x from -1 to 1); no floor point lies within 0.06 m of its edge.
  CaseResult c =
      describe("daylight-sun-patch",
               "Direct sunlight of 50,000 lx normal illuminance (altitude 60, azimuth 180) through the "
               "2 m x 2 m roof opening of the black room onto 25 floor points",
               "E_n sin(altitude) inside the opening's sunlit patch, 0 outside (parallel rays)", "lx", 20000, o);
  Fixture f;
  blackRoom(f, true);
  const glm::dvec3 sun = sunAt(60, 180);
  Light beam;
  beam.type = LightType::Directional;
  beam.name = "sun";
  beam.direction = -sun;
  beam.position = glm::dvec3(0, 0, 1.5) + 3.5 * sun;
  beam.radius = 3.5;
  beam.power_w = 50000.0 * std::numbers::pi * beam.radius * beam.radius;
  const PointMeter floor = daylightFloor();
  const std::vector<glm::dvec3>& points = floor.points;
  SensorScene scene = f.scene({beam});
  scene.setMeters({floor});
  const Timed t = run(scene, c.rays, o);
  c.seconds = t.seconds;
  const double shift = 3.0 / std::tan(60 * std::numbers::pi / 180);
  for (std::size_t k = 0; k < points.size(); ++k) {
    const bool lit = std::abs(points[k].x) < 1.0 && std::abs(points[k].y - shift) < 1.0;
    const double ref = lit ? 50000.0 * std::sin(60 * std::numbers::pi / 180) : 0.0;
    c.rows.push_back({"sun " + pointLabel(points[k]), ref, t.results.meters[0].irradiance_w_m2[k],
                      t.results.meters[0].stderr_w_m2[k], std::nan(""), 1e-9});
  }
  return c;
}

std::vector<CaseResult> allCases(const CaseOptions& o) {
  std::vector<CaseResult> all;
  all.push_back(pointSourceCase(o));
  all.push_back(areaSourceCase(o));
  all.push_back(areaSourcePointsCase(o));
  all.push_back(obstructionCase(o));
  all.push_back(blackCubeCase(o));
  for (const double rho : {0.2, 0.5, 0.8}) all.push_back(diffuseCubeCase(rho, o));
  all.push_back(diffuseCubeCase(0.95, o, true));
  all.push_back(clearGlassCase(o));
  all.push_back(daylightOpeningCase(true, o));
  all.push_back(daylightOpeningCase(false, o));
  all.push_back(daylightSunCase(o));
  return all;
}

}  // namespace duplex::validation
