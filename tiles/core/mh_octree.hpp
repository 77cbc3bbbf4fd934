// Reader of MH octree buffers (MH 2016 §4; layout: mh_octree_format.hpp, MHOCT.md): one
// full validation pass at open, then lookups that read only validated words.
//
// Thread safety: a MhOctree is immutable after open; lookups are const, noexcept, never
// allocate, and may run concurrently. The buffer is borrowed: the caller keeps it alive.
#pragma once
#include <algorithm>
#include <bit>
#include <cstdint>
#include <span>

#include "common/bytes.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/mh_octree_format.hpp"

namespace st {

class alignas(64) MhOctree {
 public:
  // The bytes at the object's start that hold every field a walk reads (see the members):
  // one cache line.
  static constexpr size_t kWalkBytes = 64;
  // Validates the whole buffer: header fields, every node reached from the root once (in
  // bounds, no overlap, only the child slots the level's geometry splits, no children at
  // the finest level, each offset naming either a block it claims after its node or a
  // shared block of validated nodes one level down, far words inside the buffer and
  // claimed by one node each, finite floats), zero padding, no trailing bytes, node
  // count; versions 1 and 2 are refused ("rebuild the stack"). Throws st::FormatError("MH octree: <field> at byte <offset>: ...").
  static MhOctree open(std::span<const uint8_t> bytes);

  const moct::Geometry& geometry() const { return geo_; }
  uint32_t xy_level() const { return geo_.n; }  // slices are 2^xy_level a side
  uint32_t slices() const { return slices_; }   // N; w in [0, N)
  uint32_t node_count() const { return node_count_; }
  size_t byte_size() const { return bytes_.size(); }

  // Depth of texel (x, y) of the level-`level` map of slice w (MH §3.2 traversal in 3D,
  // lazy value fetch). Every level is a complete map (multiresolution); a level above
  // xy_level() answers like depth(x >> s, y >> s, w, xy_level()), s = level - xy_level().
  // Outside the stack (w >= slices(), x or y >= 2^level, level > kMaxLevel) the texel is
  // lit: kLitDepth (ARCHITECTURE.md "Out of range").
  float depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level) const noexcept;

  // Walks to finest texels one after another, each starting from the deepest node its
  // path shares with the previous walk's (MH §3.3's lowest common node and last-sample
  // cache, carried over w): coherent texel sequences, such as one point's samples in
  // trajectory or Hilbert order, read only the nodes where their paths part.
  // Compact (216 bytes, 440 with 64-bit words; a soft lookup's batch keeps one per lane):
  // word indices fit 32 bits (a buffer's byte_size is 32-bit), codes 2 bits, x and y 20
  // (kMaxXyLevel).
  struct Path {
    uint32_t pos[moct::kMaxLevels] = {}, val[moct::kMaxLevels] = {};
    uint8_t code[moct::kMaxLevels] = {};
    uint8_t reached = 0;   // level of the last node of the previous walk
    bool valid = false;    // false: the next walk starts at the root
    uint32_t x = 0, y = 0, w = 0;
    uint64_t steps = 0;    // nodes stepped into, summed over walks (benchmark figure)
  };
  // depth(x, y, w, xy_level()) for w < slices(), x, y < 2^xy_level() (not checked).
  float depth_along(Path& p, uint64_t x, uint64_t y, uint32_t w) const noexcept;

