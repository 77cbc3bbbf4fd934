#include "tiles/core/mh_quadtree_reader.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/core/mhq_tap_walk.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st::mhq {
namespace {

const char* format_name(bool relative) { return relative ? "MMH" : "MH quadtree"; }

[[noreturn]] void fail(bool relative, const char* field, uint64_t byte, const std::string& what) {
  throw FormatError(std::string(format_name(relative)) + ": " + field + " at byte " + std::to_string(byte) +
                    ": " + what);
}

// Walks every node reachable from the root once. Marks record which words hold which
// node kind, so a shared MMH block reached again must be the same kind at the same word
// (and is not walked twice), and any overlap between nodes is caught.
class Validator {
 public:
  Validator(const uint8_t* tree, const TreeInfo& info)
      : tree_(tree), info_(info), mark_(info.words, 0), height_(info.words, 0) {}

  void run() {
    node(0, info_.root_leaf ? kCodeLeaf : kCodeInner, 0);
    for (uint64_t w = 0; w < info_.words; ++w)
      if (!mark_[w] && st::load_le<uint32_t>(tree_ + 4 * w) != 0) fail_at("padding", w, "non-zero word outside every node");
    if (!mark_[info_.words - 1]) fail_at("byte_size", info_.words - 1, "trailing bytes after the last node");
    if (nodes_ != info_.node_count)
      fail(info_.relative, "node_count", kOffNodeCount,
           "header says " + std::to_string(info_.node_count) + ", the tree holds " + std::to_string(nodes_));
  }

 private:
  static constexpr uint8_t kMarkValue = 4;  // second word of an inner node

  [[noreturn]] void fail_at(const char* field, uint64_t word, const std::string& what) const {
    fail(info_.relative, field, info_.tree_offset + 4 * word, what);
  }

  uint32_t node(uint64_t p, uint32_t code, uint32_t level) {
    const uint32_t finest = info_.levels - 1;
    const uint32_t size = code_words(code);
    if (p + size > info_.words) fail_at("node", p, "extends past the end of the buffer");
    if (mark_[p] != 0) {
      if (info_.relative && mark_[p] == code) {  // a shared block, already validated
        if (level + height_[p] > finest) fail_at("node", p, "shared subtree reaches below the finest level");
        return height_[p];
      }
      fail_at("node", p, info_.relative ? "overlaps another node of a different kind"
                                        : "reached twice or overlaps another node (MH is a tree)");
    }
    if (code == kCodeInner && mark_[p + 1] != 0) fail_at("node", p + 1, "overlaps another node");
    mark_[p] = uint8_t(code);
    if (code == kCodeInner) mark_[p + 1] = kMarkValue;
    ++nodes_;
    if (code != kCodeEmpty) {
      const uint64_t vp = code == kCodeLeaf ? p : p + 1;
      if (!std::isfinite(bits_float(st::load_le<uint32_t>(tree_ + 4 * vp)))) fail_at("value", vp, "not a finite float");
    }
    if (code == kCodeLeaf) return 0;

    const uint32_t w = st::load_le<uint32_t>(tree_ + 4 * p);
    const uint32_t mask = word_mask(w);
    if (mask == 0) fail_at("child mask", p, "inner or empty node without children");
    if (level >= finest) fail_at("child mask", p, "children below the finest level");
    uint32_t shift = info_.shift[level];
    if (info_.relative) {
      uint32_t valued_slots = 0;
      for (uint32_t s = 0; s < 4; ++s)
        if (child_code(mask, s) == kCodeLeaf || child_code(mask, s) == kCodeInner) valued_slots |= 1u << s;
      if (word_abs_flags(w) & ~valued_slots) fail_at("absolute flags", p, "flag set on a child without a value");
      shift = word_shift(w);
    } else if (word_pad(w) != 0) {
      fail_at("pad byte", p, "must be zero in MH");
    }
    const uint32_t off = word_offset(w);
    if (off == 0) fail_at("child offset", p, "zero (offsets point strictly forward)");
    const uint64_t block = block_start(p, shift, off);
    if (block < p + size) fail_at("child offset", p, "children block overlaps its parent");
    if (block + popcount8(mask) > info_.words)
      fail_at("child offset", p, "children block past the end of the buffer");
    uint32_t h = 0;
    for (uint32_t s = 0; s < 4; ++s) {
      const uint32_t cc = child_code(mask, s);
      if (cc) h = std::max(h, node(block + child_skip(mask, s), cc, level + 1) + 1);
    }
    height_[p] = uint8_t(h);
    return h;
  }

