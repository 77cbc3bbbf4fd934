#include "tiles/encode/mh_octree_share.hpp"

#include "tiles/encode/mh_internal.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <unordered_map>
#include <vector>

namespace st {
namespace {

// A subtree: kind, value bits, slot mask and its children's subtree ids (slot order).
// A block: the same without the node's own value and kind.
using Key = std::array<uint32_t, 10>;

using KeyHash = mh_detail::WordKeyHash;

uint32_t own_words(const OctNode& n) { return n.has_value && n.child_mask ? 2 : 1; }

}  // namespace

OctreeSharing measure_octree_sharing(const OctHierarchy& h, bool roundest) {
  OctreeSharing s;
  std::unordered_map<Key, uint32_t, KeyHash> subtree_ids, block_ids;
  std::vector<uint64_t> subtree_words;  // per subtree id: words of the whole subtree
  std::vector<uint32_t> occurrences;    // per subtree id
  std::vector<uint8_t> has_children;    // per subtree id
  std::vector<uint8_t> own;             // per subtree id: the node's own words
  std::vector<uint32_t> below, here;    // ids of the nodes of level l + 1, of level l
  for (size_t l = h.levels.size(); l-- > 0;) {
    const std::vector<OctNode>& level = h.levels[l];
    here.assign(level.size(), 0);
    size_t next = 0;
    for (size_t j = 0; j < level.size(); ++j) {
      const OctNode& n = level[j];
      Key block{};
      block[0] = n.child_mask;
      uint64_t words = own_words(n), slot = 0;
      for (uint32_t c = 0; c < 8; ++c)
        if (n.child_mask >> c & 1) {
          const uint32_t id = below[next++];
          block[2 + slot++] = id + 1;  // 0: no child
          words += subtree_words[id];
        }
      Key key = block;
      key[1] = n.has_value ? std::bit_cast<uint32_t>(roundest ? mh_detail::roundest_in(n.lo, n.hi) : n.value) : 0;
      key[0] |= uint32_t(n.has_value) << 8;
      auto [it, fresh] = subtree_ids.try_emplace(key, uint32_t(subtree_words.size()));
      if (fresh) {
        subtree_words.push_back(words);
        occurrences.push_back(0);
        has_children.push_back(n.child_mask != 0);
        own.push_back(uint8_t(own_words(n)));
        s.dag_words += own_words(n);
      }
      ++occurrences[it->second];
      here[j] = it->second;
      ++s.nodes;
      s.words += own_words(n);
      if (n.child_mask) {
        ++s.blocks;
        if (block_ids.try_emplace(block, uint32_t(block_ids.size())).second) {
          // A new block: its children's own words (their blocks are counted as blocks).
          for (uint32_t i = 0; i < slot; ++i) s.block_dag_words += own[block[2 + i] - 1];
        }
      }
    }
    below.swap(here);
  }
  // Block-shared words: the root, plus every distinct block's children once.
  if (!h.levels.empty() && !h.levels[0].empty()) s.block_dag_words += own_words(h.levels[0][0]);
  for (size_t id = 0; id < occurrences.size(); ++id)
    if (occurrences[id] > 1 && has_children[id]) {
      ++s.repeated_inner;
      s.largest_repeated_words = std::max(s.largest_repeated_words, subtree_words[id]);
    }
  s.unique_subtrees = subtree_words.size();
  s.unique_blocks = block_ids.size();
  return s;
}


uint64_t hybrid_octree_quad_words(const OctHierarchy& h, const std::vector<QuadSubtreeWords>& quad_words) {
  const moct::Geometry& g = h.geo;
  auto quad = [&](uint32_t w, uint32_t a, uint64_t x, uint64_t y) -> uint64_t {
    if (w >= quad_words.size() || a >= quad_words[w].levels.size()) return 0;
    const auto& lv = quad_words[w].levels[a];
    uint64_t m = 0;
    for (uint32_t b = 0; b < a; ++b) m |= ((x >> b & 1) << (2 * b)) | ((y >> b & 1) << (2 * b + 1));
    auto it = std::lower_bound(lv.begin(), lv.end(), std::pair<uint64_t, uint32_t>{m, 0});
    return it != lv.end() && it->first == m ? it->second : 0;
  };
  std::vector<uint64_t> below, here;
  for (size_t l = h.levels.size(); l-- > 0;) {
    const std::vector<OctNode>& level = h.levels[l];
    here.assign(level.size(), 0);
    const uint32_t a = g.xy_bits(uint32_t(l)), wb = g.w_bits(uint32_t(l));
    const uint32_t span = 1u << (g.k - wb);
    size_t next = 0;
    for (size_t j = 0; j < level.size(); ++j) {
      const OctNode& n = level[j];
      uint64_t oct = own_words(n);
      for (uint32_t m = n.child_mask; m; m &= m - 1) oct += below[next++];
      uint64_t x = 0, y = 0, w = 0;
      oct_coords(g, uint32_t(l), n.code, x, y, w);
      uint64_t q = span - 1;
      for (uint32_t s = 0; s < span; ++s) q += quad(uint32_t(w * span + s), a, x, y);
      here[j] = std::min(oct, q);
    }
    below.swap(here);
  }
  return below.empty() ? 0 : below[0];
}

}  // namespace st
