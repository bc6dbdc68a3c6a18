#pragma once
/// \file Material.h
/// The surface and medium materials of light transport, one type each (materials/*.h), held in one
/// variant. A new material is a header in materials/ (its parameters, reader, validation, hash,
/// printing and path step: materials/MaterialModel.h lists them) and one entry in MaterialVariant
/// below; a type missing a member fails to compile here, and its parameters reach the run-state
/// hash through its own hash().

#include "duplex/sensors/materials/Absorber.h"
#include "duplex/sensors/materials/Coating.h"
#include "duplex/sensors/materials/Dielectric.h"
#include "duplex/sensors/materials/Diffuser.h"
#include "duplex/sensors/materials/Lambertian.h"
#include "duplex/sensors/materials/MaterialModel.h"
#include "duplex/sensors/materials/Medium.h"
#include "duplex/sensors/materials/Mirror.h"

#include <ostream>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace duplex {

/// The material types, constrained to the concept (a type missing its hash or reader fails here).
template <MaterialModel... M>
using MaterialsOf = std::variant<M...>;

/// Every material type; the first is the default (an object without "material" absorbs). Their
/// order is the order of the scene file's "type" names in messages.
using MaterialVariant = MaterialsOf<Absorber, Lambertian, Mirror, Dielectric, Coating, Medium, Diffuser>;

/// The material of an object (a scene file's "material" key): one of the types, with its parameters.
struct Material {
  MaterialVariant model{};  ///< which type, and its parameters

  Material() = default;
  /// A material of type M (`Material m = Lambertian{0.8};`).
  template <MaterialModel M>
  Material(M m) : model(std::move(m)) {}  // NOLINT(google-explicit-constructor): a type is a Material

  /// Whether the material is of type M.
  template <MaterialModel M>
  [[nodiscard]] bool is() const {
    return std::holds_alternative<M>(model);
  }
  /// The parameters when the material is of type M, else nullptr.
  template <MaterialModel M>
  [[nodiscard]] const M* as() const {
    return std::get_if<M>(&model);
  }
  /// The scene file's "type" name.
  [[nodiscard]] std::string_view name() const {
    return std::visit([](const auto& m) { return std::string_view(std::remove_cvref_t<decltype(m)>::kName); }, model);
  }
  /// Whether every ray that meets the material ends there (no path restarts from it).
  [[nodiscard]] bool endsPaths() const {
    return std::visit([](const auto& m) { return std::remove_cvref_t<decltype(m)>::kEndsPaths; }, model);
  }
  /// Whether meters' next-event connections account for all the light the material sends on.
  [[nodiscard]] bool metersSeeAll() const {
    return std::visit([](const auto& m) { return std::remove_cvref_t<decltype(m)>::kMetersSeeAll; }, model);
  }
  /// Throws InvalidArgument starting with `what` for parameters out of range or per-band values not
  /// one per band of the scene (`bands`); completes derived values (a lobe's scattered fraction).
  void validate(const std::string& what, std::uint32_t bands) {
    std::visit([&](auto& m) { m.validate(what, bands); }, model);
  }
  /// Adds the type and every parameter to the run-state hash.
  void hash(StateHash& h) const {
    const std::size_t index = model.index();
    h.bytes(&index, sizeof index);
    std::visit([&](const auto& m) { m.hash(h); }, model);
  }
  /// Reads a scene file's material object: its "type" picks the type, which reads the rest.
  [[nodiscard]] static Material read(const MaterialReader& r) {
    const std::string type = r.string("type");
    Material out;
    bool found = false;
    auto tryType = [&]<class M>(const M*) {
      if (found || type != M::kName) return;
      out.model = M::read(r);
      found = true;
    };
    [&]<std::size_t... I>(std::index_sequence<I...>) {
      (tryType(static_cast<const std::variant_alternative_t<I, MaterialVariant>*>(nullptr)), ...);
      if (!found)
        r.fail("type", "unknown material \"" + type + "\" (expected " +
                           quotedNames({std::variant_alternative_t<I, MaterialVariant>::kName...}) + ")");
    }
    (std::make_index_sequence<std::variant_size_v<MaterialVariant>>{});
    return out;
  }
};

/// Writes the type and parameters, for logs and test messages: "Material{lambertian, reflectance=0.8}".
inline std::ostream& operator<<(std::ostream& os, const Material& m) {
  std::ostringstream params;
  std::visit([&](const auto& t) { t.print(params); }, m.model);
  os << "Material{" << m.name();
  if (!params.str().empty()) os << ", " << params.str();
  return os << "}";
}

}  // namespace duplex
