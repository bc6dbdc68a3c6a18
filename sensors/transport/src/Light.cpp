#include "duplex/sensors/Light.h"

#include "duplex/accel/Error.h"

#include "OrthonormalBasis.h"

#include <glm/geometric.hpp>
#include <glm/matrix.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <numbers>

namespace duplex {

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

bool finite(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

double cross2(const glm::dvec2& a, const glm::dvec2& b) { return a.x * b.y - a.y * b.x; }

// Whether closed segments [a, b] and [c, d] share a point (orientation tests; collinear overlaps
// and touching ends included).
bool segmentsMeet(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
  auto side = [](const glm::dvec2& p, const glm::dvec2& q, const glm::dvec2& r) {
    const double x = cross2(q - p, r - p);
    return x > 0.0 ? 1 : (x < 0.0 ? -1 : 0);
  };
  auto within = [](const glm::dvec2& p, const glm::dvec2& q, const glm::dvec2& r) {  // r on segment pq, collinear
    return std::min(p.x, q.x) <= r.x && r.x <= std::max(p.x, q.x) && std::min(p.y, q.y) <= r.y &&
           r.y <= std::max(p.y, q.y);
  };
  const int s1 = side(a, b, c), s2 = side(a, b, d), s3 = side(c, d, a), s4 = side(c, d, b);
  if (s1 != s2 && s3 != s4) return true;
  return (s1 == 0 && within(a, b, c)) || (s2 == 0 && within(a, b, d)) || (s3 == 0 && within(c, d, a)) ||
         (s4 == 0 && within(c, d, b));
}

}  // namespace

void Light::validate() const {
  auto bad = [this](const std::string& what) { throw InvalidArgument("light '" + name + "': " + what); };
  if (!std::isfinite(power_w)) bad("power is not finite");
  if (!(power_w > 0.0)) bad("power must be > 0 W (got " + std::to_string(power_w) + ")");
  if (!(std::isfinite(lumens) && lumens >= 0.0))
    bad("lumens must be finite and >= 0 (0: the light is given in watts; got " + std::to_string(lumens) + ")");
  double spectrum_sum = 0.0;
  for (const double s : spectrum) {
    if (!(std::isfinite(s) && s >= 0.0)) bad("spectrum entries must be finite and >= 0");
    spectrum_sum += s;
  }
  if (!spectrum.empty() && !(spectrum_sum > 0.0)) bad("spectrum must have a positive entry");
  if (!std::isfinite(spectrum_sum)) bad("spectrum entries sum to more than the largest double");
  switch (type) {
    case LightType::Spot:
      if (!(cone_angle > 0.0 && cone_angle <= std::numbers::pi)) bad("cone angle must be in (0, 180] degrees");
      [[fallthrough]];
    case LightType::Point:
      if (!finite(position)) bad("position is not finite");
      if (type == LightType::Spot && !(finite(direction) && glm::length(direction) > 0.0))
        bad("direction must be a finite non-zero vector");
      break;
    case LightType::Directional:
      if (!finite(position)) bad("position is not finite");
      if (!(finite(direction) && glm::length(direction) > 0.0)) bad("direction must be a finite non-zero vector");
      if (!(std::isfinite(radius) && radius > 0.0)) bad("radius must be finite and > 0");
      break;
    case LightType::Sky:
      if (!sky) bad("no sky luminance distribution");
      if (!finite(position)) bad("position is not finite");
      if (!(std::isfinite(radius) && radius > 0.0)) bad("radius must be finite and > 0");
      break;
    case LightType::Goniometric: {
      if (!profile) bad("no intensity profile");
      if (!finite(position)) bad("position is not finite");
      // A rotation keeps the table's solid angles: L^T L = I and det L = 1.
      const glm::dmat3& l = world_from_light.linear;
      const glm::dmat3 g = glm::transpose(l) * l;
      double off = 0.0;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) off = std::max(off, std::abs(g[i][j] - (i == j ? 1.0 : 0.0)));
      if (!world_from_light.isFinite() || !(off < 1e-9) || !(glm::determinant(l) > 0.0))
        bad("the transform's linear part must be a rotation");
      break;
    }
    case LightType::Area:
      if (!triangles.empty() &&
          (!polygon.empty() || disk || polygon_cdf.size() != triangles.size() || polygon_cdf.back() != 1.0))
        bad("an emissive mesh's area shares are not set (Light::setTriangles)");
      if (!polygon.empty() && (polygon.size() < 3 || polygon_triangles.size() != polygon.size() - 2 ||
                               polygon_cdf.size() != polygon_triangles.size() || polygon_cdf.back() != 1.0 || disk))
        bad("a polygon light's triangles are not set (Light::setPolygon)");
      if (!(std::isfinite(width) && width > 0.0 && std::isfinite(height) && height > 0.0))
        bad("size must be finite and > 0");
      if (disk && width != height) bad("a disk light has one diameter (width == height)");
      if (!world_from_light.isFinite() || world_from_light.isSingular()) bad("transform is not finite or singular");
      break;
  }
}

