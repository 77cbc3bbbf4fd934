// PackReader for stack packs (tiles/PACK.md "Stack packs"): the grid section is a
// StackGrid, every tile an MH octree buffer of one level-K cell's subtree.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/stack_slices.hpp"
#include "tiles/core/stack_grid.hpp"

namespace st {

void PackReader::load_stack() {
  stack_ = std::make_unique<StackGrid>(
      StackGrid::parse(grid_bytes_, name_ + ": stack grid at byte " + std::to_string(header_.grid_offset)));
  const StackGrid& g = *stack_;
  if (g.skip_level != header_.skip_level || g.geo.n != header_.map_level || g.light_kind != header_.light_kind)
    throw FormatError(where(header_.grid_offset) + ": stack grid disagrees with the header (skip level, map level or light kind)");
  if (g.split() != bool(header_.flags & kFeatureStackSplitCells))
    throw FormatError(where(header_.grid_offset) + (g.split() ? ": stack grid splits cells (version 2) in a pack without feature stack_split_cells"
                                                              : ": feature stack_split_cells on a stack grid that splits no cell"));
  if (g.lights[0] != header_.light)
    throw FormatError(where(40) + ": header light differs from the stack's slice 0");
  if (header_.encoding != Encoding::mh || (header_.flags & kFeatureIndexTiles))
    throw FormatError(where(20) + ": a stack pack holds MH octree tiles only (encoding mh, no index tiles)");
}

void PackReader::check_stack_index() const {
  const StackGrid& g = *stack_;
  uint64_t named = 0;
  for (uint64_t i = 0; i < g.entries.size(); ++i) {
    if (g.entries[i].kind != 1) continue;  // constant, or split (its children are entries)
    ++named;
    const auto t = find(g.tile_id(i));
    if (!t || t->kind != TileKind::encoded || g.entries[i].level == g.geo.depth())
      throw FormatError(name_ + ": stack cell " + std::to_string(i) + " names " + describe_tile(g.tile_id(i)) +
                        ", which the tile index lacks (or the cell is at the finest level)");
  }
  if (named != index_.size())
    throw FormatError(name_ + ": " + std::to_string(index_.size() - std::min<uint64_t>(named, index_.size())) +
                      " tiles no stack cell names");
}

void PackReader::verify_stack() const {
  // The index was matched with the journal and every tile named exactly once (open);
  // here every tile inflates and opens as an MH octree of its cell's geometry.
  const StackGrid& g = *stack_;
  for (const TileIndexEntry& e : index_) {
    const std::string what = name_ + ": " + describe_tile(e.id) + " at byte " + std::to_string(e.offset);
    uint64_t cell = 0;
    if (!g.cell_of(e.id, cell) || g.entries[cell].kind != 1) throw FormatError(what + ": no stack cell names it");
    const uint32_t l = g.entries[cell].level;  // K, or deeper for a split cell's child
    const uint32_t n = g.geo.n - g.geo.xy_bits(l), k = g.geo.k - g.geo.w_bits(l);
    const std::vector<uint8_t> raw = read_raw(e.id);
    if (is_slice_tiles(raw)) {
      // A per-slice cell (stack_slices.hpp): only in a pack that says so.
      if (!(header_.flags & kFeatureStackSliceTiles))
        throw FormatError(what + ": a per-slice cell (\"STSL\") in a pack without feature stack_slice_tiles");
      SliceTiles t;
      try {
        t = SliceTiles::open(raw);
      } catch (const Error& err) {
        throw FormatError(what + ": " + err.what());
      }
      if (t.xy_level() != n || t.w_level() != k) throw FormatError(what + ": per-slice cell geometry differs from its cell's");
      if (t.has_planes() && !(header_.flags & kFeaturePlaneTiles))
        throw FormatError(what + ": a per-slice cell with plane slices (\"STPN\") in a pack without feature plane_tiles");
      if (t.has_wide_planes() && !(header_.flags & kFeatureWidePlaneBlocks))
        throw FormatError(what + ": a per-slice cell with wide labelled plane slices (version 3) in a pack without feature wide_plane_blocks");
      continue;
    }
    MhOctree t;
    try {
      t = MhOctree::open(raw);
    } catch (const Error& err) {
      throw FormatError(what + ": " + err.what());
    }
    if (t.geometry().n != n || t.geometry().k != k || t.slices() != (1u << k))
      throw FormatError(what + ": octree geometry differs from its cell's");
    if (t.depth(0, 0, 0, 0) != g.entries[cell].value)
      throw FormatError(what + ": root value differs from its cell entry's");
  }
}

void PackReader::check_stack_range() const {
  const StackGrid& g = *stack_;
  auto bad = [&](float v) { return !(v >= 0.0f && v <= kLitDepth); };
  for (const auto& lv : g.coarse)
    if (std::any_of(lv.begin(), lv.end(), bad))
      throw FormatError(name_ + ": stack grid: a coarse value outside the depth range [0, 1]");
  for (const StackEntry& e : g.entries)
    if (bad(e.value)) throw FormatError(name_ + ": stack grid: an entry value outside the depth range [0, 1]");
}

std::string PackReader::stack_summary() const {
  const StackGrid& g = *stack_;
  uint64_t tiles = 0, split = 0;
  for (const StackEntry& e : g.entries) tiles += e.kind == 1, split += e.kind == kStackSplit;
  char buf[260];
  std::snprintf(buf, sizeof buf,
                "  stack: %u slices of %llu^2 (octree %u levels, w padded to %u), skip level %u: %llu cells (%llu split), "
                "%llu tiles\n",
                g.slices, (unsigned long long)(uint64_t(1) << g.geo.n), g.geo.levels(), 1u << g.geo.k, g.skip_level,
                (unsigned long long)g.entries.size(), (unsigned long long)split, (unsigned long long)tiles);
  return std::string(buf) + "  light set: " + g.spec + "\n";
}

}  // namespace st
