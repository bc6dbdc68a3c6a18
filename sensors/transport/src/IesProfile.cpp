/// \file IesProfile.cpp
/// LM-63 reader, symmetry unfolding, exact cell integrals and cell-wise sampling of the intensity
/// table. Format facts from ANSI/IES LM-63-02 and LM-63-19: a header of keyword lines up to
/// "TILT=", optional tilt data, then whitespace- or comma-separated numbers in a fixed order.

#include "duplex/sensors/IesProfile.h"
#include "duplex/sensors/SensorResults.h"

#include "duplex/accel/Error.h"
#include "duplex/accel/AtomicFile.h"
#include "duplex/accel/InputFile.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <utility>

namespace duplex {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

/// Numbers after the header, with the line each starts on (for messages).
class NumberReader {
 public:
  NumberReader(std::string_view text, std::size_t first_line, const std::string& source)
      : text_(text), line_(first_line), source_(source) {}

  /// The next number; `what` names it in the error.
  double next(const char* what) {
    skipSeparators();
    if (pos_ >= text_.size()) fail(std::string("the file ends before ") + what);
    const std::size_t start = pos_;
    while (pos_ < text_.size() && !isSeparator(text_[pos_])) ++pos_;
    const std::string_view token = text_.substr(start, pos_ - start);
    double value = 0.0;
    // from_chars rejects a leading '+', which some writers emit.
    const std::string_view digits = token.front() == '+' ? token.substr(1) : token;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    if (ec != std::errc() || end != digits.data() + digits.size())
      fail(std::string("'") + std::string(token) + "' is not a number (" + what + ")");
    if (!std::isfinite(value)) fail(std::string(what) + " is not finite");
    return value;
  }
  /// A count: a whole number >= minimum.
  int count(const char* what, int minimum) {
    const double v = next(what);
    if (v != std::floor(v) || v < minimum || v > 1e6)
      fail(std::string(what) + " must be a whole number >= " + std::to_string(minimum) + ", not " + format(v));
    return static_cast<int>(v);
  }
  /// Whether anything but separators is left.
  bool atEnd() {
    skipSeparators();
    return pos_ >= text_.size();
  }
  [[noreturn]] void fail(const std::string& problem) const {
    throw FileError(source_ + ": line " + std::to_string(line_) + ": " + problem);
  }
  static std::string format(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
  }

 private:
  static bool isSeparator(char c) { return c == ',' || std::isspace(static_cast<unsigned char>(c)) != 0; }
  void skipSeparators() {
    while (pos_ < text_.size() && isSeparator(text_[pos_])) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
  }
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t line_;
  const std::string& source_;
};

std::string_view trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  return s;
}

/// Checks angles: strictly increasing, within [lo, hi]. Returns an empty string or the problem.
std::string checkAngles(const std::vector<double>& a, double lo, double hi, const char* what) {
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i] < lo || a[i] > hi)
      return std::string(what) + " angle " + NumberReader::format(a[i]) + " is outside [" + NumberReader::format(lo) +
             ", " + NumberReader::format(hi) + "] degrees";
    if (i > 0 && !(a[i] > a[i - 1]))
      return std::string(what) + " angles must increase (" + NumberReader::format(a[i - 1]) + " then " +
             NumberReader::format(a[i]) + ")";
  }
  return {};
}

