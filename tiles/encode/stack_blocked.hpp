// Out-of-core construction of a shadow-map stack's pack (MH 2016 §4 cut at a skip level,
// tiles/PACK.md "Stack packs"): the slices are spilled to a file in blocks of the octree,
// each block is read back and reduced alone, and the cut's tiles go to a second file, so
// memory is bounded by one block (and the octree's top levels) instead of N x R^2.
//
// Block level B <= K (the skip level): every level-B node of the octree is one block of
// S x S texels x W slices (S = 2^(n - a(B)), W = 2^(k - b(B)), MHOCT.md's geometry), the
// coarsest level whose blocks hold at most `block_texels`. A level-B node's subtree is
// build_octree of its own texels (padded in w as the whole stack is), so the blocked
// result is the one-shot build's, node for node and byte for byte (tested): per block
// the subtree's root interval and child mask feed the top levels 0..B (octree_top_values),
// its valued nodes at levels B+1..K feed the grid, and its level-K cells are encoded as
// tiles at once; the only thing a block cannot know, the value an empty cell root inherits
// from above B, is patched into each tile's root word when the top is done.
//
// Spill layout: texel (x, y, w) at byte 8 (((c W + w mod W) S + y mod S) S + x mod S),
// c = ((w / W) 2^a(B) + y / S) 2^a(B) + x / S; padding slices are holes.
#pragma once
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tiles/encode/mh_octree_build.hpp"
#include "tiles/encode/stack_slices_encode.hpp"
#include "tiles/core/stack_grid.hpp"

namespace st {

// Default block budget: 2^24 texels (128 MiB of intervals per block read back).
inline constexpr uint64_t kStackBlockTexels = uint64_t(1) << 24;

// The block level for skip level K (see above).
uint32_t stack_block_level(const moct::Geometry& g, uint32_t K, uint64_t block_texels);

// A stack's slices in a spill file (removed by the destructor). Throws st::Error when the
// file cannot be made or written, naming it.
class StackSpill {
 public:
  StackSpill(std::string path, uint32_t level, uint32_t slices, uint32_t block_level);
  ~StackSpill();
  StackSpill(const StackSpill&) = delete;
  StackSpill& operator=(const StackSpill&) = delete;

  const moct::Geometry& geo() const { return geo_; }
  uint32_t slices() const { return slices_; }
  uint32_t block_level() const { return block_; }
  uint64_t side() const { return uint64_t(1) << geo_.n; }
  uint64_t block_side() const { return bs_; }
  uint32_t block_slices() const { return bw_; }
  uint64_t bytes() const;  // the spill's size with every real slice written

  // Full-width rows y0 .. y0 + rows - 1 of slice w (data: rows x side, row-major); y0 and
  // rows are multiples of block_side().
  void write_rows(uint32_t w, uint64_t y0, uint64_t rows, std::span<const Interval> data) {
    write_region(w, 0, y0, side(), rows, data);
  }
  // The region [x0, x0 + width) x [y0, y0 + rows) of slice w (data: rows x width,
  // row-major); x0, y0, width and rows are multiples of block_side().
  void write_region(uint32_t w, uint64_t x0, uint64_t y0, uint64_t width, uint64_t rows,
                    std::span<const Interval> data);
  // Block (bx, by, bw) of level B: its real slices (>= 1, else throws), local coordinates.
  IntervalStack read_block(uint64_t bx, uint64_t by, uint64_t bw) const;
  Interval texel(uint64_t x, uint64_t y, uint32_t w) const;

 private:
  uint64_t offset(uint64_t x, uint64_t y, uint64_t w) const;
  std::string path_;
  int fd_ = -1;
  moct::Geometry geo_;
  uint32_t slices_ = 0, block_ = 0, bw_ = 0;
  uint64_t bs_ = 0, nx_ = 0;
};

struct BlockedCutStats {
  uint64_t blocks = 0, octree_nodes = 0, max_block_nodes = 0;
  double reduce_seconds = 0, patch_seconds = 0;
};

// The cut of a spilled stack's octree: the same grid and tiles as
// cut_stack(build_octree(whole stack), skip_level, tile_bytes), tiles raw in a file.
class BlockedStackCut {
 public:
  // skip_level must be >= spill.block_level() (default: default_stack_skip_level); past
  // `tile_bytes` the cut moves one level deeper and reduces the blocks again, as cut_stack.
  // `cells`: each cell's form (stack_slices_encode.hpp): the octree (cut_stack's bytes),
  // per-slice tiles, or the smaller of the two (zlib level 6) among those that fit.
  // `split`: a cell whose kept form overflows `tile_bytes` is split into its
  // children one level deeper (and so on down; stack_grid.hpp "Split cells") instead of
  // the whole cut moving deeper: K stays where it starts, only the overflowing cells go
  // deeper (the pack then has feature stack_split_cells).
  // `planes`: a per-slice cell's slices may be plane tiles (encode_slice_tiles; the pack
  // then has feature plane_tiles); none: DAG-MH or MMH slices only. Each cell first weighs
  // its octree against its plain per-slice form; only a cell that keeps the per-slice form
  // fits planes, and keeps them where its grouped stream gets shorter still. The level-K
  // cells of a block are weighed on every hardware thread (the bytes do not depend on it).
  BlockedStackCut(const StackSpill& spill, std::optional<uint32_t> skip_level, uint32_t tile_bytes,
                  std::string tile_path, BlockedCutStats* stats = nullptr, StackCells cells = StackCells::octree,
                  bool split = false, std::optional<PlaneFitOptions> planes = std::nullopt);
  ~BlockedStackCut();
  BlockedStackCut(const BlockedStackCut&) = delete;
  BlockedStackCut& operator=(const BlockedStackCut&) = delete;

  StackGrid grid;  // lights and spec left empty: the caller fills them
  uint64_t max_tile_bytes = 0, tile_bytes_total = 0;
  uint64_t slice_cells = 0;  // tiles in the per-slice form
  uint64_t split_cells = 0;  // cells split below the skip level (split_cells)
  size_t tile_count() const { return tiles_.size(); }
  // Tile i (increasing cell order): its cell and octree buffer.
  std::pair<uint64_t, std::vector<uint8_t>> tile(size_t i) const;
  // Where tile i lies (benchmarks' byte accounting): the level-K cell it is, or is below
  // (a split cell's), its own octree level, and whether it is the octree form.
  struct TilePlace {
    uint64_t root = 0;
    uint32_t level = 0;
    bool octree = true;
  };
  TilePlace tile_place(size_t i) const;

 private:
  struct Ref {
    uint64_t cell, offset;  // cell: a split child's is set once the cut is done
    uint32_t size;
    bool octree;
    uint64_t root;  // the level-K cell it is or lies below
    uint32_t level;
  };
  // A cell below a split one while the blocks are read (numbered when the cut is done):
  // kind as StackEntry, value NaN where it inherits its parent's, ref its tile (kind 1)
  // or its first child (kind 2; the children contiguous).
  struct SplitNode {
    uint8_t kind;
    float value;
    uint32_t ref;
  };
  void run(const StackSpill& spill, uint32_t K, uint32_t tile_bytes, BlockedCutStats* stats);
  StackCells cells_ = StackCells::octree;
  bool split_ = false;
  std::optional<PlaneFitOptions> planes_;
  std::vector<Ref> tiles_;
  std::vector<SplitNode> nodes_;
  std::vector<std::pair<uint64_t, uint32_t>> split_roots_;  // (level-K cell, its first child node)
  std::string path_;
  int fd_ = -1;
};

}  // namespace st
