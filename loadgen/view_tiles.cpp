#include "loadgen/view_tiles.hpp"

#include <algorithm>
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

}  // namespace st::loadgen
