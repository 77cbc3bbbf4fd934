// What one camera frame needs from the map: a grid of screen samples is cast
// onto the ground plane of the WorldFrame (the receivers the frame shades), and each
// sample picks the map level whose texel matches its pixel's footprint (finer near the
// camera, coarser far away: the hierarchy's every level is a complete map, MH §3.3).
// Samples needing a level finer than the skip level K need the tile under their level-K
// cell (or, under an index entry, the sub-cell one index level deeper); coarser samples
// are answered by the skip grid and need nothing.
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

struct ViewNeeds {
  std::vector<Vec3d> points;     // receivers (world) of the samples that hit the ground
  std::vector<float> footprints; // per point: its pixel's side in world units (filtered lookups)
  std::vector<CellNeed> cells;   // nearest first
  uint32_t samples = 0;          // samples_x * samples_y
};

ViewNeeds view_needs(const WorldFrame& world, const Camera& camera, uint32_t map_level, const CutGrid& grid,
                     const ViewOptions& options = {});

// view_needs' points and footprints alone (cells empty): what a frame looks up. The tiles
// they need come from client::Map::request_view, which casts the same samples.
ViewNeeds view_points(const WorldFrame& world, const Camera& camera, uint32_t map_level,
                      const ViewOptions& options = {});

// The cells lookups at `level` of these light-space points need (outside points and
// constant entries need none); for renderers that know their receivers exactly.
std::vector<CellNeed> cells_for_points(const std::vector<LightPoint>& points, uint32_t level, const CutGrid& grid);

// Level whose texel is about `footprint` world units for a map of `extent` world units,
// clamped to [0, map_level].
uint32_t level_for_footprint(double extent, double footprint, uint32_t map_level);

}  // namespace st::loadgen