  const uint8_t* tree_;
  const TreeInfo& info_;
  std::vector<uint8_t> mark_;
  std::vector<uint8_t> height_;
  uint64_t nodes_ = 0;
};

// Lookups over a validated buffer (MH §3.2 traversal). MH fetches lazily: it remembers
// the word of the last valued node and reads the float once at the end. MMH must sum the
// relative values along the path, so it reads each valued node it passes.
template <bool kRelative>
class TreeEvaluator final : public Evaluator, public WindowDepths, public TapWalks {
 public:
  TreeEvaluator(std::span<const uint8_t> bytes, const TreeInfo& info)
      : tree_(bytes.data() + info.tree_offset), finest_(info.levels - 1), root_leaf_(info.root_leaf),
        shift_(info.shift), tree_bytes_(bytes.subspan(std::min<size_t>(info.tree_offset, bytes.size()))),
        walker_(tree_, root_leaf_, shift_) {}

  uint32_t finest_level() const override { return finest_; }

  float depth(uint32_t level, uint64_t x, uint64_t y) const override {
    level = std::min(level, kMaxLevel);
    Cursor c = root();
    descend(c, level, x, y, level);
    return value(c);
  }

  // The node the walk ended at: every texel under a leaf (or under the missing child)
  // takes the same path and gets the same value (the last-sample cache of MH §3.3).
  DepthRegion depth_region(uint32_t level, uint64_t x, uint64_t y) const override {
    level = std::min(level, kMaxLevel);
    Cursor c = root();
    descend(c, level, x, y, level);
    return {value(c), level - (c.missing ? c.level + 1 : c.level)};
  }

  // Single taps through kept regions and walks resumed from the last walk's path
  // (tap_batch.hpp).
  void pcf_batch(std::span<const PcfQuery> queries, std::span<float> out) const override {
    TapWalkPath path;
    single_tap_batch(*this, queries, out,
                     [&](uint32_t level, uint64_t x, uint64_t y) { return walk_resumed(path, level, x, y); });
  }

  // TapWalks (tap_batch.hpp): the same walk, its path kept by the caller.
  DepthRegion walk_tap(uint32_t level, uint64_t x, uint64_t y, TapPath& path) const noexcept override {
    return walk_resumed(tap_path<TapWalkPath>(path, this), level, x, y);
  }
  // TapWalks::tap_run: the same walks, inlined into one loop over the run.
  TapRunEnd tap_run(const TapRun& run, TapPath& path) const noexcept override {
    TapWalkPath& p = tap_path<TapWalkPath>(path, this);
    return tap_run_loop(run, [&](uint32_t l, uint64_t x, uint64_t y) { return walk_resumed(p, l, x, y); });
  }

  // WindowDepths::prefetch: the tree's first kPrefetchBytes (the root's block and, in the
  // depth-first layout of MHQUAD.md, the first subtrees below it), which walks read first;
  // a walk's loads depend on each other (node, then child), so a tile whose lines left the
  // cache otherwise costs a batch one miss after another. The client calls it when a batch
  // enters the tile, and for the next run's tile before it walks a run (client/remote_map_lookups.cpp).
  // 16 KiB: every tile of a real level's pack whole (Quake 3 oa_dm1 at 8192^2: at most
  // 10,240 raw bytes, 3.7 KiB on average, each walked by about 20 of a view's taps in
  // Morton order, whose walks reach most of its lines); 2 KiB left those walks missing.
  void prefetch() const noexcept override {
    const size_t n = std::min(tree_bytes_.size(), kPrefetchBytes);
    for (size_t o = 0; o < n; o += 64) __builtin_prefetch(tree_bytes_.data() + o);
  }

