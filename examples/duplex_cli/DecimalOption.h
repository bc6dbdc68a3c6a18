#pragma once
/// \file DecimalOption.h
/// kDecimal: the check of every integer option of the tool's commands.

#include <CLI/CLI.hpp>

#include <algorithm>
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

}  // namespace duplex::cli
