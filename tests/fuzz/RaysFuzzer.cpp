// libFuzzer target of the record-file reader (RecordFileReader, the ray, hit, point, closest and
// transmittance files): the whole input is the file, written to a temporary file and read as each
// record type in blocks. A FileError (a size that is not a multiple of the record) is the expected
// refusal; otherwise the records read must be the file's bytes, and a read past the end must throw
// InvalidArgument. Anything else (a crash, a sanitizer report, another exception, other bytes) is a
// finding.

#include "FuzzInputFile.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/RayFile.h"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

extern "C" int LLVMFuzzerInitialize(int*, char***) { return 0; }

namespace {

[[noreturn]] void violated(const char* what) {
  std::fprintf(stderr, "RecordFileReader property violated: %s\n", what);
  std::abort();
}

template <class Record>
void readAs(const std::filesystem::path& file, const std::uint8_t* data, std::size_t size) {
  try {
    duplex::RecordFileReader<Record> reader(file, "fuzz");
    if (reader.count() * sizeof(Record) != size) violated("count() is not the file's records");
    std::vector<Record> block(3);  // a block size that divides no record count of the seeds
    for (std::size_t first = 0; first < reader.count(); first += block.size()) {
      const std::size_t n = std::min(block.size(), reader.count() - first);
      reader.read(first, std::span<Record>(block.data(), n));
      if (std::memcmp(block.data(), data + first * sizeof(Record), n * sizeof(Record)) != 0)
        violated("records read differ from the file's bytes");
    }
    try {
      reader.read(reader.count(), std::span<Record>(block.data(), 1));
      violated("a read past the end did not throw");
    } catch (const duplex::InvalidArgument&) {
    }
  } catch (const duplex::FileError&) {
    if (size % sizeof(Record) == 0) violated("FileError for a whole number of records");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path& file = duplex::fuzz::writeInputFile(data, size, ".bin");
  readAs<duplex::Ray>(file, data, size);
  readAs<duplex::HitRecord>(file, data, size);
  readAs<duplex::PointRecord>(file, data, size);
  readAs<duplex::ClosestRecord>(file, data, size);
  readAs<float>(file, data, size);
  return 0;
}
