// The cut of a hierarchy into tiles (ARCHITECTURE.md "Tiles, skip grid and packs"; MH §3.1
// "Tiled construction"; DAG-MH §3.7 skip list).
//
// A map of level L is cut at the skip level K: a dense 2^K x 2^K grid of entries (the
// skip grid) plus the values of levels 0..K-1 (CutGrid). Entry (cx, cy) stands for the
// level-K node (K, cx, cy); it is
//   - constant: nothing finer is stored below; its value answers levels >= K;
//   - tile:     the subtree below the node, encoded on its own (its root made valued:
//               an empty or absent node inherits its ancestor's value v and the
//               admissible interval [v, v]), of at most `tile_bytes` encoded bytes;
//   - index:    the subtree encoded to more than `tile_bytes`, so it is cut again d
//               levels deeper into an index tile (a CutGrid of d levels) whose entries
//               are constants, tiles or index tiles in turn: the page table is a sparse
//               quadtree of tiles.
// Every tile is named by make_tile_id(level, x, y) of its root. The pack evaluator answers
// levels down to each tile's root exactly as Hierarchy::depth_at on the hierarchy that was
// cut, and below it what the tile's encoding answers (MH: depth_at bit-exactly; MMH and
// DAG-MH may re-pick values inside the admissible intervals). tiles/PACK.md has it all.
//
// Two ways in:
//   - in memory: cut_hierarchy(h, ...) for a whole map's hierarchy;
//   - out of core: a TileCutter takes the hierarchy of one level-K cell at a time (the
//     cell's intervals built with build_hierarchy, in any order, from any thread), and
//     coarse_grid() builds levels 0..K-1 over the cells' root intervals at the end (MH
//     §3.1: the roots' bounds form a new map that is compressed again). Each cell keeps
//     its own root value at level K, so the pack answers levels >= K exactly like the
//     cells' hierarchies and levels < K like the coarse hierarchy.
#pragma once
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "tiles/encode/encode.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/tile_cut_grid.hpp"

namespace st {

// How a tile's subtree is encoded and opened. TileCodec::of(e) uses encode()/open_encoded();
// tests and tools may plug in another codec as long as the pack's Encoding tag names it.
struct TileCodec {
  Encoding encoding = Encoding::mh;
  std::function<std::vector<uint8_t>(const Hierarchy&)> encode;
  std::function<std::unique_ptr<Evaluator>(std::span<const uint8_t>)> open;
  // Optional second encoding of a tile: a subtree takes it instead of encode()'s when it
  // fits tile_bytes and deflates (zlib level 6, as packs store tiles) to fewer bytes, or
  // when encode()'s does not fit and it does. open() must tell them apart (DAG-MH packs:
  // MMH tiles by their magic, tiles/PACK.md "Mixed tiles"). Empty: encode() alone.
  std::function<std::vector<uint8_t>(const Hierarchy&)> alternative;
  // Optional, with `alternative`: a cheap guess of the smaller encoding for a subtree,
  // > 0 the alternative, < 0 encode(), 0 unsure. A sure guess encodes only that one (the
  // other still where it does not fit tile_bytes); unsure or empty: both, as above.
  std::function<int(const Hierarchy&)> choose;
  static TileCodec of(Encoding e);
  // The encoding a cut keeps for a subtree under a bound of `bound` bytes: encode()'s, or
  // the alternative's where it fits and deflates (kEncodingChoiceZlibLevel) strictly
  // smaller or encode()'s does not fit; a sure `choose` guess encodes only its pick (the
  // other still where the pick does not fit). `bytes` empty: none fits, and `smallest` is
  // the smallest encoding seen. With `may_refuse`, an encode() that throws st::Error (a
  // subtree too large for its format) counts as one that does not fit.
  struct Fit {
    std::vector<uint8_t> bytes;
    size_t smallest = SIZE_MAX;
  };
  Fit encode_within(const Hierarchy& h, size_t bound, bool may_refuse = false) const;
  // encode_within with no bound: the encoding a cut keeps where the tile bound does not bite.
  std::vector<uint8_t> encode_smaller(const Hierarchy& h) const { return encode_within(h, SIZE_MAX).bytes; }
  // DAG-MH tiles, each an MMH buffer instead where that stores smaller (map builds'
  // default). Unless `exhaustive`, only tiles whose share of zero-width intervals leaves
  // the winner unsure are encoded both ways (tile_cut.cpp, predict_dagmh_or_mmh): a tile
  // may then be larger than its other encoding, the pack measured no larger than MMH's.
  static TileCodec dagmh_or_mmh(bool exhaustive = false);
  // `base` (its encode and alternative) with plane blocks (plane_codec.cpp, tiles/core/
  // PLANES.md): a tile is also encoded as plane blocks over base's encoding of the rest,
  // and the candidate that fits tile_bytes and deflates smallest is kept.
  static TileCodec with_planes(TileCodec base, uint32_t tile_bytes, const PlaneFitOptions& fit = {});
};

inline constexpr uint32_t kDefaultTileBytes = 64 * 1024;
// The zlib level at which two encodings of a tile are compared (packs' default).
inline constexpr int kEncodingChoiceZlibLevel = 6;

// Default skip level for a map of level L: ceil(L / 2), at most 8 (a 256^2 grid of 8-byte
// entries + the coarse pyramid = 597 KiB), so cells are <= 4096^2 texels at L = 20 and a
// small map still gets cells of a few texels.
uint32_t default_skip_level(uint32_t map_level);

struct CutParams {
  uint32_t map_level = 0;   // L
  uint32_t skip_level = 0;  // K <= min(L, kMaxSkipLevel)
  uint32_t tile_bytes = kDefaultTileBytes;  // bound on one tile's encoded size
  TileCodec codec;
  // Throws st::Error naming the bad field.
  void validate() const;
};

// One tile produced by the cut: uncompressed (encoded tile bytes or a serialized CutGrid).
struct CutTile {
  uint64_t id = 0;
  TileKind kind = TileKind::encoded;
  std::vector<uint8_t> raw;
};

// The result of cutting one level-K cell: its skip-grid entry, its root's admissible
// interval (for the coarse levels) and its tiles (children before the index tiles that
// point at them). Empty or constant cells produce no tiles.
struct CutCell {
  uint32_t cx = 0, cy = 0;
  GridEntry entry;
  float lo = 0, hi = 0;
  std::vector<CutTile> tiles;
};

class TileCutter {
 public:
  explicit TileCutter(CutParams params);  // validates
  const CutParams& params() const { return params_; }