/// The full-circle C-planes of a file's horizontal angles: (angle in [0, 360], source plane).
/// Throws via `fail` for a range without a known symmetry.
template <class Fail>
std::vector<std::pair<double, std::size_t>> unfold(const std::vector<double>& h, const Fail& fail) {
  std::vector<std::pair<double, std::size_t>> planes;
  const double first = h.front(), last = h.back();
  const std::size_t n = h.size();
  if (n == 1) {
    // Rotationally symmetric: one plane everywhere.
    planes = {{0.0, 0}, {360.0, 0}};
  } else if (first == 0.0 && last == 90.0) {
    // Quadrant symmetric: mirrored about the 0-180 and 90-270 planes.
    for (std::size_t i = 0; i < n; ++i) {
      planes.emplace_back(h[i], i);
      planes.emplace_back(180.0 - h[i], i);
      planes.emplace_back(180.0 + h[i], i);
      planes.emplace_back(360.0 - h[i], i);
    }
  } else if (first == 0.0 && last == 180.0) {
    // Bilateral about the 0-180 plane.
    for (std::size_t i = 0; i < n; ++i) {
      planes.emplace_back(h[i], i);
      planes.emplace_back(360.0 - h[i], i);
    }
  } else if (first == 90.0 && last == 270.0) {
    // Bilateral about the 90-270 plane (older type C files): phi and 180 - phi agree.
    for (std::size_t i = 0; i < n; ++i) {
      planes.emplace_back(h[i], i);
      if (h[i] <= 180.0) planes.emplace_back(180.0 - h[i], i);
      if (h[i] >= 180.0) planes.emplace_back(540.0 - h[i], i);
    }
  } else if (first == 0.0 && last == 360.0) {
    for (std::size_t i = 0; i < n; ++i) planes.emplace_back(h[i], i);
  } else {
    fail("horizontal angles " + NumberReader::format(first) + " ... " + NumberReader::format(last) +
         " have no known symmetry (expected 0; 0-90; 0-180; 90-270; 0-360 degrees)");
  }
  std::sort(planes.begin(), planes.end());
  // Mirrored planes on a symmetry axis coincide: keep one.
  planes.erase(
      std::unique(planes.begin(), planes.end(), [](const auto& a, const auto& b) { return a.first == b.first; }),
      planes.end());
  return planes;
}

}  // namespace

IesProfile IesProfile::load(const std::filesystem::path& file) {
  if (const std::string problem = notRegularFile(file); !problem.empty())
    throw FileError(file.string() + ": cannot open the IES file: " + problem);
  std::ifstream in(file, std::ios::binary);
  if (!in) throw FileError(file.string() + ": cannot open the IES file");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw FileError(file.string() + ": read error");
  return parse(text.str(), file.string());
}

IesProfile IesProfile::parse(std::string_view text, const std::string& source) {
  IesProfile p;
  p.source_ = source;
  // Header: keyword lines ("[KEY] value"; "[MORE]" continues the last one) and, in LM-63-1986
  // files, free text, up to the TILT= line.
  std::size_t pos = 0, line = 0;
  std::string last_key;
  bool tilt_found = false;
  std::string tilt_value;
  while (pos < text.size()) {
    const std::size_t eol = std::min(text.find('\n', pos), text.size());
    const std::string_view l = trim(text.substr(pos, eol - pos));
    pos = eol + 1;
    ++line;
    if (l.rfind("TILT", 0) == 0) {
      const std::string_view rest = trim(l.substr(4));
      if (rest.empty() || rest.front() != '=')
        throw FileError(source + ": line " + std::to_string(line) + ": malformed TILT line '" + std::string(l) + "'");
      tilt_value = std::string(trim(rest.substr(1)));
      tilt_found = true;
      break;
    }
    if (!l.empty() && l.front() == '[') {
      const std::size_t close = l.find(']');
      if (close == std::string_view::npos) continue;  // free text that happens to start with '['
      const std::string key(l.substr(1, close - 1));
      const std::string value(trim(l.substr(close + 1)));
      if (key == "MORE" && !last_key.empty()) {
        p.keywords_[last_key] += "\n" + value;
      } else {
        auto& slot = p.keywords_[key];
        slot = slot.empty() ? value : slot + "\n" + value;
        last_key = key;
      }
    }
  }
  if (!tilt_found) throw FileError(source + ": no TILT= line: not an IES LM-63 file");
  if (pos > text.size()) pos = text.size();
  NumberReader r(text.substr(pos), line + 1, source);

  // Tilt data: parsed so that the table after it is found and malformed data is reported.
  if (tilt_value == "NONE") {
    p.tilt_ = Tilt::None;
  } else if (tilt_value == "INCLUDE") {
    p.tilt_ = Tilt::Include;
    const double geometry = r.next("the lamp-to-luminaire geometry");
    if (geometry != 1 && geometry != 2 && geometry != 3) r.fail("lamp-to-luminaire geometry must be 1, 2 or 3");
    const int pairs = r.count("the number of tilt angles", 1);
    for (int i = 0; i < 2 * pairs; ++i) (void)r.next(i < pairs ? "a tilt angle" : "a tilt factor");
  } else if (!tilt_value.empty()) {
    p.tilt_ = Tilt::File;
  } else {
    r.fail("TILT= has no value");
  }

  p.lamps_ = r.count("the number of lamps", 1);
  p.lumens_per_lamp_ = r.next("lumens per lamp");
  const double multiplier = r.next("the candela multiplier");
  if (!(multiplier > 0.0)) r.fail("the candela multiplier must be > 0, not " + NumberReader::format(multiplier));
  const int nv = r.count("the number of vertical angles", 2);
  const int nh = r.count("the number of horizontal angles", 1);
  const double type = r.next("the photometric type");
  if (type == 2 || type == 3)
    r.fail(std::string("photometric type ") + (type == 2 ? "B" : "A") + " is not supported (type C only)");
  if (type != 1) r.fail("photometric type must be 1 (C), 2 (B) or 3 (A), not " + NumberReader::format(type));
  const double units = r.next("the units type");
  if (units != 1 && units != 2) r.fail("units type must be 1 (feet) or 2 (meters), not " + NumberReader::format(units));
  for (const char* what : {"the luminous opening width", "the luminous opening length", "the luminous opening height"})
    (void)r.next(what);
  const double ballast = r.next("the ballast factor");
  if (!(ballast > 0.0)) r.fail("the ballast factor must be > 0, not " + NumberReader::format(ballast));
  (void)r.next("the ballast-lamp factor / file generation type");
  (void)r.next("the input watts");

  std::vector<double> vertical(static_cast<std::size_t>(nv)), horizontal(static_cast<std::size_t>(nh));
  for (double& a : vertical) a = r.next("a vertical angle");
  for (double& a : horizontal) a = r.next("a horizontal angle");
  std::vector<double> candela(static_cast<std::size_t>(nv) * static_cast<std::size_t>(nh));
  for (double& c : candela) {
    c = r.next("a candela value");
    if (c < 0.0) r.fail("candela value " + NumberReader::format(c) + " is negative");
    c *= multiplier * ballast;
  }
  if (!r.atEnd())
    r.fail("unexpected data after the candela table (counts say " + std::to_string(nv) + " x " + std::to_string(nh) +
           " values)");
  if (const std::string problem = checkAngles(vertical, 0.0, 180.0, "vertical"); !problem.empty())
    throw FileError(source + ": " + problem);
  p.vertical_deg_ = std::move(vertical);
  p.finish(horizontal, candela, source);
  return p;
}

