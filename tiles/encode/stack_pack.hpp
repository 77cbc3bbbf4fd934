// The cut and the pack of a shadow-map stack (tiles/PACK.md "Stack packs"): an
// OctHierarchy (MH 2016 §4) cut at octree level K into a StackGrid and one MH octree
// buffer per level-K cell with anything stored below it, written as a pack with the
// `stack` feature.
#pragma once
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "tiles/encode/mh_octree_build.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/stack_grid.hpp"

namespace st {

struct StackCut {
  StackGrid grid;  // lights and spec left empty: the caller fills them
  std::vector<std::pair<uint64_t, std::vector<uint8_t>>> tiles;  // (cell, octree buffer), by cell
  uint64_t max_tile_bytes = 0;
};

// The default skip level: ceil(L / 2), lowered until the level has at most 2^18 cells.
uint32_t default_stack_skip_level(const moct::Geometry& g);

// Cuts at level `skip_level` (default above). A cell with nothing stored below is a
// constant entry; otherwise its subtree, root made valued (an empty root inherits its
// ancestor's value), is encoded. If a tile exceeds `tile_bytes` the whole cut moves one
// level deeper (a uniform K keeps tile ids one level), up to the finest level above the
// leaves or kStackMaxCells cells; past that it throws st::Error naming the largest tile.
StackCut cut_stack(const OctHierarchy& h, std::optional<uint32_t> skip_level, uint32_t tile_bytes);

// The subtree below `root` (a node of level K of `h` with children) as a hierarchy of its
// own, root made valued with `inherited` when it is empty: what cut_stack encodes for a
// cell. `cursor` (L + 1 zeros at first) carries the scan of h's levels between calls made
// in increasing code order.
OctHierarchy cell_subtree(const OctHierarchy& h, uint32_t K, const OctNode& root, float inherited,
                          std::vector<size_t>& cursor);

struct StackPackParams {
  uint32_t tile_bytes = 64 * 1024;
  uint32_t flags = 0;  // extra features (exit_depths)
  uint64_t scene_hash = 0;
  PackParamList build_params;
  int compression_level = 6;
  // Per-slice cells stored grouped ("STSP", tiles/core/stack_slices.hpp); off: as STSL.
  bool group_slice_tiles = true;
  // The finished layout of 2D packs (tiles/PACK.md "Payloads only", "Compressed grid
  // section"): the stored tiles back to back without journal records, the tile index
  // compact, and the stack grid as one zlib stream. Off: records, plain index, raw grid.
  bool payloads_only = true;
  bool compress_grid = true;
};

// Writes the pack as `path`.tmp, then renames it to `path`. Returns the file size.
uint64_t write_stack_pack(const std::string& path, const StackCut& cut, const StackPackParams& p);

// The same pack streamed: `tile(i)` gives the i-th (cell, octree buffer) of `count`, in
// increasing cell order; one tile is held at a time (blocked builds). Same bytes.
uint64_t write_stack_pack(const std::string& path, const StackGrid& grid, size_t count,
                          const std::function<std::pair<uint64_t, std::vector<uint8_t>>(size_t)>& tile,
                          const StackPackParams& p);

}  // namespace st
