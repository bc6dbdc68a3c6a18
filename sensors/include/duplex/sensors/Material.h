#pragma once
/// \file Material.h
/// The surface materials of light transport (issue 5): no more than a scene needs.

#include <cstdint>
#include <ostream>

namespace duplex {

enum class MaterialType : std::uint8_t {
  Absorber,    ///< absorbs every ray (the default of an object without "material")
  Lambertian,  ///< diffuse reflection with albedo `reflectance`, both faces
  Mirror,      ///< specular reflection of a fraction `reflectance`, both faces
  Dielectric,  ///< smooth glass-like interface of index `ior` (outside: 1): Fresnel reflection or refraction
};

struct Material {
  MaterialType type = MaterialType::Absorber;
  double reflectance = 0.0;  ///< Lambertian, Mirror: in [0, 1]
  double ior = 1.5;          ///< Dielectric: > 0; the mesh's geometric normal points outside
};

inline std::ostream& operator<<(std::ostream& os, const Material& m) {
  static const char* names[] = {"absorber", "lambertian", "mirror", "dielectric"};
  return os << "Material{" << names[static_cast<int>(m.type)] << ", rho=" << m.reflectance << ", ior=" << m.ior << "}";
}

}  // namespace duplex
