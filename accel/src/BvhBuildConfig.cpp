// Presets, parsing and printing of the BVH build configuration (BvhBuildConfig.h).

#include "duplex/accel/BvhBuildConfig.h"

#include "duplex/accel/Error.h"

#include <charconv>
#include <cmath>
#include <ostream>
#include <sstream>
#include <string>

namespace duplex {

std::string_view toString(BvhPreset p) {
  switch (p) {
    case BvhPreset::Fast: return "fast";
    case BvhPreset::Medium: return "medium";
    case BvhPreset::High: return "high";
  }
  return "unknown";
}

BvhPreset parseBvhPreset(std::string_view name) {
  if (name == "fast") return BvhPreset::Fast;
  if (name == "medium") return BvhPreset::Medium;
  if (name == "high") return BvhPreset::High;
  throw InvalidArgument("unknown BVH preset '" + std::string(name) + "' (expected fast, medium or high)");
}

BvhBuildConfig BvhBuildConfig::preset(BvhPreset p) {
  BvhBuildConfig c;
  switch (p) {
    case BvhPreset::Fast:
      // Fewer bins cost little tree quality on meshes (their triangles are small and evenly
      // spread) and halve the binning work.
      c.bins = 8;
      c.max_leaf_size = 8;
      break;
    case BvhPreset::Medium: break;
    case BvhPreset::High:
      // Stich et al.'s alpha: try spatial splits only where object splits leave children
      // overlapping by more than 1e-5 of the root's area.
      c.spatial_split_alpha = 1e-5f;
      break;
  }
  return c;
}

namespace {

[[noreturn]] void badPart(std::string_view text, std::string_view part, std::string_view why) {
  throw InvalidArgument("BVH build config '" + std::string(text) + "': '" + std::string(part) + "' " +
                        std::string(why));
}

template <class T>
T parseNumber(std::string_view text, std::string_view part, std::string_view value) {
  T out{};
  if constexpr (std::is_floating_point_v<T>) {
    // std::from_chars for float is in libstdc++ 11+; strtof would accept leading spaces and hex.
    const auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), out);
    if (ec != std::errc() || ptr != value.data() + value.size() || !std::isfinite(out))
      badPart(text, part, "is not a finite number");
  } else {
    const auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), out);
    if (ec != std::errc() || ptr != value.data() + value.size()) badPart(text, part, "is not an unsigned integer");
  }
  return out;
}

}  // namespace

BvhBuildConfig BvhBuildConfig::parse(std::string_view text) {
  BvhBuildConfig c;
  bool first = true;
  std::size_t pos = 0;
  if (text.empty()) badPart(text, text, "is empty");
  while (pos <= text.size()) {
    const std::size_t comma = std::min(text.find(',', pos), text.size());
    const std::string_view part = text.substr(pos, comma - pos);
    pos = comma + 1;
    if (part.empty()) badPart(text, part, "is empty");
    const std::size_t eq = part.find('=');
    if (eq == std::string_view::npos) {
      if (!first) badPart(text, part, "is not key=value (a preset name comes first)");
      try {
        c = preset(parseBvhPreset(part));
      } catch (const InvalidArgument&) {
        badPart(text, part, "is not a preset (fast, medium, high) or key=value");
      }
    } else {
      const std::string_view key = part.substr(0, eq), value = part.substr(eq + 1);
      if (key == "bins") c.bins = parseNumber<std::uint32_t>(text, part, value);
      else if (key == "ct") c.traversal_cost = parseNumber<float>(text, part, value);
      else if (key == "ci") c.intersection_cost = parseNumber<float>(text, part, value);
      else if (key == "leaf") c.max_leaf_size = parseNumber<std::uint32_t>(text, part, value);
      else if (key == "alpha") c.spatial_split_alpha = parseNumber<float>(text, part, value);
      else if (key == "budget") c.spatial_split_budget = parseNumber<float>(text, part, value);
      else if (key == "parallel") c.parallel_threshold = parseNumber<std::uint32_t>(text, part, value);
      else if (key == "refit") c.refit_limit = parseNumber<float>(text, part, value);
      else badPart(text, part, "has an unknown key (bins, ct, ci, leaf, alpha, budget, parallel, refit)");
    }
    first = false;
    if (comma == text.size()) break;
  }
  c.validate();
  return c;
}

void BvhBuildConfig::validate() const {
  auto fail = [](const std::string& what) { throw InvalidArgument("BVH build config: " + what); };
  if (bins < 2 || bins > kMaxBins)
    fail("bins must be 2 to " + std::to_string(kMaxBins) + ", got " + std::to_string(bins));
  if (!(traversal_cost >= 0.0f) || !std::isfinite(traversal_cost)) fail("ct (traversal cost) must be finite and >= 0");
  if (!(intersection_cost > 0.0f) || !std::isfinite(intersection_cost))
    fail("ci (intersection cost) must be finite and > 0");
  if (max_leaf_size < 1 || max_leaf_size > 16) fail("leaf must be 1 to 16, got " + std::to_string(max_leaf_size));
  if (leaf_block != 4) fail("leaf_block must be 4 (the leaf test's width), got " + std::to_string(leaf_block));
  if (!(spatial_split_alpha >= 0.0f) || !std::isfinite(spatial_split_alpha)) fail("alpha must be finite and >= 0");
  if (!(spatial_split_budget >= 0.0f) || !(spatial_split_budget <= 4.0f)) fail("budget must be 0 to 4");
  if (!(refit_limit >= 1.0f) || !std::isfinite(refit_limit))
    fail("refit (SAH limit of refits) must be finite and >= 1");
}

std::string BvhBuildConfig::toString() const {
  std::ostringstream os;
  os.precision(9);
  os << "bins=" << bins << ",ct=" << traversal_cost << ",ci=" << intersection_cost << ",leaf=" << max_leaf_size
     << ",alpha=" << spatial_split_alpha << ",budget=" << spatial_split_budget << ",parallel=" << parallel_threshold
     << ",refit=" << refit_limit;
  return os.str();
}

std::ostream& operator<<(std::ostream& os, const BvhBuildConfig& c) { return os << c.toString(); }

}  // namespace duplex
