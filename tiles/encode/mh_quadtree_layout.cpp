#include "tiles/encode/mh_quadtree_layout.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::mhq {

uint32_t FlatTree::code_mask(uint32_t n) const {
  uint32_t m = 0;
  for (uint32_t slot = 0; slot < 4; ++slot)
    if (mask[n] >> slot & 1u) m |= code(child(n, slot)) << (2 * slot);
  return m;
}

namespace {

[[noreturn]] void bad_hierarchy(uint32_t l, size_t j, const std::string& what) {
  throw Error("hierarchy: level " + std::to_string(l) + " node " + std::to_string(j) + ": " + what);
}

}  // namespace

FlatTree flatten(const Hierarchy& h, bool need_intervals) {
  if (h.depth > kMaxLevel) throw Error("hierarchy: depth " + std::to_string(h.depth) + " exceeds 20");
  if (h.levels.size() != size_t(h.depth) + 1)
    throw Error("hierarchy: " + std::to_string(h.levels.size()) + " levels for depth " +
                std::to_string(h.depth));
  if (h.levels[0].size() != 1) throw Error("hierarchy: level 0 must hold exactly the root");
  if (!h.levels[0][0].has_value) bad_hierarchy(0, 0, "the root must be valued");
  size_t total = 0;
  for (auto& lv : h.levels) total += lv.size();
  if (total >= (size_t(1) << 31)) throw Error("hierarchy: too many nodes for one tile");

  FlatTree t;
  t.depth = h.depth;
  t.level_begin.resize(h.depth + 2);
  t.first_child.resize(total);
  t.mask.resize(total);
  t.level.resize(total);
  t.valued.resize(total);
  t.value.resize(total);
  t.lo.resize(total);
  t.hi.resize(total);
  uint32_t n = 0;
  for (uint32_t l = 0; l <= h.depth; ++l) {
    t.level_begin[l] = n;
    const auto& lv = h.levels[l];
    const uint32_t next_begin = n + uint32_t(lv.size());
    uint32_t next_j = 0;  // index into level l + 1 of the next child
    for (size_t j = 0; j < lv.size(); ++j, ++n) {
      const HNode& node = lv[j];
      if (j > 0 && lv[j - 1].morton >= node.morton) bad_hierarchy(l, j, "morton codes not increasing");
      if (node.child_mask > 0xF) bad_hierarchy(l, j, "child_mask has bits above 3");
      if (l == h.depth && node.child_mask) bad_hierarchy(l, j, "children below the finest level");
      if (!node.has_value && !node.child_mask) bad_hierarchy(l, j, "neither valued nor with children");
      if (node.has_value) {
        if (!std::isfinite(node.value)) bad_hierarchy(l, j, "value is not finite");
        if (need_intervals && !(node.lo <= node.value && node.value <= node.hi && std::isfinite(node.lo) &&
                                std::isfinite(node.hi)))
          bad_hierarchy(l, j, "value outside its finite [lo, hi]");
      }
      t.first_child[n] = next_begin + next_j;
      t.mask[n] = node.child_mask;
      t.level[n] = uint8_t(l);
      t.valued[n] = node.has_value ? 1 : 0;
      t.value[n] = node.value;
      t.lo[n] = node.lo;
      t.hi[n] = node.hi;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!(node.child_mask >> c & 1u)) continue;
        if (l == h.depth || next_j >= h.levels[l + 1].size())
          bad_hierarchy(l, j, "child mask names more children than level " + std::to_string(l + 1) + " holds");
        if (h.levels[l + 1][next_j].morton != ((node.morton << 2) | c))
          bad_hierarchy(l, j, "child " + std::to_string(c) + " is not at the expected morton code");
        ++next_j;
      }
    }
    if (l < h.depth && next_j != h.levels[l + 1].size())
      bad_hierarchy(l + 1, next_j, "node has no parent (child masks name fewer nodes)");
  }
  t.level_begin[h.depth + 1] = n;
  return t;
}

namespace {

struct Pass {
  std::vector<uint32_t> pos;    // word of each emitted node
  std::vector<uint32_t> block;  // word of each owned children block
  uint64_t words = 0, padding = 0;
  uint32_t nodes = 0;
  std::array<uint64_t, kMaxLevels> max_off{};
  bool fits = true;
  bool too_big = false;
};

class Layouter {
 public:
  Layouter(const FlatTree& t, const EmitPlan& p) : t_(t), p_(p) {
    if (!p_.block_owner.empty())
      for (uint32_t n = 0; n < t_.size(); ++n)
        if (p_.block_owner[n] != n && p_.alive[n]) mergees_.push_back(n);
  }

