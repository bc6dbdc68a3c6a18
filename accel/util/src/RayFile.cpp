#include "duplex/accel/RayFile.h"
#include "duplex/accel/InputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cstring>
#include <limits>
#include <sstream>

namespace duplex {

static_assert(std::endian::native == std::endian::little, "ray and hit files are little endian; add byte swapping");

HitRecord HitRecord::from(const Hit& h) {
  if (!h.valid()) return miss();
  return {h.t, h.u, h.v, h.instance_id, h.prim_id};
}

ClosestRecord ClosestRecord::none() {
  return {0.0f, 0.0f, 0.0f, std::numeric_limits<float>::infinity(), kInvalidId, kInvalidId};
}

HitRecord HitRecord::miss() { return {std::numeric_limits<float>::infinity(), 0.0f, 0.0f, kInvalidId, kInvalidId}; }

template <class Record>
RecordFileReader<Record>::RecordFileReader(const std::filesystem::path& path, std::string_view kind)
    : path_(path), kind_(kind) {
  const auto fail = [&](const std::string& problem) {
    std::ostringstream msg;
    msg << kind_ << " file '" << path_.string() << "': " << problem;
    throw FileError(msg.str());
  };
  if (const std::string problem = notRegularFile(path_); !problem.empty()) fail(problem);
  fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) fail(std::string("cannot open (") + std::strerror(errno) + ")");
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int err = errno;
    ::close(fd_);
    fail(std::string("cannot read its size (") + std::strerror(err) + ")");
  }
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size % sizeof(Record) != 0) {
    ::close(fd_);
    std::ostringstream problem;
    problem << "size " << size << " bytes is not a multiple of the " << sizeof(Record) << "-byte record";
    fail(problem.str());
  }
  count_ = static_cast<std::size_t>(size / sizeof(Record));
}

template <class Record>
RecordFileReader<Record>::~RecordFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

template <class Record>
void RecordFileReader<Record>::read(std::size_t first, std::span<Record> out) {
  if (first > count_ || out.size() > count_ - first) {
    std::ostringstream msg;
    msg << kind_ << " file '" << path_.string() << "': records " << first << ".." << first + out.size() << " asked of "
        << count_;
    throw InvalidArgument(msg.str());
  }
  auto* bytes = reinterpret_cast<unsigned char*>(out.data());
  std::size_t done = 0;
  const std::size_t want = out.size_bytes();
  const auto offset = static_cast<off_t>(first * sizeof(Record));
  while (done < want) {
    const ssize_t n = ::pread(fd_, bytes + done, want - done, offset + static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      std::ostringstream msg;
      msg << kind_ << " file '" << path_.string() << "': "
          << (n == 0 ? std::string("shorter than when it was opened")
                     : std::string("read failed (") + std::strerror(errno) + ")");
      throw FileError(msg.str());
    }
    done += static_cast<std::size_t>(n);
  }
}

template <class Record>
RecordFileWriter<Record>::RecordFileWriter(const std::filesystem::path& path, std::string_view kind)
    : out_(path, std::string(kind) + " file") {}

template <class Record>
void RecordFileWriter<Record>::write(std::span<const Record> records) {
  out_.write({reinterpret_cast<const unsigned char*>(records.data()), records.size_bytes()});
}

template <class Record>
void RecordFileWriter<Record>::commit() {
  out_.commit();
}

template class RecordFileReader<Ray>;
template class RecordFileReader<HitRecord>;
template class RecordFileReader<PointRecord>;
template class RecordFileReader<ClosestRecord>;
template class RecordFileReader<float>;
template class RecordFileWriter<Ray>;
template class RecordFileWriter<HitRecord>;
template class RecordFileWriter<PointRecord>;
template class RecordFileWriter<ClosestRecord>;
template class RecordFileWriter<float>;

namespace {

template <class Record>
std::vector<Record> readRecords(const std::filesystem::path& path, const char* kind) {
  RecordFileReader<Record> in(path, kind);
  std::ostringstream what;
  what << kind << " file '" << path.string() << "' (" << in.count() << " records, read whole)";
  requireMemory(arrayBytes(in.count(), sizeof(Record)), what.str());
  std::vector<Record> out(in.count());
  in.read(0, out);
  return out;
}

template <class Record>
void writeRecords(const std::filesystem::path& path, std::span<const Record> records, const char* kind) {
  RecordFileWriter<Record> out(path, kind);
  out.write(records);
  out.commit();
}

}  // namespace

std::vector<Ray> readRayFile(const std::filesystem::path& path) { return readRecords<Ray>(path, "ray"); }
void writeRayFile(const std::filesystem::path& path, std::span<const Ray> rays) { writeRecords(path, rays, "ray"); }
std::vector<HitRecord> readHitFile(const std::filesystem::path& path) { return readRecords<HitRecord>(path, "hit"); }
void writeHitFile(const std::filesystem::path& path, std::span<const HitRecord> hits) {
  writeRecords(path, hits, "hit");
}
std::vector<PointRecord> readPointFile(const std::filesystem::path& path) {
  return readRecords<PointRecord>(path, "point");
}
void writeClosestFile(const std::filesystem::path& path, std::span<const ClosestRecord> records) {
  writeRecords(path, records, "closest");
}
std::vector<ClosestRecord> readClosestFile(const std::filesystem::path& path) {
  return readRecords<ClosestRecord>(path, "closest");
}
void writeTransmittanceFile(const std::filesystem::path& path, std::span<const float> transmittance) {
  writeRecords(path, transmittance, "transmittance");
}

}  // namespace duplex
