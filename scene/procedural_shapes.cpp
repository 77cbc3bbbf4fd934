// Closed-solid generators shared by the procedural scenes (see procedural.hpp for the
// orientation convention). Correct winding is checked by tests: a procedural scene must
// come out of append_mesh() closed with meshes_flipped == 0.
#include <cmath>
#include <numbers>

#include "scene/procedural.hpp"
#include "common/error.hpp"

namespace st::procedural {

uint32_t add_vertex(MeshSoup& m, const Vec3d& p) {
  m.vertices.push_back(p);
  return static_cast<uint32_t>(m.vertices.size() - 1);
}

void add_quad(MeshSoup& m, uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
  m.triangles.push_back({a, b, c});
  m.triangles.push_back({a, c, d});
}

void add_box(MeshSoup& m, const Vec3d& lo, const Vec3d& hi) { add_grid_box(m, lo, hi, 1, 1, 1); }

void add_grid_box(MeshSoup& m, const Vec3d& lo, const Vec3d& hi, int nx, int ny, int nz) {
  ST_CHECK(nx >= 1 && ny >= 1 && nz >= 1);
  const int n[3] = {nx, ny, nz};
  // Lattice points on the surface get one vertex each, created on first use, so faces
  // meeting at a box edge share their vertices.
  std::vector<uint32_t> index(size_t(nx + 1) * (ny + 1) * (nz + 1), UINT32_MAX);
  auto vertex = [&](int c[3]) {
    uint32_t& slot = index[(size_t(c[0]) * (ny + 1) + c[1]) * (nz + 1) + c[2]];
    if (slot == UINT32_MAX) {
      Vec3d p{lo.x + (hi.x - lo.x) * c[0] / nx, lo.y + (hi.y - lo.y) * c[1] / ny,
              lo.z + (hi.z - lo.z) * c[2] / nz};
      // Exact end points (no rounding of lo + (hi - lo) * 1).
      if (c[0] == nx) p.x = hi.x;
      if (c[1] == ny) p.y = hi.y;
      if (c[2] == nz) p.z = hi.z;
      slot = add_vertex(m, p);
    }
    return slot;
  };
  // Face of axis a at side s; (b, c) follow a cyclically so that e_b x e_c = e_a.
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    for (int side = 0; side < 2; ++side)
      for (int u = 0; u < n[b]; ++u)
        for (int v = 0; v < n[c]; ++v) {
          int p00[3], p10[3], p11[3], p01[3];
          for (int* p : {p00, p10, p11, p01}) p[a] = side ? n[a] : 0;
          p00[b] = u, p00[c] = v;
          p10[b] = u + 1, p10[c] = v;
          p11[b] = u + 1, p11[c] = v + 1;
          p01[b] = u, p01[c] = v + 1;
          uint32_t i00 = vertex(p00), i10 = vertex(p10), i11 = vertex(p11), i01 = vertex(p01);
          if (side)
            add_quad(m, i00, i10, i11, i01);  // normal +e_a
          else
            add_quad(m, i00, i01, i11, i10);  // normal -e_a
        }
  }
}

namespace {

// Joins ring index blocks a and b (n vertices each) with quads; a is "below" b in the
// loft sense (walls face to the right of the polygon edges, i.e. outwards).
void join_rings(MeshSoup& m, uint32_t a, uint32_t b, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    uint32_t j = (i + 1) % n;
    add_quad(m, a + i, b + i, b + j, a + j);
  }
}

uint32_t add_ring(MeshSoup& m, const std::vector<Vec2>& pts, double y) {
  uint32_t first = static_cast<uint32_t>(m.vertices.size());
  for (auto& p : pts) add_vertex(m, {p.x, y, p.z});
  return first;
}

}  // namespace

void add_loft(MeshSoup& m, const std::vector<Ring>& rings, Vec2 centre) {
  ST_CHECK(rings.size() >= 2 && rings[0].points.size() >= 3);
  const uint32_t n = static_cast<uint32_t>(rings[0].points.size());
  std::vector<uint32_t> first;
  for (auto& r : rings) {
    ST_CHECK(r.points.size() == n);
    first.push_back(add_ring(m, r.points, r.y));
  }
  for (size_t k = 0; k + 1 < rings.size(); ++k) join_rings(m, first[k], first[k + 1], n);
  uint32_t bottom = add_vertex(m, {centre.x, rings.front().y, centre.z});
  uint32_t top = add_vertex(m, {centre.x, rings.back().y, centre.z});
  for (uint32_t i = 0; i < n; ++i) {
    uint32_t j = (i + 1) % n;
    m.triangles.push_back({bottom, first.front() + i, first.front() + j});  // normal -Y
    m.triangles.push_back({top, first.back() + j, first.back() + i});       // normal +Y
  }
}

