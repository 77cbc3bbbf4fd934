// procedural:soup — an open town as merged real assets are: one mesh of roofless
// buildings with gable roofs on a ground quad (boundary edges at every wall foot and
// roof eave, so append_mesh finds nothing closed and every interval is [lo, lo]), with
// the hazards such assets carry, all deterministic from the seed:
//   - duplicate faces: every third building's roof written twice more, once with the
//     same corners re-indexed (new vertices that welding merges), once reversed;
//   - slivers: every building has a wall-top sliver (base its wall's width, height 1 mm)
//     and every fifth a long one over the ground (10-40 m long, 2 mm wide);
//   - overlapping nearly coplanar faces: every fourth building a second roof panel
//     1 mm above its first, shifted by a quarter of the roof; ground patches 0.5 mm
//     above the ground quad;
//   - buildings placed at random, so walls cross each other.
//
// Keys: seed (default 1), count (buildings, default 2500), size (metres a side of the
// ground, default 400). Triangles: 15 per building (8 wall, 6 roof, 1 sliver), 12 more
// for every third, 2 for every fourth, 1 for every fifth; 2 for the ground and 2 per patch
// (count / 50 + 1 patches): about 19.7 count.
#include <cmath>
#include <numbers>

#include "scene/procedural.hpp"

namespace st::procedural {

std::vector<MeshSoup> make_soup(Params& p) {
  const uint64_t seed = static_cast<uint64_t>(p.integer("seed", 1, 0, INT64_MAX));
  const int count = static_cast<int>(p.integer("count", 2500, 0, 1 << 20));
  const double size = p.real("size", 400.0, 20.0, 1e7);
  p.finish();

  MeshSoup m{"soup", {}, {}};
  Rng rng(seed ^ 0x50u);
  const double half = size / 2;
  auto v = [&](double x, double y, double z) { return add_vertex(m, {x, y, z}); };
  // Ground: facing +Y, counter-clockwise seen from above (procedural.hpp convention).
  add_quad(m, v(-half, 0, -half), v(-half, 0, half), v(half, 0, half), v(half, 0, -half));
  for (int k = 0; k < count / 50 + 1; ++k) {  // overlapping ground patches
    const double cx = rng.uniform(-half, half), cz = rng.uniform(-half, half), r = rng.uniform(2, 10);
    add_quad(m, v(cx - r, 5e-4, cz - r), v(cx - r, 5e-4, cz + r), v(cx + r, 5e-4, cz + r), v(cx + r, 5e-4, cz - r));
  }
  for (int b = 0; b < count; ++b) {
    const double cx = rng.uniform(-0.95, 0.95) * half, cz = rng.uniform(-0.95, 0.95) * half;
    const double w = rng.uniform(3, 12), d = rng.uniform(3, 12), h = rng.uniform(4, 30);
    const double ang = rng.uniform(0, std::numbers::pi), ridge = h + rng.uniform(1, 5);
    const double ca = std::cos(ang), sa = std::sin(ang);
    auto at = [&](double x, double y, double z) { return Vec3d{cx + ca * x - sa * z, y, cz + sa * x + ca * z}; };
    auto va = [&](double x, double y, double z) { return add_vertex(m, at(x, y, z)); };
    // Corners i[y][z][x] of the walls, bottom and top.
    uint32_t i[2][2][2];
    for (int yi = 0; yi < 2; ++yi)
      for (int zi = 0; zi < 2; ++zi)
        for (int xi = 0; xi < 2; ++xi) i[yi][zi][xi] = va((xi - 0.5) * w, yi * h, (zi - 0.5) * d);
    add_quad(m, i[0][0][0], i[1][0][0], i[1][0][1], i[0][0][1]);  // four walls, no floor, no ceiling
    add_quad(m, i[0][0][1], i[1][0][1], i[1][1][1], i[0][1][1]);
    add_quad(m, i[0][1][1], i[1][1][1], i[1][1][0], i[0][1][0]);
    add_quad(m, i[0][1][0], i[1][1][0], i[1][0][0], i[0][0][0]);
    const uint32_t r0 = va(0, ridge, -d / 2), r1 = va(0, ridge, d / 2);
    const size_t roof_first = m.triangles.size();
    add_quad(m, i[1][0][0], r0, r1, i[1][1][0]);  // roof panels and gables
    add_quad(m, i[1][0][1], i[1][1][1], r1, r0);
    m.triangles.push_back({i[1][0][0], i[1][0][1], r0});
    m.triangles.push_back({i[1][1][0], r1, i[1][1][1]});
    const size_t roof_end = m.triangles.size();
    if (b % 3 == 0)
      for (size_t t = roof_first; t < roof_end; ++t) {
        const Triangle tri = m.triangles[t];
        const Vec3d p0 = m.vertices[tri[0]], p1 = m.vertices[tri[1]], p2 = m.vertices[tri[2]];
        const uint32_t a = add_vertex(m, p0), c = add_vertex(m, p1), e = add_vertex(m, p2);
        m.triangles.push_back({c, e, a});              // the same face, re-indexed
        m.triangles.push_back({tri[0], tri[2], tri[1]});  // and reversed
      }
    if (b % 4 == 1) {  // a second panel 1 mm above the first, a quarter of the roof along
      const double up = 1e-3, s = d / 4;
      add_quad(m, va(-w / 2, h + up, -d / 2 + s), va(0, ridge + up, -d / 2 + s), va(0, ridge + up, d / 2 + s),
               va(-w / 2, h + up, d / 2 + s));
    }
    // Wall-top sliver: the front wall's top edge and a point 1 mm above its middle.
    m.triangles.push_back({i[1][0][0], i[1][0][1], va(0, h + 1e-3, -d / 2)});
    if (b % 5 == 2) {  // a long sliver over the ground, 2 mm wide
      const double len = rng.uniform(10, 40);
      m.triangles.push_back({va(0, 0.2, -d / 2 - 1), va(len, 0.2, -d / 2 - 1), va(len / 2, 0.2, -d / 2 - 1 - 2e-3)});
    }
  }
  return {std::move(m)};
}

}  // namespace st::procedural
