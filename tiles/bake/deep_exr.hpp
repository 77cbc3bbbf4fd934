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
//              "shadowtile.x0", "shadowtile.y0" int (as interval EXRs), and when known
//              "shadowtile.epsilon" string (%.9g), "shadowtile.samples" int (samples
//              per texel side), "shadowtile.light" string (the light spec the depths
//              are measured for), "shadowtile.scene" string (the scene's content_hash
//              in 16 hex digits): all optional, so older files still read.
// read_deep_exr rebuilds the functions (exact up to float rounding of the products).
//
// Other tools' deep images (no "shadowtile.deep" attribute) are read too when they are
// tidy (samples sorted front to back, not overlapping) and hold a whole map: a square,
// power-of-two data window at (0, 0) is level log2(side), x0 = y0 = 0. Their channels:
// "Z" FLOAT, "ZBack" FLOAT or absent (point samples), and "A" or "AR", "AG", "AB" in
// FLOAT or HALF (other channels ignored). Their depths must already be the light-space d
// of the map they are for: the caller checks the range.
//
// Errors: write throws st::Error naming the file (written to PATH.tmp, then renamed);
// read throws st::FormatError naming the file and what is wrong (not deep, another
// format version, channels missing or of another type, a region outside the map, a
// window over max_texels, unsorted or overlapping samples, alpha outside [0, 1], more
// than kMaxDeepExrSamples samples).
#pragma once
#include <string>

#include "tiles/bake/deep_sampler.hpp"

namespace st {

inline constexpr int kDeepExrFormatVersion = 1;  // format constant: bump on change
inline constexpr uint64_t kMaxDeepExrSamples = uint64_t(1) << 28;  // read-side limit

// What a file says about how it was made (its optional attributes above).
struct DeepExrInfo {
  double epsilon = -1;            // < 0: not recorded
  uint32_t samples_per_side = 0;  // 0: not recorded
  std::string light;              // empty: not recorded
  std::string scene_hash;         // empty: not recorded
  bool foreign = false;           // read: no shadowtile.deep attribute (another tool's)
};

void write_deep_exr(const std::string& path, const DeepRegion& region, double epsilon = -1);
void write_deep_exr(const std::string& path, const DeepRegion& region, const DeepExrInfo& info);
// `info`, when given, receives the file's attributes. Memory: max_texels functions plus
// at most kMaxDeepExrSamples samples of 20 bytes.
DeepRegion read_deep_exr(const std::string& path, DeepExrInfo* info = nullptr,
                         uint64_t max_texels = uint64_t(16384) * 16384);

// What a compositor sees: OpenEXR's own deep compositing (Imf::CompositeDeepScanLine)
// flattens a monochrome file to one alpha per texel, row-major; it should equal 1 - V
// behind the last sample. Throws st::FormatError for a coloured or unreadable file.
std::vector<float> composite_deep_exr_alpha(const std::string& path);

}  // namespace st
