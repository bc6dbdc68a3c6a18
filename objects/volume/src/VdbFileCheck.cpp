// The .vdb layout checked here (OpenVDB io/Archive.cc, GridDescriptor.cc, MetaMap.cc; little
// endian):
//   header   int64 magic 0x56444220, uint32 file version, uint32 library major, minor, char
//            has-grid-offsets, 36-char ASCII UUID (8-4-4-4-12 hex digits)
//   metadata uint32 count, then per entry: string name, string type, uint32 size, size bytes
//   grids    int32 count, then per grid: string unique name, string type, string instance parent
//            (file version >= 216), int64 grid, block and end positions; the grid's data spans
//            [grid, end) and the next descriptor starts at end
// where a string is a uint32 length followed by that many bytes.
//
// Inside a float grid (OpenVDB Archive.cc, Transform.cc, Maps.h, Tree.h, RootNode.h,
// InternalNode.h, LeafNode.h, Compression.h):
//   grid     uint32 compression flags (zip 1, active mask 2, blosc 4), metadata as above (the bool
//            "is_saved_as_half_float" selects 2-byte values), string map type and the map's
//            doubles, then at the topology: int32 buffer count (1), float background, uint32
//            root tiles and children; 17 bytes per tile (coord, value, active flag); per child a
//            coord and a 32^3 internal node
//   internal child mask, value mask (N^3 bits each), the node's N^3 tile values (compressed
//            values below), then its children in child-mask order (16^3 nodes, then 8^3 leaves,
//            whose topology is their 64-byte value mask)
//   buffers  at the block position, per leaf in the same order: its value mask again and its 512
//            compressed values
//   compressed values: int8 mask flag (0-6: which inactive values and whether a 512-bit selection
//            mask follow), 0-2 floats, the selection mask, then the values, only the active ones
//            when the active-mask flag is set (unless the mask flag is 6): zip or blosc chunks
//            are an int64 byte count (negative: that many raw bytes) and the bytes; uncompressed
//            values are raw; half floats store nothing at all when no value is stored.
// OpenVDB 10 reads a raw chunk of whatever length it declares into a buffer sized for the values
// (a heap overflow on a damaged file) and hands blosc a chunk whose header may claim more bytes
// than were read; the walk below checks every chunk's lengths first.
// The chunks of the internal nodes (read with the tree's topology) are also decompressed here: when
// one does not decompress to its values, OpenVDB 10 throws from RootNode::readTopology after
// allocating the node, which it then leaks. The leaves' chunks (read with the buffers, where a
// throw leaks nothing) are only checked for their lengths, which keeps the check cheap.

#include "VdbFileCheck.h"

#include "duplex/accel/Error.h"

#include <blosc.h>
#include <zlib.h>

#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <map>
#include <optional>

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

// OpenVDB reads the UUID with a formatted stream read (boost's operator>>), which skips
// whitespace before and inside it: a whitespace byte there would make OpenVDB read everything
// after it one byte later than this walk does, and trust lengths this walk never checked. So the
// UUID must be exactly what OpenVDB writes.
void uuid(Reader& r) {
  const std::int64_t at = r.pos();
  std::array<char, 36> text{};
  r.bytes(text.data(), 36, "UUID");
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    const bool dash = i == 8 || i == 13 || i == 18 || i == 23;
    const bool ok = dash ? c == '-' : (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
    if (!ok)
      r.fail("the UUID at byte " + std::to_string(at) + " has byte " + std::to_string(static_cast<unsigned char>(c)) +
             " at character " + std::to_string(i + 1) + " (expected 8-4-4-4-12 hexadecimal digits)");
  }
}

