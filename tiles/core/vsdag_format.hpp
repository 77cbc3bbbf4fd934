// Voxel shadow DAG tile format, version 1 (voxelized shadows 2014, §3-§6): one tile's
// shadow volume in projected light space as a DAG of octree nodes with 3-state child
// masks, leaves of 8x8x1 voxels in 64-bit masks (§5, §6.2) and a dense top grid (§6.2
// "Optimizations"). tiles/core/VSDAG.md draws the layout and states the exactness
// contract; tests/tiles/vsdag_format_test.cpp pins every offset below.
//
// Every constant marked "format constant" is part of the on-disk layout: changing one
// changes kVersion.
#pragma once
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace st::vsdag {

inline constexpr uint32_t kMagic = 0x47445356;  // "VSDG" little-endian; format constant
inline constexpr uint32_t kVersion = 1;         // format constant

inline constexpr uint32_t kLeafXyBits = 3;   // a leaf is 8x8 texels of one depth slab; format constant
inline constexpr uint32_t kZNodeBits = 3;    // the node above the leaves splits depth 8 ways; format constant
inline constexpr uint32_t kMinZBits = 3, kMaxZBits = 20;  // depth resolution 2^z_bits slabs; format constants
inline constexpr uint32_t kDefaultZBits = 16;
inline constexpr uint32_t kGridMaxCells = 64;  // top levels folded into the grid up to this many cells; format constant
inline constexpr uint32_t kMaxLevels = 40;     // inner octree levels (<= 17 xy + 17 z splits)
inline constexpr uint32_t kMaxCount = 1u << 30;  // node_words, leaf_count; format constant

// Child and grid states (2 bits; format constants). A leaf bit set = lit.
inline constexpr uint32_t kShadow = 0, kLit = 1, kMixed = 2;
inline constexpr uint32_t kStateShift = 30;          // grid cell: state in bits 31..30
inline constexpr uint32_t kIndexMask = (1u << 30) - 1;  // grid cell: node word offset in 29..0

// Split of one inner level: bit 0 = splits x and y, bit 1 = splits depth.
inline constexpr uint8_t kSplitXy = 1, kSplitZ = 2;

// Header: 64 bytes, all uint32 little-endian, at byte 0.
struct Header {
  uint32_t magic;          //  0
  uint32_t version;        //  4
  uint32_t header_bytes;   //  8 = 64
  uint32_t xy_bits;        // 12 finest level: the tile is 2^xy_bits texels a side, <= 20
  uint32_t z_bits;         // 16 depth slabs 2^z_bits, kMinZBits..kMaxZBits
  uint32_t grid_xy_bits;   // 20 = Shape::of(xy_bits, z_bits)
  uint32_t grid_z_bits;    // 24 idem
  uint32_t inner_levels;   // 28 idem
  uint32_t leaf_count;     // 32 < 2^30
  uint32_t node_words;     // 36 < 2^30
  uint32_t leaf_offset;    // 40 = 64
  uint32_t grid_offset;    // 44 = leaf_offset + 8 * leaf_count
  uint32_t node_offset;    // 48 = grid_offset + 4 * grid cells
  uint32_t total_bytes;    // 52 = node_offset + 4 * node_words = the buffer's length
  uint32_t reserved0;      // 56 = 0
  uint32_t reserved1;      // 60 = 0
};
static_assert(sizeof(Header) == 64);
static_assert(offsetof(Header, total_bytes) == 52);

// The tree's shape, a function of (xy_bits, z_bits) alone. The voxel volume is
// 2^p x 2^p x 2^z_bits with p = max(xy_bits, 3) (tiles under 8x8 are padded by repeating
// their edge). Bottom up: leaves 8x8x1, the z-node above them 1x1x8 (§5 "8x8x1"), then
// inner levels splitting x and y by 2 and/or depth by 2. Top down the splits go: the axis
// with more bits left splits alone, then both together (an octree, §4); the first levels
// fold into the dense grid while it stays within kGridMaxCells.
struct Shape {
  uint32_t xy_bits = 0, z_bits = 0, padded_xy_bits = 0;
  uint32_t grid_xy_bits = 0, grid_z_bits = 0;
  uint32_t levels = 0;              // inner levels between the grid and the z-nodes
  uint8_t split[kMaxLevels] = {};   // kSplitXy | kSplitZ per inner level, top down
  uint8_t xy_shift[kMaxLevels] = {};  // coordinate bit level i splits on (x and y)
  uint8_t z_shift[kMaxLevels] = {};   // slab bit level i splits on
  uint32_t grid_cells() const { return 1u << (2 * grid_xy_bits + grid_z_bits); }
  // Grid cell of texel (x, y) at slab k: (cz << 2gx) | (cy << gx) | cx.
  uint32_t grid_cell(uint64_t x, uint64_t y, uint32_t k) const {
    const uint32_t xs = padded_xy_bits - grid_xy_bits, zs = z_bits - grid_z_bits;
    return uint32_t(((k >> zs) << (2 * grid_xy_bits)) | ((y >> xs) << grid_xy_bits) | (x >> xs));
  }
  // Child slot at inner level i: bit 0 x, bit 1 y, bit 2 depth (0 for an axis not split).
  uint32_t child(uint32_t i, uint64_t x, uint64_t y, uint32_t k) const {
    uint32_t c = 0;
    if (split[i] & kSplitXy) c |= uint32_t((x >> xy_shift[i]) & 1) | uint32_t(((y >> xy_shift[i]) & 1) << 1);
    if (split[i] & kSplitZ) c |= ((k >> z_shift[i]) & 1) << 2;
    return c;
  }
  static Shape of(uint32_t xy_bits, uint32_t z_bits) {
    Shape s;
    s.xy_bits = xy_bits, s.z_bits = z_bits;
    s.padded_xy_bits = xy_bits < kLeafXyBits ? kLeafXyBits : xy_bits;
    uint32_t a = s.padded_xy_bits - kLeafXyBits, b = z_bits - kZNodeBits;  // splits left
    uint8_t seq[kMaxLevels];
    uint32_t n = 0;
    while (a > 0 || b > 0) {
      const uint8_t sp = a > b ? kSplitXy : b > a ? kSplitZ : uint8_t(kSplitXy | kSplitZ);
      if (sp & kSplitXy) --a;
      if (sp & kSplitZ) --b;
      seq[n++] = sp;
    }
    uint32_t first = 0, cells_log = 0;
    while (first < n) {
      const uint32_t add = (seq[first] & kSplitXy ? 2 : 0) + (seq[first] & kSplitZ ? 1 : 0);
      if ((1u << (cells_log + add)) > kGridMaxCells) break;
      cells_log += add;
      if (seq[first] & kSplitXy) ++s.grid_xy_bits;
      if (seq[first] & kSplitZ) ++s.grid_z_bits;
      ++first;
    }
    uint32_t xs = s.padded_xy_bits - s.grid_xy_bits, zs = z_bits - s.grid_z_bits;
    for (uint32_t i = first; i < n; ++i) {
      const uint32_t l = s.levels++;
      s.split[l] = seq[i];
      if (seq[i] & kSplitXy) s.xy_shift[l] = uint8_t(--xs);
      if (seq[i] & kSplitZ) s.z_shift[l] = uint8_t(--zs);
    }
    return s;
  }
};

// Receiver depth -> slab (the format's quantization rule, also the GPU's): r < 0 is lit
// and r > 1 (or NaN) shadowed outright; otherwise slab k = min(floor(r * 2^z_bits),
// 2^z_bits - 1), exact in float because the scale is a power of two.
inline constexpr int32_t kReceiverLit = -1, kReceiverShadowed = -2;
inline int32_t receiver_slab(float r, uint32_t z_bits) {
  if (r < 0.0f) return kReceiverLit;
  if (!(r <= 1.0f)) return kReceiverShadowed;
  const float scaled = r * float(1u << z_bits);
  const uint32_t k = uint32_t(scaled);  // floor: scaled >= 0
  const uint32_t top = (1u << z_bits) - 1;
  return int32_t(k < top ? k : top);
}

// Leaf bit of texel (x, y) inside its 8x8 leaf (§6.2: the last three bits of x and y).
inline uint32_t leaf_bit(uint64_t x, uint64_t y) { return uint32_t((y & 7) * 8 + (x & 7)); }

// The exactness contract (VSDAG.md "Exactness contract") as a check on a decoded depth
// value `d`, whose lit test `r <= d` answers as the voxels do, for a texel whose true
// interval is [lo, hi]: every receiver in a slab before lo's is lit, every receiver in a
// slab after hi's is shadowed. `shadowtile verify` checks vsdag packs with it.
inline bool depth_within_contract(float lo, float hi, float d, uint32_t z_bits) {
  const double scale = double(1u << z_bits);
  const double first_of_lo = std::floor(std::clamp(double(lo), 0.0, 1.0) * scale) / scale;
  const double past_hi = (std::floor(std::clamp(double(hi), 0.0, 1.0) * scale) + 1) / scale;
  // Exact in float: multiples of a power of two no finer than 2^-20.
  if (first_of_lo > 0 && !(d >= std::nextafter(float(first_of_lo), -1.0f))) return false;
  if (past_hi < 1 && !(double(d) < past_hi)) return false;  // the last slab holds r = 1 too
  return true;
}

}  // namespace st::vsdag