void add_courtyard(MeshSoup& m, const std::vector<Vec2>& outer, const std::vector<Vec2>& inner,
                   double y0, double y1, int floors) {
  ST_CHECK(outer.size() == inner.size() && outer.size() >= 3 && floors >= 1);
  const uint32_t n = static_cast<uint32_t>(outer.size());
  // A cyclic loft: up the outside, across the roof, down the courtyard walls, back under
  // the floor. Going down flips the wall normals towards the courtyard, as needed.
  std::vector<uint32_t> cycle;
  for (int f = 0; f <= floors; ++f) cycle.push_back(add_ring(m, outer, y0 + (y1 - y0) * f / floors));
  for (int f = floors; f >= 0; --f) cycle.push_back(add_ring(m, inner, y0 + (y1 - y0) * f / floors));
  for (size_t k = 0; k < cycle.size(); ++k) join_rings(m, cycle[k], cycle[(k + 1) % cycle.size()], n);
}

std::vector<Vec2> subdivide(const std::vector<Vec2>& polygon, const std::vector<int>& counts) {
  ST_CHECK(counts.size() == polygon.size());
  std::vector<Vec2> out;
  for (size_t i = 0; i < polygon.size(); ++i) {
    const Vec2 a = polygon[i], b = polygon[(i + 1) % polygon.size()];
    const int n = counts[i];
    ST_CHECK(n >= 1);
    for (int t = 0; t < n; ++t)
      out.push_back({a.x + (b.x - a.x) * t / n, a.z + (b.z - a.z) * t / n});
  }
  return out;
}

std::vector<int> edge_counts(const std::vector<Vec2>& polygon, double spacing) {
  std::vector<int> counts;
  for (size_t i = 0; i < polygon.size(); ++i) {
    const Vec2 a = polygon[i], b = polygon[(i + 1) % polygon.size()];
    const double len = std::hypot(b.x - a.x, b.z - a.z);
    counts.push_back(std::max(1, static_cast<int>(std::lround(len / spacing))));
  }
  return counts;
}

void add_tube(MeshSoup& m, const std::vector<Vec3d>& path, double radius, int sides) {
  ST_CHECK(path.size() >= 2 && sides >= 3);
  const size_t count = path.size();
  auto tangent = [&](size_t k) {
    const Vec3d& a = path[k == 0 ? 0 : k - 1];
    const Vec3d& b = path[k + 1 == count ? k : k + 1];
    return normalize(b - a);
  };
  Vec3d t = tangent(0);
  Vec3d helper = std::fabs(t.x) < 0.9 ? Vec3d{1, 0, 0} : Vec3d{0, 1, 0};
  Vec3d normal = normalize(cross(t, helper));
  std::vector<uint32_t> first;
  for (size_t k = 0; k < count; ++k) {
    t = tangent(k);
    // Parallel transport by projection: keeps the frame from twisting along the path.
    normal = normalize(normal - t * dot(normal, t));
    const Vec3d binormal = cross(t, normal);
    first.push_back(static_cast<uint32_t>(m.vertices.size()));
    for (int s = 0; s < sides; ++s) {
      const double phi = 2.0 * std::numbers::pi * s / sides;
      add_vertex(m, path[k] + (normal * std::cos(phi) + binormal * std::sin(phi)) * radius);
    }
  }
  // Ring points turn counter-clockwise about the tangent, the opposite of the loft
  // convention, hence the mirrored quad and cap order.
  const uint32_t n = static_cast<uint32_t>(sides);
  for (size_t k = 0; k + 1 < count; ++k)
    for (uint32_t i = 0; i < n; ++i) {
      uint32_t j = (i + 1) % n;
      add_quad(m, first[k] + i, first[k] + j, first[k + 1] + j, first[k + 1] + i);
    }
  uint32_t start = add_vertex(m, path.front()), end = add_vertex(m, path.back());
  for (uint32_t i = 0; i < n; ++i) {
    uint32_t j = (i + 1) % n;
    m.triangles.push_back({start, first.front() + j, first.front() + i});
    m.triangles.push_back({end, first.back() + i, first.back() + j});
  }
}

void add_uv_sphere(MeshSoup& m, const Vec3d& centre, double radius, int segments) {
  ST_CHECK(segments >= 3);
  const int stacks = std::max(2, segments / 2);
  const uint32_t n = static_cast<uint32_t>(segments);
  const uint32_t north = add_vertex(m, centre + Vec3d{0, radius, 0});
  std::vector<uint32_t> first;  // rings j = 1 .. stacks-1, from north to south
  for (int j = 1; j < stacks; ++j) {
    const double theta = std::numbers::pi * j / stacks;
    first.push_back(static_cast<uint32_t>(m.vertices.size()));
    for (int i = 0; i < segments; ++i) {
      const double phi = 2.0 * std::numbers::pi * i / segments;
      add_vertex(m, centre + Vec3d{std::sin(theta) * std::cos(phi), std::cos(theta),
                                   std::sin(theta) * std::sin(phi)} * radius);
    }
  }
  const uint32_t south = add_vertex(m, centre - Vec3d{0, radius, 0});
  // Rings run counter-clockwise in (x, z) like a loft, but from top to bottom.
  for (size_t k = 0; k + 1 < first.size(); ++k) join_rings(m, first[k + 1], first[k], n);
  for (uint32_t i = 0; i < n; ++i) {
    uint32_t j = (i + 1) % n;
    m.triangles.push_back({north, first.front() + j, first.front() + i});
    m.triangles.push_back({south, first.back() + i, first.back() + j});
  }
}

}  // namespace st::procedural
