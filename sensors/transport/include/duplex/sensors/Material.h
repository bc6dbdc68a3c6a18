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
};

/// The material of an object (a scene file's "material" key): its type and the parameters of that type.
struct Material {
  MaterialType type = MaterialType::Absorber;  ///< what the material does; the fields below apply by type
  double reflectance = 0.0;  ///< Lambertian, Mirror: in [0, 1]; Medium: single-scattering albedo in [0, 1]
  double ior = 1.5;          ///< Dielectric: > 0; the mesh's geometric normal points outside
  double g = 0.0;            ///< Medium: Henyey-Greenstein mean cosine, in (-1, 1)
  /// Spectral scenes: the reflectance (albedo) in each band; empty: `reflectance` in every band.
  std::vector<double> band_reflectance{};

  /// Reflectance (Medium: albedo) in spectral band `band` (< the scene's band count).
  [[nodiscard]] double reflectanceIn(std::uint32_t band) const {
    return band_reflectance.empty() ? reflectance : band_reflectance[band];
  }
};

/// Writes the type and parameters, for logs and test messages.
inline std::ostream& operator<<(std::ostream& os, const Material& m) {
  static const char* names[] = {"absorber", "lambertian", "mirror", "dielectric", "medium"};
  os << "Material{" << names[static_cast<int>(m.type)] << ", rho=" << m.reflectance << ", ior=" << m.ior
     << ", g=" << m.g;
  if (!m.band_reflectance.empty()) {
    os << ", bands=[";
    for (std::size_t k = 0; k < m.band_reflectance.size(); ++k) os << (k ? ", " : "") << m.band_reflectance[k];
    os << "]";
  }
  return os << "}";
}

}  // namespace duplex