// Bytes of the transform's map after its type name (the doubles each map type writes); maps not
// listed are unknown to OpenVDB too (the frustum map is walked by transformMap).
std::int64_t mapBytes(const std::string& type) {
  static const std::map<std::string, std::int64_t> bytes = {{"UniformScaleMap", 5 * 24},
                                                            {"ScaleMap", 5 * 24},
                                                            {"UniformScaleTranslateMap", 6 * 24},
                                                            {"ScaleTranslateMap", 6 * 24},
                                                            {"TranslationMap", 24},
                                                            {"AffineMap", 128},
                                                            {"UnitaryMap", 128}};
  const auto it = bytes.find(type);
  return it == bytes.end() ? -1 : it->second;
}

// Bytes of the value of each fixed-size metadata type OpenVDB registers (TypedMetadata reads
// exactly these, whatever size the entry declares: a different size would leave the stream inside
// the value and make every later length come from the wrong bytes).
std::int64_t metadataValueBytes(const std::string& type) {
  static const std::map<std::string, std::int64_t> bytes = {
      {"bool", 1},   {"float", 4},  {"double", 8}, {"int32", 4},  {"int64", 8},  {"vec2i", 8},
      {"vec2s", 8},  {"vec2d", 16}, {"vec3i", 12}, {"vec3s", 12}, {"vec3d", 24}, {"vec4i", 16},
      {"vec4s", 16}, {"vec4d", 32}, {"mat4s", 64}, {"mat4d", 128}};
  const auto it = bytes.find(type);
  return it == bytes.end() ? -1 : it->second;
}

// A blosc chunk of `chunk` bytes at the reader's position must decompress to exactly `expected`
// bytes: blosc's header (version, version, flags, type size, then uint32 uncompressed, block and
// compressed sizes) is what OpenVDB hands blosc, which trusts it. `padded` allows the padding of
// points::bloscCompress (arrays shorter than 128 bytes are compressed as 128). Leaves the reader
// after the chunk.
void bloscChunk(Reader& r, std::int64_t chunk, std::int64_t expected, const std::string& where, bool padded = false) {
  if (chunk < 16) r.fail(where + ": a blosc chunk of " + std::to_string(chunk) + " bytes, too short for its header");
  std::uint32_t header[4];
  r.bytes(reinterpret_cast<char*>(header), 16, "blosc header");
  const bool size_ok = header[1] == static_cast<std::uint64_t>(expected) ||
                       (padded && expected < 128 && header[1] > expected && header[1] <= 128);
  if (!size_ok || header[3] != static_cast<std::uint64_t>(chunk))
    r.fail(where + ": a blosc chunk of " + std::to_string(chunk) + " bytes holds a blosc block of " +
           std::to_string(header[1]) + " bytes in " + std::to_string(header[3]) + " (" + std::to_string(expected) +
           " bytes expected)");
  r.skip(chunk - 16, "blosc data");
}

// io::DelayedLoadMetadata ("__delayedload"): uint32 leaf count, then the leaves' int8 mask flags
// and their int64 compressed buffer sizes, each array as a uint32 byte count followed by a blosc
// chunk of that many bytes, or by the raw array when the count is 0 (the second array is absent
// when it is 0xffffffff). OpenVDB sizes the arrays by the leaf count and by the blosc header's
// uncompressed size before reading them: both must be the array's bytes, and every leaf stores at
// least its 64-byte value mask in the grid, which bounds the count by the grid's bytes
// (`grid_bytes`; the file's bytes for file-level metadata). The value must fit in its declared size
// (OpenVDB skips what it does not read, but does not stop at the declared end).
void delayedLoadMetadata(Reader& r, std::int64_t size, std::int64_t grid_bytes, const std::string& where) {
  if (size == 0) return;  // OpenVDB reads nothing for an empty value
  const std::int64_t end = r.pos() + size;
  auto inside = [&] {
    if (r.pos() > end)
      r.fail(where + ": delayed-load metadata runs past the " + std::to_string(size) + " bytes it declares");
  };
  const auto count = r.value<std::uint32_t>("delayed-load leaf count");
  if (std::int64_t{count} * 64 > grid_bytes)
    r.fail(where + ": delayed-load metadata for " + std::to_string(count) + " leaves, more than its " +
           std::to_string(grid_bytes) + " bytes can hold");
  for (const std::int64_t item : {1, 8}) {
    const auto bytes = r.value<std::uint32_t>("delayed-load array size");
    if (item == 8 && bytes == 0xffffffffu) break;
    if (bytes == 0) {
      r.skip(count * item, "delayed-load array");
    } else {
      if (bytes > end - r.pos())
        r.fail(where + ": delayed-load array of " + std::to_string(bytes) + " bytes runs past its metadata value");
      bloscChunk(r, bytes, count * item, where + ": delayed-load array", /*padded=*/true);
    }
    inside();
  }
  inside();
  r.skip(end - r.pos(), "delayed-load metadata");
}