IesProfile IesProfile::fromTable(std::vector<double> vertical_deg, std::vector<double> horizontal_deg,
                                 std::vector<double> candela, std::string source) {
  try {
    if (vertical_deg.size() < 2) throw FileError(source + ": at least 2 vertical angles are needed");
    if (horizontal_deg.empty()) throw FileError(source + ": at least 1 horizontal angle is needed");
    if (candela.size() != vertical_deg.size() * horizontal_deg.size())
      throw FileError(source + ": " + std::to_string(candela.size()) + " candela values for " +
                      std::to_string(vertical_deg.size()) + " x " + std::to_string(horizontal_deg.size()) + " angles");
    for (const double c : candela)
      if (!std::isfinite(c) || c < 0.0)
        throw FileError(source + ": candela value " + NumberReader::format(c) + " is negative or not finite");
    if (const std::string problem = checkAngles(vertical_deg, 0.0, 180.0, "vertical"); !problem.empty())
      throw FileError(source + ": " + problem);
    IesProfile p;
    p.source_ = std::move(source);
    p.vertical_deg_ = std::move(vertical_deg);
    p.finish(horizontal_deg, candela, p.source_);
    return p;
  } catch (const FileError& e) {
    throw InvalidArgument(std::string("IesProfile::fromTable: ") + e.what());
  }
}

