#pragma once
/// \file MemoryOption.h
/// --max-memory SIZE: the memory limit (duplex::setMemoryLimit) of the commands that load scenes,
/// meshes or ray files, or run.

#include <duplex/accel/MemoryLimit.h>

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

namespace duplex::cli {

/// Adds --max-memory to `cmd`, stored in `bytes` (0 when not given: the default limit). Sizes as
/// duplex::parseByteSize reads them ("4G", "512M", "1.5GiB", plain bytes); 0 and anything else
/// are refused while the command line is parsed.
inline CLI::Option* addMaxMemoryOption(CLI::App& cmd, std::uint64_t& bytes) {
  return cmd
      .add_option_function<std::string>(
          "--max-memory",
          [&bytes](const std::string& value) {
            const auto parsed = parseByteSize(value);
            bytes = parsed.value_or(0);
          },
          "Refuse inputs (scene files, meshes, sensor bins, ray and point files) that need more memory than "
          "SIZE, before allocating: 4G, 512M, 1.5GiB (powers of 1024) or plain bytes (default: the physical "
          "memory, or the control group's limit when smaller)")
      ->check(
          [](const std::string& value) {
            const auto parsed = parseByteSize(value);
            if (!parsed || *parsed == 0)
              return std::string("expected a size above 0 such as 4G, 512M, 1.5GiB or 1000000, got '" + value + "'");
            return std::string();
          },
          "SIZE");
}

}  // namespace duplex::cli