// MetaMap::readMeta: uint32 count, then per entry: string name, string type, uint32 size, value.
// Returns the value of a bool "is_saved_as_half_float" entry, if there is one.
std::optional<bool> metadata(Reader& r, std::int64_t grid_bytes, const std::string& where) {
  std::optional<bool> half;
  const auto count = r.value<std::uint32_t>("metadata count");
  for (std::uint32_t k = 0; k < count; ++k) {
    const std::string name = r.string("metadata name");
    const std::string type = r.string("metadata type");
    const auto size = r.value<std::uint32_t>("metadata size");
    const std::string entry = where + ": metadata \"" + name + "\"";
    const std::int64_t fixed = metadataValueBytes(type);
    if (fixed >= 0 && size != fixed)
      r.fail(entry + " of type " + type + " declares " + std::to_string(size) + " bytes, not " + std::to_string(fixed));
    if (type == "__delayedload") {
      delayedLoadMetadata(r, size, grid_bytes, entry);
    } else if (name == "is_saved_as_half_float") {
      // Grid::saveFloatAsHalf is this entry's asBool(): refused unless it is the bool OpenVDB writes.
      if (type != "bool") r.fail(entry + " has type " + type + ", not bool");
      half = r.value<char>("metadata value") != 0;
    } else {
      r.skip(size, "metadata value");  // strings and unknown types: OpenVDB reads `size` bytes
    }
  }
  return half;
}

// Transform::read: string map type, then the map. Returns false for a map type not listed
// (OpenVDB refuses unregistered ones before reading them).
bool transformMap(Reader& r, const std::string& where, int depth = 0) {
  const std::string type = r.string("transform map type");
  if (type == "NonlinearFrustumMap") {
    // Bounding box (6 doubles), taper, depth, then a second (linear) map of its own.
    if (depth > 0) r.fail(where + ": a frustum map inside a frustum map");
    r.skip(8 * 8, "frustum map");
    if (!transformMap(r, where, depth + 1)) r.fail(where + ": a frustum map over an unknown map type");
    return true;
  }
  const std::int64_t map_bytes = mapBytes(type);
  if (map_bytes < 0) return false;
  r.skip(map_bytes, "transform");
  return true;
}

constexpr std::uint32_t kZip = 0x1, kActiveMask = 0x2, kBlosc = 0x4;

// What OpenVDB reads of every grid before its tree (io::File::readAllGridMetadata reads it of all
// grids, instances and other value types too): uint32 compression flags, metadata, transform.
struct GridHeader {
  std::uint32_t compression = 0;
  bool half = false;
  bool linear = false;  ///< the transform was walked (a map type listed in mapBytes)
};
GridHeader gridHeader(Reader& r, const VdbGridExtent& e) {
  const std::string where = "grid \"" + e.unique_name + "\"";
  GridHeader h;
  h.compression = r.value<std::uint32_t>("grid compression flags");
  // The descriptor's "_HalfFloat" suffix only sets the grid's metadata entry, which readMeta then
  // replaces: the values are half floats exactly when the grid's own entry says so.
  h.half = metadata(r, e.end_pos - e.grid_pos, where).value_or(false);
  h.linear = transformMap(r, where);
  return h;
}

