// MH octree reader (mh_octree.hpp): validation at open, then the MH §3.2 traversal with
// eight child slots (MH §4).
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <string>
#include <vector>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/mh_octree.hpp"

namespace st {
namespace {

using namespace moct;

[[noreturn]] void fail(const char* field, uint64_t byte, const std::string& what) {
  throw FormatError(std::string("MH octree: ") + field + " at byte " + std::to_string(byte) + ": " + what);
}

// Walks every node stored in the tree once, depth first in slot order (the encoder's
// layout order). A node's offset names a block: if the block's first child word is not
// yet a node, the node claims the block (its children are validated here; marks catch
// overlaps and words claimed twice); if it is, the block is shared, accepted only where
// every child the node's mask names is already a validated node of that kind one level
// down. A node of level l + 1 is validated, with its whole subtree, before any node of
// level l that is not its ancestor is visited (only ancestors are on the recursion's
// path), so a shared block reads only validated words; and every step goes one level
// down, so no walk can loop. A far offset (version 3) names its block through a far word:
// the word must lie in the tree, be no node's and no other node's far word (it is marked
// claimed, so a node laid over it later is refused as an overlap); the block it names
// then follows the same rules, so a far target keeps every walk acyclic too.
class Validator {
 public:
  Validator(const uint8_t* tree, uint64_t words, size_t tree_offset, const Geometry& geo, const uint8_t* shift)
      : tree_(tree), words_(words), tree_offset_(tree_offset), geo_(geo), shift_(shift), mark_(words, 0) {}

  uint64_t run(bool root_leaf) {
    node(0, root_leaf ? kCodeLeaf : kCodeInner, 0);
    for (uint64_t w = 0; w < words_; ++w)
      if (!mark_[w] && st::load_le<uint32_t>(tree_ + 4 * w) != 0) fail_at("padding", w, "non-zero word outside every node");
    if (!mark_[words_ - 1]) fail_at("byte_size", words_ - 1, "trailing bytes after the last node");
    return nodes_;
  }

 private:
  // mark_[w]: 0 no node; a node's first word: its code | (level + 1) << 3; an inner
  // node's second word: kSecond.
  static constexpr uint8_t kSecond = 4, kFarWord = 2;  // first marks are >= 9
  static uint8_t first_mark(uint32_t code, uint32_t level) { return uint8_t(code | (level + 1) << 3); }

  [[noreturn]] void fail_at(const char* field, uint64_t word, const std::string& what) const {
    fail(field, tree_offset_ + 4 * word, what);
  }

  void node(uint64_t p, uint32_t code, uint32_t level) {
    const uint32_t size = code_words(code);
    if (p + size > words_) fail_at("node", p, "extends past the end of the buffer");
    if (mark_[p] || (size == 2 && mark_[p + 1])) fail_at("node", p, "reached twice or overlaps another node");
    mark_[p] = first_mark(code, level);
    if (size == 2) mark_[p + 1] = kSecond;
    ++nodes_;
    if (code != kCodeEmpty) {
      const uint64_t vp = code == kCodeLeaf ? p : p + 1;
      if (!std::isfinite(bits_float(st::load_le<uint32_t>(tree_ + 4 * vp)))) fail_at("value", vp, "not a finite float");
    }
    if (code == kCodeLeaf) return;
    const uint32_t w = st::load_le<uint32_t>(tree_ + 4 * p);
    const uint32_t mask = word_mask(w);
    if (mask == 0) fail_at("child mask", p, "inner or empty node without children");
    if (level >= geo_.depth()) fail_at("child mask", p, "children below the finest level");
    uint32_t used = 0;
    for (uint32_t s = 0; s < kSlots; ++s)
      if (child_code(mask, s)) used |= 1u << s;
    if (used & ~geo_.slot_set(level))
      fail_at("child mask", p, "a child in a slot level " + std::to_string(level) + " does not split");
    const int32_t off = word_offset(w);
    if (off == 0) fail_at("child offset", p, "zero");
    uint64_t block = block_start(p, shift_[level], off);  // wraps to a huge value before word 0
    if (is_far(off)) {
      const uint64_t f = far_word(p, off);
      if (f >= words_) fail_at("far word", p, "word " + std::to_string(f) + " lies past the end of the tree");
      if (mark_[f])
        fail_at("far word", p, "word " + std::to_string(f) + " is a node's word or another node's far word");
      mark_[f] = kFarWord;
      block = st::load_le<uint32_t>(tree_ + 4 * f);
    }
    if (block >= words_ || block + popcount16(mask) > words_)
      fail_at("child offset", p, "children block outside the tree");
    if (mark_[block]) {  // a shared block: validated nodes of the kinds the mask names
      for (uint32_t s = 0; s < kSlots; ++s)
        if (const uint32_t cc = child_code(mask, s)) {
          const uint64_t c = block + child_skip(mask, s);
          if (mark_[c] != first_mark(cc, level + 1))
            fail_at("child offset", p,
                    "shared block: word " + std::to_string(c) + " is not a validated node of the child's kind at level " +
                        std::to_string(level + 1));
        }
      return;
    }
    if (block < p + size) fail_at("child offset", p, "children block overlaps its parent");
    for (uint32_t s = 0; s < kSlots; ++s)
      if (const uint32_t cc = child_code(mask, s)) node(block + child_skip(mask, s), cc, level + 1);
  }

