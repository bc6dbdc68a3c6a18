#include "MeshFileReaders.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/MemoryLimit.h"

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <sstream>
#include <unordered_map>

namespace duplex::mesh_files {

namespace {

// The arrays a reader is about to build, with the file's bytes it holds meanwhile, against the
// memory limit: a position per vertex, a triangle per face (more corners add triangles as they
// are read), and `extra` bytes (the STL readers' vertex index).
void requireArrays(const std::string& file, std::uint64_t file_bytes, std::uint64_t vertices, std::uint64_t faces,
                   std::uint64_t extra = 0) {
  std::uint64_t bytes = saturatingAdd(file_bytes, arrayBytes(vertices, sizeof(glm::vec3)));
  bytes = saturatingAdd(bytes, arrayBytes(faces, sizeof(TriangleMesh::Triangle)));
  std::ostringstream what;
  what << "mesh file '" << file << "' (" << vertices << " vertices, " << faces << " faces)";
  requireMemory(saturatingAdd(bytes, extra), what.str());
}

[[noreturn]] void fail(const std::string& file, const std::string& where, const std::string& what) {
  std::ostringstream msg;
  msg << "mesh file '" << file << "': ";
  if (!where.empty()) msg << where << ": ";
  msg << what;
  throw FileError(msg.str());
}

std::string lineName(std::size_t line) {
  std::ostringstream s;
  s << "line " << line;
  return s.str();
}

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

bool equalsIgnoringCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

// Numbers as the C library reads them: decimal floats to the nearest float (not through double,
// which could round twice), with an optional leading '+'. Out-of-range magnitudes become
// infinities or zeros, as strtof gives them (a non-finite vertex makes its triangles degenerate).
std::optional<float> parseFloat(std::string_view token) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  float value = 0.0f;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (end != token.data() + token.size() || token.empty()) return std::nullopt;
  if (ec == std::errc::result_out_of_range) {
    double d = 0.0;
    const auto r = std::from_chars(token.data(), token.data() + token.size(), d);
    if (r.ptr != token.data() + token.size()) return std::nullopt;
    if (r.ec == std::errc::result_out_of_range) {
      const bool negative = token[0] == '-';
      // Which way it overflowed: an exponent with a minus sign underflows to zero.
      const std::size_t e = token.find_first_of("eE");
      const bool tiny = e != std::string_view::npos && e + 1 < token.size() && token[e + 1] == '-';
      if (tiny) return negative ? -0.0f : 0.0f;
      return negative ? -std::numeric_limits<float>::infinity() : std::numeric_limits<float>::infinity();
    }
    return static_cast<float>(d);
  }
  if (ec != std::errc()) return std::nullopt;
  return value;
}

std::optional<long long> parseInteger(std::string_view token) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  long long value = 0;
  const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (ec != std::errc() || end != token.data() + token.size() || token.empty()) return std::nullopt;
  return value;
}

// Whitespace-separated tokens of one line.
class Tokens {
 public:
  explicit Tokens(std::string_view line) : rest_(line) {}
  std::optional<std::string_view> next() {
    std::size_t i = 0;
    while (i < rest_.size() && isSpace(rest_[i])) ++i;
    if (i == rest_.size()) return std::nullopt;
    std::size_t j = i;
    while (j < rest_.size() && !isSpace(rest_[j])) ++j;
    const std::string_view token = rest_.substr(i, j - i);
    rest_.remove_prefix(j);
    return token;
  }
  [[nodiscard]] std::string_view rest() const { return rest_; }

 private:
  std::string_view rest_;
};

// Lines of a text, numbered from 1; a final line without '\n' counts.
class Lines {
 public:
  explicit Lines(std::string_view text) : text_(text) {}
  std::optional<std::string_view> next() {
    if (pos_ >= text_.size()) return std::nullopt;
    const std::size_t end = text_.find('\n', pos_);
    const std::size_t stop = end == std::string_view::npos ? text_.size() : end;
    std::string_view line = text_.substr(pos_, stop - pos_);
    pos_ = stop + 1;
    ++number_;
    return line;
  }
  [[nodiscard]] std::size_t number() const { return number_; }
  [[nodiscard]] std::size_t offset() const { return std::min(pos_, text_.size()); }
  [[nodiscard]] std::size_t remaining() const { return text_.size() - offset(); }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t number_ = 0;
};

// ---------------------------------------------------------------------------------------------
// OBJ: "v x y z [w | r g b]" and "f i[/t][/n] ..." (1-based; negative indices count back from the
// vertices read so far). Forward references are allowed and checked once the file is read.
// Texture coordinates, normals, groups, materials and smoothing are not used; free-form
// geometry and unknown keywords are counted in ignored_statements. Lines may continue with '\'.