// Walks one float grid's tree (layout above), checking every length against the values it must
// hold; throws through Reader::fail with the grid, the place and the problem.
class FloatTreeWalk {
 public:
  FloatTreeWalk(Reader& r, const VdbGridExtent& e) : r_(r), e_(e), what_("grid \"" + e.unique_name + "\"") {}

  void run() {
    r_.seek(e_.grid_pos);
    const GridHeader header = gridHeader(r_, e_);
    if (!header.linear) return;
    compression_ = header.compression;
    half_ = header.half;
    const auto buffers = r_.value<std::int32_t>("tree buffer count");
    if (buffers != 1) fail("tree has " + std::to_string(buffers) + " buffers (OpenVDB reads 1)");
    (void)r_.value<float>("background value");
    const auto tiles = r_.value<std::uint32_t>("root tile count");
    const auto children = r_.value<std::uint32_t>("root child count");
    r_.skip(std::int64_t{tiles} * (12 + 4 + 1), "root tiles");
    // The buffers follow the tree's order: root children by origin (later duplicates replace
    // earlier ones, as in OpenVDB's root table), then child-mask order below.
    std::map<std::array<std::int32_t, 3>, std::vector<std::uint16_t>> roots;
    for (std::uint32_t c = 0; c < children; ++c) {
      std::array<std::int32_t, 3> origin{};
      for (std::int32_t& x : origin) x = r_.value<std::int32_t>("root child origin");
      std::vector<std::uint16_t> leaf_counts;
      internalNode(5, leaf_counts);
      roots[origin] = std::move(leaf_counts);
    }
    if (r_.pos() != e_.block_pos)
      fail("its tree topology ends at byte " + std::to_string(r_.pos()) + ", not at its block position " +
           std::to_string(e_.block_pos));
    std::size_t leaf = 0;
    for (const auto& [origin, counts] : roots)
      for (const std::uint16_t active : counts) {
        r_.skip(64, "leaf value mask");
        compressedValues(active, 512, "leaf buffer " + std::to_string(leaf++));
      }
    if (r_.pos() != e_.end_pos)
      fail("its leaf buffers end at byte " + std::to_string(r_.pos()) + ", not at its end position " +
           std::to_string(e_.end_pos));
  }

 private:
  [[noreturn]] void fail(const std::string& problem) const { r_.fail(what_ + ": " + problem); }

  // Returns the number of set bits of a mask of `bits` bits read from the file.
  std::uint32_t mask(std::uint32_t bits, const char* what) {
    std::vector<std::uint64_t> words(bits / 64);
    r_.bytes(reinterpret_cast<char*>(words.data()), static_cast<std::int64_t>(bits / 8), what);
    std::uint32_t on = 0;
    for (const std::uint64_t w : words) on += static_cast<std::uint32_t>(std::popcount(w));
    return on;
  }

  // A 2^(3 log2dim) internal node; appends the active-voxel count of each leaf below it.
  void internalNode(int log2dim, std::vector<std::uint16_t>& leaf_counts) {
    const std::uint32_t n = 1u << (3 * log2dim);
    const std::int64_t at = r_.pos();
    std::vector<std::uint64_t> child(n / 64);
    r_.bytes(reinterpret_cast<char*>(child.data()), n / 8, "internal node child mask");
    const std::uint32_t active = mask(n, "internal node value mask");
    compressedValues(active, n, "internal node at byte " + std::to_string(at), true);
    for (const std::uint64_t w : child)
      for (int b = 0; b < std::popcount(w); ++b) {
        if (log2dim == 5) {
          internalNode(4, leaf_counts);
        } else {
          leaf_counts.push_back(static_cast<std::uint16_t>(mask(512, "leaf value mask")));
        }
      }
  }

