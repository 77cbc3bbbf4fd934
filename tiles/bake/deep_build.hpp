// The deep tiles of a whole map (DSM 2000 §5.4): level L cut into tiles of 2^side_bits
// texels a side, each sampled (deep_sampler.hpp) and encoded with its mips
// (deep_encode.hpp). A tile whose every function is empty (no partial occluder along any
// of its rays) is not stored, so a scene without partial occluders has no deep data.
// Tiles are built one at a time (memory: one tile's functions); the result is sorted
// by (ty, tx).
#pragma once
#include <cstdint>
#include <vector>

#include "tiles/bake/deep_sampler.hpp"
#include "tiles/encode/deep_encode.hpp"

namespace st {

struct DeepTileBytes {
  uint32_t tx = 0, ty = 0;
  std::vector<uint8_t> bytes;
};

struct DeepMapBuild {
  uint32_t level = 0, side_bits = 0;
  std::vector<DeepTileBytes> tiles;
  DeepSampleStats sampling;
  uint64_t bytes = 0;          // all tiles
  uint64_t empty_tiles = 0;    // not stored
};

// Throws st::Error for side_bits above the level or deep::kMaxSideBits, a map of more
// than 2^20 tiles, or a tile over max_tile_bytes (raise epsilon or shrink the tiles).
DeepMapBuild build_deep_tiles(const DeepSampler& sampler, uint32_t level, uint32_t side_bits,
                              const DeepSampleOptions& options,
                              uint64_t max_tile_bytes = uint64_t(64) << 20);

// The same tiles from functions already made, e.g. read from a deep OpenEXR
// (deep_exr.hpp): `map` must hold the whole of its level (x0 = y0 = 0, 2^level a side,
// every function passing check(), depths in [0, 1]). recompress_epsilon >= 0 first
// compresses every function with that bound (§3.3); negative keeps them as they are.
// encode_epsilon is the mip-0 bound the mips are recompressed against (deep_encode.hpp).
// Memory: the map itself plus one tile. st::Error (one line, naming the texel or tile)
// for a partial region, a depth outside [0, 1], an invalid function or a tile over
// max_tile_bytes. sampling.vertices_in / vertices_out count before and after.
DeepMapBuild deep_tiles_from_functions(const DeepRegion& map, uint32_t side_bits, double recompress_epsilon,
                                       double encode_epsilon, uint64_t max_tile_bytes = uint64_t(64) << 20);

class PackWriter;

// Appends the deep map to a pack (tiles/PACK.md "Deep tiles"): each tile as a deep tile
// record, then the deep directory (deep_pack.hpp) naming them. `epsilon` and
// `samples_per_side` are the build's (the directory records them). Nothing is appended
// for a map without tiles (no partial occluder: the pack stays as it was). st::Error if
// a tile or the directory exceeds the pack's tile_bytes.
void append_deep_map(PackWriter& writer, const DeepMapBuild& map, double epsilon, uint32_t samples_per_side);

}  // namespace st
