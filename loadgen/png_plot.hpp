// Minimal PNG charts for reports (line plots and histograms), drawn into an RGB buffer
// and written with libpng. The load tester must not link tiles/bake (Embree, OpenEXR),
// so this does not reuse tiles/bake/png_io. Text uses a built-in 3x5 pixel font scaled 2x
// (upper-case letters, digits and . , % - / : ( ) _ = +).
//
// Errors: write() throws st::Error naming the file.
#pragma once
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace st::loadgen {

struct Colour {
  uint8_t r = 0, g = 0, b = 0;
};

struct Series {
  std::string label;
  Colour colour;
  std::vector<double> x, y;
  bool bars = false;  // histogram bars from y = 0 instead of a polyline
};

struct PlotSpec {
  std::string title, x_label, y_label;
  bool log_x = false, log_y = false;
  uint32_t width = 800, height = 480;
  // Fixed ranges; NaN: from the data.
  double x_min = NAN, x_max = NAN, y_min = NAN, y_max = NAN;
};

void write_plot_png(const std::string& path, const PlotSpec& spec, const std::vector<Series>& series);

// An 8-bit RGB image (row 0 at the top) written with libpng (PATH.tmp, then renamed).
void write_rgb_png(const std::string& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgb);

// Palette for successive series.
Colour series_colour(size_t i);

}  // namespace st::loadgen
