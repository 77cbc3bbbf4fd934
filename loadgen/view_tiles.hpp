// A synthetic camera's screen: its sample grid and display (the rays themselves are cast
// by the client, client::Map::view_samples and request_view, from the camera's matrix),
// and the cells that lookups at known light-space points need (render, report): a point
// needing a level finer than the skip level K needs the tile under its level-K cell (or,
// under an index entry, the sub-cell one index level deeper).
#pragma once
#include <cstdint>
#include <vector>

#include "loadgen/camera_path.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st::loadgen {

struct ViewOptions {
  uint32_t samples_x = 64, samples_y = 36;  // shaded points per frame
  double display_width = 1920;              // pixels across: sets each sample's level
  double max_distance = 0;                  // 0: 1.5 spans of the footprint
};

// The need of one cell: every tile under texels [x0, x0+w) x [y0, y0+w) of `level`.
struct CellNeed {
  uint32_t level = 0;       // finest level a sample in the cell asked for (> K)
  uint32_t cell_level = 0;  // K, or K + index levels under an index entry
  uint64_t cx = 0, cy = 0;  // cell at cell_level
  double distance = 0;      // nearest sample's distance from the camera
  uint64_t x0() const { return cx << (level - cell_level); }
  uint64_t y0() const { return cy << (level - cell_level); }
  uint64_t side() const { return uint64_t(1) << (level - cell_level); }
  uint64_t key() const { return (uint64_t(cell_level) << 58) | (cy << 29) | cx; }
};

// The cells lookups at `level` of these light-space points need (outside points and
// constant entries need none); for renderers that know their receivers exactly.
std::vector<CellNeed> cells_for_points(const std::vector<LightPoint>& points, uint32_t level, const CutGrid& grid);

}  // namespace st::loadgen
