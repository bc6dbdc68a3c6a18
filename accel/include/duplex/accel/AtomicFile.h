#pragma once
/// \file AtomicFile.h
/// Writing a whole file so that readers never see it half-written: the bytes go to "<path>.tmp",
/// are flushed to the disk (fsync), and the file is then renamed over `path` (atomic on POSIX file
/// systems) and the folder flushed. A process killed while writing, or a power loss, leaves either
/// the previous file or the whole new one.

#include <filesystem>
#include <span>
#include <string_view>

namespace duplex {

/// Writes `bytes` to `path` through "<path>.tmp". Throws FileError naming `path` and `what` (e.g.
/// "bottom-level structure file") when the file cannot be written or replaced; the temporary file
/// is removed then. Thread-safe for distinct paths.
void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes,
                         std::string_view what);

}  // namespace duplex