  // Cuts cell (cx, cy) given the hierarchy of its 2^(L-K) x 2^(L-K) texels (depth L-K,
  // root valued). Const and stateless: call it from any thread. Throws st::Error if the
  // cell is out of range or the hierarchy malformed (wrong depth, unsorted, root not
  // valued).
  CutCell cut_cell(uint32_t cx, uint32_t cy, Hierarchy&& cell) const;

  // The skip grid once every cell is cut: entries from the cells, levels 0..K-1 from a
  // hierarchy built over the cells' root intervals (`build_coarse`; empty: bottom-up
  // build_hierarchy, MH §3.1 Alg. 2). Throws st::Error if a cell is missing or repeated.
  using CoarseBuilder = std::function<Hierarchy(const IntervalTile&)>;
  CutGrid coarse_grid(std::span<const CellRecord> cells, const CoarseBuilder& build_coarse = {}) const;

 private:
  CutParams params_;
};

// In-memory cut of a whole map's hierarchy (depth L): returns the skip grid and hands
// every cell, constant ones included (the writer journals all cells), to `sink` in
// row-major order. Levels < K come from `h` itself, so the cut answers exactly like
// h.depth_at at every level.
CutGrid cut_hierarchy(const Hierarchy& h, const CutParams& params,
                      const std::function<void(CutCell&&)>& sink);

// --- building blocks (exposed for tests) ---------------------------------------------

// Splits `h` (depth D >= d) at relative level d: the values of levels 0..d and, for every
// node of level d with descendants, its subtree as a Hierarchy of depth D - d whose root
// is valued (inheriting [v, v] when empty). subtrees[j * 2^d + i] is null for constants.
struct SplitResult {
  CutGrid grid;  // all entries constant; the caller marks the ones it turns into tiles
  std::vector<float> lo, hi;  // per entry: the node's admissible interval ([v, v] if inherited)
  std::vector<std::unique_ptr<Hierarchy>> subtrees;
};
SplitResult split_hierarchy(const Hierarchy& h, uint32_t d);

// Checks the structural contract of hierarchy.hpp (levels = depth + 1, morton sorted,
// in range, children present exactly as the masks say, root valued, empty nodes have
// children); throws st::Error(what + ...) otherwise.
void check_hierarchy(const Hierarchy& h, const char* what);

}  // namespace st
