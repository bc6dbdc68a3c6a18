#pragma once
/// \file Roughness.h
/// How a mirror or dielectric spreads the light it reflects or transmits about the specular
/// direction: smooth, or one of the lobes (GaussianScatter.h, AbgScatter.h) held in one variant. A
/// lobe type has the members of a material type (MaterialModel.h) but kEndsPaths, kMetersSeeAll
/// and step(), and instead `scatteredFraction()` and `sampleRadius(r_max, rng)` (a radius of its
/// lobe in direction-cosine space, negative when it yields none).

#include "duplex/sensors/materials/AbgScatter.h"
#include "duplex/sensors/materials/GaussianScatter.h"
#include "duplex/sensors/materials/MaterialModel.h"

#include <concepts>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

namespace duplex {

/// A lobe type (see the file comment).
template <class L>
concept RoughnessModel = std::default_initializable<L> &&
    requires(L& l, const L& cl, const MaterialReader& r, StateHash& h, std::ostream& os, const std::string& what,
             std::uint32_t bands) {
  { L::kName } -> std::convertible_to<std::string_view>;
  { L::read(r) } -> std::same_as<L>;
  { cl.scatteredFraction() } -> std::convertible_to<double>;
  l.validate(what, bands);
  cl.hash(h);
  cl.print(os);
};

/// No lobe: the specular direction.
struct Smooth {};

/// The lobes, constrained to the concept: a lobe missing a member fails to compile here.
template <RoughnessModel... L>
using RoughnessVariant = std::variant<Smooth, L...>;

/// A surface's roughness (a scene file's optional "scatter" object of a mirror or dielectric).
struct Roughness {
  /// Smooth or one lobe; a new lobe type is one entry here.
  RoughnessVariant<GaussianScatter, AbgScatter> model{};

  /// Reads the material's optional "scatter" key ({"model": name, ...}; absent: smooth).
  static Roughness read(const MaterialReader& material) {
    Roughness out;
    if (!material.has("scatter")) return out;
    const MaterialReader r = material.child("scatter");
    const std::string model = r.string("model");
    bool found = false;
    [&]<std::size_t... I>(std::index_sequence<I...>) {
      auto tryLobe = [&]<class L>(const L*) {
        if (found || model != L::kName) return;
        out.model = L::read(r);
        found = true;
      };
      (tryLobe(static_cast<const std::variant_alternative_t<I + 1, Variant>*>(nullptr)), ...);
    }
    (std::make_index_sequence<std::variant_size_v<Variant> - 1>{});
    if (!found) r.fail("model", "unknown scatter model \"" + model + "\" (expected " + lobeNames() + ")");
    return out;
  }
  /// Checks the lobe's parameters (sets derived values such as ABg's total integrated scatter).
  void validate(const std::string& what, std::uint32_t bands) {
    std::visit(
        [&](auto& l) {
          if constexpr (!std::same_as<std::remove_cvref_t<decltype(l)>, Smooth>) l.validate(what, bands);
        },
        model);
  }
  /// Adds which lobe and its parameters.
  void hash(StateHash& h) const {
    const std::size_t index = model.index();
    h.bytes(&index, sizeof index);
    std::visit(
        [&](const auto& l) {
          if constexpr (!std::same_as<std::remove_cvref_t<decltype(l)>, Smooth>) l.hash(h);
        },
        model);
  }
  /// ", <lobe>" for a rough surface, nothing for a smooth one.
  void print(std::ostream& os) const {
    std::visit(
        [&](const auto& l) {
          if constexpr (!std::same_as<std::remove_cvref_t<decltype(l)>, Smooth>) {
            os << ", ";
            l.print(os);
          }
        },
        model);
  }
  /// Whether a lobe is set.
  [[nodiscard]] bool rough() const { return model.index() != 0; }

  /// After a specular step: with the lobe's probability (one random number when rough), the
  /// direction redrawn from the lobe about the specular one (Event::scatterAbout).
  template <class Event>
  void spread(Event& ev, SurfaceStep& step) const {
    std::visit(
        [&](const auto& l) {
          if constexpr (!std::same_as<std::remove_cvref_t<decltype(l)>, Smooth>)
            if (ev.uniform() < l.scatteredFraction()) ev.scatterAbout(l, step);
        },
        model);
  }

 private:
  using Variant = decltype(model);
  // The lobes' names (the alternatives after Smooth), quoted, for messages.
  static std::string lobeNames() {
    return []<std::size_t... I>(std::index_sequence<I...>) {
      return quotedNames({std::variant_alternative_t<I + 1, Variant>::kName...});
    }
    (std::make_index_sequence<std::variant_size_v<Variant> - 1>{});
  }
};

}  // namespace duplex
