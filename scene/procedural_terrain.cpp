// procedural:terrain — a heightfield made solid: the top surface, four vertical skirts
// and a flat bottom, one closed mesh. Heights are fractal value noise from the seeded
// hash below (no std distributions), so the same seed gives the same bits everywhere.
//
// Keys: seed (default 1), size (grid cells per side, default 256), extent (metres per
// side, default 1000), height (relief amplitude in metres, default 150).
// Triangles: 4 size^2 (top and bottom grids) + 8 size (skirts).
#include <cmath>

#include "scene/procedural.hpp"

namespace st::procedural {
namespace {

double lattice(uint64_t seed, int64_t ix, int64_t iz, int octave) {
  Rng h(seed ^ (uint64_t(ix) * 0x9e3779b97f4a7c15ull) ^ (uint64_t(iz) * 0xc2b2ae3d27d4eb4full) ^
        (uint64_t(octave) << 56));
  return h.uniform();
}

double smooth(double t) { return t * t * (3 - 2 * t); }

// Value noise, 6 octaves, in [0, 1).
double fbm(uint64_t seed, double x, double z) {
  double sum = 0, amp = 0.5, norm = 0, freq = 1.0 / 16;
  for (int o = 0; o < 6; ++o) {
    const double fx = x * freq, fz = z * freq;
    const double gx = std::floor(fx), gz = std::floor(fz);
    const double tx = smooth(fx - gx), tz = smooth(fz - gz);
    const int64_t ix = static_cast<int64_t>(gx), iz = static_cast<int64_t>(gz);
    const double a = lattice(seed, ix, iz, o), b = lattice(seed, ix + 1, iz, o);
    const double c = lattice(seed, ix, iz + 1, o), d = lattice(seed, ix + 1, iz + 1, o);
    sum += amp * ((a * (1 - tx) + b * tx) * (1 - tz) + (c * (1 - tx) + d * tx) * tz);
    norm += amp;
    amp *= 0.5;
    freq *= 2;
  }
  return sum / norm;
}

}  // namespace

std::vector<MeshSoup> make_terrain(Params& p) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const int n = static_cast<int>(p.integer("size", 256, 1, 4096));
  const double extent = p.real("extent", 1000.0, 1e-3, 1e9);
  const double height = p.real("height", 150.0, 0.0, 1e9);
  p.finish();

  MeshSoup m{"terrain", {}, {}};
  const uint32_t row = static_cast<uint32_t>(n + 1);
  const double cell = extent / n, half = extent / 2;
  const double base = -0.1 * extent;  // well below the lowest point (heights are >= 0)
  auto coord = [&](int i) { return i == n ? half : -half + cell * i; };
  // Noise is sampled on grid coordinates so the relief does not depend on `extent`.
  for (int k = 0; k <= n; ++k)
    for (int i = 0; i <= n; ++i)
      add_vertex(m, {coord(i), height * fbm(seed, i * 256.0 / n, k * 256.0 / n), coord(k)});
  const uint32_t bottom = static_cast<uint32_t>(m.vertices.size());
  for (int k = 0; k <= n; ++k)
    for (int i = 0; i <= n; ++i) add_vertex(m, {coord(i), base, coord(k)});
  auto top_at = [&](int i, int k) { return uint32_t(k) * row + uint32_t(i); };
  for (int k = 0; k < n; ++k)
    for (int i = 0; i < n; ++i) {
      const uint32_t v00 = top_at(i, k), v10 = top_at(i + 1, k), v01 = top_at(i, k + 1),
                     v11 = top_at(i + 1, k + 1);
      add_quad(m, v00, v01, v11, v10);                                  // top, +Y
      add_quad(m, bottom + v00, bottom + v10, bottom + v11, bottom + v01);  // bottom, -Y
    }
  // Skirts: walk the boundary counter-clockwise in (x, z) and wall it like a loft.
  std::vector<uint32_t> loop;
  for (int i = 0; i < n; ++i) loop.push_back(top_at(i, 0));
  for (int k = 0; k < n; ++k) loop.push_back(top_at(n, k));
  for (int i = n; i > 0; --i) loop.push_back(top_at(i, n));
  for (int k = n; k > 0; --k) loop.push_back(top_at(0, k));
  for (size_t e = 0; e < loop.size(); ++e) {
    const uint32_t t0 = loop[e], t1 = loop[(e + 1) % loop.size()];
    add_quad(m, bottom + t0, t0, t1, bottom + t1);
  }
  return {std::move(m)};
}

}  // namespace st::procedural
