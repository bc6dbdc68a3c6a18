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
#include <string>
#include <string_view>

namespace duplex {

/// A file written in pieces that appears at `path` only when complete: write() appends to
/// "<path>.tmp", commit() closes it (flushed to the disk first when `sync`) and renames it over
/// `path`. Every write and the close are checked (a full disk is an error, not a short file); on
/// any failure, and when destroyed without commit(), the temporary file is removed and `path`
/// keeps what it held before. Errors are FileError naming `path` and `what`. Not thread-safe.
class AtomicFileWriter {
 public:
  /// Creates "<path>.tmp" (replacing a stale one). Throws FileError when it cannot be created.
  AtomicFileWriter(std::filesystem::path path, std::string_view what, bool sync = false);
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  /// Removes the temporary file unless commit() succeeded.
  ~AtomicFileWriter();
  /// Appends `bytes`. Throws FileError (the temporary file removed) when they cannot be written.
  void write(std::span<const unsigned char> bytes);
  /// Closes the file and renames it to the path. Throws FileError (the temporary file removed)
  /// when closing or renaming fails. Nothing may be written afterwards.
  void commit();
  /// Bytes written so far.
  [[nodiscard]] std::size_t size() const { return size_; }

 private:
  [[noreturn]] void fail(const std::string& problem, const std::string& detail);
  std::filesystem::path path_, tmp_;
  std::string what_;
  bool sync_ = false;
  int fd_ = -1;
  std::size_t size_ = 0;
};

/// Writes `bytes` to `path` through "<path>.tmp" (flushed to the disk when `sync`). Throws FileError
/// naming `path` and `what` (e.g. "bottom-level structure file") when the file cannot be written
/// or replaced; the temporary file is removed then. Thread-safe for distinct paths.
void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes, std::string_view what,
                         bool sync);

}  // namespace duplex
