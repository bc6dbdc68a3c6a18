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
      if (!(std::isfinite(width) && width > 0.0 && std::isfinite(height) && height > 0.0))
        bad("size must be finite and > 0");
      if (disk && width != height) bad("a disk light has one diameter (width == height)");
      if (!world_from_light.isFinite() || world_from_light.isSingular()) bad("transform is not finite or singular");
      break;
  }
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
      const glm::dvec3 p_ls = light.disk ? glm::dvec3(rad * std::cos(phi_d), rad * std::sin(phi_d), 0.0)
                                         : glm::dvec3((u[0] - 0.5) * light.width, (u[1] - 0.5) * light.height, 0.0);
      r.origin = light.world_from_light.point(p_ls);
      const glm::dvec3 ex = light.world_from_light.vector(glm::dvec3(1, 0, 0));
      const glm::dvec3 ey = light.world_from_light.vector(glm::dvec3(0, 1, 0));
      glm::dvec3 n = glm::normalize(glm::cross(ex, ey));
      double v = u[2];
      if (light.two_sided) {  // half the rays from each face
        if (v < 0.5) {
          n = -n;
          v = 2.0 * v;
        } else {
          v = 2.0 * v - 1.0;
        }
      }
      const glm::dvec3 t = glm::normalize(ex), b = glm::cross(n, t);
      const double s = std::sqrt(v), phi = kTwoPi * u[3];
      r.dir = s * std::cos(phi) * t + s * std::sin(phi) * b + std::sqrt(std::max(0.0, 1.0 - v)) * n;
      break;
    }
  }
  return r;
}

}  // namespace duplex