void Light::setPolygon(std::vector<glm::dvec2> vertices) {
  auto bad = [this](const std::string& what) { throw InvalidArgument("light '" + name + "': " + what); };
  const std::size_t n = vertices.size();
  if (n < 3) bad("a polygon has at least 3 vertices (got " + std::to_string(n) + ")");
  double signed_area = 0.0, half_w = 0.0, half_h = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const glm::dvec2& v = vertices[i];
    if (!(std::isfinite(v.x) && std::isfinite(v.y))) bad("polygon vertex " + std::to_string(i) + " is not finite");
    signed_area += 0.5 * cross2(v, vertices[(i + 1) % n]);
    half_w = std::max(half_w, std::abs(v.x));
    half_h = std::max(half_h, std::abs(v.y));
  }
  // Simple: no two edges meet but adjacent ones at their shared vertex.
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) {
      const bool adjacent = j == i + 1 || (i == 0 && j == n - 1);
      const glm::dvec2 &a = vertices[i], &b = vertices[(i + 1) % n], &c = vertices[j], &d = vertices[(j + 1) % n];
      // Adjacent edges share a vertex; they must not fold back onto each other there.
      const bool meet =
          adjacent ? cross2(b - a, d - c) == 0.0 && glm::dot(b - a, d - c) < 0.0 : segmentsMeet(a, b, c, d);
      if (meet)
        bad("polygon edges " + std::to_string(i) + " and " + std::to_string(j) +
            " cross or touch (not a simple polygon)");
    }
  if (!(std::abs(signed_area) > 0.0)) bad("the polygon has no area");
  const double orientation = signed_area > 0.0 ? 1.0 : -1.0;
  // Ear clipping: a convex corner whose triangle holds no other remaining vertex is cut off.
  std::vector<std::uint32_t> left(n);
  for (std::size_t i = 0; i < n; ++i) left[i] = static_cast<std::uint32_t>(i);
  std::vector<std::array<std::uint32_t, 3>> triangles;
  while (left.size() > 3) {
    const std::size_t m = left.size();
    bool cut = false;
    for (std::size_t i = 0; i < m && !cut; ++i) {
      const std::uint32_t ia = left[(i + m - 1) % m], ib = left[i], ic = left[(i + 1) % m];
      const glm::dvec2 &a = vertices[ia], &b = vertices[ib], &c = vertices[ic];
      if (!(orientation * cross2(b - a, c - b) > 0.0)) continue;  // reflex or straight corner
      bool empty = true;
      for (const std::uint32_t k : left) {
        if (k == ia || k == ib || k == ic) continue;
        const glm::dvec2& p = vertices[k];
        if (orientation * cross2(b - a, p - a) >= 0.0 && orientation * cross2(c - b, p - b) >= 0.0 &&
            orientation * cross2(a - c, p - c) >= 0.0) {
          empty = false;
          break;
        }
      }
      if (!empty) continue;
      triangles.push_back({ia, ib, ic});
      left.erase(left.begin() + static_cast<std::ptrdiff_t>(i));
      cut = true;
    }
    if (!cut) bad("the polygon could not be triangulated (not a simple polygon)");
  }
  triangles.push_back({left[0], left[1], left[2]});
  std::vector<double> cdf(triangles.size());
  double acc = 0.0;
  for (std::size_t t = 0; t < triangles.size(); ++t) {
    const glm::dvec2 &a = vertices[triangles[t][0]], &b = vertices[triangles[t][1]], &c = vertices[triangles[t][2]];
    cdf[t] = (acc += 0.5 * std::abs(cross2(b - a, c - a)));
  }
  for (double& c : cdf) c /= acc;
  cdf.back() = 1.0;
  polygon = std::move(vertices);
  polygon_triangles = std::move(triangles);
  polygon_cdf = std::move(cdf);
  disk = false;
  width = 2.0 * half_w;
  height = 2.0 * half_h;
}

