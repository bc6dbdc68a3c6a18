#pragma once
/// \file Absorber.h
/// The absorber: every ray that meets it ends there (the material of an object without one).

#include "duplex/sensors/materials/MaterialModel.h"

namespace duplex {

/// Absorbs every ray (a scene file's {"type": "absorber"}).
struct Absorber {
  static constexpr std::string_view kName = "absorber";  ///< its scene file "type"
  static constexpr bool kEndsPaths = true;               ///< no path restarts from it
  static constexpr bool kMetersSeeAll = true;            ///< it sends nothing on

  /// No keys but "type".
  static Absorber read(const MaterialReader& r) {
    r.onlyKeys({"type"});
    return {};
  }
  /// No parameters to check.
  void validate(const std::string& /*what*/, std::uint32_t /*bands*/) {}
  /// No parameters.
  void hash(StateHash& /*h*/) const {}
  /// No parameters.
  void print(std::ostream& /*os*/) const {}
  /// The path ends.
  template <class Event>
  SurfaceStep step(Event& /*ev*/) const {
    return {};
  }
};

}  // namespace duplex
