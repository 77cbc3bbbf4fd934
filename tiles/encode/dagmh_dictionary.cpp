// DAG-MH pack dictionary builder (tiles/encode/dagmh_dictionary.hpp; format DAGMH.md
// "Dictionary"). Nodes are keyed by topology exactly as the per-tile DAG keys them
// (DAG-MH §3.1): flags and the keys of the children, compared in full, so equal keys mean
// equal subtrees, hence equal value counts and value offsets.
#include "tiles/encode/dagmh_dictionary.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>

#include "common/error.hpp"
#include "tiles/core/dagmh_validate.hpp"

namespace st::dagmh {
namespace {

struct CanonNode {
  uint32_t flags = 0, height = 0, tiles = 0, last_tile = ~0u;
  std::vector<uint32_t> child;         // canonical ids (treelet ids where the flag says treelet)
  std::vector<uint32_t> value_offset;  // as stored
};

struct TileParse {
  Header h{};
  Sections s{};
  std::vector<uint32_t> starts;         // node start words, in order
  std::vector<uint32_t> node_canon;     // canonical id per start
  std::unordered_map<uint32_t, uint32_t> start_index;  // word -> index in starts
  std::vector<uint32_t> treelet_canon;  // canonical id per treelet
};

}  // namespace

SharedTiles share_across_tiles(const std::vector<std::vector<uint8_t>>& tiles, uint32_t min_tiles) {
  if (min_tiles < 2) throw Error("dagmh dictionary: min_tiles must be at least 2");
  std::map<std::array<uint32_t, kTreeletWords>, uint32_t> treelet_ids;
  std::vector<std::array<uint32_t, kTreeletWords>> treelet_bits;
  std::vector<uint32_t> treelet_tiles, treelet_last;
  std::unordered_map<std::string, uint32_t> node_ids;
  std::vector<CanonNode> canon;
  std::vector<TileParse> parsed(tiles.size());

  for (uint32_t ti = 0; ti < tiles.size(); ++ti) {
    const auto& buf = tiles[ti];
    const View view = validate(buf);
    TileParse& p = parsed[ti];
    p.h = load_header(buf.data());
    p.s = sections_of(p.h, buf.size());
    if (p.h.flags & kFlagDictionary)
      throw Error("dagmh dictionary: tile " + std::to_string(ti) + " already references a dictionary");
    p.treelet_canon.resize(p.h.treelet_count);
    for (uint32_t t = 0; t < p.h.treelet_count; ++t) {
      std::array<uint32_t, kTreeletWords> bits;
      for (uint32_t w = 0; w < kTreeletWords; ++w) bits[w] = st::load_le<uint32_t>(view.treelets + size_t(t) * kTreeletBytes + 4 * w);
      auto [it, fresh] = treelet_ids.try_emplace(bits, uint32_t(treelet_bits.size()));
      if (fresh) treelet_bits.push_back(bits), treelet_tiles.push_back(0), treelet_last.push_back(~0u);
      p.treelet_canon[t] = it->second;
      if (treelet_last[it->second] != ti) treelet_last[it->second] = ti, ++treelet_tiles[it->second];
    }
    for (uint32_t w = 0; w < p.h.node_words;) {
      p.start_index[w] = uint32_t(p.starts.size());
      p.starts.push_back(w);
      w += node_words(st::load_le<uint32_t>(view.nodes + size_t(w) * 4));
    }
    p.node_canon.resize(p.starts.size());
    for (size_t k = p.starts.size(); k-- > 0;) {  // children lie after their parents
      const uint8_t* node = view.nodes + size_t(p.starts[k]) * 4;
      CanonNode n;
      n.flags = st::load_le<uint32_t>(node);
      std::string key(reinterpret_cast<const char*>(&n.flags), 4);
      uint32_t rank = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((n.flags >> c) & 1)) continue;
        const uint32_t ref = st::load_le<uint32_t>(node + 4 + 8 * rank);
        const bool treelet = (n.flags >> (kNodeTreeletShift + c)) & 1;
        const uint32_t id = treelet ? p.treelet_canon[ref] : p.node_canon[p.start_index.at(ref)];
        n.child.push_back(id);
        n.value_offset.push_back(st::load_le<uint32_t>(node + 8 + 8 * rank));
        n.height = std::max(n.height, treelet ? 1u : canon[id].height + 1);
        key.append(reinterpret_cast<const char*>(&id), 4);
        ++rank;
      }
      auto [it, fresh] = node_ids.try_emplace(std::move(key), uint32_t(canon.size()));
      if (fresh) canon.push_back(std::move(n));
      CanonNode& cn = canon[it->second];
      if (cn.last_tile != ti) cn.last_tile = ti, ++cn.tiles;
      p.node_canon[k] = it->second;
    }
  }

  // The dictionary: shared nodes by decreasing height (children after parents, as the
  // validator demands), then shared treelets. Sharing is closed downward: a child occurs
  // in every tile its parent occurs in.
  SharedTiles out;
  std::vector<uint32_t> dict_node_word(canon.size(), ~0u), dict_treelet(treelet_bits.size(), ~0u);
  std::vector<uint32_t> order;
  for (uint32_t i = 0; i < canon.size(); ++i)
    if (canon[i].tiles >= min_tiles) order.push_back(i);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return canon[a].height > canon[b].height; });
  uint64_t words = 0;
  for (uint32_t i : order) dict_node_word[i] = uint32_t(words), words += node_words(canon[i].flags);
  uint32_t dict_treelets = 0;
  for (uint32_t i = 0; i < treelet_bits.size(); ++i)
    if (treelet_tiles[i] >= min_tiles) dict_treelet[i] = dict_treelets++;
  if (words > kRefIndexMask) throw Error("dagmh dictionary: more than 2^30 node words");
  const uint32_t dict_words = uint32_t(words);
  out.dict_nodes = order.size();
  out.dict_treelets = dict_treelets;
  std::shared_ptr<const Dictionary> dict;
  if (!order.empty() || dict_treelets > 0) {
    DictHeader dh{};
    dh.magic = kDictMagic;
    dh.version = kDictVersion;
    dh.header_bytes = sizeof(DictHeader);
    dh.node_words = uint32_t(words);
    dh.treelet_count = dict_treelets;
    dh.node_offset = sizeof(DictHeader);
    dh.treelet_offset = uint32_t(sizeof(DictHeader) + words * 4);
    const uint64_t total = dh.treelet_offset + uint64_t(dict_treelets) * kTreeletBytes;
    if (total > 0xFFFFFFFFull) throw Error("dagmh dictionary: exceeds 4 GiB");
    dh.total_bytes = uint32_t(total);
    out.dictionary.assign(total, 0);
    std::memcpy(out.dictionary.data(), &dh, sizeof dh);
    for (uint32_t i : order) {
      const CanonNode& n = canon[i];
      uint8_t* p = out.dictionary.data() + dh.node_offset + size_t(dict_node_word[i]) * 4;
      st::store_le<uint32_t>(p, n.flags);
      uint32_t rank = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((n.flags >> c) & 1)) continue;
        const bool treelet = (n.flags >> (kNodeTreeletShift + c)) & 1;
        st::store_le<uint32_t>(p + 4 + 8 * rank, treelet ? dict_treelet[n.child[rank]] : dict_node_word[n.child[rank]]);
        st::store_le<uint32_t>(p + 8 + 8 * rank, n.value_offset[rank]);
        ++rank;
      }
    }
    for (uint32_t i = 0; i < treelet_bits.size(); ++i)
      if (dict_treelet[i] != ~0u)
        for (uint32_t w = 0; w < kTreeletWords; ++w)
          st::store_le<uint32_t>(out.dictionary.data() + dh.treelet_offset + size_t(dict_treelet[i]) * kTreeletBytes + 4 * w,
                                 treelet_bits[i][w]);
    dict = Dictionary::open(out.dictionary);
  }

  // Rewrite each tile that uses the dictionary: its own nodes and treelets keep their
  // order (children still lie after parents), references are remapped, values are copied
  // as they are, and the skip table is walked anew over the rewritten DAG.
  out.tiles.resize(tiles.size());
  for (uint32_t ti = 0; ti < tiles.size(); ++ti) {
    const auto& buf = tiles[ti];
    const TileParse& p = parsed[ti];
    const Header& h = p.h;
    const Sections& hs = p.s;
    out.bytes_before += buf.size();
    bool uses = false;
    for (uint32_t c : p.node_canon) uses |= dict_node_word[c] != ~0u;
    for (uint32_t c : p.treelet_canon) uses |= dict_treelet[c] != ~0u;
    if (!uses) {
      out.tiles[ti] = buf;
      out.bytes_after += buf.size();
      continue;
    }
    std::vector<uint32_t> new_word(p.starts.size(), ~0u), new_treelet(h.treelet_count, ~0u);
    uint32_t local_words = 0, local_treelets = 0;
    for (size_t k = 0; k < p.starts.size(); ++k)
      if (dict_node_word[p.node_canon[k]] == ~0u) {
        new_word[k] = local_words;
        local_words += node_words(st::load_le<uint32_t>(buf.data() + hs.nodes + size_t(p.starts[k]) * 4));
      }
    for (uint32_t t = 0; t < h.treelet_count; ++t)
      if (dict_treelet[p.treelet_canon[t]] == ~0u) new_treelet[t] = local_treelets++;
    auto inner = [&](uint32_t w) {
      const uint32_t k = p.start_index.at(w), c = p.node_canon[k];
      return dict_node_word[c] != ~0u ? dict_node_word[c] : dict_words + new_word[k];
    };
    auto treelet = [&](uint32_t t) {
      const uint32_t c = p.treelet_canon[t];
      return dict_treelet[c] != ~0u ? dict_treelet[c] : dict_treelets + new_treelet[t];
    };
    auto tagged = [&](uint32_t ref) {
      const uint32_t tag = ref & kRefTagMask, index = ref & kRefIndexMask;
      if (tag == kRefInner) return kRefInner | inner(index);
      if (tag == kRefTreelet) return kRefTreelet | treelet(index);
      return ref;
    };
    Header nh = h;
    nh.flags = kFlagDictionary;
    nh.dictionary_crc = dict->crc();
    nh.node_words = local_words;
    nh.treelet_count = local_treelets;
    nh.root_ref = tagged(h.root_ref);
    // The skip level by the encoder's rule (§3.7, dagmh_encode.cpp): at most the tile's
    // own, lowered while the table would exceed 1/16 of the rest of the smaller buffer.
    const uint64_t multiplier_bytes = hs.end - hs.multipliers;
    nh.skip_level = 0;
    const uint64_t rest = sections_of(nh, 0).multipliers + multiplier_bytes;
    uint32_t skip = h.skip_level;
    while (skip > 0 && skip_table_entries(skip) * kSkipEntryBytes * 16 > rest) --skip;
    nh.skip_level = uint8_t(skip);
    Sections ns = sections_of(nh, 0);
    ns.end = ns.multipliers + multiplier_bytes;
    std::vector<uint8_t> o(ns.end, 0);
    std::memcpy(o.data(), &nh, sizeof nh);
    for (size_t k = 0; k < p.starts.size(); ++k) {
      if (new_word[k] == ~0u) continue;
      const uint8_t* src = buf.data() + hs.nodes + size_t(p.starts[k]) * 4;
      uint8_t* dst = o.data() + ns.nodes + size_t(new_word[k]) * 4;
      const uint32_t flags = st::load_le<uint32_t>(src);
      std::memcpy(dst, src, size_t(node_words(flags)) * 4);
      uint32_t rank = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((flags >> c) & 1)) continue;
        const uint32_t ref = st::load_le<uint32_t>(src + 4 + 8 * rank);
        st::store_le<uint32_t>(dst + 4 + 8 * rank, (flags >> (kNodeTreeletShift + c)) & 1 ? treelet(ref) : inner(ref));
        ++rank;
      }
    }
    for (uint32_t t = 0; t < h.treelet_count; ++t)
      if (new_treelet[t] != ~0u)
        std::memcpy(o.data() + ns.treelets + size_t(new_treelet[t]) * kTreeletBytes,
                    buf.data() + hs.treelets + size_t(t) * kTreeletBytes, kTreeletBytes);
    std::memcpy(o.data() + ns.chunks, buf.data() + hs.chunks, size_t(ns.end - ns.chunks));
    // The skip table: one cursor per texel of level `skip`, by walking the rewritten DAG.
    View view;
    view.skip = o.data() + ns.skip;
    view.nodes = o.data() + ns.nodes;
    view.treelets = o.data() + ns.treelets;
    view.chunks = o.data() + ns.chunks;
    view.multipliers = o.data() + ns.multipliers;
    view.finest_level = nh.finest_level;
    view.skip_level = skip;
    view.root_ref = nh.root_ref;
    view.value_count = nh.value_count;
    view.dict_node_words = dict->node_words();
    view.dict_treelet_count = dict->treelet_count();
    view.dict_nodes = dict->nodes();
    view.dict_treelets = dict->treelets();
    const uint64_t side = skip == 0 ? 0 : uint64_t(1) << skip;  // S = 0: no table
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) {
        const Cursor c = view.descend(view.root(), skip, skip, x, y);
        std::memcpy(o.data() + ns.skip + (y * side + x) * sizeof(Cursor), &c, sizeof c);
      }
    validate(o, dict.get());  // a malformed rewrite never leaves this function
    out.bytes_after += o.size();
    ++out.tiles_rewritten;
    out.tiles[ti] = std::move(o);
  }
  return out;
}

}  // namespace st::dagmh