void Light::setTriangles(std::vector<std::array<glm::dvec3, 3>> tris) {
  auto bad = [this](const std::string& what) { throw InvalidArgument("light '" + name + "': " + what); };
  if (tris.empty()) bad("an emissive mesh without triangles");
  std::vector<double> cdf(tris.size());
  double acc = 0.0, extent = 0.0;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    for (const glm::dvec3& v : tris[t]) {
      if (!finite(v)) bad("emissive mesh triangle " + std::to_string(t) + " has a non-finite vertex");
      extent = std::max({extent, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
    }
    cdf[t] = (acc += 0.5 * glm::length(glm::cross(tris[t][1] - tris[t][0], tris[t][2] - tris[t][0])));
  }
  if (!(acc > 0.0) || !std::isfinite(acc)) bad("the emissive mesh has no area");
  for (double& c : cdf) c /= acc;
  cdf.back() = 1.0;
  triangles = std::move(tris);
  polygon.clear();
  polygon_triangles.clear();
  polygon_cdf = std::move(cdf);
  disk = false;
  width = height = 2.0 * extent;
}

double Light::localArea() const {
  if (!triangles.empty()) {
    double a = 0.0;
    for (const auto& t : triangles) a += 0.5 * glm::length(glm::cross(t[1] - t[0], t[2] - t[0]));
    return a;
  }
  if (!polygon.empty()) {
    double a = 0.0;
    for (std::size_t i = 0; i < polygon.size(); ++i) a += 0.5 * cross2(polygon[i], polygon[(i + 1) % polygon.size()]);
    return std::abs(a);
  }
  return width * height * (disk ? std::numbers::pi / 4.0 : 1.0);
}

double Light::intensity(const glm::dvec3& dir_ws) const {
  switch (type) {
    case LightType::Point: return power_w / (4.0 * std::numbers::pi);
    case LightType::Spot: {
      const double c = glm::dot(glm::normalize(dir_ws), glm::normalize(direction));
      return c >= std::cos(cone_angle) ? power_w / (kTwoPi * (1.0 - std::cos(cone_angle))) : 0.0;
    }
    case LightType::Goniometric:
      // The luminaire frame is the transpose (inverse) of the rotation applied to world directions.
      return power_w * profile->intensity(glm::transpose(world_from_light.linear) * dir_ws) / profile->integral();
    default: return 0.0;
  }
}

Light placeLight(const Light& light, const Affine& world_from_node) {
  Light out = light;
  const Affine& w = world_from_node;
  out.position = w.point(light.position);
  out.direction = w.vector(light.direction);
  out.world_from_light = w * light.world_from_light;
  if (light.type == LightType::Sky)
    throw InvalidArgument("light '" + light.name + "': a sky is not placed at a node (it lights the world)");
  if (light.type == LightType::Directional || light.type == LightType::Goniometric) {
    // The uniform scale of a similarity: |L e_x|, checked against L^T L = s^2 I.
    const glm::dmat3 g = glm::transpose(w.linear) * w.linear;
    const double s2 = g[0][0];
    double off = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) off = std::max(off, std::abs(g[i][j] - (i == j ? s2 : 0.0)));
    if (!(off <= 1e-9 * s2) || !(glm::determinant(w.linear) > 0.0))
      throw InvalidArgument("light '" + light.name +
                            "': its node's world transform must be a rotation with uniform scale (a " +
                            (light.type == LightType::Directional ? "directional" : "goniometric") + " light)");
    const double scale = std::sqrt(s2);
    if (light.type == LightType::Directional) out.radius = light.radius * scale;
    else out.world_from_light.linear = (w.linear / scale) * light.world_from_light.linear;
  }
  out.validate();
  return out;
}

namespace {

// A triangle of a polygon or mesh by its share of the area (`cdf`: the cumulative shares), from
// uniform u0, and sqrt of u0's place inside that share (uniform again): the point (1 - s) a +
// s (1 - u1) b + s u1 c is then uniform over the triangle for another uniform u1.
std::pair<std::size_t, double> triangleByArea(const std::vector<double>& cdf, double u0) {
  const std::size_t k =
      std::min(cdf.size() - 1, static_cast<std::size_t>(std::upper_bound(cdf.begin(), cdf.end(), u0) - cdf.begin()));
  const double lo = k ? cdf[k - 1] : 0.0;
  return {k, std::sqrt(std::clamp((u0 - lo) / (cdf[k] - lo), 0.0, 1.0))};
}

}  // namespace

