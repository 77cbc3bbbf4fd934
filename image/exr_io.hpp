// Depth-interval maps as OpenEXR files (ARCHITECTURE.md "Definitions": depths are float32, never quantized).
//
// Layout of a file written here (OpenEXR 3, lossless ZIP compression):
//   channels   "hi", "lo"   FLOAT (32-bit), one sample per texel
//   data window (0, 0) - (width - 1, height - 1); row j of the file = tile row j
//   storage    scanline when both sides are <= kExrScanlineMaxSide, otherwise tiled
//              (kExrTileSide^2 tiles, ONE_LEVEL) so huge maps stream tile by tile
//   attributes "shadowtile.format"  int     kExrFormatVersion
//              "shadowtile.level"   int     map level L (2^L texels a side)
//              "shadowtile.x0"      int     first texel column of the region in the map
//              "shadowtile.y0"      int     first texel row
//              "shadowtile.light"   string  light spec (LightSpec::to_string), optional
//              "shadowtile.lightspace" string 18 doubles (%.17g) + kind, optional
// Round trip is bit-exact (float32 channels, lossless compression).
//
// Errors: write throws st::Error naming the file (the file is written to PATH.tmp and
// renamed, so an existing file is never left half-written); read throws
// st::FormatError naming the file and field for anything missing, malformed or
// inconsistent (wrong channel type, region outside the map, oversize data window).
#pragma once
#include <optional>
#include <string>

#include "tiles/core/interval.hpp"
#include "tiles/core/light.hpp"

namespace st {

inline constexpr int kExrFormatVersion = 1;       // format constant: bump on change
inline constexpr uint32_t kExrScanlineMaxSide = 4096;
inline constexpr uint32_t kExrTileSide = 256;
inline constexpr uint64_t kExrMaxTexels = uint64_t(16384) * 16384;  // read-side limit

struct ExrLightInfo {
  std::string spec;                  // LightSpec::to_string(), may be empty
  std::optional<LightSpace> space;   // exact light space when it was written
};

void write_interval_exr(const std::string& path, const IntervalTile& tile,
                        const ExrLightInfo& light = {});

IntervalTile read_interval_exr(const std::string& path, ExrLightInfo* light = nullptr);

// True when the file at `path` was stored as a tiled EXR (for tests and tools).
bool exr_is_tiled(const std::string& path);

}  // namespace st
