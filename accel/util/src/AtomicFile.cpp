#include "duplex/accel/AtomicFile.h"

#include "duplex/accel/Error.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <system_error>

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

void writeFileAtomically(const std::filesystem::path& path, std::span<const unsigned char> bytes, std::string_view what,
                         bool sync) {
  std::filesystem::path tmp = path;
  tmp += ".tmp";
  // Every failure: the temporary file removed (if there is one), and an error naming the file.
  const auto fail = [&](const std::string& problem, const std::string& detail) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw FileError(path.string() + ": " + problem + " the " + std::string(what) + " (" + detail + ")");
  };
  const auto systemError = [&](int err) { return tmp.string() + ": " + std::strerror(err); };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail("cannot write", systemError(errno));
  // The data reach the disk before the rename makes them the file: after a power loss the path
  // then holds either the previous file or the whole new one (the rename alone orders nothing).
  const bool written = writeAll(fd, bytes) && (!sync || ::fsync(fd) == 0);
  const int write_errno = written ? 0 : errno;
  if (::close(fd) != 0 && written) fail("closing", systemError(errno));
  if (!written) fail("writing (disk full?)", systemError(write_errno));
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) fail("cannot replace", ec.message());
  if (!sync) return;
  // And the rename itself: the folder's entry is flushed too. Best effort (some file systems refuse
  // fsync on a folder); the file is complete either way.
  std::filesystem::path dir = path.parent_path();
  if (dir.empty()) dir = ".";
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
}

}  // namespace duplex
