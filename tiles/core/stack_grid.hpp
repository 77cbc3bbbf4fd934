// The skip grid of a stack pack (tiles/PACK.md "Stack packs"): the top K levels of a
// shadow-map stack's octree (MH 2016 §4; geometry in MHOCT.md) as dense values, the
// level-K cells as entries (constant, or a tile holding the cell's subtree as an MH octree
// buffer), and the stack's N light spaces and light-set spec, so a client needs nothing
// but the pack to map world points into every slice.
//
// Layout (little-endian; pinned by tests/tiles/stack_pack_test.cpp):
//   0   4      magic "STSG"
//   4   4      version 1
//   8   1      xy_level n (slices 2^n a side, <= 20)
//   9   1      w_level k (2^(k-1) < N <= 2^k, <= 12)
//   10  1      skip_level K (octree level of the cells, <= max(n, k))
//   11  1      light_kind of every sample (0 sun, 1 spot, 2 sun_ground, 3 spot_window)
//   12  4      slices N
//   16  4      spec_size S (<= 4096): the light set's spec text
//   20  4      zero
//   24  144 N  lights: N x 18 f64 (LightSpace::to_array), sample w at 24 + 144 w
//   ..  S      spec bytes, then zero padding to a multiple of 4
//   ..  4 C    coarse values (f32) of octree levels 0..K-1, level l being
//              cells(l) = 4^a(l) 2^b(l) values in (w, y, x) row-major order
//              (a(l), b(l): MHOCT.md's x, y and w resolution bits of level l)
//   ..  8 E    E = cells(K) entries, same order: f32 value, u8 kind (0 constant, 1 tile),
//              u8 0, u16 0
// Tile of cell i (its dense index above): id = ceil(B / 2) << 58 | i, B = 2 a(K) + b(K)
// (a valid pack tile id: i < 2^B <= 4^ceil(B/2)).
#pragma once
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "tiles/core/light.hpp"
#include "tiles/core/mh_octree_format.hpp"

namespace st {

inline constexpr uint32_t kStackGridMagic = 0x47535453u;  // "STSG"
inline constexpr uint32_t kStackGridVersion = 1;
inline constexpr uint32_t kStackGridFixedBytes = 24;
inline constexpr uint32_t kStackMaxSpecBytes = 4096;
inline constexpr uint64_t kStackMaxCells = uint64_t(1) << 22;  // entries at level K (32 MiB)
// The largest grid parse accepts: 2^12 lights, the longest spec, and the coarse levels (each
// level has at least twice its parent's cells, so fewer than the 2^22 entries together) and
// the entries at the most cells; the bound a compressed stack grid section inflates to.
inline constexpr uint64_t kStackMaxGridBytes = kStackGridFixedBytes + 144 * 4096 + kStackMaxSpecBytes + (4 + 8) * kStackMaxCells;

struct StackEntry {
  float value = 0;
  uint8_t kind = 0;  // 0 constant, 1 tile
  bool operator==(const StackEntry&) const = default;
};

struct StackGrid {
  moct::Geometry geo;
  uint32_t slices = 0, skip_level = 0;
  LightKind light_kind = LightKind::sun;
  std::vector<std::array<double, 18>> lights;  // one per slice
  std::string spec;
  std::vector<std::vector<float>> coarse;  // levels 0..K-1
  std::vector<StackEntry> entries;         // level K

  // Cells of octree level l and the dense index of (x, y, w) there.
  uint64_t cells(uint32_t l) const { return uint64_t(1) << (2 * geo.xy_bits(l) + geo.w_bits(l)); }
  uint64_t index(uint32_t l, uint64_t x, uint64_t y, uint64_t w) const {
    const uint32_t a = geo.xy_bits(l);
    return (((w << a) + y) << a) + x;
  }
  uint64_t tile_id(uint64_t cell) const;
  // The cell of a tile id, or false when the id names no cell of this grid.
  bool cell_of(uint64_t id, uint64_t& cell) const;
  LightSpace light(uint32_t w) const { return LightSpace::from_array(light_kind, lights[w]); }

  static uint64_t serialized_size(const moct::Geometry& geo, uint32_t slices, uint32_t skip_level, size_t spec_size);
  std::vector<uint8_t> serialize() const;
  // Checks every field (magic, version, levels, N against k, lights LightSpace::check_array,
  // spec size and padding, exact size, entry kinds, zero bytes, no NaN); throws
  // st::FormatError("<what>: ... at byte N").
  static StackGrid parse(std::span<const uint8_t> bytes, const std::string& what);
};

}  // namespace st
