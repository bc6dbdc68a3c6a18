#pragma once
/// \file DecimalOption.h
/// kDecimal: the transform of every integer option of the tool's commands; the options several
/// commands share (--threads, --primary).

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdint>
#include <string>

namespace duplex::cli {

namespace detail {

/// `value` as a plain decimal integer: "1000000" as it is, and the forms people write counts in,
/// "1e6", "2.5e6", "2M", "1.5k" (k = 10^3, M = 10^6, G = 10^9, T = 10^12, decimal), converted
/// exactly. Empty when it is no non-negative integer (a fraction left, a sign, hex, too large).
inline std::string plainDecimal(const std::string& value) {
  std::size_t i = 0;
  std::string digits;   // mantissa digits, the decimal point removed
  long long point = 0;  // digits after the point
  bool seen_point = false;
  for (; i < value.size() && ((value[i] >= '0' && value[i] <= '9') || (value[i] == '.' && !seen_point)); ++i) {
    if (value[i] == '.') seen_point = true;
    else {
      digits += value[i];
      if (seen_point) ++point;
    }
  }
  if (digits.empty()) return {};
  long long exponent = 0;
  if (i < value.size() && (value[i] == 'e' || value[i] == 'E')) {
    const std::size_t start = ++i;
    for (; i < value.size() && value[i] >= '0' && value[i] <= '9' && i - start < 4; ++i)
      exponent = exponent * 10 + (value[i] - '0');
    if (i == start) return {};
  } else if (i < value.size()) {
    const std::string suffixes = "kKMGT";
    const std::size_t k = suffixes.find(value[i]);
    if (k == std::string::npos) return {};
    exponent = k <= 1 ? 3 : 3 * static_cast<long long>(k);
    ++i;
  }
  if (i != value.size()) return {};
  exponent -= point;
  if (exponent < 0) {  // the digits dropped must be zeros
    const auto drop = static_cast<std::size_t>(-exponent);
    if (drop > digits.size() || digits.find_first_not_of('0', digits.size() - drop) != std::string::npos) return {};
    digits.resize(digits.size() - drop);
  } else {
    if (exponent > 40) return {};
    digits.append(static_cast<std::size_t>(exponent), '0');
  }
  const std::size_t nonzero = digits.find_first_not_of('0');
  digits = nonzero == std::string::npos ? "0" : digits.substr(nonzero);
  if (digits.size() > 20 || (digits.size() == 20 && digits > "18446744073709551615")) return {};
  return digits;
}

}  // namespace detail

/// The transform of every integer option of the tool's commands: plain decimal integers, and
/// counts written as "1e6" or "2M" (detail::plainDecimal), turned into plain decimal before CLI11
/// converts them. It refuses what CLI11 would misread: CLI11 parses integers with base 0
/// (strtoull), so "010" would be 8 and "0x10" 16, and it would wrap "-1" around for an unsigned
/// 64-bit option.
inline const CLI::Validator kDecimal(
    [](std::string& value) {
      if (value.size() > 1 && value.front() == '0' && value[1] >= '0' && value[1] <= '9')
        return std::string("must be written without leading zeros (decimal), got '" + value + "'");
      const std::string plain = detail::plainDecimal(value);
      if (plain.empty())
        return std::string("must be a non-negative decimal integer (or a count such as 1e6 or 2M), got '" + value +
                           "'");
      value = plain;
      return std::string();
    },
    "UINT");

/// --threads N: worker threads, 1 to 4096 (the option's default, 0, means all hardware threads).
inline CLI::Option* addThreadsOption(CLI::App& cmd, int& threads) {
  return cmd.add_option("--threads", threads, "Worker threads (default: all hardware threads)")
      ->transform(kDecimal)
      ->check(CLI::Range(1, 4096));
}

/// --primary W: primary rays of a W x W image (the camera of `duplex rays`), 1 to 8192.
inline CLI::Option* addPrimaryOption(CLI::App& cmd, std::uint32_t& width) {
  return cmd.add_option("--primary", width, "Primary rays of a W x W image (default 512)")
      ->transform(kDecimal)
      ->check(CLI::Range(1u, 8192u));
}

}  // namespace duplex::cli
