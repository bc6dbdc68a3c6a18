#include "SensorImage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>

namespace duplex::cli {

namespace {

// Viridis at 9 stops (matplotlib's table, sampled), interpolated linearly.
std::array<std::uint8_t, 3> viridis(double x) {
  static constexpr double stops[9][3] = {{68, 1, 84},    {71, 44, 122}, {59, 81, 139},  {44, 113, 142}, {33, 144, 141},
                                         {39, 173, 129}, {92, 200, 99}, {170, 220, 50}, {253, 231, 37}};
  x = std::clamp(x, 0.0, 1.0) * 8.0;
  const int i = std::min(7, static_cast<int>(x));
  const double f = x - i;
  std::array<std::uint8_t, 3> c{};
  for (int k = 0; k < 3; ++k)
    c[k] = static_cast<std::uint8_t>(std::lround(stops[i][k] + f * (stops[i + 1][k] - stops[i][k])));
  return c;
}

// A 3 x 5 pixel font for the scale labels (digits, '.', 'e', '+', '-'), one row per 3 bits.
std::array<std::uint8_t, 5> glyph(char ch) {
  switch (ch) {
    case '0': return {7, 5, 5, 5, 7};
    case '1': return {2, 6, 2, 2, 7};
    case '2': return {7, 1, 7, 4, 7};
    case '3': return {7, 1, 7, 1, 7};
    case '4': return {5, 5, 7, 1, 1};
    case '5': return {7, 4, 7, 1, 7};
    case '6': return {7, 4, 7, 5, 7};
    case '7': return {7, 1, 1, 1, 1};
    case '8': return {7, 5, 7, 5, 7};
    case '9': return {7, 5, 7, 1, 7};
    case '.': return {0, 0, 0, 0, 2};
    case 'e': return {0, 7, 7, 4, 7};
    case '+': return {0, 2, 7, 2, 0};
    case '-': return {0, 0, 7, 0, 0};
    default: return {0, 0, 0, 0, 0};
  }
}

void put(demo::RgbImage& img, std::uint32_t x, std::uint32_t y, std::array<std::uint8_t, 3> c) {
  if (x >= img.width || y >= img.height) return;
  std::uint8_t* p = &img.pixels[(static_cast<std::size_t>(y) * img.width + x) * 3];
  p[0] = c[0];
  p[1] = c[1];
  p[2] = c[2];
}

// Text at (x, y) (top-left), each font pixel drawn as s x s.
void text(demo::RgbImage& img, std::uint32_t x, std::uint32_t y, const std::string& s, std::uint32_t scale) {
  for (char ch : s) {
    const auto g = glyph(ch);
    for (std::uint32_t r = 0; r < 5; ++r)
      for (std::uint32_t c = 0; c < 3; ++c)
        if (g[r] & (4u >> c))
          for (std::uint32_t dy = 0; dy < scale; ++dy)
            for (std::uint32_t dx = 0; dx < scale; ++dx)
              put(img, x + c * scale + dx, y + r * scale + dy, {255, 255, 255});
    x += 4 * scale;
  }
}

}  // namespace

demo::RgbImage falseColourImage(const std::vector<double>& values, std::uint32_t nx, std::uint32_t ny) {
  double vmax = 0.0;
  for (double v : values)
    if (std::isfinite(v)) vmax = std::max(vmax, v);
  // Bins drawn as squares of `cell` pixels, the map at least ~256 pixels on its longer side.
  const std::uint32_t cell = std::max<std::uint32_t>(1, 256 / std::max(nx, ny));
  const std::uint32_t map_w = nx * cell, map_h = std::max<std::uint32_t>(ny * cell, 64);
  const std::uint32_t font = 2, margin = 8, bar_w = 16, label_w = 9 * 4 * font;
  demo::RgbImage img;
  img.width = map_w + margin + bar_w + margin + label_w + margin;
  img.height = map_h + 2 * margin;
  img.pixels.assign(static_cast<std::size_t>(img.width) * img.height * 3, 32);
  for (std::uint32_t iy = 0; iy < ny; ++iy) {
    for (std::uint32_t ix = 0; ix < nx; ++ix) {
      const double v = values[static_cast<std::size_t>(iy) * nx + ix];
      const auto c =
          std::isfinite(v) ? viridis(vmax > 0.0 ? v / vmax : 0.0) : std::array<std::uint8_t, 3>{128, 128, 128};
      const std::uint32_t top = margin + (ny - 1 - iy) * cell;
      for (std::uint32_t y = 0; y < cell; ++y)
        for (std::uint32_t x = 0; x < cell; ++x) put(img, margin + ix * cell + x, top + y, c);
    }
  }
  // Scale bar: maximum at the top, 0 at the bottom, labelled.
  const std::uint32_t bar_x = margin + map_w + margin;
  for (std::uint32_t y = 0; y < map_h; ++y) {
    const auto c = viridis(1.0 - static_cast<double>(y) / std::max<std::uint32_t>(1, map_h - 1));
    for (std::uint32_t x = 0; x < bar_w; ++x) put(img, bar_x + x, margin + y, c);
  }
  char label[32];
  std::snprintf(label, sizeof label, "%.2e", vmax);
  text(img, bar_x + bar_w + margin / 2, margin, label, font);
  text(img, bar_x + bar_w + margin / 2, margin + map_h - 5 * font, "0", font);
  return img;
}

}  // namespace duplex::cli
