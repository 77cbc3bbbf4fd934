// Plane blocks of a tile (tiles/core/PLANES.md): find the aligned squares of a tile's
// finest texels that one plane answers exactly, take their subtrees out of the hierarchy,
// and wrap the rest's encoding behind the planes (plane_format.hpp).
//
// Why: on open geometry every texel's interval is one float wide (hi = lo), so a planar
// surface seen at a slant stores one value per texel in every tree encoding. Each of those
// values is the canonical depth of one triangle's plane (tiles/bake/canonical_depth.hpp),
// so a block on one triangle's plane is an affine function of the texel, rounded once.
// The encoder does not need to know the triangles: it finds, per block, integers (a, b, c)
// whose decoded depths (plane_format.hpp, integer arithmetic) lie in every texel's
// admissible interval, as a linear feasibility problem in three unknowns (Seidel's
// randomized LP), and verifies every texel with the decoder's own function. So a block is
// a plane only when it reproduces exactly what the intervals admit, for every receiver.
//
// A texel's admissible interval is taken from the hierarchy: its own leaf's [lo, hi], or
// the [lo, hi] of the deepest valued node that answers it (hierarchy.hpp: that interval is
// admissible for every texel the node answers for).
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <vector>

#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/plane_format.hpp"

namespace st {

// Where a build's texels went (bench_plane_packs --stats): counted over every tile searched
// (a tile the cut encodes twice counts twice). Optional: PlaneFitOptions::stats.
struct PlaneFitStats {
  std::atomic<uint64_t> tiles{0};              // tiles searched
  std::atomic<uint64_t> values_before{0};      // valued nodes of the searched tiles' hierarchies
  std::atomic<uint64_t> values_after{0};       // ... left in the pruned hierarchies
  std::atomic<uint64_t> leaves_before{0};      // valued finest texels (one value each)
  std::atomic<uint64_t> leaves_after{0};       // ... left
  std::atomic<uint64_t> plane_blocks{0}, labelled_blocks{0}, wide_blocks{0};  // wide: of the labelled, 5+ planes
  // 8x8 blocks (not inside a larger block) with valued nodes left after the search, by why
  // they were not labelled, and those nodes: [0] fewer than min_labelled_nodes, [1] a texel
  // without a preimage (tiny depth, above 1), [2] more planes than the palette holds (max_palette).
  std::array<std::atomic<uint64_t>, 3> left_blocks{}, left_values{};
  // Labelled or left 8x8 blocks by how many planes the greedy growth needs for all their
  // texels ([16]: 16 or more, or a texel without a preimage), and their valued nodes.
  std::array<std::atomic<uint64_t>, 17> need_blocks{}, need_values{};
  // Count needs beyond the palette (costs a growth to 16 planes per rejected block).
  bool count_needs = true;
};

struct PlaneFitOptions {
  uint32_t min_shift = 2;          // smallest block: 2^min_shift a side
  uint32_t min_stored_nodes = 8;   // a block with a plane of its own must take at least this many valued nodes out
  uint32_t max_tile_depth = 10;    // tiles deeper than this are not searched (memory, time)
  uint32_t min_reused_nodes = 2;   // a block that reuses a plane already in the tile's table: at least this many
  uint32_t min_labelled_nodes = 2; // an 8x8 block labelled with up to max_palette planes: at least this many (4 before: bytes +0.2-0.4% on open meshes)
  // A labelled block's most planes: 1..4 a labelled block (2-bit labels), 5..8 a wide one
  // (3-bit labels, plane_format.hpp, version 3 tiles); 4: no wide block (the form before).
  uint32_t max_palette = planes::kWidePalette;
  // Planes of one surface merged after the search: a plane that answers another's texels
  // too, or one refitted over both, replaces them (fewer table entries; tiles/core/PLANES.md).
  bool merge_surfaces = true;
  // Each plane then replaced by one answering the same texels with the most trailing zero
  // bits (b and c, then a): the table deflates smaller (tiles/core/PLANES.md).
  bool round_planes = true;
  // Tiles whose valued nodes are less than this share zero-width (hi = lo: open surfaces under
  // the default rule) are not searched: wide intervals (closed objects) let the trees merge
  // their values, planes did not store smaller there (procedural:city) and cost build time.
  double min_zero_width_share = 0.5;
  // TileCodec::with_planes weighs a plane tile by the zlib size of its packed form
  // (tiles/core/plane_pack.hpp), as a pack stores it (PackParams::pack_plane_tiles).
  bool packed = true;
  // ... with its labels predicted ("STPL", PackParams::predict_plane_labels), else "STPQ".
  bool predicted = true;
  // An 8x8 block's texels that no palette or known plane answers get planes grown from a
  // seed texel (the LP over the texels taken so far, each next-nearest texel added when a
  // plane still answers them all), so a block across several small triangles is labelled;
  // false: one plane fitted to all of them at once (the form before).
  bool grow_labels = true;
  // Seeds a labelled block's growth tries each round (1..3: the first texel left, then each
  // next the farthest from those before).
  uint32_t grow_seeds = 3;
  // The growth skips a refit that four of its texels already rule out (an exact certificate:
  // the same planes either way, only faster); false: every refit is tried (the tests compare).
  bool rule_out = true;
  // After the prune, a valued node above the blocks whose nearest valued ancestor's value is
  // admissible everywhere it answers (every finest texel exact, every coarser level within
  // the texels' [min lo, max hi]) is emptied: fewer inner values and map-preview nodes
  // (tiles/core/PLANES.md); false: the hierarchy's own coarse values (the form before).
  bool drop_coarse_values = true;
  PlaneFitStats* stats = nullptr;  // not owned; counted into when set
};

// An 8x8 block whose texels are answered by up to 8 planes (plane_format.hpp, labelled block;
// a wide one when it has more than 4).
struct LabelBlock {
  uint32_t start = 0;                  // finest-level morton code of the block's first texel
  std::vector<planes::Plane> palette;  // 1..8 planes resolved to the block's corner (shift 3)
  uint8_t label[64] = {};              // texel (x, y) of the block: palette[label[8 y + x]]
};

struct PlaneSplit {
  std::vector<planes::Plane> planes;   // sorted by start, disjoint
  std::vector<LabelBlock> labelled;    // sorted by start, disjoint from each other and from `planes`
  Hierarchy pruned;                    // the hierarchy without the nodes below each block
  uint64_t texels = 0;                 // finest texels the planes answer
};

// Blocks are tried top-down (the largest first, down to min_shift), each first with the
// planes already found in the tile, then with a fit of its own; an 8x8 block that neither
// answers is labelled when up to max_palette planes answer all its texels. No block:
// `planes` and `labelled` are empty and `pruned` a copy of h.
PlaneSplit fit_planes(const Hierarchy& h, const PlaneFitOptions& o = {});

// The plane tile: header, table, block records, labelled blocks, then `inner` (the encoding
// of PlaneSplit::pruned). Blocks whose planes are equal share one table entry.
std::vector<uint8_t> wrap_planes(const std::vector<planes::Plane>& planes, uint32_t finest_level,
                                 std::span<const uint8_t> inner, const std::vector<LabelBlock>& labelled = {});

// One block: integers (a, b, c) whose depth lies in [lo[i], hi[i]] for texel i = y * side + x
// of the 2^shift square, verified with planes::Plane::depth; false when none was found.
bool fit_block(std::span<const float> lo, std::span<const float> hi, uint32_t shift, planes::Plane& out);

}  // namespace st
