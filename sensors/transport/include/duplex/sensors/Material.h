#pragma once
/// \file Material.h
/// The surface and medium materials of light transport: no more than a scene needs.

#include <cstdint>
#include <ostream>
#include <vector>

namespace duplex {

/// How a surface or medium treats a ray that meets it.
enum class MaterialType : std::uint8_t {
  Absorber,    ///< absorbs every ray (the default of an object without "material")
  Lambertian,  ///< diffuse reflection with albedo `reflectance`, both faces
  Mirror,      ///< specular reflection of a fraction `reflectance`, both faces
  Dielectric,  ///< smooth glass-like interface of index `ior` (outside: 1): Fresnel reflection or refraction
  /// Scattering fog (on a medium object only): at each collision (free flights sampled through the
  /// density) the ray scatters with probability `reflectance` (the single-scattering albedo) into a
  /// Henyey-Greenstein lobe of asymmetry `g`, else it is absorbed.
  Medium,
  /// Ideal thin coating: a fraction `reflectance` reflected specularly, `transmittance` passed
  /// through undeviated, the rest absorbed (per band when given per band), both faces.
  Coating,
};

/// How a Mirror or Dielectric spreads the light it reflects or transmits about the specular
/// direction, in direction-cosine space (beta: the direction's projection onto the surface plane).
enum class ScatterModel : std::uint8_t {
  None,      ///< smooth: the specular direction
  Gaussian,  ///< BSDF proportional to exp(-|beta - beta0|^2 / sigma^2), a fraction `scatter_fraction` of the light
  /// BSDF A / (B + |beta - beta0|^g); the fraction scattered is its total integrated scatter at
  /// normal incidence, 2 pi A int_0^1 r / (B + r^g) dr (at most 1), the rest specular
  ABg,
};

/// The material of an object (a scene file's "material" key): its type and the parameters of that type.
struct Material {
  MaterialType type = MaterialType::Absorber;  ///< what the material does; the fields below apply by type
  double reflectance = 0.0;  ///< Lambertian, Mirror: in [0, 1]; Medium: single-scattering albedo in [0, 1]
  double ior = 1.5;          ///< Dielectric: > 0; the mesh's geometric normal points outside
  double g = 0.0;            ///< Medium: Henyey-Greenstein mean cosine, in (-1, 1)
  /// Spectral scenes: the reflectance (albedo) in each band; empty: `reflectance` in every band.
  std::vector<double> band_reflectance{};
  double transmittance = 0.0;                ///< Coating: fraction transmitted undeviated, in [0, 1 - reflectance]
  std::vector<double> band_transmittance{};  ///< Coating, spectral scenes: per band; empty: `transmittance`
  /// Dielectric: Beer-Lambert absorption coefficient inside (per scene unit of path length, >= 0):
  /// a ray crossing a thickness L keeps exp(-absorption L) of its power.
  double absorption = 0.0;
  std::vector<double> band_absorption{};      ///< Dielectric, spectral scenes: per band; empty: `absorption`
  ScatterModel scatter = ScatterModel::None;  ///< Mirror, Dielectric: rough reflection and transmission
  double scatter_fraction = 0.0;              ///< Gaussian: given (default 1); ABg: the total integrated scatter
  double sigma = 0.0;                         ///< Gaussian: width in direction-cosine space, > 0
  double abg_a = 0.0;                         ///< ABg: A >= 0
  double abg_b = 0.0;                         ///< ABg: B > 0
  double abg_g = 0.0;                         ///< ABg: g > 0

  /// Reflectance (Medium: albedo) in spectral band `band` (< the scene's band count).
  [[nodiscard]] double reflectanceIn(std::uint32_t band) const {
    return band_reflectance.empty() ? reflectance : band_reflectance[band];
  }
  /// Coating: transmittance in spectral band `band`.
  [[nodiscard]] double transmittanceIn(std::uint32_t band) const {
    return band_transmittance.empty() ? transmittance : band_transmittance[band];
  }
  /// Dielectric: absorption coefficient in spectral band `band`.
  [[nodiscard]] double absorptionIn(std::uint32_t band) const {
    return band_absorption.empty() ? absorption : band_absorption[band];
  }
};

/// Writes the type and parameters, for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Material& m) {
  static const char* names[] = {"absorber", "lambertian", "mirror", "dielectric", "medium", "coating"};
  os << "Material{" << names[static_cast<int>(m.type)] << ", rho=" << m.reflectance << ", ior=" << m.ior
     << ", g=" << m.g;
  if (!m.band_reflectance.empty()) {
    os << ", bands=[";
    for (std::size_t k = 0; k < m.band_reflectance.size(); ++k) os << (k ? ", " : "") << m.band_reflectance[k];
    os << "]";
  }
  if (m.type == MaterialType::Coating) os << ", t=" << m.transmittance;
  if (m.absorption > 0.0 || !m.band_absorption.empty()) os << ", absorption=" << m.absorption;
  if (m.scatter == ScatterModel::Gaussian) os << ", gaussian sigma=" << m.sigma << " fraction=" << m.scatter_fraction;
  if (m.scatter == ScatterModel::ABg)
    os << ", ABg A=" << m.abg_a << " B=" << m.abg_b << " g=" << m.abg_g << " TIS=" << m.scatter_fraction;
  return os << "}";
}

}  // namespace duplex
