#include "loadgen/view_tiles.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "tiles/core/page_table.hpp"

namespace st::loadgen {

namespace {
// The cell that lookups at `level` (> K) of light-space point (u, v) need first, from the
// skip grid alone (the load tester does not hold index tiles' contents): the tile the
// page-table walk reaches, or, below an index tile of d levels, its sub-cell at K + d.
// False when a constant entry answers.
bool first_cell(const CutGrid& grid, uint32_t level, double u, double v, CellNeed& n) {
  const auto [x, y] = LightSpace::texel_of(level, u, v);
  auto no_index_tiles = [](uint64_t, const GridEntry&) -> const CutGrid* { return nullptr; };
  const PageHit hit = walk_page_table(grid, level, x, y, no_index_tiles);
  if (hit.kind == PageHit::Kind::value) return false;
  const TileAddress a = tile_address(hit.tile);
  n.cell_level = a.level, n.cx = a.x, n.cy = a.y;
  const uint32_t below = a.level + hit.entry.index_levels;
  if (hit.entry.kind == EntryKind::index && level > below) {
    n.cell_level = below;
    n.cx = x >> (level - below), n.cy = y >> (level - below);
  }
  return true;
}
}  // namespace

uint32_t level_for_footprint(double extent, double footprint, uint32_t map_level) {
  if (!(footprint > 0)) return map_level;
  const double l = std::ceil(std::log2(extent / footprint));
  if (!(l > 0)) return 0;
  return l >= double(map_level) ? map_level : uint32_t(l);
}

std::vector<CellNeed> cells_for_points(const std::vector<LightPoint>& points, uint32_t level, const CutGrid& grid) {
  std::vector<CellNeed> out;
  const uint32_t k = grid.levels;
  if (level <= k) return out;
  std::unordered_map<uint64_t, size_t> index;
  for (const LightPoint& lp : points) {
    if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
    CellNeed n;
    if (!first_cell(grid, level, lp.u, lp.v, n)) continue;
    n.level = level;
    if (index.try_emplace(n.key(), out.size()).second) out.push_back(n);
  }
  return out;
}

ViewNeeds view_points(const WorldFrame& world, const Camera& camera, uint32_t, const ViewOptions& o) {
  ViewNeeds out;
  out.samples = o.samples_x * o.samples_y;
  const CameraBasis b = basis(camera);
  const double max_dist = o.max_distance > 0 ? o.max_distance : 1.5 * world.span();
  const double pixel_angle = 2 * b.tan_half_x / std::max(1.0, o.display_width);
  out.points.reserve(out.samples);
  out.footprints.reserve(out.samples);
  for (uint32_t j = 0; j < o.samples_y; ++j)
    for (uint32_t i = 0; i < o.samples_x; ++i) {
      const Vec3d d = ray_dir(b, (i + 0.5) / o.samples_x, (j + 0.5) / o.samples_y);
      if (!(d.y < -1e-9)) continue;  // sky
      const double t = (world.ground - camera.pos.y) / d.y;
      if (!(t > 0) || t > max_dist) continue;
      out.points.push_back(camera.pos + d * t);
      out.footprints.push_back(float(t * pixel_angle));
    }
  return out;
}

ViewNeeds view_needs(const WorldFrame& world, const Camera& camera, uint32_t map_level, const CutGrid& grid,
                     const ViewOptions& o) {
  ViewNeeds out;
  out.samples = o.samples_x * o.samples_y;
  const CameraBasis b = basis(camera);
  const double max_dist = o.max_distance > 0 ? o.max_distance : 1.5 * world.span();
  const double pixel_angle = 2 * b.tan_half_x / std::max(1.0, o.display_width);
  // World size of the map: a sun's box side; a spot's footprint span (approximate).
  const double extent = world.light.parallel() ? world.light.extent_uv() : world.span();
  const uint32_t k = grid.levels;
  std::unordered_map<uint64_t, size_t> index;
  out.points.reserve(out.samples);
  out.footprints.reserve(out.samples);
  for (uint32_t j = 0; j < o.samples_y; ++j)
    for (uint32_t i = 0; i < o.samples_x; ++i) {
      const Vec3d d = ray_dir(b, (i + 0.5) / o.samples_x, (j + 0.5) / o.samples_y);
      if (!(d.y < -1e-9)) continue;  // sky
      const double t = (world.ground - camera.pos.y) / d.y;
      if (!(t > 0) || t > max_dist) continue;
      const Vec3d p = camera.pos + d * t;
      out.points.push_back(p);
      out.footprints.push_back(float(t * pixel_angle));
      const uint32_t level = level_for_footprint(extent, t * pixel_angle, map_level);
      if (level <= k) continue;
      const LightPoint lp = world.light.to_light(p);
      if (!(lp.u >= 0 && lp.u < 1 && lp.v >= 0 && lp.v < 1)) continue;
      CellNeed n;
      if (!first_cell(grid, level, lp.u, lp.v, n)) continue;
      n.level = std::max(level, n.cell_level);
      n.distance = t;
      auto [it, fresh] = index.try_emplace(n.key(), out.cells.size());
      if (fresh) {
        out.cells.push_back(n);
      } else {
        CellNeed& m = out.cells[it->second];
        m.level = std::max(m.level, n.level);
        m.distance = std::min(m.distance, t);
      }
    }
  std::sort(out.cells.begin(), out.cells.end(),
            [](const CellNeed& a, const CellNeed& b) { return a.distance < b.distance; });
  return out;
}

}  // namespace st::loadgen
