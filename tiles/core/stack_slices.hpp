// Per-slice cells of a stack pack (tiles/core/MHOCT.md "Per-slice cells", tiles/PACK.md
// "Stack packs"): a level-K cell of a shadow-map stack stored as its slices' own 2D tiles
// (DAG-MH, or MMH where that stored smaller, as a 2D DAG-MH pack's mixed tiles) instead of
// one MH octree over (x, y, w). The builder takes whichever of the two stores smaller per
// cell, so a stack pack is never much larger than the same slices as separate 2D packs
// where the slices disagree (a day's sun at 4K^2) and keeps the octree where they agree.
// A stack tile's first four bytes say which it is ("STOC" octree, "STSL" per-slice).
//
// Layout (little-endian; pinned by tests/tiles/stack_slices_test.cpp):
//   0   4      magic "STSL"
//   4   2      version 1
//   6   1      xy_level m: each slice's square is 2^m texels a side (0..20)
//   7   1      w_level j: 2^j slice entries (0..12)
//   8   4      byte_size: the whole buffer, header included
//   12  4      zero
//   16  8 2^j  entries, slice 0 first: u32 offset, u32 word
//                offset 0: the slice is constant, word = the f32 value's bits
//                else: the slice's 2D buffer is bytes [offset, offset + word) (word = its
//                size), a DAG-MH ("DGMH") or MMH ("STMM") buffer of finest level m, or
//                a plane tile ("STPN", tiles/core/PLANES.md) over one of those (a pack
//                holding one declares feature plane_tiles)
//   B          the 2D buffers, back to back in order of first use, each followed by zero
//              bytes to a multiple of 4; B = 16 + 8 2^j; slices with equal buffers name
//              the same one; the last buffer's padding ends the buffer (byte_size)
// Slices past the stack's N (the last cells' padding) are constant kLitDepth.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "tiles/core/dagmh_traverse.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {

inline constexpr uint32_t kSliceTilesMagic = 0x4C535453u;  // "STSL"; format constant
inline constexpr uint16_t kSliceTilesVersion = 1;           // format constant
inline constexpr uint32_t kSliceTilesHeaderBytes = 16;      // format constant
inline constexpr uint32_t kSliceTilesEntryBytes = 8;        // format constant

// Whether `bytes` start with "STSL".
bool is_slice_tiles(std::span<const uint8_t> bytes);

class SliceTiles {
 public:
  // Validates the header, every entry (constant values finite; buffers inside the buffer,
  // 4-aligned, laid out back to back in first-use order with zero padding, no byte
  // unaccounted for) and opens every distinct 2D buffer with its own full validation
  // (finest level m). Throws st::FormatError("slice tiles: <field> at byte <offset>: ...").
  // The bytes are borrowed: the caller keeps them alive and unchanged.
  static SliceTiles open(std::span<const uint8_t> bytes);

  uint32_t xy_level() const { return xy_level_; }
  uint32_t w_level() const { return w_level_; }
  uint32_t slices() const { return uint32_t(slot_.size()); }
  size_t byte_size() const { return byte_size_; }
  size_t buffers() const { return evals_.size(); }
  // Whether some slice's tile is a plane tile ("STPN"): its pack must declare plane_tiles.
  bool has_planes() const { return planes_; }
  // Whether some slice's plane tile is version 3 (wide labelled blocks): its pack must
  // declare wide_plane_blocks too.
  bool has_wide_planes() const { return wide_planes_; }

