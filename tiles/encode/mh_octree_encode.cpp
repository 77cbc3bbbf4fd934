// The MH octree encoder: flatten, lay out depth-first (a node's children block follows
// the blocks of its earlier siblings' subtrees, so offsets shrink level by level), share
// equal blocks (near by offset, far by a far word), find per-level shifts that make every
// near offset fit 16 bits, then write the words.
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/mh_internal.hpp"
#include "tiles/encode/mh_octree_flat.hpp"
#include "tiles/encode/mh_octree_merge.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>

#include "common/error.hpp"

namespace st {
namespace {

using namespace moct;
using moct_detail::Flat;

// Layout rounds that add far words, and the most near hits a copied block may have and
// still be replaced by a far word (encode_octree); constants of the encoder, not of the
// format. Measured on the city at 1024^2 x 32 (MHOCT.md "Version 3 measured"): far words
// for every copy made the buffer grow after round 3 (a copy other nodes reach by near
// offsets relays the block; dropping it sends them out of reach too); at most 2 hits kept
// the least words (0.772 of the N quadtrees' bytes; 0 hits 0.781, 4 hits 0.778).
constexpr uint32_t kFarRounds = 4;
constexpr uint32_t kFarMaxHits = 2;

[[noreturn]] void bad(uint32_t l, size_t j, const std::string& what) {
  throw Error("octree hierarchy: level " + std::to_string(l) + " node " + std::to_string(j) + ": " + what);
}

Flat flatten(const OctHierarchy& h) {
  const Geometry& g = h.geo;
  if (g.n > kMaxXyLevel || g.k > kMaxWLevel) throw Error("octree hierarchy: geometry out of range");
  if (h.slices < 1 || h.slices > (1u << g.k) || (g.k > 0 && h.slices <= (1u << (g.k - 1))))
    throw Error("octree hierarchy: " + std::to_string(h.slices) + " slices do not pad to 2^" + std::to_string(g.k));
  if (h.levels.size() != g.levels()) throw Error("octree hierarchy: wrong number of levels");
  if (h.levels[0].size() != 1 || !h.levels[0][0].has_value) throw Error("octree hierarchy: level 0 must hold a valued root");
  size_t total = 0;
  for (const auto& lv : h.levels) total += lv.size();
  if (total >= (size_t(1) << 31)) throw Error("octree hierarchy: too many nodes for one buffer");
  Flat t;
  t.first_child.resize(total), t.mask.resize(total), t.level.resize(total), t.valued.resize(total),
      t.value.resize(total), t.lo.resize(total), t.hi.resize(total);
  uint32_t n = 0;
  for (uint32_t l = 0; l < h.levels.size(); ++l) {
    const auto& lv = h.levels[l];
    const uint32_t next_begin = n + uint32_t(lv.size());
    size_t next = 0;
    for (size_t j = 0; j < lv.size(); ++j, ++n) {
      const OctNode& node = lv[j];
      if (j && lv[j - 1].code >= node.code) bad(l, j, "codes not increasing");
      if (node.child_mask & ~g.slot_set(l)) bad(l, j, "a child in a slot this level does not split");
      if (!node.has_value && !node.child_mask) bad(l, j, "neither valued nor with children");
      if (node.has_value && !std::isfinite(node.value)) bad(l, j, "value is not finite");
      t.first_child[n] = next_begin + uint32_t(next);
      t.mask[n] = node.child_mask;
      t.level[n] = uint8_t(l);
      t.valued[n] = node.has_value;
      t.value[n] = node.value;
      t.lo[n] = node.lo, t.hi[n] = node.hi;
      for (uint32_t c = 0; c < kSlots; ++c) {
        if (!(node.child_mask >> c & 1u)) continue;
        const uint64_t want = (node.code << g.step_bits(l)) | (g.splits_xy(l) ? c : c >> 2);
        if (l + 1 >= h.levels.size() || next >= h.levels[l + 1].size() || h.levels[l + 1][next].code != want)
          bad(l, j, "child " + std::to_string(c) + " is not at the expected code");
        ++next;
      }
    }
    if (l + 1 < h.levels.size() && next != h.levels[l + 1].size()) bad(l + 1, next, "node has no parent");
  }
  return t;
}

// Block ids: two nodes of one level get one id iff their children are equal all the way
// down (kinds, values, slots). Subtrees are hash-consed bottom-up; keys hold ids, never
// hashes alone.
using Key = std::array<uint32_t, 11>;
using KeyHash = mh_detail::WordKeyHash;

// block_id[n] for nodes with children (0 for the others); returns the number of ids.
uint32_t block_ids(const Flat& t, std::vector<uint32_t>& block_id) {
  std::unordered_map<Key, uint32_t, KeyHash> subtrees, blocks;
  std::vector<uint32_t> sub(t.size(), 0);
  block_id.assign(t.size(), 0);
  for (uint32_t n = uint32_t(t.size()); n-- > 0;) {
    Key block{};
    block[0] = t.mask[n] | uint32_t(t.level[n]) << 8;
    const uint32_t c0 = t.first_child[n], cn = uint32_t(std::popcount(unsigned(t.mask[n])));
    for (uint32_t i = 0; i < cn; ++i) block[3 + i] = sub[c0 + i] + 1;
    Key key = block;
    key[1] = t.valued[n] ? 1u : 0u;
    key[2] = t.valued[n] ? float_bits(t.value[n]) : 0u;
    sub[n] = subtrees.try_emplace(key, uint32_t(subtrees.size())).first->second;
    if (cn) block_id[n] = blocks.try_emplace(block, uint32_t(blocks.size()) + 1).first->second;
  }
  return uint32_t(blocks.size()) + 1;
}

// Whether a far word (1 word) saves anything over a copy of the node's block: the copy
// costs the block's words and its children's subtrees, so a block of one leaf or one
// childless empty node costs no more than the far word.
std::vector<uint8_t> far_worth(const Flat& t) {
  std::vector<uint8_t> worth(t.size(), 0);
  for (uint32_t n = 0; n < t.size(); ++n) {
    if (!t.mask[n]) continue;
    uint32_t words = 0;
    bool deeper = false;
    const uint32_t c0 = t.first_child[n], cn = uint32_t(std::popcount(unsigned(t.mask[n])));
    for (uint32_t c = c0; c < c0 + cn; ++c) words += code_words(t.kind(c)), deeper = deeper || t.mask[c];
    worth[n] = words > 1 || deeper;
  }
  return worth;
}

struct Pass {
  std::vector<uint32_t> pos, block;
  std::vector<uint8_t> stored, shared;  // per node: written; its block is a back-reference
  std::vector<uint32_t> far_pos;        // per node: its reserved far word (0: none; word 0 is the root)
  std::vector<uint8_t> far, copied;     // per node: block reached through the far word; an equal
                                        // block was out of reach, so this one is a copy
  std::vector<uint32_t> last;           // per block id: the latest copy laid out (0: none)
  std::vector<uint32_t> last_owner;     // per block id: the node that laid that copy out
  std::vector<uint32_t> hits;           // per node: nodes that share its block by a near offset
  uint64_t words = 0, padding = 0, shared_blocks = 0, out_of_reach = 0, far_blocks = 0, far_words = 0;
  uint32_t nodes = 0;
  std::array<uint64_t, kMaxLevels> max_off{};
  bool fits = true, too_big = false;
};

// One layout with the shifts `sh`; the nodes with far_want get a far word after the block
// that holds them (format version 3), used when their block's equal copy, or their own
// block, lies beyond the 16-bit offset's reach.
void layout(const Flat& t, const std::vector<uint32_t>& block_id, uint32_t ids, const std::vector<uint8_t>& far_want,
            const std::array<uint8_t, kMaxLevels>& sh, Pass& out) {
  out.pos.assign(t.size(), 0);
  out.block.assign(t.size(), 0);
  out.stored.assign(t.size(), 0);
  out.shared.assign(t.size(), 0);
  out.far_pos.assign(t.size(), 0);
  out.far.assign(t.size(), 0);
  out.copied.assign(t.size(), 0);
  out.last.assign(ids, 0);
  out.last_owner.assign(ids, 0);
  out.hits.assign(t.size(), 0);
  out.max_off.fill(0);
  out.fits = true, out.too_big = false, out.padding = 0, out.shared_blocks = 0, out.out_of_reach = 0;
  out.far_blocks = 0, out.far_words = 0;
  out.stored[0] = 1, out.nodes = 1;
  uint64_t w = code_words(t.kind(0));
  uint64_t end = w;  // past the last node or used far word: unused far words at the end are cut
  std::vector<uint32_t> stack{0};
  while (!stack.empty()) {
    const uint32_t n = stack.back();
    stack.pop_back();
    if (!t.mask[n]) continue;
    const uint32_t s = sh[t.level[n]];
    // The latest copy of an equal block (laid out earlier, so its nodes are validated
    // before this one is reached), if the signed offset reaches it: blocks of one level
    // share its alignment, so the copy's start is a multiple of 2^s.
    if (const uint32_t copy = out.last[block_id[n]]) {
      const int64_t d = int64_t(uint64_t(copy) >> s) - int64_t(uint64_t(out.pos[n]) >> s);
      if (d != 0 && d >= -int64_t(kMaxBackOffset) && d <= int64_t(kMaxOffset)) {
        out.block[n] = copy, out.shared[n] = 1;
        ++out.shared_blocks;
        ++out.hits[out.last_owner[block_id[n]]];
        continue;
      }
      if (out.far_pos[n]) {
        out.block[n] = copy, out.shared[n] = 1, out.far[n] = 1;
        end = std::max<uint64_t>(end, out.far_pos[n] + 1);
        ++out.shared_blocks, ++out.far_blocks;
        continue;
      }
      ++out.out_of_reach;
      out.copied[n] = 1;
    }
    const uint64_t align = uint64_t(1) << s;
    const uint64_t start = (w + align - 1) & ~(align - 1);
    out.padding += start - w;
    w = start;
    if (w >= kMaxBytes / 4) {
      out.too_big = true;
      out.words = w;
      return;
    }
    out.block[n] = uint32_t(w);
    out.last[block_id[n]] = uint32_t(w);
    out.last_owner[block_id[n]] = n;
    const uint64_t off = (w >> s) - (uint64_t(out.pos[n]) >> s);
    if (out.far_pos[n] && off > kMaxOffset)
      out.far[n] = 1, ++out.far_blocks;  // its own block beyond reach: the far word names it
    else
      out.max_off[t.level[n]] = std::max(out.max_off[t.level[n]], off);
    const uint32_t c0 = t.first_child[n], cn = uint32_t(std::popcount(unsigned(t.mask[n])));
    for (uint32_t c = c0; c < c0 + cn; ++c) {
      out.pos[c] = uint32_t(w);
      out.stored[c] = 1;
      ++out.nodes;
      w += code_words(t.kind(c));
    }
    end = w;
    for (uint32_t c = c0; c < c0 + cn; ++c)  // at most 8 far words: within kFarCodes of every child
      if (far_want[c]) out.far_pos[c] = uint32_t(w++), ++out.far_words;
    for (uint32_t c = c0 + cn; c-- > c0;)
      if (t.mask[c]) stack.push_back(c);
  }
  out.words = end;
  if (end > (kMaxBytes - tree_offset(kMaxLevels)) / 4) out.too_big = true;
  for (uint64_t m : out.max_off) out.fits = out.fits && m <= kMaxOffset;
}

[[noreturn]] void too_big(uint64_t words) {
  throw Error("MH octree: stack too large for one buffer (" + std::to_string(words * 4) +
              " tree bytes exceed the 32-bit byte_size); cut it into smaller stacks");
}

void put_u32(std::vector<uint8_t>& b, size_t off, uint32_t v) { std::memcpy(b.data() + off, &v, 4); }

// Always on: walks every node of the hierarchy through the written buffer, as a reader
// does (near and far blocks, shared or not), and checks that each one is found with its
// kind and child mask and that each valued one reads a value inside its window (the
// central window of its interval, or its own value: value_windows). So whatever the
// merger and the layout shared, every texel of every slice and level keeps the lossless
// invariant (MH 2016 §3.1) of the hierarchy it was given.
void verify_buffer(const Flat& t, const std::vector<float>& wlo, const std::vector<float>& whi,
                   const std::vector<uint8_t>& out, size_t tree_off, const std::array<uint8_t, kMaxLevels>& sh) {
  const uint8_t* tree = out.data() + tree_off;
  const uint64_t words = (out.size() - tree_off) / 4;
  auto word = [&](uint64_t i) {
    if (i >= words) throw Error("MH octree encoder: internal error: a node lies outside the buffer");
    uint32_t v;
    std::memcpy(&v, tree + 4 * i, 4);
    return v;
  };
  auto check_value = [&](uint32_t n, uint64_t at) {
    const float v = bits_float(word(at));
    if (!(wlo[n] <= v && v <= whi[n]))
      throw Error("MH octree encoder: internal error: node " + std::to_string(n) + " reads a value outside its window");
  };
  struct Item {
    uint32_t node;
    uint64_t pos;
  };
  std::vector<Item> stack{{0, 0}};
  check_value(0, t.mask[0] ? 1 : 0);
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    if (!t.mask[it.node]) continue;
    const uint32_t w = word(it.pos);
    if (word_mask(w) != t.code_mask(it.node))
      throw Error("MH octree encoder: internal error: node " + std::to_string(it.node) + " has the wrong child mask");
    if (is_far(word_offset(w))) (void)word(far_word(it.pos, word_offset(w)));
    const uint64_t block = child_block(tree, it.pos, sh[t.level[it.node]], w);
    uint32_t c = t.first_child[it.node];
    for (uint32_t slot = 0; slot < kSlots; ++slot) {
      if (!(t.mask[it.node] >> slot & 1u)) continue;
      const uint64_t at = block + child_skip(word_mask(w), slot);
      if (t.valued[c]) check_value(c, t.mask[c] ? at + 1 : at);
      stack.push_back({c++, at});
    }
  }
}

}  // namespace