  // A kernel with no tap clamped is one count_window (MH §3.3's hierarchical PCF). At the
  // map's edge (taps repeat): MH §3.3, Fig. 5: the taps share the root path down to the
  // lowest common node of the kernel's corner texels; each tap continues from there, and a
  // tap whose texel lies in the region where the previous tap's walk stopped reuses its
  // answer (the last-sample cache). Same walks as depth(), so the result equals the
  // average of single lookups.
  float pcf(uint32_t level, uint64_t x, uint64_t y, uint32_t r, float receiver) const override {
    r = std::clamp<uint32_t>(r, 1, kMaxPcf);
    level = std::min(level, kMaxLevel);
    const uint64_t side = uint64_t(1) << level;
    const uint64_t x0 = pcf_tap(x, 0, r, side), x1 = pcf_tap(x, r - 1, r, side);
    const uint64_t y0 = pcf_tap(y, 0, r, side), y1 = pcf_tap(y, r - 1, r, side);
    // No tap clamped at the map's edge: the kernel is the window, each texel once.
    if (x1 - x0 == r - 1 && y1 - y0 == r - 1) return pcf_fraction(count_window(level, x0, y0, r, r, receiver), r);
    const uint64_t diff = (x0 ^ x1) | (y0 ^ y1);
    const uint32_t common = level - uint32_t(std::bit_width(diff));
    Cursor base = root();
    descend(base, level, x0, y0, common);
    uint32_t lit = 0;
    if (base.missing || base.code == kCodeLeaf || base.level == level) {
      lit = receiver <= value(base) ? r * r : 0;
    } else {
      bool cached = false;
      uint32_t cache_shift = 0, cache_lit = 0;
      uint64_t cache_x = 0, cache_y = 0;
      for (uint32_t j = 0; j < r; ++j) {
        const uint64_t ty = pcf_tap(y, j, r, side);
        for (uint32_t i = 0; i < r; ++i) {
          const uint64_t tx = pcf_tap(x, i, r, side);
          if (cached && (tx >> cache_shift) == cache_x && (ty >> cache_shift) == cache_y) {
            lit += cache_lit;
            continue;
          }
          Cursor c = base;
          descend(c, level, tx, ty, level);
          cache_lit = receiver <= value(c) ? 1 : 0;
          lit += cache_lit;
          // Every texel under the node where the walk ended (or under the missing child)
          // takes the same path and gets the same value.
          cache_shift = level - (c.missing ? c.level + 1 : c.level);
          cache_x = tx >> cache_shift;
          cache_y = ty >> cache_shift;
          cached = true;
        }
      }
    }
    return float(lit) / float(r * r);
  }

  // WindowDepths (tap_batch.hpp): the walk to the rectangle's lowest common node, then
  // every node below it that overlaps the rectangle once, depth first.
  uint32_t depth_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                        float* out) const override {
    level = std::min(level, kMaxLevel);
    const uint64_t x1 = x0 + w - 1, y1 = y0 + h - 1;
    const uint32_t common = level - uint32_t(std::bit_width((x0 ^ x1) | (y0 ^ y1)));
    Cursor base = root();
    descend(base, level, x0, y0, common);
    fill(base, level, x0, y0, x1, y1, x0, y0, h, out);
    if (base.missing) return level - (base.level + 1);
    return base.code == kCodeLeaf ? level - base.level : 0;
  }

  // WindowDepths::count_window: depth_window's walk, a node where depth()'s walk stops
  // counted whole (MH 2016 §3.3's hierarchical PCF).
  uint32_t count_window(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                        float receiver) const override {
    level = std::min(level, kMaxLevel);
    const uint64_t x1 = x0 + w - 1, y1 = y0 + h - 1;
    const uint32_t common = level - uint32_t(std::bit_width((x0 ^ x1) | (y0 ^ y1)));
    Cursor base = root();
    descend(base, level, x0, y0, common);
    return count(base, level, x0, y0, x1, y1, FlatTaps{receiver});
  }
  uint32_t count_window_plane(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                              const ReceiverPlane& p) const override {
    level = std::min(level, kMaxLevel);
    const uint64_t x1 = x0 + w - 1, y1 = y0 + h - 1;
    const uint32_t common = level - uint32_t(std::bit_width((x0 ^ x1) | (y0 ^ y1)));
    Cursor base = root();
    descend(base, level, x0, y0, common);
    return count(base, level, x0, y0, x1, y1, PlaneTaps{p, level});
  }
  // pcf's walks with the receiver plane (receiver_plane.hpp window_pcf_plane).
  float pcf_on_plane(uint32_t level, uint64_t x, uint64_t y, uint32_t r, const ReceiverPlane& p) const override {
    return window_pcf_plane(*this, level, x, y, r, p);
  }

 private:
  struct Cursor {
    uint64_t pos = 0;      // word of the current node
    uint64_t val_pos = 0;  // MH: word of the last valued node's float
    float value = 0;       // MMH: decoded value of the last valued node
    uint32_t code = 0;
    uint32_t level = 0;
    bool missing = false;  // stopped because the next child is absent
  };

