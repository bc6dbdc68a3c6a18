#pragma once
/// \file MaterialModel.h
/// What every material of light transport is made of: the concept a material type satisfies, the
/// reader it reads itself from a scene file with, the run-state hash it adds its parameters to,
/// and the answer of its path step. A material type (materials/Lambertian.h, ...) is one small
/// struct with its parameters and
/// - `static constexpr std::string_view kName`: its scene file "type";
/// - `static constexpr bool kEndsPaths`: whether every ray that meets it ends there (no path
///   restarts from its surface);
/// - `static constexpr bool kMetersSeeAll`: whether meters' next-event connections account for all
///   the light it sends on (only then may a run with meters contain it);
/// - `static M read(const MaterialReader&)`: its keys, with errors naming the JSON pointer;
/// - `void validate(const std::string& what, std::uint32_t bands)`: throws InvalidArgument starting
///   with `what` for a parameter out of range (and completes derived values);
/// - `void hash(StateHash&) const`: every parameter the paths depend on (a resumed run must not
///   mix states traced with another material);
/// - `void print(std::ostream&) const`: its parameters, for logs and test messages;
/// - `template <class Event> SurfaceStep step(Event&) const`: what it does with a ray that meets
///   it. The path loop's Event gives `d`, `n` and `nf` (world space, unit: the incoming direction,
///   the geometric normal, the normal facing the incoming ray), `band` (spectral band), `front`
///   (met from the side the geometric normal points to), `travelled` (world distance since the
///   ray's origin), `uniform()` (the path's next random number in [0, 1)), `attenuate(keep)` (keep
///   a fraction of the power, the rest absorbed), the outgoing directions `mirror()`, `diffuse()`
///   and `straight()`, `refractOrReflect(eta_i, eta_t, transmits)` (exact polarised Fresnel) and
///   `scatterAbout(lobe, step)` (a rough lobe about the step's specular direction).
/// Material.h lists the types in one variant; a type missing any of these fails to compile there.

#include <glm/vec3.hpp>

#include <nlohmann/json_fwd.hpp>

#include <concepts>
#include <cstdint>
#include <initializer_list>
#include <ostream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace duplex {

struct ObjectSpecContext;

/// A dimensionless material value per spectral band: `value` in every band, or `bands` (one per
/// band of the scene) when given.
struct BandValue {
  double value = 0.0;           ///< the value; with `bands`: their mean (for messages)
  std::vector<double> bands{};  ///< per band; empty: `value` in every band
  BandValue() = default;
  /// `v` in every band.
  BandValue(double v) : value(v) {}  // NOLINT(google-explicit-constructor): a number is a BandValue
  /// `mean` for messages, `per_band` in the bands.
  BandValue(double mean, std::vector<double> per_band) : value(mean), bands(std::move(per_band)) {}
  /// The value in spectral band `band` (< the scene's band count).
  [[nodiscard]] double in(std::uint32_t band) const { return bands.empty() ? value : bands[band]; }
  /// Throws InvalidArgument "<what>: ..." when the value or a band's is not in [lo, hi] (NaN
  /// included), naming `name`, or when the bands are not one per band of the scene (`scene_bands`).
  void check(const std::string& what, const char* name, double lo, double hi, std::uint32_t scene_bands) const;
};

/// FNV-1a over bytes: the run-state fingerprint that saved states are checked against on resume.
struct StateHash {
  std::uint64_t value = 1469598103934665603ull;  ///< the hash so far
  /// Adds `n` bytes at `p`.
  void bytes(const void* p, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) value = (value ^ static_cast<const unsigned char*>(p)[i]) * 1099511628211ull;
  }
  /// Adds a number's bytes.
  void add(double x) { bytes(&x, sizeof x); }
  /// Adds the value and its bands.
  void add(const BandValue& v) {
    add(v.value);
    bytes(v.bands.data(), v.bands.size() * sizeof(double));
  }
};