void IesProfile::finish(const std::vector<double>& horizontal_in, const std::vector<double>& candela_in,
                        const std::string& where) {
  if (const std::string problem = checkAngles(horizontal_in, 0.0, 360.0, "horizontal"); !problem.empty())
    throw FileError(where + ": " + problem);
  const auto planes =
      unfold(horizontal_in, [&](const std::string& problem) { throw FileError(where + ": " + problem); });
  const std::size_t nv = vertical_deg_.size();
  horizontal_deg_.clear();
  candela_.clear();
  for (const auto& [angle, plane] : planes) {
    horizontal_deg_.push_back(angle);
    candela_.insert(candela_.end(), candela_in.begin() + static_cast<std::ptrdiff_t>(plane * nv),
                    candela_in.begin() + static_cast<std::ptrdiff_t>((plane + 1) * nv));
  }
  vertical_rad_.resize(nv);
  for (std::size_t v = 0; v < nv; ++v) vertical_rad_[v] = vertical_deg_[v] * kDegree;
  horizontal_rad_.resize(horizontal_deg_.size());
  for (std::size_t h = 0; h < horizontal_deg_.size(); ++h) horizontal_rad_[h] = horizontal_deg_[h] * kDegree;

  // Exact integral of the bilinear intensity over each cell [g0, g1] x [p0, p1]:
  //   dphi * ((A - B) * (I00 + I01) / 2 + B * (I10 + I11) / 2),
  // with A = integral of sin(g) dg and B = integral of s * sin(g) dg, s = (g - g0) / (g1 - g0).
  const std::size_t nh = horizontal_deg_.size();
  cell_cdf_.assign((nh - 1) * (nv - 1), 0.0);
  double sum = 0.0;
  for (std::size_t h = 0; h + 1 < nh; ++h) {
    const double dphi = horizontal_rad_[h + 1] - horizontal_rad_[h];
    for (std::size_t v = 0; v + 1 < nv; ++v) {
      const double g0 = vertical_rad_[v], g1 = vertical_rad_[v + 1], dg = g1 - g0;
      const double a = std::cos(g0) - std::cos(g1);
      const double b = (-dg * std::cos(g1) + std::sin(g1) - std::sin(g0)) / dg;
      const double lo = 0.5 * (candela_[h * nv + v] + candela_[(h + 1) * nv + v]);
      const double hi = 0.5 * (candela_[h * nv + v + 1] + candela_[(h + 1) * nv + v + 1]);
      sum += std::max(0.0, dphi * ((a - b) * lo + b * hi));
      cell_cdf_[h * (nv - 1) + v] = sum;
    }
  }
  total_ = sum;
  if (!(total_ > 0.0)) throw FileError(where + ": every candela value is 0: the luminaire emits nothing");
}

std::size_t IesProfile::cellOf(double gamma, double phi, double& s, double& t) const {
  // phi into [0, 2 pi); then the cells holding gamma and phi, and the fractions inside them.
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  phi = std::fmod(phi, kTwoPi);
  if (phi < 0.0) phi += kTwoPi;
  const std::size_t nv = vertical_rad_.size(), nh = horizontal_rad_.size();
  auto v = static_cast<std::size_t>(std::upper_bound(vertical_rad_.begin(), vertical_rad_.end(), gamma) -
                                    vertical_rad_.begin());
  v = std::clamp<std::size_t>(v, 1, nv - 1) - 1;
  auto h = static_cast<std::size_t>(std::upper_bound(horizontal_rad_.begin(), horizontal_rad_.end(), phi) -
                                    horizontal_rad_.begin());
  h = std::clamp<std::size_t>(h, 1, nh - 1) - 1;
  s = std::clamp((gamma - vertical_rad_[v]) / (vertical_rad_[v + 1] - vertical_rad_[v]), 0.0, 1.0);
  t = std::clamp((phi - horizontal_rad_[h]) / (horizontal_rad_[h + 1] - horizontal_rad_[h]), 0.0, 1.0);
  return h * (nv - 1) + v;
}

double IesProfile::intensityAt(double gamma, double phi) const {
  if (!(gamma >= vertical_rad_.front() && gamma <= vertical_rad_.back()) || !std::isfinite(phi)) return 0.0;
  double s = 0.0, t = 0.0;
  const std::size_t cell = cellOf(gamma, phi, s, t);
  const std::size_t nv = vertical_rad_.size();
  const std::size_t h = cell / (nv - 1), v = cell % (nv - 1);
  const double i00 = candela_[h * nv + v], i01 = candela_[(h + 1) * nv + v];
  const double i10 = candela_[h * nv + v + 1], i11 = candela_[(h + 1) * nv + v + 1];
  return (1.0 - s) * ((1.0 - t) * i00 + t * i01) + s * ((1.0 - t) * i10 + t * i11);
}