  // Texel (x, y) of the level-`level` map of slice w (level <= xy_level(); x, y < 2^level;
  // w < slices(); not checked): the slice's 2D tile's answer, or its constant.
  float depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level) const {
    const int32_t s = slot_[w];
    return s < 0 ? value_[w] : evals_[size_t(s)]->depth(level, x, y);
  }

  // Lookup-side access for walks that run several slices' walks in lockstep
  // (the soft and time lookups read record() below instead): whether slice w is a constant (and its value), else its tile's
  // evaluator and, when that tile is DAG-MH, a copy of its validated view (nullptr for MMH).
  bool is_constant(uint32_t w) const { return slot_[w] < 0; }
  float constant_value(uint32_t w) const { return value_[w]; }
  const Evaluator& evaluator(uint32_t w) const { return *evals_[size_t(slot_[w])]; }
  const dagmh::View* view(uint32_t w) const {
    const size_t s = size_t(slot_[w]);
    return has_view_[s] ? &views_[s] : nullptr;
  }
  // Bounds of slice w's answers, found at open: every depth(x, y, w, level) of any texel
  // and level lies in [lo, hi] (a constant: its value twice; a DAG-MH tile: the least and
  // greatest of its stored values, every answer being one of them). Unknown (an MMH tile,
  // not searched; a NaN value): lo = hi = NaN, which no receiver's test passes. A receiver
  // at depth d <= lo is lit in the whole slice square and one at d > hi shadowed, without a
  // walk (the soft and time lookups' early-out, stack_map.cpp).
  struct Bounds {
    float lo, hi;
  };
  Bounds bounds(uint32_t w) const { return bounds_[w]; }

  // What the soft and time lookups' gathered walks (stack_map.cpp) read of slice w, in one
  // place: its bounds, its kind, and the tile's level and DAG-MH view inline, so that a
  // sample costs one record (one cache line, Record below) instead of a chain of
  // the object's arrays (slot_, has_view_, views_, bounds_: a dependent miss each). Built
  // at the end of open() from the accessors above and equal to them.
  // An MMH slice's record holds its tree (the first tree word, MHQUAD.md) and whether the
  // root is a leaf, so that the lookups walk it in their rounds (stack_map.cpp: the same
  // walk as the evaluator's depth(), a step per round); kind evaluator is any other 2D
  // tile (a plane slice, "STPN"), answered by its evaluator.
  // One cache line: a DAG-MH view's sections as 32-bit offsets from its skip table (the
  // sections follow it in one buffer, DAGMH.md), so that a sample's record is one line
  // rather than two (a soft lookup's loads are bounded by the lines in flight). A DAG-MH
  // tile with a dictionary (its references partly outside the tile) is kind evaluator.
  enum class RecordKind : uint32_t { constant, view, mmh, evaluator };
  struct alignas(64) Record {
    float lo, hi;             // bounds(w); a constant: its value twice
    RecordKind kind;
    uint32_t xy_level;        // xy_level()
    const Evaluator* eval;    // kinds mmh and evaluator: &evaluator(w)
    const uint8_t* base;      // kind view: view(w)->skip; kind mmh: word 0 of the MMH tree (validated at open)
    uint32_t nodes, treelets, chunks, multipliers;  // kind view: view(w)'s sections, bytes after `base`
    uint32_t root_ref;        // kind view: view(w)->root_ref
    uint8_t skip_level;       // kind view: view(w)->skip_level
    uint8_t mmh_root_leaf;    // kind mmh: the root is a leaf (a constant tile)
    // Kind view: *view(w) for the walks (no dictionary; value_count left zero: a walk
    // never reads it).
    dagmh::View dagmh() const {
      dagmh::View v;
      v.skip = base, v.nodes = base + nodes, v.treelets = base + treelets, v.chunks = base + chunks;
      v.multipliers = base + multipliers, v.finest_level = xy_level, v.skip_level = skip_level, v.root_ref = root_ref;
      return v;
    }
  };
  static_assert(sizeof(Record) == 64);
  const Record& record(uint32_t w) const { return records_[w]; }
  // record(0)'s address (slice w's at records() + w): a StackTileRef keeps it, so that a
  // lookup reaches a slice's record without loading this object first.
  const Record* records() const { return records_.data(); }

 private:
  void build_records();
  uint32_t xy_level_ = 0, w_level_ = 0;
  size_t byte_size_ = 0;
  bool planes_ = false, wide_planes_ = false;
  std::vector<int32_t> slot_;  // per slice: index into evals_, or -1 (constant)
  std::vector<float> value_;   // per slice: the constant (when slot_ < 0)
  std::vector<std::shared_ptr<const Evaluator>> evals_;
  std::vector<dagmh::View> views_;  // per evaluator: its DAG-MH view (when has_view_)
  std::vector<uint8_t> has_view_;
  std::vector<const uint8_t*> mmh_tree_;  // per evaluator: an MMH tile's tree, else nullptr
  std::vector<uint8_t> mmh_root_leaf_;
  std::vector<Bounds> bounds_;  // per slice
  std::vector<Record> records_;  // per slice (build_records)
};

// The grouped stored form of a per-slice cell ("STSP", tiles/PACK.md "Stack packs",
// MHOCT.md "Grouped per-slice cells"): the same bytes as the cell's "STSL" buffer,
// permuted so the zlib stream sees like with like (every slice's headers, then their
// structure, then their values), the same size. Pack tiles only: the pack reader and the
// client ungroup a tile as it is read (before any reader, CPU or GPU, sees it), so every
// lookup reads plain STSL. Layout after the STSL header and entries (the magic "STSP",
// the rest as in STSL), each part the distinct 2D buffers' pieces in order of first use:
//   heads       DAG-MH: its 32-byte header; MMH: its header and shifts (tree offset);
//               a plane tile: the whole buffer in its packed form ("STPL" or "STPQ",
//               plane_pack.hpp, the same size; nothing of it in the parts below)
//   structure   DAG-MH: skip table, inner nodes, treelets and chunk infos
//   node words  MMH: the tree words that are nodes, in word order (mmh_word_roles)
//   multipliers DAG-MH: the multiplier section
//   values      MMH: the tree words that are values, in word order
//   zero bytes  to byte_size (the buffers' padding, the MMH trees' padding words)
inline constexpr uint32_t kGroupedSliceTilesMagic = 0x50535453u;  // "STSP"; format constant