  uint32_t word(uint64_t w) const { return st::load_le<uint32_t>(tree_ + 4 * w); }

  // depth_region's answer, the walk resumed from the deepest node of `path` (the last
  // walk) on this texel's path (mhq_tap_walk.hpp: the same walk, in a loop for taps).
  DepthRegion walk_resumed(TapWalkPath& path, uint32_t level, uint64_t x, uint64_t y) const {
    if (level > kMaxLevel) return depth_region(level, x, y);
    return walker_.walk(path, level, x, y);
  }

  Cursor root() const {
    Cursor c;
    c.code = root_leaf_ ? kCodeLeaf : kCodeInner;
    c.val_pos = root_leaf_ ? 0 : 1;
    if constexpr (kRelative) c.value = bits_float(word(c.val_pos));
    return c;
  }

  float value(const Cursor& c) const {
    if constexpr (kRelative) return c.value;
    return bits_float(word(c.val_pos));
  }

  // The child in `slot` (code != 0) of the inner or empty node at c, whose word is w.
  Cursor child(const Cursor& c, uint32_t w, uint32_t slot, uint32_t code) const {
    const uint32_t mask = word_mask(w);
    const uint32_t shift = kRelative ? word_shift(w) : shift_[c.level];
    const uint64_t at = block_start(c.pos, shift, word_offset(w)) + child_skip(mask, slot);
    Cursor n = c;
    n.pos = at;
    n.code = code;
    n.level += 1;
    if (code != kCodeEmpty) {
      const uint64_t vp = code == kCodeLeaf ? at : at + 1;
      if constexpr (kRelative) {
        const float s = bits_float(word(vp));
        n.value = (word_abs_flags(w) >> slot & 1u) ? s : mmh_add(c.value, s);
      } else {
        n.val_pos = vp;
      }
    }
    return n;
  }

  // Walks toward texel (x, y) of `level` until level `until`, a leaf or a missing child;
  // from a node at level l the child slot comes from bit (level - l - 1) of x and y, i.e.
  // bit (level - l') for the child's level l' = l + 1 (MH Fig. 5).
  void descend(Cursor& c, uint32_t level, uint64_t x, uint64_t y, uint32_t until) const {
    while (c.level < until && c.code != kCodeLeaf) {
      const uint32_t bit = level - (c.level + 1);
      const uint32_t slot = uint32_t((x >> bit) & 1u) | uint32_t(((y >> bit) & 1u) << 1);
      const uint32_t w = word(c.pos);
      const uint32_t code = child_code(word_mask(w), slot);
      if (!code) {
        c.missing = true;
        return;
      }
      c = child(c, w, slot, code);
    }
  }

  // depth_window below c, a node on the path of every texel of [ax, bx] x [ay, by] (all
  // inside its square): where depth()'s walk would stop (a leaf, a missing child, the
  // level itself) its value covers the part of the rectangle under it; else each child
  // that overlaps the rectangle, with its part. The recursion is at most 21 deep.
  void fill(const Cursor& c, uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by, uint64_t x0,
            uint64_t y0, uint32_t h, float* out) const {
    if (c.missing || c.code == kCodeLeaf || c.level >= level) {
      window_put(value(c), ax, ay, bx, by, x0, y0, h, out);
      return;
    }
    const uint32_t bit = level - (c.level + 1);
    const uint32_t w = word(c.pos);
    const uint32_t mask = word_mask(w);
    // The node's square is 2^(bit+1) texels, aligned; its children split it at `mid`.
    const uint64_t half = uint64_t(1) << bit;
    const QuadSplit split(ax, ay, bx, by, half);
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      const uint32_t code = child_code(mask, slot);
      if (!code) {  // depth() stops here: the last valued node's value (c's)
        window_put(value(c), cx0, cy0, cx1, cy1, x0, y0, h, out);
        continue;
      }
      fill(child(c, w, slot, code), level, cx0, cy0, cx1, cy1, x0, y0, h, out);
    }
  }

  // fill's walk, counting the lit texels of [ax, bx] x [ay, by] instead of writing them
  // (Taps: FlatTaps or PlaneTaps, receiver_plane.hpp).
  template <class Taps>
  uint32_t count(const Cursor& c, uint32_t level, uint64_t ax, uint64_t ay, uint64_t bx, uint64_t by,
                 const Taps& taps) const {
    if (c.missing || c.code == kCodeLeaf || c.level >= level) return taps.count(value(c), ax, ay, bx, by);
    const uint32_t bit = level - (c.level + 1);
    const uint32_t w = word(c.pos);
    const uint32_t mask = word_mask(w);
    const uint64_t half = uint64_t(1) << bit;
    const QuadSplit split(ax, ay, bx, by, half);
    uint32_t lit = 0;
    for (uint32_t slot = 0; slot < 4; ++slot) {
      uint64_t cx0, cy0, cx1, cy1;
      if (!split.part(slot, cx0, cy0, cx1, cy1)) continue;
      const uint32_t code = child_code(mask, slot);
      if (!code) {  // depth() stops here: c's value answers the part
        lit += taps.count(value(c), cx0, cy0, cx1, cy1);
        continue;
      }
      lit += count(child(c, w, slot, code), level, cx0, cy0, cx1, cy1, taps);
    }
    return lit;
  }

  const uint8_t* tree_;
  uint32_t finest_;
  bool root_leaf_;
  std::array<uint8_t, kMaxLevels> shift_;
  std::span<const uint8_t> tree_bytes_;  // from the tree's first word to the tile's end (prefetch)
  static constexpr size_t kPrefetchBytes = 16384;
  TapWalker<kRelative> walker_;  // the single taps' walk (after tree_, root_leaf_, shift_)
};

}  // namespace