ParsedMesh readObj(std::string_view text, const std::string& file) {
  ParsedMesh mesh;
  Lines lines(text);
  std::vector<std::uint32_t> corners;
  std::string joined;  // a line continued with '\'
  long long max_index = 0;
  std::size_t max_index_line = 0;
  // The arrays grow as statements are read: before a growth (to twice the capacity, the old
  // array still held while it is copied), what they will take against the memory limit.
  const auto requireGrowth = [&](std::size_t more_positions, std::size_t more_triangles) {
    const auto grown = [](std::size_t size, std::size_t capacity, std::size_t more) -> std::uint64_t {
      return size + more <= capacity ? capacity : std::max<std::uint64_t>(2 * std::uint64_t{capacity}, size + more);
    };
    const std::uint64_t nv = grown(mesh.positions.size(), mesh.positions.capacity(), more_positions);
    const std::uint64_t nt = grown(mesh.triangles.size(), mesh.triangles.capacity(), more_triangles);
    if (nv == mesh.positions.capacity() && nt == mesh.triangles.capacity()) return;
    const std::uint64_t copying = nv != mesh.positions.capacity()
                                      ? arrayBytes(mesh.positions.capacity(), sizeof(glm::vec3))
                                      : arrayBytes(mesh.triangles.capacity(), sizeof(TriangleMesh::Triangle));
    requireArrays(file, text.size(), nv, nt, copying);
  };
  while (auto raw = lines.next()) {
    std::string_view line = *raw;
    const std::size_t first_line = lines.number();
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    while (!line.empty() && isSpace(line.back())) line.remove_suffix(1);
    if (!line.empty() && line.back() == '\\') {
      joined.assign(line.substr(0, line.size() - 1));
      while (auto more = lines.next()) {
        std::string_view m = *more;
        if (const std::size_t hash = m.find('#'); hash != std::string_view::npos) m = m.substr(0, hash);
        while (!m.empty() && isSpace(m.back())) m.remove_suffix(1);
        const bool again = !m.empty() && m.back() == '\\';
        joined += ' ';
        joined.append(m.substr(0, again ? m.size() - 1 : m.size()));
        if (!again) break;
      }
      line = joined;
    }
    Tokens tokens(line);
    const auto keyword = tokens.next();
    if (!keyword) continue;
    if (*keyword == "v") {
      glm::vec3 p;
      for (int k = 0; k < 3; ++k) {
        const auto token = tokens.next();
        const auto value = token ? parseFloat(*token) : std::nullopt;
        if (!value) fail(file, lineName(first_line), "a vertex needs three numbers ('v x y z')");
        p[k] = *value;
      }
      if (mesh.positions.size() >= std::numeric_limits<std::uint32_t>::max())
        fail(file, lineName(first_line), "more than 2^32 - 1 vertices");
      requireGrowth(1, 0);
      mesh.positions.push_back(p);
    } else if (*keyword == "f") {
      corners.clear();
      while (const auto token = tokens.next()) {
        const std::string_view index_text = token->substr(0, token->find('/'));
        const auto index = parseInteger(index_text);
        if (!index || *index == 0)
          fail(file, lineName(first_line),
               "'" + std::string(*token) + "' is not a vertex index (1-based, or negative)");
        const long long count = static_cast<long long>(mesh.positions.size());
        long long zero_based = 0;
        if (*index < 0) {
          if (-*index > count)
            fail(file, lineName(first_line),
                 "vertex index " + std::string(index_text) + " reaches before the first vertex");
          zero_based = count + *index;
        } else {
          if (*index > max_index) {
            max_index = *index;
            max_index_line = first_line;
          }
          zero_based = *index - 1;
        }
        if (zero_based > std::numeric_limits<std::uint32_t>::max()) fail(file, lineName(first_line), "index too large");
        corners.push_back(static_cast<std::uint32_t>(zero_based));
      }
      if (corners.size() < 3) fail(file, lineName(first_line), "a face needs at least three vertices");
      requireGrowth(0, corners.size() - 2);
      addFace(mesh, corners);
    } else if (*keyword == "vt" || *keyword == "vn" || *keyword == "vp" || *keyword == "g" || *keyword == "o" ||
               *keyword == "s" || *keyword == "usemtl" || *keyword == "mtllib" || *keyword == "l" || *keyword == "p") {
      // Not geometry a ray hits (lines and points have no area), or attributes Duplex does not use.
    } else {
      ++mesh.ignored_statements;
    }
  }
  if (max_index > static_cast<long long>(mesh.positions.size())) {
    std::ostringstream what;
    what << "vertex index " << max_index << " but the file has " << mesh.positions.size() << " vertices";
    fail(file, lineName(max_index_line), what.str());
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// Binary scalars of the PLY and OFF formats.

enum class ScalarKind { Signed, Unsigned, Float };

struct ScalarType {
  ScalarKind kind = ScalarKind::Float;
  std::uint8_t bytes = 4;
};

std::optional<ScalarType> plyScalarType(std::string_view name) {
  if (name == "char" || name == "int8") return ScalarType{ScalarKind::Signed, 1};
  if (name == "uchar" || name == "uint8") return ScalarType{ScalarKind::Unsigned, 1};
  if (name == "short" || name == "int16") return ScalarType{ScalarKind::Signed, 2};
  if (name == "ushort" || name == "uint16") return ScalarType{ScalarKind::Unsigned, 2};
  if (name == "int" || name == "int32") return ScalarType{ScalarKind::Signed, 4};
  if (name == "uint" || name == "uint32") return ScalarType{ScalarKind::Unsigned, 4};
  if (name == "float" || name == "float32") return ScalarType{ScalarKind::Float, 4};
  if (name == "double" || name == "float64") return ScalarType{ScalarKind::Float, 8};
  return std::nullopt;
}

// Reads a little- or big-endian byte sequence of `bytes` bytes.
std::uint64_t loadBits(const char* p, std::uint8_t bytes, bool big_endian) {
  std::uint64_t v = 0;
  for (std::uint8_t i = 0; i < bytes; ++i) {
    const auto byte = static_cast<std::uint64_t>(static_cast<unsigned char>(p[big_endian ? i : bytes - 1 - i]));
    v = (v << 8) | byte;
  }
  return v;
}

// A scalar as a double (every PLY scalar type fits one exactly), or as a float for float32
// properties (vertex coordinates keep their bits).
double loadScalar(const char* p, ScalarType type, bool big_endian) {
  const std::uint64_t bits = loadBits(p, type.bytes, big_endian);
  switch (type.kind) {
    case ScalarKind::Unsigned: return static_cast<double>(bits);
    case ScalarKind::Signed: {
      const unsigned shift = 64u - 8u * type.bytes;
      return static_cast<double>(static_cast<std::int64_t>(bits << shift) >> shift);
    }
    case ScalarKind::Float:
      if (type.bytes == 4) return static_cast<double>(std::bit_cast<float>(static_cast<std::uint32_t>(bits)));
      return std::bit_cast<double>(bits);
  }
  return 0.0;
}

// A face corner read as a double: a vertex index when it is a whole number in [0, vertices).
std::optional<std::uint32_t> vertexIndex(double value, std::size_t vertices) {
  if (!(value >= 0.0) || value != std::floor(value) || value >= static_cast<double>(vertices)) return std::nullopt;
  return static_cast<std::uint32_t>(value);
}

// ---------------------------------------------------------------------------------------------
// PLY (ascii, binary_little_endian, binary_big_endian): element "vertex" with properties x, y,
// z; element "face" with a list property "vertex_indices" (or "vertex_index"); every other element
// and property is read past. The header's counts are bounded by the bytes after it.

struct PlyProperty {
  std::string name;
  bool list = false;
  ScalarType count_type;  // list only
  ScalarType type;        // the value, or the list's items
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

std::string plyElementName(const PlyElement& e, std::uint64_t item) {
  std::ostringstream s;
  s << e.name << " " << item;
  return s.str();
}

ParsedMesh readPly(std::string_view bytes, const std::string& file) {
  Lines lines(bytes);
  const auto magic = lines.next();
  if (!magic || (*magic != "ply" && *magic != "ply\r")) fail(file, "", "not a PLY file (no 'ply' on the first line)");
  std::optional<PlyFormat> format;
  std::vector<PlyElement> elements;
  bool ended = false;
  while (auto raw = lines.next()) {
    Tokens tokens(*raw);
    const auto keyword = tokens.next();
    const std::string where = lineName(lines.number());
    if (!keyword) continue;
    if (*keyword == "end_header") {
      ended = true;
      break;
    }
    if (*keyword == "comment" || *keyword == "obj_info") continue;
    if (*keyword == "format") {
      const auto name = tokens.next();
      const auto version = tokens.next();
      if (!name || !version || *version != "1.0") fail(file, where, "expected 'format <ascii|binary_...> 1.0'");
      if (*name == "ascii") format = PlyFormat::Ascii;
      else if (*name == "binary_little_endian") format = PlyFormat::BinaryLittle;
      else if (*name == "binary_big_endian") format = PlyFormat::BinaryBig;
      else fail(file, where, "unknown format '" + std::string(*name) + "'");
    } else if (*keyword == "element") {
      const auto name = tokens.next();
      const auto count = tokens.next();
      const auto n = count ? parseInteger(*count) : std::nullopt;
      if (!name || !n || *n < 0) fail(file, where, "expected 'element <name> <count>'");
      elements.push_back({std::string(*name), static_cast<std::uint64_t>(*n), {}});
    } else if (*keyword == "property") {
      if (elements.empty()) fail(file, where, "a property before any element");
      PlyProperty p;
      auto type = tokens.next();
      if (type && *type == "list") {
        p.list = true;
        const auto count_type = tokens.next();
        const auto ct = count_type ? plyScalarType(*count_type) : std::nullopt;
        if (!ct || ct->kind == ScalarKind::Float) fail(file, where, "a list's count needs an integer type");
        p.count_type = *ct;
        type = tokens.next();
      }
      const auto t = type ? plyScalarType(*type) : std::nullopt;
      const auto name = tokens.next();
      if (!t || !name) fail(file, where, "expected 'property <type> <name>' or 'property list <type> <type> <name>'");
      p.type = *t;
      p.name = std::string(*name);
      elements.back().properties.push_back(std::move(p));
    } else {
      fail(file, where, "unknown header keyword '" + std::string(*keyword) + "'");
    }
  }
  if (!ended) fail(file, "", "the header has no 'end_header'");
  if (!format) fail(file, "", "the header has no 'format' line");

  const PlyElement* vertex = nullptr;
  const PlyElement* face = nullptr;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex" && !vertex) vertex = &e;
    if (e.name == "face" && !face) face = &e;
  }
  if (!vertex) fail(file, "", "no 'vertex' element");
  if (!face) fail(file, "", "no 'face' element");
  std::array<int, 3> xyz = {-1, -1, -1};
  for (std::size_t i = 0; i < vertex->properties.size(); ++i) {
    const PlyProperty& p = vertex->properties[i];
    for (int k = 0; k < 3; ++k)
      if (!p.list && p.name == std::string(1, static_cast<char>('x' + k)) && xyz[k] < 0) xyz[k] = static_cast<int>(i);
  }
  if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail(file, "", "the 'vertex' element lacks an x, y or z property");
  int corners_property = -1;
  for (std::size_t i = 0; i < face->properties.size(); ++i) {
    const PlyProperty& p = face->properties[i];
    if (p.list && (p.name == "vertex_indices" || p.name == "vertex_index") && corners_property < 0)
      corners_property = static_cast<int>(i);
  }
  if (corners_property < 0) fail(file, "", "the 'face' element has no list property 'vertex_indices'");
  if (vertex->count > std::numeric_limits<std::uint32_t>::max()) fail(file, "", "more than 2^32 - 1 vertices");

  // Every element's items need at least this many bytes: bound the counts before allocating.
  const std::size_t data_start = lines.offset();
  const std::size_t data_bytes = bytes.size() - data_start;
  for (const PlyElement& e : elements) {
    std::uint64_t least = 0;
    for (const PlyProperty& p : e.properties)
      least += *format == PlyFormat::Ascii ? 2 : (p.list ? p.count_type.bytes : p.type.bytes);
    if (least > 0 && e.count > data_bytes / least) {
      std::ostringstream what;
      what << "declares " << e.count << " " << e.name << " elements but only " << data_bytes
           << " bytes of data follow the header (truncated or malformed)";
      fail(file, "", what.str());
    }
  }

  requireArrays(file, bytes.size(), vertex->count, face->count);
  ParsedMesh mesh;
  mesh.positions.resize(vertex->count);
  mesh.triangles.reserve(face->count);
  std::vector<std::uint32_t> corners;
  std::vector<double> values;  // one item's scalar values, lists flattened

  if (*format == PlyFormat::Ascii) {
    Lines data(bytes.substr(data_start));
    Tokens tokens("");
    const std::size_t header_lines = lines.number();
    // The next token of the data, across lines; nullopt at the end.
    auto next = [&]() -> std::optional<std::string_view> {
      for (;;) {
        if (auto t = tokens.next()) return t;
        const auto line = data.next();
        if (!line) return std::nullopt;
        tokens = Tokens(*line);
      }
    };
    for (const PlyElement& e : elements) {
      if (e.properties.empty()) continue;  // nothing to read, however many it declares
      for (std::uint64_t item = 0; item < e.count; ++item) {
        const bool is_vertex = &e == vertex, is_face = &e == face;
        auto where = [&] {
          std::ostringstream s;
          s << plyElementName(e, item) << " (line " << header_lines + std::max<std::size_t>(data.number(), 1) << ")";
          return s.str();
        };
        for (std::size_t pi = 0; pi < e.properties.size(); ++pi) {
          const PlyProperty& p = e.properties[pi];
          std::uint64_t n = 1;
          if (p.list) {
            const auto t = next();
            const auto c = t ? parseInteger(*t) : std::nullopt;
            if (!t) fail(file, where(), "the file ends inside the element (truncated)");
            if (!c || *c < 0 || static_cast<std::uint64_t>(*c) > data.remaining() + tokens.rest().size())
              fail(file, where(), "'" + std::string(*t) + "' is not a list length the file can hold");
            n = static_cast<std::uint64_t>(*c);
          }
          const bool wanted_corners = is_face && static_cast<int>(pi) == corners_property;
          if (wanted_corners) corners.clear();
          for (std::uint64_t j = 0; j < n; ++j) {
            const auto t = next();
            if (!t) fail(file, where(), "the file ends inside the element (truncated)");
            if (p.type.kind == ScalarKind::Float) {
              const auto v = parseFloat(*t);
              if (!v) fail(file, where(), "'" + std::string(*t) + "' is not a number");
              if (is_vertex)
                for (int k = 0; k < 3; ++k)
                  if (xyz[k] == static_cast<int>(pi)) mesh.positions[item][k] = *v;
              if (wanted_corners) {
                const auto index = vertexIndex(*v, vertex->count);
                if (!index) fail(file, where(), "'" + std::string(*t) + "' is not a vertex index");
                corners.push_back(*index);
              }
            } else {
              const auto v = parseInteger(*t);
              if (!v) fail(file, where(), "'" + std::string(*t) + "' is not an integer");
              if (is_vertex)
                for (int k = 0; k < 3; ++k)
                  if (xyz[k] == static_cast<int>(pi)) mesh.positions[item][k] = static_cast<float>(*v);
              if (wanted_corners) {
                if (*v < 0 || static_cast<std::uint64_t>(*v) >= vertex->count) {
                  std::ostringstream what;
                  what << "vertex index " << *v << " out of range (" << vertex->count << " vertices)";
                  fail(file, where(), what.str());
                }
                corners.push_back(static_cast<std::uint32_t>(*v));
              }
            }
          }
          if (wanted_corners) {
            if (corners.size() < 3) fail(file, where(), "a face needs at least three vertices");
            addFace(mesh, corners);
          }
        }
      }
    }
    return mesh;
  }

  const bool big = *format == PlyFormat::BinaryBig;
  std::size_t pos = data_start;
  for (const PlyElement& e : elements) {
    if (e.properties.empty()) continue;  // nothing to read, however many it declares
    const bool is_vertex = &e == vertex, is_face = &e == face;
    for (std::uint64_t item = 0; item < e.count; ++item) {
      auto where = [&] {
        std::ostringstream s;
        s << plyElementName(e, item) << " (byte " << pos << ")";
        return s.str();
      };
      for (std::size_t pi = 0; pi < e.properties.size(); ++pi) {
        const PlyProperty& p = e.properties[pi];
        std::uint64_t n = 1;
        if (p.list) {
          if (bytes.size() - pos < p.count_type.bytes)
            fail(file, where(), "the file ends inside the element (truncated)");
          const double c = loadScalar(bytes.data() + pos, p.count_type, big);
          pos += p.count_type.bytes;
          if (!(c >= 0.0)) fail(file, where(), "a negative list length");
          n = static_cast<std::uint64_t>(c);
        }
        if (n > (bytes.size() - pos) / p.type.bytes)
          fail(file, where(), "the file ends inside the element (truncated)");
        const bool wanted_corners = is_face && static_cast<int>(pi) == corners_property;
        if (is_vertex) {
          for (int k = 0; k < 3; ++k)
            if (xyz[k] == static_cast<int>(pi))
              mesh.positions[item][k] = static_cast<float>(loadScalar(bytes.data() + pos, p.type, big));
        } else if (wanted_corners) {
          corners.clear();
          for (std::uint64_t j = 0; j < n; ++j) {
            const double v = loadScalar(bytes.data() + pos + j * p.type.bytes, p.type, big);
            const auto index = vertexIndex(v, vertex->count);
            if (!index) {
              std::ostringstream what;
              what << "vertex index " << v << " out of range (" << vertex->count << " vertices)";
              fail(file, where(), what.str());
            }
            corners.push_back(*index);
          }
          if (corners.size() < 3) fail(file, where(), "a face needs at least three vertices");
          addFace(mesh, corners);
        }
        pos += n * p.type.bytes;
      }
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// OFF: "[ST][C][N]OFF", then "vertices faces [edges]", one vertex per line (the first three
// numbers; colours, normals and texture coordinates after them are read past), one face per line
// ("k i0 .. ik-1", colour values after them read past). '#' starts a comment. "OFF BINARY":
// 32-bit counts, vertices and indices, big-endian with a colour count per face as the format
// defines it, or little-endian without one as OpenMesh writes it: the layout that reads the
// file exactly is taken.

struct OffHeader {
  bool binary = false;
  int vertex_extra = 0;   // values after x y z per vertex in a binary file
  std::size_t after = 0;  // offset of the first byte after the header keyword's line
  std::string counts;     // what followed the keyword on its line (counts may start there)
};

OffHeader parseOffKeyword(std::string_view bytes, const std::string& file) {
  Lines lines(bytes);
  OffHeader h;
  while (auto raw = lines.next()) {
    std::string_view line = *raw;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    Tokens tokens(line);
    const auto keyword = tokens.next();
    if (!keyword) continue;
    std::string_view k = *keyword;
    if (k.substr(0, 2) == "ST") {
      h.vertex_extra += 2;
      k.remove_prefix(2);
    }
    if (!k.empty() && k[0] == 'C') {
      h.vertex_extra += 4;
      k.remove_prefix(1);
    }
    if (!k.empty() && k[0] == 'N') {
      h.vertex_extra += 3;
      k.remove_prefix(1);
    }
    if (!k.empty() && (k[0] == '4' || k[0] == 'n'))
      fail(file, lineName(lines.number()), "4-dimensional and n-dimensional OFF files are not supported");
    if (k != "OFF")
      fail(file, lineName(lines.number()), "not an OFF file (expected 'OFF', got '" + std::string(*keyword) + "')");
    std::string_view rest = tokens.rest();
    Tokens after(rest);
    if (const auto b = after.next(); b && *b == "BINARY") {
      h.binary = true;
      rest = after.rest();
    }
    h.counts = std::string(rest);
    h.after = lines.offset();
    return h;
  }
  fail(file, "", "not an OFF file (empty)");
}

// Binary OFF in one layout; nullopt when the file does not read exactly in it.
std::optional<ParsedMesh> readOffBinary(std::string_view bytes, const std::string& file, std::size_t pos,
                                        int vertex_extra, bool big, bool colour_counts, std::string& why) {
  auto need = [&](std::uint64_t n) { return n <= bytes.size() - pos; };
  auto int32 = [&]() {
    const auto v = static_cast<std::int32_t>(static_cast<std::uint32_t>(loadBits(bytes.data() + pos, 4, big)));
    pos += 4;
    return v;
  };
  if (!need(12)) {
    why = "the file ends inside the counts";
    return std::nullopt;
  }
  const std::int32_t nv = int32(), nf = int32();
  (void)int32();
  const std::uint64_t vertex_bytes = 4ull * static_cast<std::uint64_t>(3 + vertex_extra);
  if (nv < 0 || nf < 0 || !need(static_cast<std::uint64_t>(nv) * vertex_bytes) ||
      static_cast<std::uint64_t>(nf) > (bytes.size() - pos - static_cast<std::uint64_t>(nv) * vertex_bytes) / 16) {
    std::ostringstream s;
    s << "counts " << nv << " vertices, " << nf << " faces do not fit in the file";
    why = s.str();
    return std::nullopt;
  }
  requireArrays(file, bytes.size(), static_cast<std::uint64_t>(nv), static_cast<std::uint64_t>(nf));
  ParsedMesh mesh;
  mesh.positions.resize(static_cast<std::size_t>(nv));
  for (std::int32_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k)
      mesh.positions[i][k] =
          std::bit_cast<float>(static_cast<std::uint32_t>(loadBits(bytes.data() + pos + 4 * k, 4, big)));
    pos += vertex_bytes;
  }
  mesh.triangles.reserve(static_cast<std::size_t>(nf));
  std::vector<std::uint32_t> corners;
  for (std::int32_t f = 0; f < nf; ++f) {
    std::ostringstream where;
    if (!need(4)) {
      where << "face " << f << " is missing (truncated)";
      why = where.str();
      return std::nullopt;
    }
    const std::int32_t k = int32();
    if (k < 3 || !need(4ull * static_cast<std::uint64_t>(k) + (colour_counts ? 4 : 0))) {
      where << "face " << f << " (byte " << pos - 4 << ") has " << k << " corners that do not fit";
      why = where.str();
      return std::nullopt;
    }
    corners.clear();
    for (std::int32_t j = 0; j < k; ++j) {
      const std::int32_t index = int32();
      if (index < 0 || index >= nv) {
        where << "face " << f << ": vertex index " << index << " out of range (" << nv << " vertices)";
        why = where.str();
        return std::nullopt;
      }
      corners.push_back(static_cast<std::uint32_t>(index));
    }
    if (colour_counts) {
      const std::int32_t colours = int32();
      if (colours < 0 || colours > 4 || !need(4ull * static_cast<std::uint64_t>(colours))) {
        where << "face " << f << ": " << colours << " colour values";
        why = where.str();
        return std::nullopt;
      }
      pos += 4ull * static_cast<std::uint64_t>(colours);
    }
    addFace(mesh, corners);
  }
  // Trailing whitespace is tolerated; anything else means another layout.
  for (; pos < bytes.size(); ++pos)
    if (!isSpace(bytes[pos]) && bytes[pos] != '\n') {
      why = "data left after the last face";
      return std::nullopt;
    }
  return mesh;
}

ParsedMesh readOff(std::string_view bytes, const std::string& file) {
  const OffHeader header = parseOffKeyword(bytes, file);
  if (header.binary) {
    std::string why_first, why;
    constexpr std::array<std::pair<bool, bool>, 4> kLayouts = {
        {{true, true}, {false, false}, {false, true}, {true, false}}};
    for (const auto& [big, colours] : kLayouts) {
      if (auto mesh = readOffBinary(bytes, file, header.after, header.vertex_extra, big, colours, why))
        return std::move(*mesh);
      if (why_first.empty()) why_first = why;
    }
    fail(file, "", "binary OFF that reads in no layout (" + why_first + ")");
  }
  Lines lines(bytes.substr(header.after));
  const std::size_t base_line =
      static_cast<std::size_t>(std::count(bytes.begin(), bytes.begin() + static_cast<long>(header.after), '\n'));
  auto where = [&] { return lineName(base_line + lines.number()); };
  // The next line with content (comments removed); nullopt at the end.
  auto nextLine = [&]() -> std::optional<std::string_view> {
    while (auto raw = lines.next()) {
      std::string_view line = *raw;
      if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
      Tokens t(line);
      if (t.next()) return line;
    }
    return std::nullopt;
  };
  std::string_view count_line = header.counts;
  if (!Tokens(count_line).next()) {
    const auto line = nextLine();
    if (!line) fail(file, "", "no vertex and face counts");
    count_line = *line;
  }
  Tokens count_tokens(count_line);
  const auto nv_text = count_tokens.next(), nf_text = count_tokens.next();
  const auto nv = nv_text ? parseInteger(*nv_text) : std::nullopt;
  const auto nf = nf_text ? parseInteger(*nf_text) : std::nullopt;
  if (!nv || !nf || *nv < 0 || *nf < 0) fail(file, where(), "expected the counts 'vertices faces [edges]'");
  // A vertex line and a face line each need at least two bytes.
  if (static_cast<std::uint64_t>(*nv) + static_cast<std::uint64_t>(*nf) > lines.remaining() / 2 + 1) {
    std::ostringstream what;
    what << "declares " << *nv << " vertices and " << *nf << " faces but only " << lines.remaining()
         << " bytes follow (truncated or malformed)";
    fail(file, where(), what.str());
  }
  if (*nv > std::numeric_limits<std::uint32_t>::max()) fail(file, where(), "more than 2^32 - 1 vertices");
  requireArrays(file, bytes.size(), static_cast<std::uint64_t>(*nv), static_cast<std::uint64_t>(*nf));
  ParsedMesh mesh;
  mesh.positions.resize(static_cast<std::size_t>(*nv));
  for (long long i = 0; i < *nv; ++i) {
    const auto line = nextLine();
    if (!line) {
      std::ostringstream what;
      what << "declares " << *nv << " vertices but contains only " << i << " (truncated)";
      fail(file, "", what.str());
    }
    Tokens t(*line);
    for (int k = 0; k < 3; ++k) {
      const auto token = t.next();
      const auto v = token ? parseFloat(*token) : std::nullopt;
      if (!v) fail(file, where(), "a vertex needs three numbers");
      mesh.positions[static_cast<std::size_t>(i)][k] = *v;
    }
  }
  mesh.triangles.reserve(static_cast<std::size_t>(*nf));
  std::vector<std::uint32_t> corners;
  for (long long f = 0; f < *nf; ++f) {
    const auto line = nextLine();
    if (!line) {
      std::ostringstream what;
      what << "declares " << *nf << " faces but contains only " << f << " (truncated or malformed)";
      fail(file, "", what.str());
    }
    Tokens t(*line);
    const auto k_text = t.next();
    const auto k = k_text ? parseInteger(*k_text) : std::nullopt;
    if (!k || *k < 3) fail(file, where(), "a face needs a corner count of at least 3");
    corners.clear();
    for (long long j = 0; j < *k; ++j) {
      const auto token = t.next();
      const auto index = token ? parseInteger(*token) : std::nullopt;
      if (!index) fail(file, where(), "the face has fewer vertex indices than its count");
      if (*index < 0 || *index >= *nv) {
        std::ostringstream what;
        what << "vertex index " << *index << " out of range (" << *nv << " vertices)";
        fail(file, where(), what.str());
      }
      corners.push_back(static_cast<std::uint32_t>(*index));
    }
    addFace(mesh, corners);
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// STL: binary (80-byte header, a facet count, 50 bytes per facet) or ASCII ("solid ...", facets
// of three vertices, "endsolid"). The file's corners with equal coordinates become one vertex,
// numbered in the order they first appear, so that edges are shared as in the indexed formats.

struct VertexKey {
  std::array<std::uint32_t, 3> bits;
  bool operator==(const VertexKey&) const = default;
};

struct VertexKeyHash {
  std::size_t operator()(const VertexKey& k) const {
    std::uint64_t h = 0x9e3779b97f4a7c15ull;
    for (const std::uint32_t b : k.bits) h = (h ^ b) * 0x100000001b3ull;
    return static_cast<std::size_t>(h ^ (h >> 29));
  }
};

class VertexMerger {
 public:
  /// Bytes of the index per vertex: a node (next pointer, key, value, cached hash, the allocator's
  /// header) and its bucket.
  static constexpr std::uint64_t kBytesPerVertex =
      sizeof(void*) + sizeof(VertexKey) + sizeof(std::uint32_t) + sizeof(std::size_t) + 16 + sizeof(void*);
  explicit VertexMerger(ParsedMesh& mesh, std::size_t corners) : mesh_(mesh) { index_.reserve(corners); }
  std::uint32_t add(const glm::vec3& p) {
    VertexKey key;
    for (int k = 0; k < 3; ++k) key.bits[k] = std::bit_cast<std::uint32_t>(p[k] == 0.0f ? 0.0f : p[k]);  // -0 == +0
    const auto [it, inserted] = index_.try_emplace(key, static_cast<std::uint32_t>(mesh_.positions.size()));
    if (inserted) mesh_.positions.push_back(p);
    return it->second;
  }

 private:
  ParsedMesh& mesh_;
  std::unordered_map<VertexKey, std::uint32_t, VertexKeyHash> index_;
};

ParsedMesh readStlBinary(std::string_view bytes, const std::string& file) {
  if (bytes.size() < 84) fail(file, "", "shorter than a binary STL header (84 bytes)");
  const auto n = static_cast<std::uint32_t>(loadBits(bytes.data() + 80, 4, false));
  const std::uint64_t room = (bytes.size() - 84) / 50;
  if (n > room) {
    std::ostringstream what;
    what << "declares " << n << " facets but has room for only " << room << " (truncated)";
    fail(file, "", what.str());
  }
  // At most three vertices per facet.
  requireArrays(file, bytes.size(), 3ull * n, n, arrayBytes(3ull * n, VertexMerger::kBytesPerVertex));
  ParsedMesh mesh;
  mesh.triangles.reserve(n);
  VertexMerger merger(mesh, 3ull * n);
  std::vector<std::uint32_t> corners(3);
  for (std::uint32_t f = 0; f < n; ++f) {
    const char* facet = bytes.data() + 84 + 50ull * f + 12;  // after the normal
    for (int c = 0; c < 3; ++c) {
      glm::vec3 p;
      for (int k = 0; k < 3; ++k)
        p[k] = std::bit_cast<float>(static_cast<std::uint32_t>(loadBits(facet + 12 * c + 4 * k, 4, false)));
      corners[c] = merger.add(p);
    }
    addFace(mesh, corners);
  }
  return mesh;
}

ParsedMesh readStlAscii(std::string_view bytes, const std::string& file) {
  // Facets need far more than 64 bytes each: a bound for the vertices, the facets and the index.
  requireArrays(file, bytes.size(), 3 * (bytes.size() / 64), bytes.size() / 64,
                arrayBytes(3 * (bytes.size() / 64), VertexMerger::kBytesPerVertex));
  ParsedMesh mesh;
  // Facets need far more than 64 bytes each: a bound for the reservation.
  VertexMerger merger(mesh, bytes.size() / 64);
  Lines lines(bytes);
  Tokens tokens("");
  auto next = [&]() -> std::optional<std::string_view> {
    for (;;) {
      if (auto t = tokens.next()) return t;
      const auto line = lines.next();
      if (!line) return std::nullopt;
      tokens = Tokens(*line);
    }
  };
  auto expect = [&](std::string_view word) {
    const auto t = next();
    if (!t || !equalsIgnoringCase(*t, word))
      fail(file, lineName(lines.number()),
           "expected '" + std::string(word) + "', got '" + std::string(t.value_or("end of file")) + "'");
  };
  auto number = [&]() {
    const auto t = next();
    const auto v = t ? parseFloat(*t) : std::nullopt;
    if (!v)
      fail(file, lineName(lines.number()), "expected a number, got '" + std::string(t.value_or("end of file")) + "'");
    return *v;
  };
  std::vector<std::uint32_t> corners(3);
  bool any_solid = false;
  while (auto t = next()) {
    if (!equalsIgnoringCase(*t, "solid"))
      fail(file, lineName(lines.number()), "expected 'solid', got '" + std::string(*t) + "'");
    any_solid = true;
    tokens = Tokens("");  // the solid's name: the rest of the line
    for (;;) {
      const auto word = next();
      if (!word) fail(file, "", "the file ends inside a solid (no 'endsolid'; truncated)");
      if (equalsIgnoringCase(*word, "endsolid")) {
        tokens = Tokens("");
        break;
      }
      if (!equalsIgnoringCase(*word, "facet"))
        fail(file, lineName(lines.number()), "expected 'facet' or 'endsolid', got '" + std::string(*word) + "'");
      expect("normal");
      for (int k = 0; k < 3; ++k) (void)number();
      expect("outer");
      expect("loop");
      for (int c = 0; c < 3; ++c) {
        expect("vertex");
        glm::vec3 p;
        for (int k = 0; k < 3; ++k) p[k] = number();
        corners[c] = merger.add(p);
      }
      expect("endloop");
      expect("endfacet");
      addFace(mesh, corners);
    }
  }
  if (!any_solid) fail(file, "", "empty");
  return mesh;
}

// A file named .stl is binary when its size is exactly what its facet count says (some binary
// files start with "solid" too), ASCII when it starts with "solid", binary otherwise.
ParsedMesh readStl(std::string_view bytes, const std::string& file) {
  if (bytes.size() >= 84) {
    const std::uint64_t n = loadBits(bytes.data() + 80, 4, false);
    if (bytes.size() == 84 + 50 * n) return readStlBinary(bytes, file);
  }
  std::size_t i = 0;
  while (i < bytes.size() && (isSpace(bytes[i]) || bytes[i] == '\n')) ++i;
  if (equalsIgnoringCase(bytes.substr(i, 5), "solid")) return readStlAscii(bytes, file);
  return readStlBinary(bytes, file);
}

}  // namespace

void addFace(ParsedMesh& mesh, const std::vector<std::uint32_t>& corners) {
  const std::size_t n = corners.size();
  if (n > 3) ++mesh.polygons_triangulated;
  bool repeated = false;
  if (n <= 8) {
    for (std::size_t i = 0; i < n && !repeated; ++i)
      for (std::size_t j = i + 1; j < n && !repeated; ++j) repeated = corners[i] == corners[j];
  } else {
    std::vector<std::uint32_t> sorted(corners);
    std::sort(sorted.begin(), sorted.end());
    repeated = std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end();
  }
  if (repeated) ++mesh.repeated_corner_faces;
  for (std::size_t k = 1; k + 1 < n; ++k) mesh.triangles.push_back({corners[0], corners[k], corners[k + 1]});
}

ParsedMesh read(Format format, std::string_view bytes, const std::string& file) {
  switch (format) {
    case Format::Obj: return readObj(bytes, file);
    case Format::Ply: return readPly(bytes, file);
    case Format::Off: return readOff(bytes, file);
    case Format::Stl: return readStl(bytes, file);
    case Format::StlAscii: return readStlAscii(bytes, file);
    case Format::StlBinary: return readStlBinary(bytes, file);
  }
  throw InternalError("mesh_files::read: unknown format");
}

}  // namespace duplex::mesh_files