  // depth_along in resumable steps, so that the walks of many points can be interleaved
  // and their cache misses overlap (the batched soft lookups of StackLookup and StackMap):
  // along_begin starts the walk to (x, y, w) from the lowest common node with the path's
  // previous walk and returns its cursor; along_step takes one node down, recording it in
  // the path, and returns true while the walk goes on, the new node's word then at
  // along_next(k), which a caller prefetches before it steps other walks; once along_step
  // returns false, along_value(k) is the answer. Begin, steps and value answer as
  // depth_along does and leave the path as it does, bit for bit (tested). The cursor is a
  // value the caller keeps in registers. Same preconditions as depth_along.
  struct Walk {
    uint64_t pos = 0, val = 0;
    uint32_t code = 0, level = 0;
  };
  Walk along_begin(Path& p, uint64_t x, uint64_t y, uint32_t w) const noexcept {
    uint32_t start = 0;
    if (p.valid) {  // as depth_along
      start = std::min(shared_levels(x, y, w, p.x, p.y, p.w), uint32_t(p.reached));
    } else {
      const Walk r = along_root();
      p.pos[0] = uint32_t(r.pos), p.val[0] = uint32_t(r.val), p.code[0] = uint8_t(r.code);
    }
    p.reached = uint8_t(start);
    p.x = uint32_t(x), p.y = uint32_t(y), p.w = w;
    p.valid = true;
    return {p.pos[start], p.val[start], p.code[start], start};
  }
  bool along_step(Path& p, Walk& k) const noexcept {
    if (!along_step_to(k, p.x, p.y, p.w)) return false;
    const uint32_t l = k.level;
    p.pos[l] = uint32_t(k.pos), p.val[l] = uint32_t(k.val), p.code[l] = uint8_t(k.code);
    p.reached = uint8_t(l);
    ++p.steps;
    return true;
  }
  // The walk without a path, for callers that keep many walks and hand a node on
  // themselves (StackMap's gathered soft lookups: a sample's walk starts from a copy of
  // another's at the deepest level their paths share): the root's cursor; one step of the
  // walk towards (x, y, w), as along_step; and the deepest octree level whose node lies on
  // the paths to both (x, y, w) and (x2, y2, w2) (nodes of level l agree iff x, y agree
  // above bit depth - l and w above bit depth - l: the geometry's xy and w bits end
  // together at the finest level).
  Walk along_root() const noexcept {
    return {0, root_leaf_ ? 0u : 1u, root_leaf_ ? uint32_t(moct::kCodeLeaf) : uint32_t(moct::kCodeInner), 0};
  }
  uint32_t shared_levels(uint64_t x, uint64_t y, uint32_t w, uint64_t x2, uint64_t y2, uint32_t w2) const noexcept {
    const uint32_t L = geo_.depth();
    const uint32_t hx = uint32_t(std::bit_width((x ^ x2) | (y ^ y2)));
    const uint32_t hw = uint32_t(std::bit_width(uint32_t(w ^ w2)));
    return L - std::min(L, std::max(hx, hw));
  }
  bool along_step_to(Walk& k, uint64_t x, uint64_t y, uint32_t w) const noexcept {
    const uint32_t l = k.level;
    if (l >= geo_.depth() || k.code == moct::kCodeLeaf) return false;
    // The child slot without branches or a table: the step from level l halves x and y
    // where l + n >= depth and w where l + k >= depth (moct::Geometry), and then reads
    // the bit depth - l - 1 of each (xy_bits(l + 1) = l + 1 + n - depth resolution bits of
    // n, w_bits(l + 1) of k); a 0 bit masks an axis the level does not split.
    const uint32_t L = geo_.depth(), s = L - l - 1;
    const uint32_t xy_bit = uint32_t(l + geo_.n >= L), w_bit = uint32_t(l + geo_.k >= L);
    const uint32_t slot = uint32_t((x >> s) & xy_bit) | uint32_t((y >> s) & xy_bit) << 1 | ((w >> s) & w_bit) << 2;
    const uint32_t word_p = word_inline(k.pos);
    const uint32_t mask = moct::word_mask(word_p);
    const uint32_t cc = moct::child_code(mask, slot);
    if (!cc) return false;
    k.pos = moct::child_block(tree_, k.pos, shift_[l], word_p) + moct::child_skip(mask, slot);
    // Branchless: an empty node keeps the inherited value; a leaf's is its word, an inner's the next.
    k.val = cc == moct::kCodeEmpty ? k.val : k.pos + (cc >> 1);
    k.code = cc;
    k.level = l + 1;
    return true;
  }
  float along_value(const Walk& k) const noexcept { return moct::bits_float(word_inline(k.val)); }
  const void* along_next(const Walk& k) const noexcept { return tree_ + 4 * k.pos; }
  // The tree's first word (the root's), which every walk reads first (StackTileRef keeps it).
  const uint8_t* words() const noexcept { return tree_; }

  // The walk, for lookups that share it among samples (stack_lookup.hpp). A cursor stands
  // on a node; `val` is the word of the last valued node's float on its path.
  struct Cursor {
    uint64_t pos = 0, val = 0;
    uint32_t code = 0;   // the node's own 2-bit kind (moct::kCodeLeaf / Empty / Inner)
    uint32_t level = 0;  // octree level
  };
  Cursor root() const noexcept;
  // The cursor's child in `slot` (0..7); false where the slot holds no child.
  bool child(const Cursor& c, uint32_t slot, Cursor& out) const noexcept;
  float value(const Cursor& c) const noexcept;

 private:
  uint32_t word(uint64_t w) const noexcept;
  uint32_t word_inline(uint64_t w) const noexcept { return st::load_le<uint32_t>(tree_ + 4 * w); }
  // What a walk reads (along_root, shared_levels, along_step_to, along_value) first, in the
  // object's first kWalkBytes, one cache line (the class is aligned to one): a lookup that
  // meets a cell prefetches that line of its object only (stack_map.cpp). The step's child
  // slot comes from geo_ and the level (along_step_to), not from a per-level table.
  const uint8_t* tree_ = nullptr;
  moct::Geometry geo_{};
  uint8_t shift_[moct::kMaxLevels] = {};
  bool root_leaf_ = false;
  // The rest.
  std::span<const uint8_t> bytes_;
  uint32_t slices_ = 0, node_count_ = 0;
  // Per level l (the step to l + 1): whether it halves x, y / w, the x, y resolution bits
  // of level l + 1, and the bit of a full-resolution w it reads.
  bool split_xy_[moct::kMaxLevels] = {}, split_w_[moct::kMaxLevels] = {};
  uint8_t xy_next_[moct::kMaxLevels] = {}, w_shift_[moct::kMaxLevels] = {};
};

}  // namespace st
