// The skip grid of a stack pack (tiles/PACK.md "Stack packs"): the top K levels of a
// shadow-map stack's octree (MH 2016 §4; geometry in MHOCT.md) as dense values, the
// level-K cells as entries (constant, or a tile holding the cell's subtree as an MH octree
// buffer), and the stack's N light spaces and light-set spec, so a client needs nothing
// but the pack to map world points into every slice.
//
// Layout (little-endian; pinned by tests/tiles/stack_pack_test.cpp):
//   0   4      magic "STSG"
//   4   4      version 1, or 2 with split cells (below)
//   8   1      xy_level n (slices 2^n a side, <= 20)
//   9   1      w_level k (2^(k-1) < N <= 2^k, <= 12)
//   10  1      skip_level K (octree level of the cells, <= max(n, k))
//   11  1      light_kind of every sample (0 sun, 1 spot, 2 sun_ground, 3 spot_window)
//   12  4      slices N
//   16  4      spec_size S (<= 4096): the light set's spec text
//   20  4      version 1: zero; version 2: X, the entries below the skip level (> 0)
//   24  144 N  lights: N x 18 f64 (LightSpace::to_array), sample w at 24 + 144 w
//   ..  S      spec bytes, then zero padding to a multiple of 4
//   ..  4 C    coarse values (f32) of octree levels 0..K-1, level l being
//              cells(l) = 4^a(l) 2^b(l) values in (w, y, x) row-major order
//              (a(l), b(l): MHOCT.md's x, y and w resolution bits of level l)
//   ..  8 E    E = cells(K) + X entries: f32 value, u8 kind (0 constant, 1 tile, 2 split),
//              u8 0, u16 0; the first cells(K) are level K's in the order above
// Split cells (version 2, pack feature stack_split_cells; MHOCT.md "Split cells"): an
// entry of kind 2 at level l < L (its value still level l's dense value) is answered by
// its 2^step_bits(l) children at level l + 1 instead, themselves entries (any kind). The
// children of the split entries follow level K's entries as blocks, one block per split
// entry in the order of the split entries' own indices (breadth first), each block in
// (w, y, x) row-major order of the children's offsets inside their parent. An entry's
// index in this one sequence is its "cell": a tile of level l holds the subtree of its
// cell (MH octree of x, y level n - a(l), w level k - b(l)).
// Tile of cell i: id = ceil(B / 2) << 58 | i, B = 2 a(K) + b(K) without splits, else the
// bits of E - 1 (a valid pack tile id: i < 2^B <= 4^ceil(B/2)).
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
inline constexpr uint32_t kStackGridSplitVersion = 2;  // entries below the skip level
inline constexpr uint32_t kStackGridFixedBytes = 24;
inline constexpr uint32_t kStackMaxSpecBytes = 4096;
inline constexpr uint64_t kStackMaxCells = uint64_t(1) << 22;  // entries, level K's and split children's
// The largest grid parse accepts: 2^12 lights, the longest spec, and the coarse levels (each
// level has at least twice its parent's cells, so fewer than the 2^22 entries together) and
// the entries at the most cells; the bound a compressed stack grid section inflates to.
inline constexpr uint64_t kStackMaxGridBytes = kStackGridFixedBytes + 144 * 4096 + kStackMaxSpecBytes + (4 + 8) * kStackMaxCells;

struct StackEntry {
  float value = 0;
  uint8_t kind = 0;   // 0 constant, 1 tile, 2 split (kStackSplit)
  uint8_t level = 0;  // octree level of the cell (parse and StackGrid::link set it)
  uint32_t first = 0;  // split: the index of its first child (parse / link)
  // The stored fields (level and first follow from the kinds).
  bool operator==(const StackEntry& o) const { return value == o.value && kind == o.kind; }
};
inline constexpr uint8_t kStackSplit = 2;

struct StackGrid {
  moct::Geometry geo;
  uint32_t slices = 0, skip_level = 0;
  LightKind light_kind = LightKind::sun;
  std::vector<std::array<double, 18>> lights;  // one per slice
  std::string spec;
  std::vector<std::vector<float>> coarse;  // levels 0..K-1
  std::vector<StackEntry> entries;         // level K's, then split children (above)