namespace {
/// (gamma, phi) of a luminaire-frame direction; false for a zero or non-finite vector.
bool anglesOf(const glm::dvec3& d, double& gamma, double& phi) {
  const double len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  if (!(len > 0.0) || !std::isfinite(len)) return false;
  gamma = std::acos(std::clamp(-d.z / len, -1.0, 1.0));
  phi = std::atan2(d.y, d.x);
  return true;
}
}  // namespace

double IesProfile::intensity(const glm::dvec3& direction_lf) const {
  double gamma = 0.0, phi = 0.0;
  return anglesOf(direction_lf, gamma, phi) ? intensityAt(gamma, phi) : 0.0;
}

IesProfile::Sample IesProfile::sample(double u1, double u2) const {
  // Cell by its share of the integral (u1 rescaled and reused inside the cell would correlate the
  // two coordinates; the cell's position in the CDF gives an independent remainder instead).
  const double target = std::clamp(u1, 0.0, 1.0) * total_;
  auto it = std::upper_bound(cell_cdf_.begin(), cell_cdf_.end(), target);
  if (it == cell_cdf_.end()) --it;
  while (it != cell_cdf_.begin() && *it == *(it - 1)) --it;  // never a cell of zero weight
  const auto cell = static_cast<std::size_t>(it - cell_cdf_.begin());
  const double below = cell == 0 ? 0.0 : cell_cdf_[cell - 1];
  const double cell_weight = cell_cdf_[cell] - below;
  const double u_remap = std::clamp((target - below) / cell_weight, 0.0, 1.0);
  const std::size_t nv = vertical_rad_.size();
  const std::size_t h = cell / (nv - 1), v = cell % (nv - 1);
  // Uniform in the cell's solid angle: cos(gamma) uniform between the cell's bounds, phi uniform.
  const double c0 = std::cos(vertical_rad_[v]), c1 = std::cos(vertical_rad_[v + 1]);
  const double cos_g = c0 + u_remap * (c1 - c0);
  const double phi = horizontal_rad_[h] + std::clamp(u2, 0.0, 1.0) * (horizontal_rad_[h + 1] - horizontal_rad_[h]);
  const double sin_g = std::sqrt(std::max(0.0, 1.0 - cos_g * cos_g));
  Sample out;
  out.direction_lf = {sin_g * std::cos(phi), sin_g * std::sin(phi), -cos_g};
  const double solid_angle = (c0 - c1) * (horizontal_rad_[h + 1] - horizontal_rad_[h]);
  out.weight = intensityAt(std::acos(std::clamp(cos_g, -1.0, 1.0)), phi) * solid_angle / cell_weight;
  return out;
}

double IesProfile::pdf(const glm::dvec3& direction_lf) const {
  double gamma = 0.0, phi = 0.0;
  if (!anglesOf(direction_lf, gamma, phi)) return 0.0;
  if (!(gamma >= vertical_rad_.front() && gamma <= vertical_rad_.back())) return 0.0;
  double s = 0.0, t = 0.0;
  const std::size_t cell = cellOf(gamma, phi, s, t);
  const std::size_t nv = vertical_rad_.size();
  const std::size_t h = cell / (nv - 1), v = cell % (nv - 1);
  const double cell_weight = cell_cdf_[cell] - (cell == 0 ? 0.0 : cell_cdf_[cell - 1]);
  const double solid_angle =
      (std::cos(vertical_rad_[v]) - std::cos(vertical_rad_[v + 1])) * (horizontal_rad_[h + 1] - horizontal_rad_[h]);
  return cell_weight / total_ / solid_angle;
}

}  // namespace duplex

namespace duplex {

namespace {

// The shortest decimal form that reads back as the same double.
std::string shortest(double v) {
  char buf[64];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, end) : NumberReader::format(v);
}

// Numbers of one kind, at most ten per line (LM-63-2002 keeps lines within 256 characters).
void putNumbers(std::string& out, const double* v, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    out += shortest(v[i]);
    out += (i + 1) % 10 == 0 || i + 1 == n ? '\n' : ' ';
  }
}

}  // namespace

