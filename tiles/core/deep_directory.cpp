// The deep directory: see deep_directory.hpp.
#include "tiles/core/deep_directory.hpp"

#include <bit>
#include <cmath>
#include <cstring>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/deep_format.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

uint64_t DeepDirectory::tile_count() const {
  uint64_t n = 0;
  for (uint8_t b : bitmap) n += uint64_t(std::popcount(b));
  return n;
}

uint64_t DeepDirectory::tile_id(uint32_t tx, uint32_t ty) const {
  return kDeepTileIdBit | make_tile_id(tiles_per_side_bits(), tx, ty);
}

namespace {
std::string shape_error(uint32_t level, uint32_t side_bits) {
  if (level > kMaxLevel) return "level " + std::to_string(level) + " above " + std::to_string(kMaxLevel);
  if (side_bits > deep::kMaxSideBits || side_bits > level)
    return "tiles of 2^" + std::to_string(side_bits) + " texels in a level-" + std::to_string(level) +
           " map (at most 2^" + std::to_string(deep::kMaxSideBits) + " and the map's side)";
  if (level - side_bits > deep::kMaxTilesPerSideBits)
    return "2^" + std::to_string(level - side_bits) + " tiles a side (at most 2^" +
           std::to_string(deep::kMaxTilesPerSideBits) + ")";
  return {};
}
}  // namespace

DeepDirectory DeepDirectory::make(uint32_t level, uint32_t side_bits, float epsilon, uint32_t samples_per_side) {
  if (std::string why = shape_error(level, side_bits); !why.empty()) throw Error("deep directory: " + why);
  if (!std::isfinite(epsilon) || epsilon < 0) throw Error("deep directory: epsilon must be finite and >= 0");
  if (samples_per_side < 1 || samples_per_side > 64) throw Error("deep directory: samples per side in 1..64");
  DeepDirectory d;
  d.level = level, d.side_bits = side_bits, d.epsilon = epsilon, d.samples_per_side = samples_per_side;
  d.bitmap.assign(bitmap_bytes(level - side_bits), 0);
  return d;
}

std::vector<uint8_t> DeepDirectory::serialize() const {
  std::vector<uint8_t> out;
  out.reserve(deep::kDirectoryHeaderBytes + bitmap.size());
  append_le<uint32_t>(out, deep::kDirectoryMagic);
  append_le<uint32_t>(out, deep::kDirectoryVersion);
  append_le<uint32_t>(out, deep::kDirectoryHeaderBytes);
  append_le<uint32_t>(out, level);
  append_le<uint32_t>(out, side_bits);
  append_le<uint32_t>(out, uint32_t(tile_count()));
  append_le<float>(out, epsilon);
  append_le<uint32_t>(out, samples_per_side);
  out.insert(out.end(), bitmap.begin(), bitmap.end());
  return out;
}

DeepDirectory DeepDirectory::parse(std::span<const uint8_t> b, const std::string& what) {
  auto fail = [&](size_t off, const std::string& msg) {
    throw FormatError(what + ": deep directory: " + msg + " (byte " + std::to_string(off) + ")");
  };
  if (b.size() < deep::kDirectoryHeaderBytes)
    fail(0, "truncated: " + std::to_string(b.size()) + " bytes, the header needs 32");
  if (load_le<uint32_t>(b, 0) != deep::kDirectoryMagic) fail(0, "bad magic");
  if (load_le<uint32_t>(b, 4) != deep::kDirectoryVersion) fail(4, "unknown version " + std::to_string(load_le<uint32_t>(b, 4)));
  if (load_le<uint32_t>(b, 8) != deep::kDirectoryHeaderBytes) fail(8, "bad header size");
  DeepDirectory d;
  d.level = load_le<uint32_t>(b, 12);
  d.side_bits = load_le<uint32_t>(b, 16);
  if (std::string why = shape_error(d.level, d.side_bits); !why.empty()) fail(12, why);
  const uint32_t n = load_le<uint32_t>(b, 20);
  d.epsilon = load_le<float>(b, 24);
  if (!std::isfinite(d.epsilon) || d.epsilon < 0) fail(24, "epsilon not finite and >= 0");
  d.samples_per_side = load_le<uint32_t>(b, 28);
  if (d.samples_per_side < 1 || d.samples_per_side > 64) fail(28, "samples per side outside 1..64");
  const uint32_t p = d.level - d.side_bits;
  const size_t want = bitmap_bytes(p);
  if (b.size() != deep::kDirectoryHeaderBytes + want)
    fail(32, std::to_string(b.size() - deep::kDirectoryHeaderBytes) + " bitmap bytes, the shape needs " +
                 std::to_string(want));
  d.bitmap.assign(b.begin() + deep::kDirectoryHeaderBytes, b.end());
  const uint64_t bits = uint64_t(1) << (2 * p);
  if (bits % 8 && (d.bitmap.back() >> (bits % 8)) != 0) fail(b.size() - 1, "bits past the last tile set");
  if (n == 0 || d.tile_count() != n)
    fail(20, "tile count " + std::to_string(n) + " != the bitmap's " + std::to_string(d.tile_count()) +
                 " (and must be >= 1)");
  return d;
}

}  // namespace st
