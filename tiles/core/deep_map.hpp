// A deep shadow map as a grid of deep tiles (DEEP.md; DSM 2000 §5.4 "tiled format"):
// level L is cut into tiles of 2^side_bits texels a side; a tile that no partial
// occluder touches is absent and answers transmittance 1. Lookups take map coordinates
// (u, v) in [0, 1) (light.hpp) and a light-space depth; `filtered` takes a footprint
// width in map units and filters within the tile holding (u, v) (bilinear clamps at the
// tile's edge; a footprint wider than a tile is answered by the tile's coarsest mip).
// No allocation per lookup; the map borrows the tiles' bytes (they must outlive it).
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/deep_tile.hpp"

namespace st {

class DeepMap {
 public:
  // Tiles are given by position; each is opened (validated) here. Throws st::Error for
  // a level above 20, side_bits above the map level or deep::kMaxSideBits, a tile outside
  // the map or given twice, or a tile whose side differs (st::FormatError for a bad tile).
  DeepMap(uint32_t level, uint32_t side_bits);
  void add_tile(uint32_t tx, uint32_t ty, std::span<const uint8_t> bytes);

  uint32_t level() const { return level_; }
  uint32_t side_bits() const { return side_bits_; }
  uint32_t tiles_per_side() const { return 1u << (level_ - side_bits_); }
  size_t tile_count() const { return tiles_.size(); }

  std::array<float, 3> transmittance(double u, double v, float z) const;
  std::array<float, 3> filtered(double u, double v, float z, double width) const;

 private:
  const DeepTileView* tile_at(double u, double v, double& lu, double& lv) const;
  uint32_t level_ = 0, side_bits_ = 0;
  // Present tiles sorted by key ty * tiles_per_side + tx (absent tiles cost nothing; a
  // lookup is a binary search).
  std::vector<std::pair<uint64_t, DeepTileView>> tiles_;
};

}  // namespace st