  const uint8_t* tree_;
  uint64_t words_;
  size_t tree_offset_;
  const Geometry& geo_;
  const uint8_t* shift_;
  std::vector<uint8_t> mark_;
  uint64_t nodes_ = 0;
};

}  // namespace

MhOctree MhOctree::open(std::span<const uint8_t> bytes) {
  const size_t size = bytes.size();
  const uint8_t* b = bytes.data();
  if (size < kHeaderFixedSize) fail("header", 0, "truncated: " + std::to_string(size) + " bytes, need at least 20");
  if (st::load_le<uint32_t>(b + kOffMagic) != kMagic) fail("magic", kOffMagic, "not an MH octree buffer");
  const uint16_t version = st::load_le<uint16_t>(b + kOffVersion);
  if (version == 1 || version == 2)
    fail("version", kOffVersion,
         "version " + std::to_string(version) + (version == 1 ? " (forward offsets only)" : " (no far words)") +
             " is no longer read; this reader reads version 3: rebuild the stack");
  if (version != kVersion) fail("version", kOffVersion, "unsupported version " + std::to_string(version));
  static_assert(offsetof(MhOctree, tree_) + sizeof(tree_) <= kWalkBytes && offsetof(MhOctree, geo_) + sizeof(geo_) <= kWalkBytes &&
                offsetof(MhOctree, shift_) + sizeof(shift_) <= kWalkBytes && offsetof(MhOctree, root_leaf_) < kWalkBytes);
  MhOctree t;
  t.geo_.n = b[kOffXyLevel];
  t.geo_.k = b[kOffWLevel];
  if (t.geo_.n > kMaxXyLevel) fail("xy_level", kOffXyLevel, std::to_string(t.geo_.n) + " exceeds 20");
  if (t.geo_.k > kMaxWLevel) fail("w_level", kOffWLevel, std::to_string(t.geo_.k) + " exceeds 12");
  t.slices_ = st::load_le<uint16_t>(b + kOffSlices);
  const uint32_t pad_slices = 1u << t.geo_.k;
  if (!(t.slices_ <= pad_slices && (t.geo_.k == 0 ? t.slices_ == 1 : t.slices_ > pad_slices / 2)))
    fail("slices", kOffSlices,
         std::to_string(t.slices_) + " slices do not pad to 2^" + std::to_string(t.geo_.k) + " (the smallest power of two)");
  const uint8_t flags = b[kOffFlags];
  if (flags & ~kFlagsKnown) fail("flags", kOffFlags, "unknown bits set");
  if (b[kOffReserved] != 0) fail("reserved", kOffReserved, "must be zero");
  t.root_leaf_ = flags & kFlagRootLeaf;
  t.node_count_ = st::load_le<uint32_t>(b + kOffNodeCount);
  const uint32_t byte_size = st::load_le<uint32_t>(b + kOffByteSize);
  if (byte_size != size)
    fail("byte_size", kOffByteSize,
         "header says " + std::to_string(byte_size) + " bytes, buffer has " + std::to_string(size));
  const uint32_t levels = t.geo_.levels();
  const size_t tree_off = tree_offset(levels);
  if (size < tree_off + 4) fail("header", 0, "truncated: " + std::to_string(size) + " bytes, no room for the root");
  for (uint32_t l = 0; l < levels; ++l) {
    t.shift_[l] = b[kOffShifts + l];
    if (t.shift_[l] > kMaxShift) fail("shift", kOffShifts + l, "greater than 15");
  }
  for (size_t o = kOffShifts + levels; o < tree_off; ++o)
    if (b[o] != 0) fail("header padding", o, "must be zero");
  if ((size - tree_off) % 4 != 0) fail("byte_size", kOffByteSize, "tree is not a whole number of 32-bit words");
  const uint64_t words = (size - tree_off) / 4;
  const uint64_t nodes = Validator(b + tree_off, words, tree_off, t.geo_, t.shift_).run(t.root_leaf_);
  if (nodes != t.node_count_)
    fail("node_count", kOffNodeCount,
         "header says " + std::to_string(t.node_count_) + ", the tree holds " + std::to_string(nodes));
  for (uint32_t l = 0; l + 1 < levels; ++l) {
    t.split_xy_[l] = t.geo_.splits_xy(l), t.split_w_[l] = t.geo_.splits_w(l);
    t.xy_next_[l] = uint8_t(t.geo_.xy_bits(l + 1));
    t.w_shift_[l] = uint8_t(t.geo_.k - t.geo_.w_bits(l + 1));
  }
  t.bytes_ = bytes;
  t.tree_ = b + tree_off;
  return t;
}

uint32_t MhOctree::word(uint64_t w) const noexcept { return st::load_le<uint32_t>(tree_ + 4 * w); }

MhOctree::Cursor MhOctree::root() const noexcept {
  Cursor c;
  c.code = root_leaf_ ? kCodeLeaf : kCodeInner;
  c.val = root_leaf_ ? 0 : 1;
  return c;
}

bool MhOctree::child(const Cursor& c, uint32_t slot, Cursor& out) const noexcept {
  if (c.code == kCodeLeaf) return false;
  const uint32_t w = word(c.pos);
  const uint32_t mask = word_mask(w);
  const uint32_t code = child_code(mask, slot);
  if (!code) return false;
  out.pos = child_block(tree_, c.pos, shift_[c.level], w) + child_skip(mask, slot);
  out.code = code;
  out.level = c.level + 1;
  out.val = code == kCodeEmpty ? c.val : (code == kCodeLeaf ? out.pos : out.pos + 1);
  return true;
}

float MhOctree::value(const Cursor& c) const noexcept { return bits_float(word(c.val)); }

float MhOctree::depth(uint64_t x, uint64_t y, uint32_t w, uint32_t level) const noexcept {
  if (level > kMaxLevel || w >= slices_) return kLitDepth;
  if ((x >> level) != 0 || (y >> level) != 0) return kLitDepth;
  if (level > geo_.n) {
    x >>= level - geo_.n, y >>= level - geo_.n;
    level = geo_.n;
  }
  // MH Fig. 5 in 3D: the slot's x, y bits are those of the child's x, y resolution, its w
  // bit that of the child's w resolution (w is given at the finest, 2^k). The per-level
  // constants come from tables filled at open.
  const uint32_t target = geo_.level_of_xy(level);
  uint64_t pos = 0, val = root_leaf_ ? 0 : 1;
  uint32_t code = root_leaf_ ? kCodeLeaf : kCodeInner;
  for (uint32_t l = 0; l < target && code != kCodeLeaf; ++l) {
    const uint32_t b = level - xy_next_[l];
    uint32_t slot = split_xy_[l] ? uint32_t((x >> b) & 1) | uint32_t((y >> b) & 1) << 1 : 0u;
    if (split_w_[l]) slot |= uint32_t((w >> w_shift_[l]) & 1) << 2;
    const uint32_t word_p = word(pos);
    const uint32_t mask = word_mask(word_p);
    code = child_code(mask, slot);
    if (!code) break;
    pos = child_block(tree_, pos, shift_[l], word_p) + child_skip(mask, slot);
    if (code != kCodeEmpty) val = code == kCodeLeaf ? pos : pos + 1;
  }
  return bits_float(word(val));
}

float MhOctree::depth_along(Path& p, uint64_t x, uint64_t y, uint32_t w) const noexcept {
  // The resumable walk (mh_octree.hpp) run to its end: along_begin restarts at the deepest
  // node the previous walk shares (nodes of level l agree iff x, y agree above bit
  // n - xy_bits(l) and w above bit k - w_bits(l)), along_step takes one step.
  Walk k = along_begin(p, x, y, w);
  while (along_step(p, k)) {
  }
  return along_value(k);
}

}  // namespace st