  bool alive(uint32_t n) const { return p_.alive.empty() || p_.alive[n]; }
  uint32_t owner(uint32_t n) const { return p_.block_owner.empty() ? n : p_.block_owner[n]; }

  uint32_t block_shift(uint32_t n, const std::array<uint8_t, kMaxLevels>& sh) const {
    uint32_t levels = p_.block_parent_levels.empty() ? 0 : p_.block_parent_levels[n];
    if (!levels) return sh[t_.level[n]];
    uint32_t a = 0;
    for (uint32_t l = 0; l < kMaxLevels; ++l)
      if (levels >> l & 1u) a = std::max<uint32_t>(a, sh[l]);
    return a;
  }

  // Depth-first pre-order: visiting a node writes its children block, then its
  // children are visited in slot order. Nodes below a mergee are never reached.
  void run(const std::array<uint8_t, kMaxLevels>& sh, Pass& out) const {
    const size_t n_nodes = t_.size();
    out.pos.resize(n_nodes);
    out.block.resize(n_nodes);
    out.max_off.fill(0);
    out.fits = true;
    out.too_big = false;
    out.padding = 0;
    uint64_t w = code_words(t_.code(0));
    out.pos[0] = 0;
    uint32_t nodes = 1;
    stack_.assign(1, 0);
    auto note_offset = [&](uint32_t n, uint64_t block) {
      const uint32_t s = sh[t_.level[n]];
      const uint64_t off = (block >> s) - (uint64_t(out.pos[n]) >> s);
      ST_CHECK(off >= 1);  // blocks follow every parent (pre-order layout)
      auto& m = out.max_off[t_.level[n]];
      m = std::max(m, off);
    };
    while (!stack_.empty()) {
      const uint32_t n = stack_.back();
      stack_.pop_back();
      if (!t_.mask[n] || owner(n) != n) continue;
      const uint64_t align = uint64_t(1) << block_shift(n, sh);
      const uint64_t start = (w + align - 1) & ~(align - 1);
      out.padding += start - w;
      w = start;
      if (w >= kMaxBytes / 4) {
        out.too_big = true;
        return;
      }
      out.block[n] = uint32_t(w);
      note_offset(n, w);
      const uint32_t c0 = t_.first_child[n];
      const uint32_t cn = popcount8(t_.mask[n]);
      for (uint32_t c = c0; c < c0 + cn; ++c) {
        out.pos[c] = uint32_t(w);
        w += code_words(t_.code(c));
      }
      nodes += cn;
      for (uint32_t c = c0 + cn; c-- > c0;)
        if (t_.mask[c]) stack_.push_back(c);
    }
    out.words = w;
    out.nodes = nodes;
    if (w > (kMaxBytes - tree_offset(kMaxLevels)) / 4) {
      out.too_big = true;
      return;
    }
    for (uint32_t n : mergees_) note_offset(n, out.block[owner(n)]);
    for (uint64_t m : out.max_off) out.fits = out.fits && m <= kMaxOffset;
  }

 private:
  const FlatTree& t_;
  const EmitPlan& p_;
  std::vector<uint32_t> mergees_;
  mutable std::vector<uint32_t> stack_;
};

[[noreturn]] void too_big(uint64_t words) {
  throw Error("MH quadtree: tile too large for one buffer (" + std::to_string(words * 4) +
              " tree bytes exceed the 32-bit byte_size); cut the tile deeper");
}

void put_u32(std::vector<uint8_t>& b, size_t off, uint32_t v) { std::memcpy(b.data() + off, &v, 4); }

}  // namespace

void unscaled_layout(const FlatTree& t, std::vector<uint32_t>& pos, std::vector<uint32_t>& block) {
  const EmitPlan plain;
  Pass pass;
  Layouter(t, plain).run(std::array<uint8_t, kMaxLevels>{}, pass);
  pos = std::move(pass.pos);
  block = std::move(pass.block);
}