  // Cells of octree level l and the dense index of (x, y, w) there.
  uint64_t cells(uint32_t l) const { return uint64_t(1) << (2 * geo.xy_bits(l) + geo.w_bits(l)); }
  uint64_t index(uint32_t l, uint64_t x, uint64_t y, uint64_t w) const {
    const uint32_t a = geo.xy_bits(l);
    return (((w << a) + y) << a) + x;
  }
  // Whether some cell is split (version 2, pack feature stack_split_cells).
  bool split() const { return entries.size() > cells(skip_level); }
  // Children of a cell of level l, and the offset of child (x, y, w) (coordinates at level
  // l + 1) inside its parent's block.
  uint32_t children(uint32_t l) const { return 1u << geo.step_bits(l); }
  uint64_t child_offset(uint32_t l, uint64_t x, uint64_t y, uint64_t w) const {
    const uint32_t dx = geo.splits_xy(l), dw = geo.splits_w(l);
    const uint64_t mx = (uint64_t(1) << dx) - 1;
    return ((((w & ((uint64_t(1) << dw) - 1)) << dx) + (y & mx)) << dx) + (x & mx);
  }
  // The cell answering (x, y, w) (x, y at xy level q, a(T) <= q <= n; w < 2^k) at octree
  // level T >= K: level K's cell, then down split cells while above T. Sets `level` to
  // the cell's level (<= T; < T only where the cell is not split).
  uint64_t cell_at(uint32_t T, uint32_t q, uint64_t x, uint64_t y, uint64_t w, uint32_t& level) const {
    uint32_t l = skip_level;
    uint64_t i = index(l, x >> (q - geo.xy_bits(l)), y >> (q - geo.xy_bits(l)), w >> (geo.k - geo.w_bits(l)));
    while (l < T && entries[i].kind == kStackSplit) {
      const uint64_t first = entries[i].first;
      ++l;
      const uint32_t sx = q - geo.xy_bits(l), sw = geo.k - geo.w_bits(l);
      i = first + child_offset(l - 1, x >> sx, y >> sx, w >> sw);
    }
    level = l;
    return i;
  }
  // Sets every entry's level and every split entry's first child from the kinds (the
  // builders' grids; parse does the same). Throws st::Error when the split children do not
  // fill the entries exactly or a split lies at the finest level.
  void link();
  // Calls fn(cell, level, x, y, w) for every cell, parents before their children (x, y,
  // w: the cell's coordinates at its level).
  template <class Fn>
  void visit(Fn&& fn) const {
    const uint32_t K = skip_level, a = geo.xy_bits(K), b = geo.w_bits(K);
    for (uint64_t w = 0; w < (uint64_t(1) << b); ++w)
      for (uint64_t y = 0; y < (uint64_t(1) << a); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << a); ++x) visit_from(index(K, x, y, w), K, x, y, w, fn);
  }
  uint64_t tile_id(uint64_t cell) const;
  // The cell of a tile id, or false when the id names no cell of this grid.
  bool cell_of(uint64_t id, uint64_t& cell) const;
  LightSpace light(uint32_t w) const { return LightSpace::from_array(light_kind, lights[w]); }

  // `split_entries`: the entries below the skip level (X).
  static uint64_t serialized_size(const moct::Geometry& geo, uint32_t slices, uint32_t skip_level, size_t spec_size,
                                  uint64_t split_entries = 0);
  std::vector<uint8_t> serialize() const;
  // Checks every field (magic, version, split children, levels, N against k, lights LightSpace::check_array,
  // spec size and padding, exact size, entry kinds, zero bytes, no NaN); throws
  // st::FormatError("<what>: ... at byte N").
  static StackGrid parse(std::span<const uint8_t> bytes, const std::string& what);

 private:
  template <class Fn>
  void visit_from(uint64_t i, uint32_t l, uint64_t x, uint64_t y, uint64_t w, Fn& fn) const {
    fn(i, l, x, y, w);
    if (entries[i].kind != kStackSplit) return;
    const uint32_t dx = geo.splits_xy(l), dw = geo.splits_w(l);
    for (uint64_t cw = 0; cw < (uint64_t(1) << dw); ++cw)
      for (uint64_t cy = 0; cy < (uint64_t(1) << dx); ++cy)
        for (uint64_t cx = 0; cx < (uint64_t(1) << dx); ++cx)
          visit_from(entries[i].first + ((((cw << dx) + cy) << dx) + cx), l + 1, (x << dx) + cx, (y << dx) + cy,
                     (w << dw) + cw, fn);
  }
};

}  // namespace st