std::string formatIes(const IesTable& table) {
  // The reader's checks (angles, symmetric ranges, counts, negative values) decide what is writable.
  (void)IesProfile::fromTable(table.vertical_deg, table.horizontal_deg, table.values, "formatIes");
  const double v0 = table.vertical_deg.front(), v1 = table.vertical_deg.back();
  if (!((v0 == 0.0 || v0 == 90.0) && (v1 == 90.0 || v1 == 180.0)))
    throw InvalidArgument("formatIes: type C vertical angles must run from 0 or 90 to 90 or 180 degrees");
  std::string out = "IESNA:LM-63-2002\n";
  std::vector<std::pair<std::string, std::string>> keywords = table.keywords;
  for (const char* required : {"TEST", "TESTLAB", "ISSUEDATE", "MANUFAC"}) {
    const bool present =
        std::any_of(keywords.begin(), keywords.end(), [&](const auto& k) { return k.first == required; });
    if (!present) keywords.emplace_back(required, "");
  }
  for (const auto& [key, value] : keywords) {
    if (key.empty() || key.find_first_of("[]\r\n") != std::string::npos)
      throw InvalidArgument("formatIes: keyword '" + key + "' must be non-empty, without brackets or line breaks");
    std::string_view rest = value;
    bool first = true;
    do {
      const std::size_t eol = std::min(rest.find('\n'), rest.size());
      out += first ? "[" + key + "] " : std::string("[MORE] ");
      out += rest.substr(0, eol);
      out += '\n';
      rest = eol < rest.size() ? rest.substr(eol + 1) : std::string_view{};
      first = false;
    } while (!rest.empty());
  }
  out += "TILT=NONE\n";
  // lamps, lumens per lamp, multiplier, vertical and horizontal counts, photometric type C (1),
  // units (2: metres), luminous opening 0 x 0 x 0 (a point), ballast factor, file generation type
  // (future use: 1), input watts.
  std::ostringstream header;
  header << "1 " << shortest(table.lumens_per_lamp) << " 1 " << table.vertical_deg.size() << ' '
         << table.horizontal_deg.size() << " 1 2 0 0 0\n1 1 0\n";
  out += header.str();
  putNumbers(out, table.vertical_deg.data(), table.vertical_deg.size());
  putNumbers(out, table.horizontal_deg.data(), table.horizontal_deg.size());
  for (std::size_t h = 0; h < table.horizontal_deg.size(); ++h)
    putNumbers(out, table.values.data() + h * table.vertical_deg.size(), table.vertical_deg.size());
  return out;
}

void writeIes(const std::filesystem::path& file, const IesTable& table) {
  const std::string text = formatIes(table);
  writeFileAtomically(file, {reinterpret_cast<const unsigned char*>(text.data()), text.size()}, "IES file",
                      /*sync=*/false);
}

}  // namespace duplex

namespace duplex {

IesTable farFieldIesTable(const SensorResult& s, std::uint64_t rays, std::uint64_t seed) {
  if (s.shape != SensorShape::FarField)
    throw InvalidArgument("farFieldIesTable: sensor '" + s.name + "' is not a far-field sensor");
  const std::uint32_t nc = s.nx, ng = s.ny;
  IesTable table;
  for (std::uint32_t ig = 0; ig < ng; ++ig) table.vertical_deg.push_back(ig * 180.0 / (ng - 1));
  for (std::uint32_t ic = 0; ic < nc; ++ic) table.horizontal_deg.push_back(ic * 360.0 / nc);
  // The run's flux per unit of a cell's measure (its solid angle) is the intensity: candela when
  // the run is photometric, else W/sr.
  const bool candela = !s.illuminance_lx.empty();
  const std::vector<double>& values = candela ? s.illuminance_lx : s.irradiance_w_m2;
  table.values = values;
  if (nc > 1) {  // a full circle of C-planes ends with 360, the plane of 0 again
    table.horizontal_deg.push_back(360.0);
    table.values.insert(table.values.end(), values.begin(), values.begin() + ng);
  }
  std::ostringstream other;
  if (candela) other << "Luminous intensity in candela (a photometric run): " << rays << " rays, seed " << seed;
  else other << "Radiant intensity in W/sr (a radiometric run), not candela: " << rays << " rays, seed " << seed;
  table.keywords = {{"TEST", "duplex sensor far-field measurement"},
                    {"TESTLAB", "duplex (simulated)"},
                    {"ISSUEDATE", ""},
                    {"MANUFAC", ""},
                    {"LUMCAT", s.name},
                    {"OTHER", other.str()},
                    {"_UNITS", candela ? "cd" : "W/sr"}};
  return table;
}

}  // namespace duplex
