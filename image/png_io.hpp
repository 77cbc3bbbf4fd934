// PNG output (libpng): a generic 8-bit RGB writer other commands reuse (render previews)
// and a preview of a depth-interval map.
//
// Preview colours: texels with a hit are grey, brighter = nearer the light (lo mapped
// linearly from the nearest to the farthest hit in the tile); lit texels (no hit, the
// kLitDepth sentinel) are dark blue so they never read as a far surface. Maps larger
// than `max_side` are point-sampled down (every k-th texel) to keep previews small.
//
// Errors: st::Error naming the file. Files are written to PATH.tmp and renamed.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "tiles/core/interval.hpp"

namespace st {

struct Rgb8 {
  uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb8&) const = default;
};

inline constexpr Rgb8 kPreviewLitColour{16, 24, 96};

// `pixels` is row-major, width * height entries, row 0 at the top.
void write_png(const std::string& path, uint32_t width, uint32_t height,
               const std::vector<Rgb8>& pixels);

// Reads an 8-bit RGB or grey PNG back (tests and tools). Throws st::FormatError.
std::vector<Rgb8> read_png(const std::string& path, uint32_t& width, uint32_t& height);

// One 8-bit plane of a PNG (any PNG colour type and depth, converted by libpng): its
// alpha, and its grey level (sRGB colour turned to grey by libpng); `has_alpha` says
// whether the file carries alpha (an alpha channel or tRNS), else alpha is all 255.
// Rows are as stored (row 0 at the top). Images over max_texels are refused before
// anything is decoded (memory stays bounded). Throws st::FormatError naming `name`.
struct PngPlanes {
  uint32_t width = 0, height = 0;
  bool has_alpha = false;
  std::vector<uint8_t> grey, alpha;  // width * height each
};
PngPlanes read_png_planes(const std::string& path, uint64_t max_texels);
// The same from bytes in memory (a texture embedded in a scene file).
PngPlanes read_png_planes(const void* data, size_t size, const std::string& name,
                          uint64_t max_texels);
// Writes an 8-bit grey + alpha PNG (tests and tools); `ga` is width * height pairs.
void write_png_grey_alpha(const std::string& path, uint32_t width, uint32_t height,
                          const std::vector<uint8_t>& ga);

// The preview image of `tile` (point-sampled to at most max_side a side).
std::vector<Rgb8> depth_preview(const IntervalTile& tile, uint32_t max_side, uint32_t& width,
                                uint32_t& height);
void write_depth_preview_png(const std::string& path, const IntervalTile& tile,
                             uint32_t max_side = 4096);

}  // namespace st