EmittedRay sampleLight(const Light& light, const double u[4]) {
  EmittedRay r;
  switch (light.type) {
    case LightType::Point: {
      // Uniform on the sphere (Archimedes: z uniform in [-1, 1]).
      const double z = 1.0 - 2.0 * u[0], s = std::sqrt(std::max(0.0, 1.0 - z * z)), phi = kTwoPi * u[1];
      r.origin = light.position;
      r.dir = glm::dvec3(s * std::cos(phi), s * std::sin(phi), z);
      break;
    }
    case LightType::Spot: {
      // Uniform over the cone's solid angle: cos(theta) uniform in [cos(alpha), 1].
      const glm::dvec3 n = glm::normalize(light.direction);
      glm::dvec3 t, b;
      detail::orthonormalBasis(n, t, b);
      const double c = 1.0 - u[0] * (1.0 - std::cos(light.cone_angle)), s = std::sqrt(std::max(0.0, 1.0 - c * c));
      const double phi = kTwoPi * u[1];
      r.origin = light.position;
      r.dir = s * std::cos(phi) * t + s * std::sin(phi) * b + c * n;
      break;
    }
    case LightType::Directional: {
      const glm::dvec3 n = glm::normalize(light.direction);
      glm::dvec3 t, b;
      detail::orthonormalBasis(n, t, b);
      const double rad = light.radius * std::sqrt(u[0]), phi = kTwoPi * u[1];
      r.origin = light.position + rad * std::cos(phi) * t + rad * std::sin(phi) * b;
      r.dir = n;
      break;
    }
    case LightType::Sky: {
      // A direction by the sky's luminance; the ray enters across the lit sphere from a disk of its
      // radius perpendicular to the direction, one radius upstream of the centre.
      const CieSky::Sample s = light.sky->sample(u[0], u[1]);
      glm::dvec3 t, b;
      detail::orthonormalBasis(s.dir_ws, t, b);
      const double rad = light.radius * std::sqrt(u[2]), phi = kTwoPi * u[3];
      r.origin = light.position + light.radius * s.dir_ws + rad * std::cos(phi) * t + rad * std::sin(phi) * b;
      r.dir = -s.dir_ws;
      r.weight = s.weight;
      break;
    }
    case LightType::Goniometric: {
      // The table's own importance sampling: directions distributed as the intensity, with weights
      // intensity / (pdf * integral) of mean 1 (IesProfile::sample).
      const IesProfile::Sample s = light.profile->sample(u[0], u[1]);
      r.origin = light.position;
      r.dir = glm::normalize(light.world_from_light.linear * s.direction_lf);
      r.weight = s.weight;
      break;
    }
    case LightType::Area: {
      // Uniform over the (affinely mapped) rectangle or disk, cosine-weighted about its world normal.
      const double rad = 0.5 * light.width * std::sqrt(u[0]), phi_d = kTwoPi * u[1];
      glm::dvec3 p_ls = light.disk ? glm::dvec3(rad * std::cos(phi_d), rad * std::sin(phi_d), 0.0)
                                   : glm::dvec3((u[0] - 0.5) * light.width, (u[1] - 0.5) * light.height, 0.0);
      if (!light.polygon.empty()) {
        const auto [k, s] = triangleByArea(light.polygon_cdf, u[0]);
        const auto& tri = light.polygon_triangles[k];
        const glm::dvec2 p = (1.0 - s) * light.polygon[tri[0]] + s * (1.0 - u[1]) * light.polygon[tri[1]] +
                             s * u[1] * light.polygon[tri[2]];
        p_ls = glm::dvec3(p, 0.0);
      }
      r.origin = light.world_from_light.point(p_ls);
      const glm::dvec3 ex = light.world_from_light.vector(glm::dvec3(1, 0, 0));
      const glm::dvec3 ey = light.world_from_light.vector(glm::dvec3(0, 1, 0));
      glm::dvec3 n = glm::normalize(glm::cross(ex, ey));
      if (!light.triangles.empty()) {
        // Its front face.
        const auto [k, s] = triangleByArea(light.polygon_cdf, u[0]);
        const glm::dvec3 a = light.world_from_light.point(light.triangles[k][0]),
                         b = light.world_from_light.point(light.triangles[k][1]),
                         c = light.world_from_light.point(light.triangles[k][2]);
        r.origin = (1.0 - s) * a + s * (1.0 - u[1]) * b + s * u[1] * c;
        n = glm::normalize(glm::cross(b - a, c - a));
        r.normal = n;
      }
      double v = u[2];
      if (light.two_sided) {  // half the rays from each face
        if (v < 0.5) {
          n = -n;
          v = 2.0 * v;
        } else {
          v = 2.0 * v - 1.0;
        }
      }
      glm::dvec3 t = glm::normalize(ex), b = glm::cross(n, t);
      if (!light.triangles.empty()) detail::orthonormalBasis(n, t, b);  // the face is not the local plane
      const double s = std::sqrt(v), phi = kTwoPi * u[3];
      r.dir = s * std::cos(phi) * t + s * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - v)) * n;
      break;
    }
  }
  return r;
}

}  // namespace duplex