std::vector<uint8_t> serialize(const FlatTree& t, const EmitPlan& plan, LayoutStats* stats) {
  Layouter lay(t, plan);
  std::array<uint8_t, kMaxLevels> sh{};
  Pass pass;
  uint32_t passes = 0;
  // 1) The smallest per-level shifts that make every offset fit: raise the shift of each
  //    level whose largest offset overflows 16 bits by as much as that overflow needs and
  //    lay out again (a shift changes the padding and so other levels' offsets; iterate
  //    to the fixed point, usually one or two rounds).
  for (;;) {
    lay.run(sh, pass);
    ++passes;
    if (pass.too_big) too_big(pass.words);
    if (pass.fits) break;
    for (uint32_t l = 0; l < t.depth; ++l) {
      if (pass.max_off[l] <= kMaxOffset) continue;
      const uint32_t raise = std::max<uint32_t>(1, uint32_t(std::bit_width((pass.max_off[l] - 1) / kMaxOffset)));
      if (sh[l] + raise > kMaxShift) too_big(pass.words);
      sh[l] = uint8_t(sh[l] + raise);
    }
  }
  // 2) Exhaustive search around it (Lefebvre & Hoppe 2007): for every scaled level try
  //    the neighbouring shifts and keep the one giving the smallest buffer. Larger
  //    shifts only add padding unless they happen to align blocks, so one step each way
  //    is where a smaller layout can hide.
  Pass trial;
  for (uint32_t l = 0; l < t.depth; ++l) {
    if (sh[l] == 0) continue;
    const uint8_t base = sh[l];
    for (int d : {-1, 1}) {
      const int cand = int(base) + d;
      if (cand < 0 || cand > int(kMaxShift)) continue;
      auto trial_sh = sh;
      trial_sh[l] = uint8_t(cand);
      lay.run(trial_sh, trial);
      ++passes;
      if (!trial.too_big && trial.fits && trial.words < pass.words) {
        std::swap(pass, trial);
        sh = trial_sh;
      }
    }
  }
  ST_CHECK(pass.fits && !pass.too_big);

  const uint32_t levels = t.depth + 1;
  const size_t tree_off = tree_offset(levels);
  const uint64_t byte_size = tree_off + pass.words * 4;
  std::vector<uint8_t> out(byte_size, 0);
  put_u32(out, kOffMagic, plan.relative ? kMagicMmh : kMagicMh);
  const uint16_t version = kVersion;
  std::memcpy(out.data() + kOffVersion, &version, 2);
  out[kOffLevels] = uint8_t(levels);
  out[kOffFlags] = uint8_t((t.mask[0] ? 0 : kFlagRootLeaf) | (plan.relative ? kFlagRelative : 0));
  put_u32(out, kOffNodeCount, pass.nodes);
  put_u32(out, kOffByteSize, uint32_t(byte_size));
  for (uint32_t l = 0; l < levels; ++l) out[kOffShifts + l] = sh[l];

  auto owner = [&](uint32_t n) { return plan.block_owner.empty() ? n : plan.block_owner[n]; };
  auto stored = [&](uint32_t n) { return plan.stored.empty() ? t.value[n] : plan.stored[n]; };
  for (uint32_t n = 0; n < t.size(); ++n) {
    if (!lay.alive(n)) continue;
    const size_t at = tree_off + size_t(pass.pos[n]) * 4;
    const uint32_t code = t.code(n);
    if (code == kCodeLeaf) {
      put_u32(out, at, float_bits(stored(n)));
      continue;
    }
    const uint32_t o = owner(n);
    const uint32_t s = sh[t.level[n]];
    const uint32_t off = uint32_t((uint64_t(pass.block[o]) >> s) - (uint64_t(pass.pos[n]) >> s));
    uint32_t pad = 0;
    if (plan.relative) {
      uint32_t abs_flags = 0;
      for (uint32_t slot = 0; slot < 4; ++slot)
        if ((t.mask[o] >> slot & 1u) && plan.absolute[t.child(o, slot)]) abs_flags |= 1u << slot;
      pad = abs_flags | (s << 4);
    }
    put_u32(out, at, node_word(t.code_mask(o), pad, off));
    if (code == kCodeInner) put_u32(out, at + 4, float_bits(stored(n)));
  }
  if (stats) {
    stats->shift = sh;
    stats->words = pass.words;
    stats->padding_words = pass.padding;
    stats->nodes = pass.nodes;
    stats->layout_passes = passes;
  }
  return out;
}

}  // namespace st::mhq
