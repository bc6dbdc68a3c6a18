#include "duplex/accel/AtomicFile.h"

#include "duplex/accel/Error.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <system_error>
#include <utility>

namespace duplex {

namespace {

// Writes all of `bytes` to `fd`, retrying short writes and interrupted calls; false with errno set.
bool writeAll(int fd, std::span<const unsigned char> bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    done += static_cast<std::size_t>(n);
  }
  return true;
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(std::filesystem::path path, std::string_view what, bool sync)
    : path_(std::move(path)), what_(what), sync_(sync) {
  tmp_ = path_;
  tmp_ += ".tmp";
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) fail("cannot write", tmp_.string() + ": " + std::strerror(errno));
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ < 0) return;
  ::close(fd_);
  std::error_code ignored;
  std::filesystem::remove(tmp_, ignored);
}

void AtomicFileWriter::fail(const std::string& problem, const std::string& detail) {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  std::error_code ignored;
  std::filesystem::remove(tmp_, ignored);
  throw FileError(path_.string() + ": " + problem + " the " + what_ + " (" + detail + ")");
}

void AtomicFileWriter::write(std::span<const unsigned char> bytes) {
  if (fd_ < 0) throw InternalError("AtomicFileWriter::write after commit or failure: " + path_.string());
  if (!writeAll(fd_, bytes)) fail("writing (disk full?)", tmp_.string() + ": " + std::strerror(errno));
  size_ += bytes.size();
}

void AtomicFileWriter::commit() {
  if (fd_ < 0) throw InternalError("AtomicFileWriter::commit twice or after a failure: " + path_.string());
  // The data reach the disk before the rename makes them the file: after a power loss the path
  // then holds either the previous file or the whole new one (the rename alone orders nothing).
  if (sync_ && ::fsync(fd_) != 0) fail("writing (disk full?)", tmp_.string() + ": " + std::strerror(errno));
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    const int err = errno;
    std::error_code ignored;
    std::filesystem::remove(tmp_, ignored);
    throw FileError(path_.string() + ": closing the " + what_ + " (" + tmp_.string() + ": " + std::strerror(err) + ")");
  }
  std::error_code ec;
  std::filesystem::rename(tmp_, path_, ec);
  if (ec) {
    const std::string why = ec.message();
    std::filesystem::remove(tmp_, ec);
    throw FileError(path_.string() + ": cannot replace the " + what_ + " (" + why + ")");
  }
  if (!sync_) return;
  // And the rename itself: the folder's entry is flushed too. Best effort (some file systems refuse
  // fsync on a folder); the file is complete either way.
  std::filesystem::path dir = path_.parent_path();
  if (dir.empty()) dir = ".";
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
}

void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes, std::string_view what,
                         bool sync) {
  AtomicFileWriter out(path, what, sync);
  out.write(bytes);
  out.commit();
}

}  // namespace duplex
