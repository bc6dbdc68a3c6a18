#include "duplex/sensors/SensorObject.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <string>

namespace duplex {

namespace {

// Integral of sqrt(r^2 - x^2) over [a, b] (both clamped to [-r, r]); zero when b <= a.
double chordIntegral(double r, double a, double b) {
  a = std::clamp(a, -r, r);
  b = std::clamp(b, -r, r);
  if (b <= a) return 0.0;
  auto f = [r](double x) { return 0.5 * (x * std::sqrt(std::max(0.0, r * r - x * x)) + r * r * std::asin(x / r)); };
  return f(b) - f(a);
}

// Area of the disk inside the quadrant {X <= x, Y <= y}: the integral over X of the length of
// {Y <= y} within the chord [-s(X), s(X)], split where the chord half-length s(X) equals |y|.
double diskQuadrantArea(double r, double x, double y) {
  const double xm = std::min(x, r);
  if (xm <= -r || y <= -r) return 0.0;
  const double full = chordIntegral(r, -r, xm);
  if (y >= r) return 2.0 * full;
  const double a = std::sqrt(r * r - y * y);  // chords longer than 2|y| are cut at Y = y
  const double inner = std::max(0.0, std::min(a, xm) + a);
  const double outer = chordIntegral(r, -r, std::min(-a, xm)) + chordIntegral(r, a, xm);
  return full + y * inner + (y >= 0.0 ? outer : -outer);
}

}  // namespace

double diskRectangleArea(double r, double x0, double x1, double y0, double y1) {
  const double area = diskQuadrantArea(r, x1, y1) - diskQuadrantArea(r, x0, y1) - diskQuadrantArea(r, x1, y0) +
                      diskQuadrantArea(r, x0, y0);
  return std::max(0.0, area);
}

SensorObject::SensorObject(std::string name, const SensorSpec& spec)
    : Object(std::move(name), ObjectRole::Crossing), spec_(spec) {
  auto bad = [this](const std::string& what) { throw InvalidArgument("sensor '" + this->name() + "': " + what); };
  // The bin areas against the process's memory limit, before they are allocated.
  const auto requireBinAreas = [this, &spec] {
    std::ostringstream what;
    what << "sensor '" << this->name() << "' (" << spec.nx << " x " << spec.ny << " bins)";
    requireMemory(arrayBytes(std::uint64_t{spec.nx} * spec.ny, sizeof(double)), what.str());
  };
  if (spec.shape == SensorShape::FarField) {
    if (spec.nx == 0 || spec.ny < 2) bad("a far-field sensor needs at least 1 C-plane and 2 vertical angles");
    if (static_cast<std::uint64_t>(spec.nx) * spec.ny > (1u << 26)) bad("more than 2^26 bins");
    if (spec.theta_bins != 0) bad("a far-field sensor takes no angular bins (its bins are directions)");
    requireBinAreas();
    // Exact solid angle of each C-gamma cell: dC (cos gamma0 - cos gamma1).
    bin_area_.resize(binCount());
    const double dc = 2.0 * std::numbers::pi / spec.nx, dg = std::numbers::pi / (spec.ny - 1);
    for (std::uint32_t ig = 0; ig < spec.ny; ++ig) {
      const double g0 = std::max(0.0, (ig - 0.5) * dg), g1 = std::min(std::numbers::pi, (ig + 0.5) * dg);
      for (std::uint32_t ic = 0; ic < spec.nx; ++ic) bin_area_[ic * spec.ny + ig] = dc * (std::cos(g0) - std::cos(g1));
    }
    return;
  }
  if (!(std::isfinite(spec.width) && spec.width > 0.0) || !(std::isfinite(spec.height) && spec.height > 0.0))
    bad("size must be finite and > 0");
  if (spec.nx == 0 || spec.ny == 0) bad("bins must be at least 1 x 1");
  if (static_cast<std::uint64_t>(spec.nx) * spec.ny > (1u << 26)) bad("more than 2^26 bins");
  if (spec.shape != SensorShape::Rectangle && spec.width != spec.height)
    bad("a disk or sphere has one diameter (width == height)");
  if (spec.shape == SensorShape::Sphere && spec.theta_bins != 0)
    bad("a sphere takes no angular bins (its bins are directions)");
  if (spec.theta_bins > 0 && spec.phi_bins == 0) bad("angular bins need at least one phi bin");
  if (static_cast<std::uint64_t>(spec.theta_bins) * spec.phi_bins > (1u << 20)) bad("more than 2^20 angular bins");
  requireBinAreas();
  // Bin areas once: a rectangle's bins are equal; a disk's are its squares cut by the circle; a
  // sphere's are equal (equal steps of z and of the azimuth cut equal areas).
  bin_area_.resize(binCount());
  if (spec.shape == SensorShape::Sphere) {
    std::fill(bin_area_.begin(), bin_area_.end(), area() / binCount());
    return;
  }
  const double bw = spec.width / spec.nx, bh = spec.height / spec.ny;
  for (std::uint32_t iy = 0; iy < spec.ny; ++iy) {
    for (std::uint32_t ix = 0; ix < spec.nx; ++ix) {
      double a = bw * bh;
      if (spec.shape == SensorShape::Disk) {
        const double x0 = -0.5 * spec.width + ix * bw, y0 = -0.5 * spec.height + iy * bh;
        a = diskRectangleArea(0.5 * spec.width, x0, x0 + bw, y0, y0 + bh);
      }
      bin_area_[iy * spec.nx + ix] = a;
    }
  }
}

std::uint32_t SensorObject::angleBinAt(double cos_theta, double phi) const {
  if (spec_.theta_bins == 0) return kInvalidId;
  constexpr double kHalfPi = 0.5 * std::numbers::pi, kTwoPi = 2.0 * std::numbers::pi;
  const double theta = std::acos(std::min(1.0, std::abs(cos_theta)));
  const auto it = std::min(spec_.theta_bins - 1, static_cast<std::uint32_t>(theta / kHalfPi * spec_.theta_bins));
  double p = std::fmod(phi, kTwoPi);
  if (p < 0.0) p += kTwoPi;
  const auto ip = std::min(spec_.phi_bins - 1, static_cast<std::uint32_t>(p / kTwoPi * spec_.phi_bins));
  return ip * spec_.theta_bins + it;
}

double SensorObject::angleBinSolidAngle(std::uint32_t bin) const {
  const std::uint32_t it = bin % spec_.theta_bins;
  const double dt = 0.5 * std::numbers::pi / spec_.theta_bins;
  return (std::cos(it * dt) - std::cos((it + 1) * dt)) * 2.0 * std::numbers::pi / spec_.phi_bins;
}

double SensorObject::area() const {
  if (spec_.shape == SensorShape::FarField) return 4.0 * std::numbers::pi;
  if (spec_.shape == SensorShape::Disk) return std::numbers::pi * 0.25 * spec_.width * spec_.width;
  if (spec_.shape == SensorShape::Sphere) return std::numbers::pi * spec_.width * spec_.width;
  return spec_.width * spec_.height;
}

Box SensorObject::bounds() const {
  if (spec_.shape == SensorShape::FarField) return Box{};  // nowhere: never placed in a scene
  if (spec_.shape == SensorShape::Sphere) {
    const float r = std::nextafter(static_cast<float>(0.5 * spec_.width), INFINITY);
    return Box(glm::vec3(-r), glm::vec3(r));
  }
  Box b;
  b.lo = glm::vec3(static_cast<float>(-0.5 * spec_.width), static_cast<float>(-0.5 * spec_.height), 0.0f);
  b.hi = glm::vec3(static_cast<float>(0.5 * spec_.width), static_cast<float>(0.5 * spec_.height), 0.0f);
  // Float rounding of the half sizes must not cut off the closed border.
  b.lo = glm::vec3(std::nextafter(b.lo.x, -INFINITY), std::nextafter(b.lo.y, -INFINITY), 0.0f);
  b.hi = glm::vec3(std::nextafter(b.hi.x, INFINITY), std::nextafter(b.hi.y, INFINITY), 0.0f);
  return b;
}

bool SensorObject::intersect(const Ray&, Hit&, QueryContext&) const { return false; }

bool SensorObject::occluded(const Ray&, QueryContext&) const { return false; }

std::uint32_t SensorObject::binAt(double x, double y) const {
  const double hw = 0.5 * spec_.width, hh = 0.5 * spec_.height;
  if (spec_.shape == SensorShape::Disk) {
    if (x * x + y * y > hw * hw) return kInvalidId;
  } else if (!(std::abs(x) <= hw && std::abs(y) <= hh)) {
    return kInvalidId;
  }
  // floor puts an inner edge into the bin above it; the upper border belongs to the last bin.
  const auto ix =
      std::min<std::uint32_t>(spec_.nx - 1, static_cast<std::uint32_t>(std::floor((x + hw) * spec_.nx / spec_.width)));
  const auto iy =
      std::min<std::uint32_t>(spec_.ny - 1, static_cast<std::uint32_t>(std::floor((y + hh) * spec_.ny / spec_.height)));
  return iy * spec_.nx + ix;
}

namespace {

// The crossings of a sphere sensor of radius r: the roots of |o + t d|^2 = r^2 in [tnear, tfar]
// (in double, with the numerically stable form of the quadratic), in order.
void sphereCrossings(const SensorObject& s, double r, const Ray& ray_os, std::vector<Hit>& hits) {
  const glm::dvec3 o(ray_os.origin), d(ray_os.dir);
  const double a = glm::dot(d, d), b = glm::dot(o, d), c = glm::dot(o, o) - r * r;
  const double disc = b * b - a * c;
  if (!(a > 0.0) || !(disc > 0.0)) return;  // degenerate direction, miss or tangent: no crossing
  const double q = -(b + std::copysign(std::sqrt(disc), b));
  double t0 = q / a, t1 = c / q;
  if (t0 > t1) std::swap(t0, t1);
  for (const double t : {t0, t1}) {
    if (!(t >= ray_os.tnear && t <= ray_os.tfar)) continue;
    const glm::dvec3 n = (o + t * d) / r;
    if (!s.spec().two_sided && glm::dot(n, d) >= 0.0) continue;  // one-sided: entering rays only
    Hit h;
    h.t = static_cast<float>(t);
    h.u = static_cast<float>(std::atan2(n.y, n.x));
    h.v = static_cast<float>(n.z);
    h.prim_id = s.sphereBinAt(n);
    h.ng = glm::vec3(n);
    hits.push_back(h);
  }
}

}  // namespace

bool SensorObject::cross(const Ray& ray_os, float& t_out, SensorCell& cell) const {
  if (spec_.shape == SensorShape::FarField) return false;
  if (spec_.shape == SensorShape::Sphere) {  // the first crossing
    std::vector<Hit> hits;
    sphereCrossings(*this, 0.5 * spec_.width, ray_os, hits);
    if (hits.empty()) return false;
    t_out = hits[0].t;
    cell = {hits[0].prim_id, hits[0].u, hits[0].v};
    return true;
  }
  const double dz = ray_os.dir.z;
  if (dz == 0.0) return false;                     // parallel (or in the plane): no crossing
  if (!spec_.two_sided && dz > 0.0) return false;  // one-sided: only rays arriving at the front (+z) face
  // In double: the crossing point decides the bin, and a float product would move it by an ulp.
  const double t = -static_cast<double>(ray_os.origin.z) / dz;
  if (!(t >= ray_os.tnear && t <= ray_os.tfar)) return false;
  const double x = ray_os.origin.x + t * ray_os.dir.x;
  const double y = ray_os.origin.y + t * ray_os.dir.y;
  const std::uint32_t bin = binAt(x, y);
  if (bin == kInvalidId) return false;
  t_out = static_cast<float>(t);
  cell = {bin, static_cast<float>(x), static_cast<float>(y)};
  return true;
}

std::uint32_t SensorObject::sphereBinAt(const glm::dvec3& n) const {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  double phi = std::atan2(n.y, n.x);
  if (phi < 0.0) phi += kTwoPi;
  const auto ix = std::min<std::uint32_t>(spec_.nx - 1, static_cast<std::uint32_t>(phi / kTwoPi * spec_.nx));
  const auto iy =
      std::min<std::uint32_t>(spec_.ny - 1, static_cast<std::uint32_t>(std::max(0.0, (n.z + 1.0) * 0.5 * spec_.ny)));
  return iy * spec_.nx + ix;
}

std::uint32_t SensorObject::farFieldBinAt(const glm::dvec3& d) const {
  const double len = glm::length(d);
  if (!(len > 0.0) || !std::isfinite(len)) return kInvalidId;
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  const double gamma = std::acos(std::clamp(-d.z / len, -1.0, 1.0));
  double c = std::atan2(d.y, d.x);
  if (c < 0.0) c += kTwoPi;
  // Cells centred on the grid's angles: floor(x + 1/2) puts an inner edge into the cell above it;
  // C wraps (the cell of C = 0 spans [-dC/2, dC/2)).
  const auto ig = std::min<std::uint32_t>(
      spec_.ny - 1, static_cast<std::uint32_t>(std::floor(gamma / std::numbers::pi * (spec_.ny - 1) + 0.5)));
  const auto ic = static_cast<std::uint32_t>(std::floor(c / kTwoPi * spec_.nx + 0.5)) % spec_.nx;
  return ic * spec_.ny + ig;
}

void SensorObject::intersectAll(const Ray& ray_os, std::vector<Hit>& hits, QueryContext&) const {
  if (spec_.shape == SensorShape::FarField) return;
  if (spec_.shape == SensorShape::Sphere) {
    sphereCrossings(*this, 0.5 * spec_.width, ray_os, hits);
    return;
  }
  float t;
  SensorCell cell;
  if (!cross(ray_os, t, cell)) return;
  Hit h;
  h.t = t;
  h.u = cell.x;
  h.v = cell.y;
  h.prim_id = cell.bin;
  h.ng = glm::vec3(0.0f, 0.0f, 1.0f);
  hits.push_back(h);
}

std::optional<FlatCrossings> SensorObject::flatCrossings() const {
  if (spec_.shape == SensorShape::Sphere || spec_.shape == SensorShape::FarField) return std::nullopt;
  const Box b = bounds();  // the half sizes rounded outwards: never inside the closed border
  return FlatCrossings{b.hi.x, b.hi.y, !spec_.two_sided};
}

std::size_t SensorObject::memoryBytes() const { return sizeof(*this) + bin_area_.capacity() * sizeof(double); }

}  // namespace duplex
