#pragma once
/// \file InputFile.h
/// What every reader checks before it opens an input file: that the path names a regular file.
/// A directory would be read as a file of absurd size (an allocation that fails), and opening a
/// FIFO or a device blocks, or never reaches an end.

#include <filesystem>
#include <string>
#include <string_view>

namespace duplex {

/// Empty when `path` names a regular file (symbolic links followed); otherwise what it names
/// instead, to follow the file's name in an error message: "no such file", "a directory, not a
/// file", "not a regular file (a FIFO, socket or device)", or the system's reason when it cannot
/// be examined.
[[nodiscard]] std::string notRegularFile(const std::filesystem::path& path);

/// Whether `output` names the existing file `input` (the same path, or another path to the same
/// file): writing it would destroy the input before it is read. False when either does not exist.
[[nodiscard]] bool sameFile(const std::filesystem::path& input, const std::filesystem::path& output);

/// The whole content of the regular file `path`, read in one piece. Throws FileError
/// "<what> '<path>': <problem>" when it is not a regular file, cannot be opened or read, or is empty.
[[nodiscard]] std::string readWholeFile(const std::filesystem::path& path, std::string_view what);

}  // namespace duplex