// Whether `bytes` start with "STSP".
bool is_grouped_slice_tiles(std::span<const uint8_t> bytes);

// Turns a grouped cell back into its STSL buffer, in place (the same size). Checks what
// the permutation needs (header, entries in first-use order, each buffer's kind and
// section sizes, a zero tail) and throws st::FormatError("grouped slice tiles: <field> at
// byte <offset>: ...") otherwise; the result still goes through SliceTiles::open.
// `plane_features` (if given) gets ORed the pack features the cell's packed plane slices
// need (plane_tiles, packed_plane_tiles, predicted_plane_labels for "STPL"; pack_format.hpp):
// a reader refuses a cell whose pack lacks one.
void ungroup_slice_tiles(std::span<uint8_t> bytes, uint32_t* plane_features = nullptr);

// The roles of an MMH tree's W words (MHQUAD.md), as the grouped form splits them:
// 1 node word, 2 value word, 0 neither (padding). A forward scan: word 0 is the root (a
// leaf when `root_leaf`, else a node with its value after it); a node word's children mark
// the words they occupy, those after it only, the first mark kept (every MMH child block
// lies after its parent). `node(i)` yields word i when i is a node, called in increasing i.
template <class NodeWord>
void mmh_word_roles(uint64_t W, bool root_leaf, std::vector<uint8_t>& role, NodeWord&& node) {
  role.assign(W, 0);
  if (W == 0) return;
  auto mark = [&](uint64_t at, uint8_t r) {
    if (at < W && role[at] == 0) role[at] = r;
  };
  role[0] = root_leaf ? 2 : 1;
  if (!root_leaf) mark(1, 2);
  for (uint64_t i = 0; i < W; ++i) {
    if (role[i] != 1) continue;
    const uint32_t word = node(i);
    const uint32_t mask = word & 0xFFu, shift = (word >> 12) & 0xFu, off = word >> 16;
    const uint64_t block = ((i >> shift) + off) << shift;
    uint64_t at = block;
    for (uint32_t c = 0; c < 4; ++c) {
      const uint32_t code = (mask >> (2 * c)) & 3u;
      if (code == 0) continue;
      if (at > i) {
        mark(at, code == 1 ? 2 : 1);
        if (code == 3 && at + 1 > i) mark(at + 1, 2);
      }
      at += code == 3 ? 2 : 1;
    }
  }
}

// A stack tile as lookups see it: an MH octree or per-slice tiles (or neither: absent).
// Converts from either pointer, so a tile source may hand out `const MhOctree*` as before.
// It also carries where a lookup starts in the tile (the octree's root word, the slices'
// records), taken from the reader when the ref is made: a soft lookup that gets a cell's
// ref then loads its first node or record at once instead of the reader object before it
// (one cache miss fewer on the chain of each cell it crosses).
struct StackTileRef {
  const MhOctree* octree = nullptr;
  const SliceTiles* slices = nullptr;
  const void* root = nullptr;  // octree: octree->words(); slices: slices->records()
  StackTileRef() = default;
  StackTileRef(const MhOctree* o) : octree(o), root(o ? o->words() : nullptr) {}  // NOLINT: implicit by design
  StackTileRef(const SliceTiles* s) : slices(s), root(s ? s->records() : nullptr) {}  // NOLINT: implicit by design
  StackTileRef(std::nullptr_t) {}                     // NOLINT: implicit by design
  explicit operator bool() const { return octree || slices; }
  // depth(x, y, w, level) of whichever it is (present; arguments in range).
  float depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level) const {
    return octree ? octree->depth(x, y, w, level) : slices->depth(x, y, w, level);
  }
};

// An opened stack tile that owns its reader (not its bytes): "STOC" as MhOctree::open,
// "STSL" as SliceTiles::open. Throws st::FormatError for anything else or a bad buffer.
class StackTile {
 public:
  static StackTile open(std::span<const uint8_t> bytes);
  StackTileRef ref() const { return octree_ ? StackTileRef(&*octree_) : StackTileRef(&*slices_); }
  // The tile's slices' side level and slice-entry level (the octree's n and k).
  uint32_t xy_level() const { return octree_ ? octree_->geometry().n : slices_->xy_level(); }
  uint32_t w_level() const { return octree_ ? octree_->geometry().k : slices_->w_level(); }
  bool is_octree() const { return bool(octree_); }
  // Per-slice with a plane slice (SliceTiles::has_planes): its pack declares plane_tiles.
  bool has_planes() const { return slices_ && slices_->has_planes(); }
  bool has_wide_planes() const { return slices_ && slices_->has_wide_planes(); }

 private:
  std::unique_ptr<MhOctree> octree_;
  std::unique_ptr<SliceTiles> slices_;
};

}  // namespace st
