#pragma once
/// \file AtomicFile.h
/// Writing a whole file so that readers never see it half-written: the bytes go to "<path>.tmp",
/// which is then renamed over `path` (atomic on POSIX file systems). A process killed while writing
/// leaves the previous file intact. With `sync` the bytes are also flushed to the disk (fsync)
/// before the rename and the folder after it, so that a power loss leaves either the previous file
/// or the whole new one; that costs a disk flush per file, nothing for a run state saved every
/// minute but a multiple of the write time for thousands of small files.

#include <filesystem>
#include <span>
#include <string_view>

namespace duplex {

/// Writes `bytes` to `path` through "<path>.tmp" (flushed to the disk when `sync`). Throws FileError
/// naming `path` and `what` (e.g. "bottom-level structure file") when the file cannot be written
/// or replaced; the temporary file is removed then. Thread-safe for distinct paths.
void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes, std::string_view what,
                         bool sync);

}  // namespace duplex