/// One material object of a scene file (or an object inside it, child()): its keys by name, with
/// errors (InvalidArgument) that name the scene file and the key's JSON pointer. Per-band values
/// may be a number, an array of one number per band, or an object of band names.
class MaterialReader {
 public:
  /// Reads `v` at JSON pointer `pointer`; `bands` are the scene's band names (per-band values
  /// must give one value per band).
  MaterialReader(const nlohmann::json& v, std::string pointer, const ObjectSpecContext& ctx,
                 const std::vector<std::string>& bands);
  /// In strict mode, fails on the first key not in `allowed`.
  void onlyKeys(std::initializer_list<std::string_view> allowed) const;
  /// Whether the object has `key`.
  [[nodiscard]] bool has(const char* key) const;
  /// The finite number at `key` (which must be present).
  [[nodiscard]] double number(const char* key) const;
  /// The finite number > 0 at `key`.
  [[nodiscard]] double positiveNumber(const char* key) const;
  /// The string at `key`.
  [[nodiscard]] std::string string(const char* key) const;
  /// The per-band value at `key`, each in [0, hi] (hi = 1: a fraction; else finite); `bands`'s
  /// mean is the value.
  [[nodiscard]] BandValue perBand(const char* key, double hi) const;
  /// The object at `key`, read at its own pointer.
  [[nodiscard]] MaterialReader child(const char* key) const;
  /// Throws the scene's error at `key` (empty: the object itself) with `problem`.
  [[noreturn]] void fail(std::string_view key, const std::string& problem) const;

 private:
  const nlohmann::json* v_;
  std::string pointer_;
  const ObjectSpecContext* ctx_;
  const std::vector<std::string>* bands_;
};

/// `names` quoted and listed for messages: "a", "b" or "c".
inline std::string quotedNames(std::initializer_list<std::string_view> names) {
  std::string out;
  std::size_t k = 0;
  for (const std::string_view n : names) {
    if (k) out += k + 1 == names.size() ? " or " : ", ";
    out += '"';
    out += n;
    out += '"';
    ++k;
  }
  return out;
}

/// A material's answer to a ray that met it: end the path, or go on in direction `next`.
struct SurfaceStep {
  bool absorbed = true;  ///< the path ends (its power absorbed)
  /// World space, any length: the outgoing direction; zero when the material refuses the path
  /// (a rough lobe that yielded no direction: a numerical failure).
  glm::dvec3 next{0.0};
  bool transmits = false;  ///< `next` must cross to the far side of the surface
  bool diffuse = false;    ///< a Lambertian reflection, which meters connect to
};

/// The split of a ray by fractions reflected and transmitted (per band) with one random number of
/// the event: `absorbed` beyond both, else `transmits` beyond the reflected fraction; the caller
/// sets the direction.
template <class Event>
SurfaceStep splitByFractions(Event& ev, const BandValue& reflect, const BandValue& transmit) {
  const double u = ev.uniform(), r = reflect.in(ev.band);
  SurfaceStep s;
  s.absorbed = u >= r + transmit.in(ev.band);
  s.transmits = !s.absorbed && u >= r;
  return s;
}

/// The hash of a pair of fractions reflected and transmitted (the materials that split by them).
inline void hashFractions(StateHash& h, const BandValue& reflect, const BandValue& transmit) {
  h.add(reflect);
  h.add(transmit);
}

/// Prints a pair of fractions reflected and transmitted: "reflect=..., transmit=...".
inline void printFractions(std::ostream& os, const BandValue& reflect, const BandValue& transmit) {
  os << "reflect=" << reflect.value << ", transmit=" << transmit.value;
}

/// A material type: parameters, reader, validation, hash and printing (the path step is checked
/// where the path loop instantiates it). See the file comment. (No copy_constructible here: a
/// Material's converting constructor asks whether Material itself is a material type while
/// Material is being copied, and clang would recurse; the variant requires copies anyway.)
template <class M>
concept MaterialModel = std::default_initializable<M> &&
    requires(M& m, const M& cm, const MaterialReader& r, StateHash& h, std::ostream& os, const std::string& what,
             std::uint32_t bands) {
  { M::kName } -> std::convertible_to<std::string_view>;
  { M::kEndsPaths } -> std::convertible_to<bool>;
  { M::kMetersSeeAll } -> std::convertible_to<bool>;
  { M::read(r) } -> std::same_as<M>;
  m.validate(what, bands);
  cm.hash(h);
  cm.print(os);
};

}  // namespace duplex
