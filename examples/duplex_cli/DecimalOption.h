#pragma once
/// \file DecimalOption.h
/// kDecimal: the check of every integer option of the tool's commands; the options several
/// commands share (--threads, --primary).

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdint>
#include <string>

namespace duplex::cli {

/// Integers in plain decimal only: CLI11 parses them with base 0 (strtoull), so "010" would be 8 and
/// "0x10" 16, and it would wrap "-1" around for an unsigned 64-bit option.
inline const CLI::Validator kDecimal(
    [](std::string& value) {
      if (value.empty() || !std::all_of(value.begin(), value.end(), [](char c) { return c >= '0' && c <= '9'; }))
        return std::string("must be a non-negative decimal integer, got '" + value + "'");
      if (value.size() > 1 && value.front() == '0')
        return std::string("must be written without leading zeros (decimal), got '" + value + "'");
      return std::string();
    },
    "UINT");

/// --threads N: worker threads, 1 to 4096 (the option's default, 0, means all hardware threads).
inline CLI::Option* addThreadsOption(CLI::App& cmd, int& threads) {
  return cmd.add_option("--threads", threads, "Worker threads (default: all hardware threads)")
      ->check(kDecimal)
      ->check(CLI::Range(1, 4096));
}

/// --primary W: primary rays of a W x W image (the camera of `duplex rays`), 1 to 8192.
inline CLI::Option* addPrimaryOption(CLI::App& cmd, std::uint32_t& width) {
  return cmd.add_option("--primary", width, "Primary rays of a W x W image (default 512)")
      ->check(kDecimal)
      ->check(CLI::Range(1u, 8192u));
}

}  // namespace duplex::cli
