// The .vdb layout checked here (OpenVDB io/Archive.cc, GridDescriptor.cc, MetaMap.cc; little
// endian):
//   header   int64 magic 0x56444220, uint32 file version, uint32 library major, minor, char
//            has-grid-offsets, 36-char ASCII UUID
//   metadata uint32 count, then per entry: string name, string type, uint32 size, size bytes
//   grids    int32 count, then per grid: string unique name, string type, string instance parent
//            (file version >= 216), int64 grid, block and end positions; the grid's data spans
//            [grid, end) and the next descriptor starts at end
// where a string is a uint32 length followed by that many bytes.

#include "VdbFileCheck.h"

#include "duplex/accel/Error.h"

#include <cstring>
#include <fstream>

namespace duplex {

namespace {

constexpr std::int64_t kMagic = 0x56444220;
constexpr std::uint32_t kOldestVersion = 222;  // OpenVDB 10 refuses older files' metadata anyway
constexpr std::uint32_t kNewestVersion = 224;
constexpr std::uint32_t kGridInstancingVersion = 216;
constexpr std::int64_t kHeaderBytes = 8 + 4 + 4 + 4 + 1 + 36;

// Bounded reads from the file: every length is checked against what is left before it is used.
class Reader {
 public:
  Reader(const std::filesystem::path& file, std::int64_t size) : file_(file), in_(file, std::ios::binary), size_(size) {
    if (!in_) fail("cannot open for reading");
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw FileError(file_.string() + ": not a readable .vdb file: " + what);
  }
  std::int64_t pos() const { return pos_; }
  std::int64_t size() const { return size_; }
  void bytes(char* out, std::int64_t n, const char* what) {
    if (n < 0 || n > size_ - pos_)
      fail(std::string(what) + " at byte " + std::to_string(pos_) + " runs past the end of the file (" +
           std::to_string(size_) + " bytes; truncated?)");
    in_.read(out, n);
    if (!in_) fail(std::string("read error in ") + what + " at byte " + std::to_string(pos_));
    pos_ += n;
  }
  template <class T>
  T value(const char* what) {
    T v{};
    char b[sizeof(T)];
    bytes(b, sizeof(T), what);
    std::memcpy(&v, b, sizeof(T));
    return v;
  }
  void skip(std::int64_t n, const char* what) {
    if (n < 0 || n > size_ - pos_)
      fail(std::string(what) + " at byte " + std::to_string(pos_) + " runs past the end of the file (" +
           std::to_string(size_) + " bytes; truncated?)");
    pos_ += n;
    in_.seekg(pos_);
  }
  std::string string(const char* what) {
    const auto n = value<std::uint32_t>(what);
    std::string s(std::min<std::int64_t>(n, size_ - pos_), '\0');
    bytes(s.data(), n, what);
    return s;
  }
  void seek(std::int64_t p) {
    pos_ = p;
    in_.seekg(p);
  }

 private:
  std::filesystem::path file_;
  std::ifstream in_;
  std::int64_t size_;
  std::int64_t pos_ = 0;
};

}  // namespace

std::vector<VdbGridExtent> checkVdbFileStructure(const std::filesystem::path& file) {
  std::error_code ec;
  const auto file_size = std::filesystem::file_size(file, ec);
  if (ec) throw FileError(file.string() + ": cannot read its size: " + ec.message());
  Reader r(file, static_cast<std::int64_t>(file_size));

  // Header.
  if (r.size() < kHeaderBytes)
    r.fail("only " + std::to_string(r.size()) + " bytes, shorter than the " + std::to_string(kHeaderBytes) +
           "-byte header (truncated?)");
  if (r.value<std::int64_t>("magic number") != kMagic) r.fail("no VDB magic number");
  const auto version = r.value<std::uint32_t>("file version");
  if (version < kOldestVersion || version > kNewestVersion)
    r.fail("file format version " + std::to_string(version) + " (readable: " + std::to_string(kOldestVersion) + " to " +
           std::to_string(kNewestVersion) + ")");
  (void)r.value<std::uint32_t>("library major version");
  (void)r.value<std::uint32_t>("library minor version");
  const char has_offsets = r.value<char>("grid-offsets flag");
  r.skip(36, "UUID");
  if (!has_offsets) r.fail("written without grid offsets (an io::Stream archive); only seekable .vdb files are read");

  // File-level metadata.
  const auto meta_count = r.value<std::uint32_t>("metadata count");
  for (std::uint32_t k = 0; k < meta_count; ++k) {
    (void)r.string("metadata name");
    (void)r.string("metadata type");
    r.skip(r.value<std::uint32_t>("metadata size"), "metadata value");
  }

  // Grid descriptors, each followed by its grid.
  const auto grid_count = r.value<std::int32_t>("grid count");
  if (grid_count < 0) r.fail("negative grid count " + std::to_string(grid_count));
  std::vector<VdbGridExtent> grids;
  for (std::int32_t g = 0; g < grid_count; ++g) {
    VdbGridExtent e;
    e.unique_name = r.string("grid name");
    e.type = r.string("grid type");
    if (version >= kGridInstancingVersion) e.instance_parent = r.string("instance parent name");
    e.grid_pos = r.value<std::int64_t>("grid position");
    e.block_pos = r.value<std::int64_t>("grid block position");
    e.end_pos = r.value<std::int64_t>("grid end position");
    const std::string what = "grid \"" + e.unique_name + "\"";
    if (e.grid_pos != r.pos())
      r.fail(what + " starts at byte " + std::to_string(e.grid_pos) + ", not right after its descriptor (byte " +
             std::to_string(r.pos()) + ")");
    // Instances store no tree: their block position stays 0.
    const bool block_ok = e.instance_parent.empty() ? e.grid_pos <= e.block_pos && e.block_pos <= e.end_pos
                                                    : e.block_pos == 0 || e.block_pos <= e.end_pos;
    if (!block_ok || e.end_pos < e.grid_pos)
      r.fail(what + ": inconsistent offsets (grid " + std::to_string(e.grid_pos) + ", block " +
             std::to_string(e.block_pos) + ", end " + std::to_string(e.end_pos) + ")");
    if (e.end_pos > r.size())
      r.fail(what + " ends at byte " + std::to_string(e.end_pos) + ", past the end of the file (" +
             std::to_string(r.size()) + " bytes; truncated)");
    r.seek(e.end_pos);
    grids.push_back(std::move(e));
  }
  return grids;
}

}  // namespace duplex