  // io::readCompressedValues: `active` of the `count` values are active (the node's value mask).
  // `inflate`: also decompress a zip or blosc chunk and require exactly the values' bytes.
  void compressedValues(std::uint32_t active, std::uint32_t count, const std::string& where, bool inflate = false) {
    const auto flag = r_.value<std::int8_t>("value compression flag");
    if (flag == 2 || flag == 4 || flag == 5) r_.skip(4, "inactive value");
    if (flag == 5) r_.skip(4, "second inactive value");
    if (flag == 3 || flag == 4 || flag == 5) r_.skip(count / 8, "selection mask");
    const std::uint32_t stored = (compression_ & kActiveMask) && flag != 6 ? active : count;
    const std::int64_t bytes = std::int64_t{stored} * (half_ ? 2 : 4);
    if (half_ && stored == 0) return;  // io::HalfReader reads nothing at all for no values
    if (!(compression_ & (kZip | kBlosc))) {
      r_.skip(bytes, "values");
      return;
    }
    const std::int64_t at = r_.pos();
    const auto chunk = r_.value<std::int64_t>("compressed chunk length");
    auto bad = [&](const std::string& problem) {
      fail(where + ": the chunk at byte " + std::to_string(at) + " " + problem + " (" + std::to_string(bytes) +
           " bytes of values expected)");
    };
    if (chunk <= 0) {
      // The raw byte count, negated without overflow (INT64_MIN is no length at all).
      if (chunk != -bytes) bad("declares " + std::to_string(0 - static_cast<std::uint64_t>(chunk)) + " raw bytes");
      r_.skip(bytes, "raw values");
      return;
    }
    if (chunk > e_.end_pos - r_.pos()) bad("declares " + std::to_string(chunk) + " bytes, past the grid's end");
    if (inflate) {
      const std::int64_t start = r_.pos();
      if (compression_ & kBlosc) {
        bloscChunk(r_, chunk, bytes, what_ + ": " + where + ": the chunk at byte " + std::to_string(at));
        r_.seek(start);
      }
      std::vector<char> packed(static_cast<std::size_t>(chunk));
      r_.bytes(packed.data(), chunk, "compressed values");
      std::vector<char> values(static_cast<std::size_t>(bytes) + 1);  // + 1: a longer result is an error too
      std::int64_t got = -1;
      if (compression_ & kBlosc) {
        got = blosc_decompress_ctx(packed.data(), values.data(), values.size(), 1);
      } else {
        uLongf n = static_cast<uLongf>(values.size());
        if (uncompress(reinterpret_cast<Bytef*>(values.data()), &n, reinterpret_cast<const Bytef*>(packed.data()),
                       static_cast<uLong>(chunk)) == Z_OK)
          got = static_cast<std::int64_t>(n);
      }
      if (got != bytes)
        bad(got < 0 ? std::string("does not decompress") : "decompresses to " + std::to_string(got) + " bytes");
      return;
    }
    if (compression_ & kBlosc) {
      bloscChunk(r_, chunk, bytes, what_ + ": " + where + ": the chunk at byte " + std::to_string(at));
    } else {
      r_.skip(chunk, "zip data");  // zlib's inflate is bounded by both lengths
    }
  }

  Reader& r_;
  const VdbGridExtent& e_;
  std::string what_;
  std::uint32_t compression_ = 0;
  bool half_ = false;
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
  uuid(r);
  if (!has_offsets) r.fail("written without grid offsets (an io::Stream archive); only seekable .vdb files are read");

  // File-level metadata.
  (void)metadata(r, r.size(), "file metadata");

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
  // Every grid's header, and the trees of the float grids (the grids Duplex reads; instances share
  // their parent's tree).
  for (const VdbGridExtent& e : grids) {
    if (e.instance_parent.empty() && (e.type == "Tree_float_5_4_3" || e.type == "Tree_float_5_4_3_HalfFloat")) {
      FloatTreeWalk(r, e).run();
    } else {
      r.seek(e.grid_pos);
      (void)gridHeader(r, e);
    }
  }
  return grids;
}

}  // namespace duplex
