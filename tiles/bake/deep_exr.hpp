// Deep shadow maps as deep scanline OpenEXR files (OpenEXR 3, "Interpreting OpenEXR Deep
// Pixels"), so compositing and lighting tools that read deep images read our visibility
// functions (DSM 2000 §3.1: a deep shadow pixel is the deep-image alpha 1 - V at every z).
//
// Layout of a file written here (ZIPS compression, lossless):
//   type       deepscanline, one pixel per texel of the region, row j = region row j
//   channels   "Z", "ZBack" FLOAT: a sample's front and back light-space depth d
//              "A" FLOAT (monochrome file) or "AR", "AG", "AB" FLOAT (coloured file):
//              the fraction of the light that reaches Z and is stopped before ZBack
//   samples    per texel, front to back, one per vertex pair whose transmittance drops:
//              Z == ZBack a point sample (a surface step), Z < ZBack a volumetric
//              sample (a linear run); samples do not overlap. A first vertex below 1
//              adds a point sample in front. Compositing "over" front to back gives
//              1 - V exactly at every vertex depth; inside a volumetric sample OpenEXR
//              interpolates exponentially where our function is linear (the two agree
//              at both ends; they differ by at most the run's curvature).
//   attributes "shadowtile.deep" int 1 (format version), "shadowtile.level",
//              "shadowtile.x0", "shadowtile.y0" int (as interval EXRs), and
//              "shadowtile.epsilon" string (%.9g) when given.
// read_deep_exr rebuilds the functions (exact up to float rounding of the products).
//
// Errors: write throws st::Error naming the file (written to PATH.tmp, then renamed);
// read throws st::FormatError naming the file and what is wrong (not deep, channels
// missing or of another type, a region outside the map, unsorted or overlapping samples,
// alpha outside [0, 1], more than kMaxDeepExrSamples samples).
#pragma once
#include <string>

#include "tiles/bake/deep_sampler.hpp"

namespace st {

inline constexpr int kDeepExrFormatVersion = 1;  // format constant: bump on change
inline constexpr uint64_t kMaxDeepExrSamples = uint64_t(1) << 28;  // read-side limit

void write_deep_exr(const std::string& path, const DeepRegion& region, double epsilon = -1);
DeepRegion read_deep_exr(const std::string& path);

// What a compositor sees: OpenEXR's own deep compositing (Imf::CompositeDeepScanLine)
// flattens a monochrome file to one alpha per texel, row-major; it should equal 1 - V
// behind the last sample. Throws st::FormatError for a coloured or unreadable file.
std::vector<float> composite_deep_exr_alpha(const std::string& path);

}  // namespace st
