#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "tests/tiles/interval_fields.hpp"

namespace st::fields {
namespace {

IntervalTile blank(uint32_t side, Interval fill) {
  IntervalTile t;
  t.level = is_power_of_two(side) ? log2_exact(side) : 0;
  t.width = t.height = side;
  t.data.assign(size_t(side) * side, fill);
  return t;
}

// Smooth height over the tile: a tilt plus a few separable waves (cheap at 4096²: each
// wave is tabulated per column and per row). Values stay within about [0.35, 0.85].
std::vector<float> smooth_surface(uint32_t side, Rng& rng) {
  constexpr int kWaves = 4;
  std::vector<double> col(side, 0.0), row(side, 0.0);
  double tilt_x = rng.uniform(-0.1, 0.1), tilt_y = rng.uniform(-0.1, 0.1);
  for (int k = 0; k < kWaves; ++k) {
    double fx = rng.uniform(0.5, 6.0) * 2 * M_PI, fy = rng.uniform(0.5, 6.0) * 2 * M_PI;
    double px = rng.uniform(0, 2 * M_PI), py = rng.uniform(0, 2 * M_PI);
    double amp = 0.04 / (k + 1);
    for (uint32_t i = 0; i < side; ++i) col[i] += amp * std::sin(fx * (i + 0.5) / side + px);
    for (uint32_t j = 0; j < side; ++j) row[j] += amp * std::sin(fy * (j + 0.5) / side + py);
  }
  std::vector<float> z(size_t(side) * side);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i)
      z[size_t(j) * side + i] =
          float(0.6 + tilt_x * ((i + 0.5) / side - 0.5) + tilt_y * ((j + 0.5) / side - 0.5) + col[i] + row[j]);
  return z;
}

// Closed boxes: interval from the roof down to `ground` (its exit depth), overlapping
// boxes keep the nearest roof. Buildings are 1..48 texels a side whatever the map size
// and their number grows with the area, so about a third of a big map is covered.
void add_buildings(IntervalTile& t, Rng& rng, const std::vector<float>* ground, float flat_ground) {
  const uint32_t side = t.width;
  const uint32_t count = std::max<uint32_t>(1, uint32_t(uint64_t(side) * side / 1500));
  const uint32_t max_size = std::max<uint32_t>(2, std::min<uint32_t>(side / 4, 48));
  for (uint32_t b = 0; b < count; ++b) {
    uint32_t w = 1 + rng.below(max_size), h = 1 + rng.below(max_size);
    uint32_t x0 = rng.below(side), y0 = rng.below(side);
    float roof = float(rng.uniform(0.2, 0.55));
    for (uint32_t j = y0; j < std::min(side, y0 + h); ++j)
      for (uint32_t i = x0; i < std::min(side, x0 + w); ++i) {
        Interval& v = t.at(i, j);
        float g = ground ? (*ground)[size_t(j) * side + i] : flat_ground;
        if (v.lo == kLitDepth) continue;  // no geometry below: keep the lit border
        v.lo = std::min(v.lo, roof);
        v.hi = std::max(v.hi, g);
      }
  }
}

void add_lit_border(IntervalTile& t, Rng& rng) {
  const uint32_t side = t.width;
  uint32_t border = side >= 8 ? 1 + rng.below(side / 8) : 0;
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < std::min(border, side); ++i) t.at(i, j) = Interval{kLitDepth, kLitDepth};
}

}  // namespace

IntervalTile uniform_field(uint32_t side, uint64_t seed) {
  Rng rng(seed);
  IntervalTile t = blank(side, {});
  for (Interval& v : t.data) {
    float lo = float(rng.uniform());
    uint64_t r = rng.next();
    float width = (r & 3) == 0 ? 0.0f : float(0.3 * double(r >> 11) * 0x1.0p-53);
    v = Interval{lo, std::min(1.0f, lo + width)};
  }
  return t;
}

IntervalTile city_field(uint32_t side, uint64_t seed) {
  Rng rng(seed);
  IntervalTile t = blank(side, {});
  // Ground: piecewise-constant blocks (terraces) of zero width.
  const uint32_t block = std::max<uint32_t>(1, side / 8);
  std::vector<float> ground(size_t(side) * side);
  std::vector<float> terrace(64);
  for (float& g : terrace) g = float(rng.uniform(0.7, 0.8));
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      float g = terrace[((j / block) % 8) * 8 + (i / block) % 8];
      ground[size_t(j) * side + i] = g;
      t.at(i, j) = Interval{g, g};
    }
  add_lit_border(t, rng);
  add_buildings(t, rng, &ground, 0.75f);
  return t;
}

IntervalTile terrain_field(uint32_t side, uint64_t seed) {
  Rng rng(seed);
  std::vector<float> z = smooth_surface(side, rng);
  IntervalTile t = blank(side, {});
  for (size_t k = 0; k < z.size(); ++k) t.data[k] = Interval{z[k], z[k]};
  return t;
}

