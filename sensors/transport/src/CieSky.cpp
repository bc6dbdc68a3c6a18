#include "duplex/sensors/CieSky.h"

#include "duplex/accel/Error.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

namespace duplex {

namespace {

constexpr double kPi = std::numbers::pi;
// The sampling grid: cells of equal solid angle, uniform in cos Z and azimuth.
constexpr int kCosCells = 64, kAzCells = 128;

// ISO 15469 / CIE S 011, table of the standard general sky: a, b (gradation), c, d, e (indicatrix).
constexpr std::array<std::array<double, 5>, 15> kGeneralSky{{
    {4.0, -0.70, 0, -1.0, 0.00},
    {4.0, -0.70, 2, -1.5, 0.15},
    {1.1, -0.80, 0, -1.0, 0.00},
    {1.1, -0.80, 2, -1.5, 0.15},
    {0.0, -1.00, 0, -1.0, 0.00},
    {0.0, -1.00, 2, -1.5, 0.15},
    {0.0, -1.00, 5, -2.5, 0.30},
    {0.0, -1.00, 10, -3.0, 0.45},
    {-1.0, -0.55, 2, -1.5, 0.15},
    {-1.0, -0.55, 5, -2.5, 0.30},
    {-1.0, -0.55, 10, -3.0, 0.45},
    {-1.0, -0.32, 10, -3.0, 0.45},
    {-1.0, -0.32, 16, -3.0, 0.30},
    {-1.0, -0.15, 16, -3.0, 0.30},
    {-1.0, -0.15, 24, -2.8, 0.15},
}};

// The direction of zenith cosine u and azimuth az (from north, +y, towards east, +x).
glm::dvec3 direction(double u, double az) {
  const double s = std::sqrt(std::max(0.0, 1.0 - u * u));
  return {s * std::sin(az), s * std::cos(az), u};
}

// Gauss-Legendre nodes and weights on [-1, 1], 8 points.
constexpr std::array<double, 8> kGlX{-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
                                     0.1834346424956498,  0.5255324099163290,  0.7966664774136267,  0.9602898564975363};
constexpr std::array<double, 8> kGlW{0.1012285362903763, 0.2223810344533745, 0.3137066458778873, 0.3626837833783620,
                                     0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};

}  // namespace

CieSky CieSky::overcast() {
  CieSky s;
  s.build();
  return s;
}

CieSky CieSky::general(int type, const glm::dvec3& sun_ws) {
  if (type < 1 || type > 15)
    throw InvalidArgument("CIE general sky: type " + std::to_string(type) + " is not one of 1-15");
  if (!(std::isfinite(sun_ws.x) && std::isfinite(sun_ws.y) && std::isfinite(sun_ws.z)) ||
      !(glm::length(sun_ws) > 0.0) || sun_ws.z < 0.0)
    throw InvalidArgument("CIE general sky: the sun's direction must be a finite vector at or above the horizon");
  CieSky s;
  s.type_ = type;
  const auto& p = kGeneralSky[static_cast<std::size_t>(type - 1)];
  s.a_ = p[0];
  s.b_ = p[1];
  s.c_ = p[2];
  s.d_ = p[3];
  s.e_ = p[4];
  s.sun_ = glm::normalize(sun_ws);
  const double zs = std::acos(std::clamp(s.sun_.z, -1.0, 1.0));
  const double f_zs =
      1.0 + s.c_ * (std::exp(s.d_ * zs) - std::exp(s.d_ * kPi / 2)) + s.e_ * std::cos(zs) * std::cos(zs);
  s.norm_ = f_zs * (1.0 + s.a_ * std::exp(s.b_));
  s.build();
  return s;
}

double CieSky::relativeLuminance(const glm::dvec3& dir_ws) const {
  const double cz = dir_ws.z;
  if (!(cz > 0.0)) return 0.0;
  if (type_ == 0) return (1.0 + 2.0 * cz) / 3.0;
  const double gradation = 1.0 + a_ * std::exp(b_ / cz);
  const double cos_chi = std::clamp(glm::dot(dir_ws, sun_), -1.0, 1.0), chi = std::acos(cos_chi);
  const double indicatrix = 1.0 + c_ * (std::exp(d_ * chi) - std::exp(d_ * kPi / 2)) + e_ * cos_chi * cos_chi;
  return indicatrix * gradation / norm_;
}

void CieSky::build() {
  // Integrals: exact for the overcast sky; else 8-point Gauss-Legendre on 64 x 128 panels in
  // (cos Z, azimuth), where dOmega = d(cos Z) d(az).
  if (type_ == 0) {
    radiance_integral_ = 4.0 * kPi / 3.0;    // 2 pi int_0^1 (1 + 2u) / 3 du
    horizontal_integral_ = 7.0 * kPi / 9.0;  // 2 pi int_0^1 (1 + 2u) u / 3 du
  } else {
    constexpr int nu = 64, na = 128;
    double sum = 0.0, sum_cos = 0.0;
    for (int i = 0; i < nu; ++i)
      for (int gi = 0; gi < 8; ++gi) {
        const double u = (i + 0.5 + 0.5 * kGlX[gi]) / nu, wu = 0.5 * kGlW[gi] / nu;
        for (int j = 0; j < na; ++j)
          for (int gj = 0; gj < 8; ++gj) {
            const double az = 2.0 * kPi * (j + 0.5 + 0.5 * kGlX[gj]) / na, wa = kPi * kGlW[gj] / na;
            const double l = relativeLuminance(direction(u, az)) * wu * wa;
            sum += l;
            sum_cos += l * u;
          }
      }
    radiance_integral_ = sum;
    horizontal_integral_ = sum_cos;
  }
  // The sampling table: each cell's mean luminance over a 3 x 3 grid of its points.
  cell_p_.assign(kCosCells * kAzCells, 0.0);
  double total = 0.0;
  for (int i = 0; i < kCosCells; ++i)
    for (int j = 0; j < kAzCells; ++j) {
      double l = 0.0;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
          l += relativeLuminance(
              direction((i + (a + 0.5) / 3.0) / kCosCells, 2.0 * kPi * (j + (b + 0.5) / 3.0) / kAzCells));
      cell_p_[static_cast<std::size_t>(i * kAzCells + j)] = l;
      total += l;
    }
  cell_cdf_.resize(cell_p_.size());
  double acc = 0.0;
  for (std::size_t k = 0; k < cell_p_.size(); ++k) {
    cell_p_[k] /= total;
    cell_cdf_[k] = (acc += cell_p_[k]);
  }
  cell_cdf_.back() = 1.0;
}

CieSky::Sample CieSky::sample(double u0, double u1) const {
  const std::size_t k =
      std::min(cell_cdf_.size() - 1,
               static_cast<std::size_t>(std::upper_bound(cell_cdf_.begin(), cell_cdf_.end(), u0) - cell_cdf_.begin()));
  const double lo = k ? cell_cdf_[k - 1] : 0.0;
  const double r = std::clamp((u0 - lo) / (cell_cdf_[k] - lo), 0.0, 1.0);  // uniform again inside the cell
  const int i = static_cast<int>(k) / kAzCells, j = static_cast<int>(k) % kAzCells;
  // cos Z in (0, 1]: never the horizon itself, where a ray would travel parallel to the ground.
  const double u = std::max((i + r) / kCosCells, 1e-9);
  Sample s;
  s.dir_ws = direction(u, 2.0 * kPi * (j + u1) / kAzCells);
  const double pdf = cell_p_[k] * (kCosCells * kAzCells) / (2.0 * kPi);
  s.weight = relativeLuminance(s.dir_ws) / (pdf * radiance_integral_);
  return s;
}

double CieSky::pdf(const glm::dvec3& dir_ws) const {
  if (!(dir_ws.z > 0.0)) return 0.0;
  const int i = std::min(kCosCells - 1, static_cast<int>(dir_ws.z * kCosCells));
  double az = std::atan2(dir_ws.x, dir_ws.y);
  if (az < 0.0) az += 2.0 * kPi;
  const int j = std::min(kAzCells - 1, static_cast<int>(az / (2.0 * kPi) * kAzCells));
  return cell_p_[static_cast<std::size_t>(i * kAzCells + j)] * (kCosCells * kAzCells) / (2.0 * kPi);
}

std::string CieSky::describe() const {
  return type_ == 0 ? std::string("CIE standard overcast sky") : "CIE general sky type " + std::to_string(type_);
}

}  // namespace duplex
