#include "loadgen/png_plot.hpp"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "common/error.hpp"

namespace st::loadgen {

void write_rgb_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb) {
  if (rgb.size() != size_t(width) * height * 3) throw Error(path + ": image buffer size mismatch");
  const std::string tmp = path + ".tmp";
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw Error(path + ": cannot open for writing");
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    std::fclose(f);
    std::remove(tmp.c_str());
    throw Error(path + ": libpng failed to write");
  }
  png_init_io(png, f);
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (uint32_t y = 0; y < height; ++y)
    png_write_row(png, const_cast<png_bytep>(rgb.data() + size_t(y) * width * 3));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fclose(f) != 0) throw Error(path + ": write failed");
  std::filesystem::rename(tmp, path);
}

Colour series_colour(size_t i) {
  static const Colour palette[] = {{31, 119, 180}, {214, 39, 40}, {44, 160, 44}, {255, 127, 14},
                                   {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {127, 127, 127}};
  return palette[i % 8];
}

namespace {

// 3x5 glyphs: 5 rows of 3 bits (bit 2 = left column).
uint16_t glyph(char c) {
  static const struct {
    char c;
    uint8_t rows[5];
  } font[] = {
      {'0', {7, 5, 5, 5, 7}}, {'1', {2, 6, 2, 2, 7}}, {'2', {7, 1, 7, 4, 7}}, {'3', {7, 1, 7, 1, 7}},
      {'4', {5, 5, 7, 1, 1}}, {'5', {7, 4, 7, 1, 7}}, {'6', {7, 4, 7, 5, 7}}, {'7', {7, 1, 1, 1, 1}},
      {'8', {7, 5, 7, 5, 7}}, {'9', {7, 5, 7, 1, 7}}, {'A', {2, 5, 7, 5, 5}}, {'B', {6, 5, 6, 5, 6}},
      {'C', {3, 4, 4, 4, 3}}, {'D', {6, 5, 5, 5, 6}}, {'E', {7, 4, 6, 4, 7}}, {'F', {7, 4, 6, 4, 4}},
      {'G', {3, 4, 5, 5, 3}}, {'H', {5, 5, 7, 5, 5}}, {'I', {7, 2, 2, 2, 7}}, {'J', {1, 1, 1, 5, 2}},
      {'K', {5, 5, 6, 5, 5}}, {'L', {4, 4, 4, 4, 7}}, {'M', {5, 7, 7, 5, 5}}, {'N', {6, 5, 5, 5, 5}},
      {'O', {2, 5, 5, 5, 2}}, {'P', {6, 5, 6, 4, 4}}, {'Q', {2, 5, 5, 6, 3}}, {'R', {6, 5, 6, 5, 5}},
      {'S', {3, 4, 2, 1, 6}}, {'T', {7, 2, 2, 2, 2}}, {'U', {5, 5, 5, 5, 7}}, {'V', {5, 5, 5, 5, 2}},
      {'W', {5, 5, 7, 7, 5}}, {'X', {5, 5, 2, 5, 5}}, {'Y', {5, 5, 2, 2, 2}}, {'Z', {7, 1, 2, 4, 7}},
      {'.', {0, 0, 0, 0, 2}}, {',', {0, 0, 0, 2, 4}}, {'%', {5, 1, 2, 4, 5}}, {'-', {0, 0, 7, 0, 0}},
      {'/', {1, 1, 2, 4, 4}}, {':', {0, 2, 0, 2, 0}}, {'(', {1, 2, 2, 2, 1}}, {')', {4, 2, 2, 2, 4}},
      {'_', {0, 0, 0, 0, 7}}, {'=', {0, 7, 0, 7, 0}}, {'+', {0, 2, 7, 2, 0}}, {'E', {7, 4, 6, 4, 7}},
  };
  const char u = char(std::toupper(static_cast<unsigned char>(c)));
  for (const auto& g : font)
    if (g.c == u) {
      uint16_t bits = 0;
      for (int r = 0; r < 5; ++r) bits = uint16_t(bits | (g.rows[r] << (3 * (4 - r))));
      return bits;
    }
  return 0;
}

struct Canvas {
  uint32_t w, h;
  std::vector<uint8_t> px;
  Canvas(uint32_t w_, uint32_t h_) : w(w_), h(h_), px(size_t(w_) * h_ * 3, 255) {}
  void set(int x, int y, Colour c) {
    if (x < 0 || y < 0 || uint32_t(x) >= w || uint32_t(y) >= h) return;
    uint8_t* p = &px[(size_t(y) * w + uint32_t(x)) * 3];
    p[0] = c.r, p[1] = c.g, p[2] = c.b;
  }
  void rect(int x0, int y0, int x1, int y1, Colour c) {
    for (int y = std::min(y0, y1); y <= std::max(y0, y1); ++y)
      for (int x = std::min(x0, x1); x <= std::max(x0, x1); ++x) set(x, y, c);
  }
  void line(double x0, double y0, double x1, double y1, Colour c) {
    const int n = int(std::max(std::fabs(x1 - x0), std::fabs(y1 - y0))) + 1;
    for (int i = 0; i <= n; ++i) {
      const double t = double(i) / n;
      const int x = int(std::lround(x0 + (x1 - x0) * t)), y = int(std::lround(y0 + (y1 - y0) * t));
      set(x, y, c), set(x + 1, y, c), set(x, y + 1, c);
    }
  }
  // Text at (x, y) top-left, scale 2 (8 px per character).
  void text(int x, int y, const std::string& s, Colour c, bool vertical = false) {
    for (char ch : s) {
      const uint16_t g = glyph(ch);
      for (int r = 0; r < 5; ++r)
        for (int col = 0; col < 3; ++col)
          if (g & (1 << (3 * (4 - r) + (2 - col))))
            for (int dy = 0; dy < 2; ++dy)
              for (int dx = 0; dx < 2; ++dx) {
                if (vertical) set(x + r * 2 + dy, y - col * 2 - dx, c);
                else set(x + col * 2 + dx, y + r * 2 + dy, c);
              }
      if (vertical) y -= 8;
      else x += 8;
    }
  }
};

std::string tick_label(double v) {
  char buf[32];
  const double a = std::fabs(v);
  if (a != 0 && (a >= 1e5 || a < 1e-2)) std::snprintf(buf, sizeof buf, "%.1e", v);
  else std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

}  // namespace

void write_plot_png(const std::string& path, const PlotSpec& spec, const std::vector<Series>& series) {
  Canvas cv(spec.width, spec.height);
  const int left = 90, right = int(spec.width) - 20, top = 40, bottom = int(spec.height) - 60;
  auto tx = [&](double v) { return spec.log_x ? std::log10(std::max(v, 1e-12)) : v; };
  auto ty = [&](double v) { return spec.log_y ? std::log10(std::max(v, 1e-12)) : v; };
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (const Series& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      if (spec.log_x && !(s.x[i] > 0)) continue;
      if (spec.log_y && !(s.y[i] > 0)) continue;
      x0 = std::min(x0, tx(s.x[i])), x1 = std::max(x1, tx(s.x[i]));
      y0 = std::min(y0, ty(s.y[i])), y1 = std::max(y1, ty(s.y[i]));
      if (s.bars && !spec.log_y) y0 = std::min(y0, 0.0);
    }
  if (!std::isnan(spec.x_min)) x0 = tx(spec.x_min);
  if (!std::isnan(spec.x_max)) x1 = tx(spec.x_max);
  if (!std::isnan(spec.y_min)) y0 = ty(spec.y_min);
  if (!std::isnan(spec.y_max)) y1 = ty(spec.y_max);
  if (!std::isfinite(x0) || !std::isfinite(x1)) x0 = 0, x1 = 1;
  if (!std::isfinite(y0) || !std::isfinite(y1)) y0 = 0, y1 = 1;
  if (x1 <= x0) x1 = x0 + 1;
  if (y1 <= y0) y1 = y0 + (y0 == 0 ? 1 : std::fabs(y0) * 0.1);
  auto px = [&](double v) { return left + (tx(v) - x0) / (x1 - x0) * (right - left); };
  auto py = [&](double v) { return bottom - (ty(v) - y0) / (y1 - y0) * (bottom - top); };
  const Colour grid{225, 225, 225}, axis{0, 0, 0};
  for (int i = 0; i <= 5; ++i) {
    const double fx = x0 + (x1 - x0) * i / 5, fy = y0 + (y1 - y0) * i / 5;
    const int gx = int(left + (right - left) * i / 5), gy = int(bottom - (bottom - top) * i / 5);
    cv.line(gx, top, gx, bottom, grid);
    cv.line(left, gy, right, gy, grid);
    const std::string lx = tick_label(spec.log_x ? std::pow(10, fx) : fx);
    const std::string ly = tick_label(spec.log_y ? std::pow(10, fy) : fy);
    cv.text(gx - int(lx.size()) * 4, bottom + 8, lx, axis);
    cv.text(left - 8 - int(ly.size()) * 8, gy - 5, ly, axis);
  }
  cv.line(left, top, left, bottom, axis);
  cv.line(left, bottom, right, bottom, axis);
  cv.text(left, 12, spec.title, axis);
  cv.text((left + right) / 2 - int(spec.x_label.size()) * 4, bottom + 30, spec.x_label, axis);
  cv.text(8, (top + bottom) / 2 + int(spec.y_label.size()) * 4, spec.y_label, axis, true);
  for (size_t si = 0; si < series.size(); ++si) {
    const Series& s = series[si];
    bool have = false;
    double lx = 0, ly = 0;
    const double bar_w = s.x.size() > 1 ? std::max(1.0, (right - left) / double(s.x.size()) * 0.8) : 10;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      if ((spec.log_x && !(s.x[i] > 0)) || (spec.log_y && !(s.y[i] > 0))) continue;
      const double cx = std::clamp(px(s.x[i]), double(left), double(right));
      const double cy = std::clamp(py(s.y[i]), double(top), double(bottom));
      if (s.bars) {
        cv.rect(int(cx - bar_w / 2), int(cy), int(cx + bar_w / 2), bottom, s.colour);
      } else {
        if (have) cv.line(lx, ly, cx, cy, s.colour);
        else cv.rect(int(cx) - 1, int(cy) - 1, int(cx) + 1, int(cy) + 1, s.colour);
        lx = cx, ly = cy, have = true;
      }
    }
    // Legend, top right.
    const int ly0 = top + 6 + int(si) * 14;
    cv.rect(right - 200, ly0, right - 188, ly0 + 9, s.colour);
    cv.text(right - 182, ly0, s.label, axis);
  }
  write_rgb_png(path, cv.w, cv.h, cv.px);
}

}  // namespace st::loadgen