IntervalTile special_values_field(uint32_t side, uint64_t seed) {
  Rng rng(seed);
  static const Interval kSpecial[] = {
      {0.0f, 0.0f},
      {1.0f, 1.0f},
      {kLitDepth, kLitDepth},
      {-0.0f, -0.0f},
      {-0.0f, 0.0f},
      {0.0f, -0.0f},  // lo <= hi holds: -0.0 == 0.0
      {FLT_TRUE_MIN, FLT_TRUE_MIN},
      {-FLT_TRUE_MIN, FLT_TRUE_MIN},
      {0.0f, FLT_MIN},
      {FLT_MIN * 0.5f, FLT_MIN * 0.75f},
      {1e-30f, 1e30f},
      {-1e30f, -1e-30f},
      {-1e30f, 1e30f},
      {1e30f, 1e30f},
      {-FLT_MAX, FLT_MAX},
      {FLT_MAX, FLT_MAX},
      {-FLT_MAX, -FLT_MAX},
      {0.5f, std::nextafter(0.5f, 1.0f)},
      {std::nextafter(1.0f, 0.0f), 1.0f},
  };
  constexpr uint32_t kCount = sizeof(kSpecial) / sizeof(kSpecial[0]);
  IntervalTile t = blank(side, {});
  // Blocks of one special value (so coarse nodes get chosen among them), with single
  // texels of another special or a random zero-width value sprinkled in.
  const uint32_t block = std::max<uint32_t>(1, std::min<uint32_t>(side / 4, 8));
  std::vector<uint32_t> block_kind(size_t(side / block + 1) * (side / block + 1));
  for (uint32_t& k : block_kind) k = rng.below(kCount);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      uint32_t r = rng.below(8);
      Interval v = kSpecial[block_kind[size_t(j / block) * (side / block + 1) + i / block]];
      if (r == 0) v = kSpecial[rng.below(kCount)];
      if (r == 1) {
        // Huge dynamic range, zero width: 1e-30 .. 1e30 log-uniform, either sign.
        float z = float(std::pow(10.0, rng.uniform(-30, 30)) * ((rng.next() & 1) ? -1 : 1));
        v = Interval{z, z};
      }
      t.at(i, j) = v;
    }
  return t;
}

IntervalTile scene_field(uint32_t side, uint64_t seed) {
  Rng rng(seed);
  std::vector<float> z = smooth_surface(side, rng);
  IntervalTile t = blank(side, {});
  // The east half's ground is a closed slab (its ray exits 0.03 deeper), the west half
  // an open mesh (zero width): real scenes mix both, and open ground barely compresses.
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      float g = z[size_t(j) * side + i];
      t.at(i, j) = Interval{g, i >= side / 2 ? g + 0.03f : g};
    }
  add_lit_border(t, rng);
  add_buildings(t, rng, &z, 0.0f);
  // Trees: open geometry, so zero-width intervals with noisy depths over a disc.
  const uint32_t trees = std::max<uint32_t>(1, uint32_t(uint64_t(side) * side / 4000));
  const uint32_t max_r = std::max<uint32_t>(1, std::min<uint32_t>(side / 64, 12));  // radius in texels
  for (uint32_t k = 0; k < trees; ++k) {
    int cx = int(rng.below(side)), cy = int(rng.below(side)), r = 1 + int(rng.below(max_r));
    float top = float(rng.uniform(0.3, 0.5));
    for (int j = std::max(0, cy - r); j <= std::min(int(side) - 1, cy + r); ++j)
      for (int i = std::max(0, cx - r); i <= std::min(int(side) - 1, cx + r); ++i) {
        if ((i - cx) * (i - cx) + (j - cy) * (j - cy) > r * r) continue;
        Interval& v = t.at(uint32_t(i), uint32_t(j));
        if (v.lo == kLitDepth) continue;
        float d = top + float(rng.uniform(0, 0.05));
        if (d < v.lo) v = Interval{d, d};
      }
  }
  return t;
}

IntervalTile constant_field(uint32_t side, Interval value) { return blank(side, value); }

std::vector<NamedField> all_fields(uint32_t side, uint64_t seed) {
  std::vector<NamedField> out;
  out.push_back({"uniform", uniform_field(side, seed)});
  out.push_back({"city", city_field(side, seed)});
  out.push_back({"terrain", terrain_field(side, seed)});
  out.push_back({"special", special_values_field(side, seed)});
  out.push_back({"scene", scene_field(side, seed)});
  out.push_back({"constant", constant_field(side, Interval{0.25f, 0.5f})});
  return out;
}

std::string first_violation(const IntervalTile& tile, const std::function<float(uint32_t, uint32_t)>& value) {
  for (uint32_t j = 0; j < tile.height; ++j)
    for (uint32_t i = 0; i < tile.width; ++i) {
      const Interval& iv = tile.at(i, j);
      float v = value(i, j);
      if (iv.lo <= v && v <= iv.hi) continue;
      char buf[200];
      std::snprintf(buf, sizeof buf, "texel (%u, %u): value %a (%.9g) not in [%a, %a] ([%.9g, %.9g])", i, j, double(v),
                    double(v), double(iv.lo), double(iv.hi), double(iv.lo), double(iv.hi));
      return buf;
    }
  return "";
}

bool small_test_scale() {
  const char* s = std::getenv("SHADOWTILE_TEST_SCALE");
  return s && std::strcmp(s, "small") == 0;
}

}  // namespace st::fields