TreeInfo validate(std::span<const uint8_t> bytes, bool relative) {
  const size_t size = bytes.size();
  const uint8_t* b = bytes.data();
  if (size < kHeaderFixedSize)
    fail(relative, "header", 0, "truncated: " + std::to_string(size) + " bytes, need at least 16");
  const uint32_t magic = st::load_le<uint32_t>(b + kOffMagic);
  const uint32_t want = relative ? kMagicMmh : kMagicMh;
  if (magic != want) {
    if (magic == (relative ? kMagicMh : kMagicMmh))
      fail(relative, "magic", kOffMagic, relative ? "this is an MH buffer (open_mh)" : "this is an MMH buffer (open_mmh)");
    fail(relative, "magic", kOffMagic, "not an MH/MMH buffer");
  }
  const uint16_t version = st::load_le<uint16_t>(b + kOffVersion);
  if (version != kVersion) fail(relative, "version", kOffVersion, "unsupported version " + std::to_string(version));
  TreeInfo info;
  info.relative = relative;
  info.levels = b[kOffLevels];
  if (info.levels < 1 || info.levels > kMaxLevels)
    fail(relative, "levels", kOffLevels, std::to_string(info.levels) + " not in 1..21");
  const uint8_t flags = b[kOffFlags];
  if (flags & ~kFlagsKnown) fail(relative, "flags", kOffFlags, "unknown bits set");
  if (bool(flags & kFlagRelative) != relative)
    fail(relative, "flags", kOffFlags, "relative-values bit disagrees with the magic");
  info.root_leaf = flags & kFlagRootLeaf;
  info.node_count = st::load_le<uint32_t>(b + kOffNodeCount);
  const uint32_t byte_size = st::load_le<uint32_t>(b + kOffByteSize);
  if (byte_size != size)
    fail(relative, "byte_size", kOffByteSize,
         "header says " + std::to_string(byte_size) + " bytes, buffer has " + std::to_string(size));
  info.tree_offset = tree_offset(info.levels);
  if (size < info.tree_offset + 4)
    fail(relative, "header", 0, "truncated: " + std::to_string(size) + " bytes, no room for the root");
  for (uint32_t l = 0; l < info.levels; ++l) {
    info.shift[l] = b[kOffShifts + l];
    if (info.shift[l] > kMaxShift) fail(relative, "shift", kOffShifts + l, "greater than 15");
  }
  for (size_t o = kOffShifts + info.levels; o < info.tree_offset; ++o)
    if (b[o] != 0) fail(relative, "header padding", o, "must be zero");
  if ((size - info.tree_offset) % 4 != 0)
    fail(relative, "byte_size", kOffByteSize, "tree is not a whole number of 32-bit words");
  info.words = (size - info.tree_offset) / 4;
  Validator(b + info.tree_offset, info).run();
  return info;
}

std::unique_ptr<Evaluator> make_evaluator(std::span<const uint8_t> bytes, const TreeInfo& info) {
  if (info.relative) return std::make_unique<TreeEvaluator<true>>(bytes, info);
  return std::make_unique<TreeEvaluator<false>>(bytes, info);
}

}  // namespace st::mhq