std::vector<uint8_t> encode_octree(const OctHierarchy& h, OctEncodeStats* stats, const OctEncodeOptions& options) {
  Flat t = flatten(h);
  std::vector<float> wlo, whi;
  moct_detail::value_windows(t, wlo, whi);
  moct_detail::MergeCounts merged;
  if (options.merge) moct_detail::merge_subtrees(t, wlo, whi, {options.merge_window, options.merge_max_pairs}, merged);
  std::vector<uint32_t> block_id;
  const uint32_t ids = block_ids(t, block_id);
  const uint32_t L = h.geo.depth();
  std::array<uint8_t, kMaxLevels> sh{};
  Pass pass, trial;
  // Far words (format version 3), chosen by hits: a node gets one when, in the previous
  // round's layout, its block repeated an earlier block that lay out of the offset's
  // reach, so it was copied, the copy costs more than the far word (far_worth), and at
  // most kFarMaxHits later nodes shared the copy by a near offset (a copy with more hits
  // is a relay worth its words). Each round lays out again with the far words of all earlier rounds
  // (positions move, so some copies fall within reach and new ones out of it), at most
  // kFarRounds rounds; deterministic (depth-first order, no hashing order involved).
  const std::vector<uint8_t> worth = far_worth(t);
  std::vector<uint8_t> far_want(t.size(), 0);
  for (uint32_t round = 1;; ++round) {
    // The smallest shifts that fit (raise each overflowing level by what its overflow
    // needs, lay out again).
    sh.fill(0);
    for (;;) {
      layout(t, block_id, ids, far_want, sh, pass);
      if (pass.too_big) too_big(pass.words);
      if (pass.fits) break;
      for (uint32_t l = 0; l < L; ++l) {
        if (pass.max_off[l] <= kMaxOffset) continue;
        const uint32_t raise = std::max<uint32_t>(1, uint32_t(std::bit_width((pass.max_off[l] - 1) / kMaxOffset)));
        if (sh[l] + raise > kMaxShift) too_big(pass.words);
        sh[l] = uint8_t(sh[l] + raise);
      }
    }
    if (round == kFarRounds) break;
    bool more = false;
    for (uint32_t n = 0; n < t.size(); ++n)
      if (pass.copied[n] && worth[n] && !far_want[n] && pass.hits[n] <= kFarMaxHits) far_want[n] = 1, more = true;
    if (!more) break;
  }
  // Far words reserved in the last round and left unused (their node found its block
  // within near reach) are dropped where that makes the buffer smaller.
  {
    std::vector<uint8_t> used(t.size(), 0);
    for (uint32_t n = 0; n < t.size(); ++n) used[n] = far_want[n] && pass.far[n];
    layout(t, block_id, ids, used, sh, trial);
    if (!trial.too_big && trial.fits && trial.words < pass.words) std::swap(pass, trial), far_want.swap(used);
  }
  // Then one step either way on every scaled level, keeping the smallest buffer (as the MH
  // quadtree encoder, MHQUAD.md "Offsets and the scale search").
  for (uint32_t l = 0; l < L; ++l) {
    if (sh[l] == 0) continue;
    for (int d : {-1, 1}) {
      auto cand = sh;
      cand[l] = uint8_t(int(sh[l]) + d);
      if (cand[l] > kMaxShift) continue;
      layout(t, block_id, ids, far_want, cand, trial);
      if (!trial.too_big && trial.fits && trial.words < pass.words) std::swap(pass, trial), sh = cand;
    }
  }
  const uint32_t levels = h.geo.levels();
  const size_t tree_off = tree_offset(levels);
  const uint64_t byte_size = tree_off + pass.words * 4;
  std::vector<uint8_t> out(byte_size, 0);
  put_u32(out, kOffMagic, kMagic);
  const uint16_t version = kVersion, slices = uint16_t(h.slices);
  std::memcpy(out.data() + kOffVersion, &version, 2);
  out[kOffXyLevel] = uint8_t(h.geo.n);
  out[kOffWLevel] = uint8_t(h.geo.k);
  std::memcpy(out.data() + kOffSlices, &slices, 2);
  out[kOffFlags] = t.mask[0] ? 0 : kFlagRootLeaf;
  put_u32(out, kOffNodeCount, pass.nodes);
  put_u32(out, kOffByteSize, uint32_t(byte_size));
  for (uint32_t l = 0; l < levels; ++l) out[kOffShifts + l] = sh[l];
  for (uint32_t n = 0; n < t.size(); ++n) {
    if (!pass.stored[n]) continue;  // inside a subtree stored once for an earlier node
    const size_t at = tree_off + size_t(pass.pos[n]) * 4;
    const uint32_t kind = t.kind(n);
    if (kind == kCodeLeaf) {
      put_u32(out, at, float_bits(t.value[n]));
      continue;
    }
    const uint32_t s = sh[t.level[n]];
    int32_t off = int32_t(int64_t(uint64_t(pass.block[n]) >> s) - int64_t(uint64_t(pass.pos[n]) >> s));
    if (pass.far[n]) {
      off = far_offset(pass.pos[n], pass.far_pos[n]);
      put_u32(out, tree_off + size_t(pass.far_pos[n]) * 4, pass.block[n]);
    }
    put_u32(out, at, node_word(t.code_mask(n), off));
    if (kind == kCodeInner) put_u32(out, at + 4, float_bits(t.value[n]));
  }
  verify_buffer(t, wlo, whi, out, tree_off, sh);
  if (stats) {
    stats->merge_candidates = merged.candidates;
    stats->merge_tests = merged.tests;
    stats->merge_quick_rejects = merged.quick_rejects;
    stats->merge_full_rejects = merged.full_rejects;
    stats->merges = merged.merges;
    stats->merged_values = merged.values_changed;
    stats->shift = sh;
    stats->words = pass.words;
    stats->padding_words = pass.padding;
    stats->nodes = pass.nodes;
    stats->shared_blocks = pass.shared_blocks;
    stats->out_of_reach = pass.out_of_reach;
    stats->far_blocks = pass.far_blocks;
    stats->far_words = pass.far_words;
  }
  return out;
}

}  // namespace st
