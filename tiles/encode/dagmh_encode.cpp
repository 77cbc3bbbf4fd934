// DAG-MH encoder: structure DAG + value chunks + skip table, assembled into one buffer
// (layout: tiles/core/DAGMH.md).
#include "tiles/encode/dagmh_encode.hpp"

#include <algorithm>
#include <numeric>

#include "tiles/core/dagmh_traverse.hpp"
#include "tiles/encode/encode.hpp"
#include "common/error.hpp"
#include "tiles/core/interval.hpp"

namespace st::dagmh {
namespace {

uint64_t skip_table_bytes(uint32_t level) { return skip_table_entries(level) * kSkipEntryBytes; }

}  // namespace

std::vector<uint8_t> encode(const Hierarchy& h, EncodeStats* stats, StructureHash hash) {
  if (h.depth > kMaxLevel) throw Error("dagmh: hierarchy depth exceeds 20");
  const DagStructure dag = build_structure(h, hash);
  const EncodedValues values = encode_values(dag.values);

  // Inner nodes by decreasing height: every child reference then points forward, which
  // is what the validator demands (acyclic by construction, §3.1).
  std::vector<uint32_t> order(dag.inner.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return dag.inner[a].height > dag.inner[b].height;
  });
  std::vector<uint32_t> word_of(dag.inner.size());
  uint64_t words = 0;
  for (uint32_t id : order) {
    word_of[id] = uint32_t(std::min<uint64_t>(words, kRefIndexMask));
    words += node_words(dag.inner[id].flags);
  }
  if (words > kRefIndexMask || dag.treelets.size() > kRefIndexMask)
    throw Error("dagmh: structure exceeds 2^30 node words or treelets");

  Header hd{};
  hd.magic = kMagic;
  hd.version = kVersion;
  hd.finest_level = uint8_t(h.depth);
  hd.node_words = uint32_t(words);
  hd.treelet_count = uint32_t(dag.treelets.size());
  hd.value_count = uint32_t(dag.values.size());
  hd.root_ref = (dag.root & kRefTagMask) == kRefInner ? kRefInner | word_of[dag.root & kRefIndexMask] : dag.root;
  const uint64_t multiplier_bytes = values.multipliers.size();
  // Skip list at level <= 6 (§3.7), coarser while its table would exceed 1/16 of the rest.
  const uint64_t rest = sections_of(hd, 0).multipliers + multiplier_bytes;
  uint32_t skip = std::min(h.depth, kMaxSkipListLevel);
  while (skip > 0 && skip_table_bytes(skip) * 16 > rest) --skip;
  hd.skip_level = uint8_t(skip);
  Sections sec = sections_of(hd, 0);
  const uint64_t total = sec.multipliers + multiplier_bytes;
  if (total > 0xFFFFFFFFull) throw Error("dagmh: encoded buffer exceeds 4 GiB");
  sec.end = total;

  std::vector<uint8_t> out(total, 0);
  std::memcpy(out.data(), &hd, sizeof(Header));
  const size_t node_offset = sec.nodes, treelet_offset = sec.treelets, chunk_offset = sec.chunks,
               multiplier_offset = sec.multipliers, skip_offset = sec.skip;
  for (uint32_t id : order) {
    const InnerNode& n = dag.inner[id];
    uint8_t* p = out.data() + node_offset + size_t(word_of[id]) * 4;
    st::store_le<uint32_t>(p, n.flags);
    uint32_t rank = 0;
    for (uint32_t c = 0; c < 4; ++c) {
      if (!((n.flags >> c) & 1)) continue;
      const bool treelet = (n.flags >> (kNodeTreeletShift + c)) & 1;
      st::store_le<uint32_t>(p + 4 + 8 * rank, treelet ? n.child[rank] : word_of[n.child[rank]]);
      st::store_le<uint32_t>(p + 8 + 8 * rank, n.value_offset[rank]);
      ++rank;
    }
  }
  for (size_t t = 0; t < dag.treelets.size(); ++t)
    for (uint32_t w = 0; w < kTreeletWords; ++w)
      st::store_le<uint32_t>(out.data() + treelet_offset + t * kTreeletBytes + w * 4, dag.treelets[t][w]);
  if (!values.chunks.empty())
    std::memcpy(out.data() + chunk_offset, values.chunks.data(), values.chunks.size() * sizeof(ChunkInfo));
  std::memcpy(out.data() + multiplier_offset, values.multipliers.data(), values.multipliers.size());

  // The skip table: one cursor per texel of level `skip`, by walking the written DAG.
  View view;
  view.skip = out.data() + skip_offset;
  view.nodes = out.data() + node_offset;
  view.treelets = out.data() + treelet_offset;
  view.chunks = out.data() + chunk_offset;
  view.multipliers = out.data() + multiplier_offset;
  view.finest_level = hd.finest_level;
  view.skip_level = skip;
  view.root_ref = hd.root_ref;
  view.value_count = hd.value_count;
  const uint64_t side = skip == 0 ? 0 : uint64_t(1) << skip;  // S = 0: no table
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const Cursor c = view.descend(view.root(), skip, skip, x, y);
      std::memcpy(out.data() + skip_offset + (y * side + x) * sizeof(Cursor), &c, sizeof(Cursor));
    }

  if (stats) {
    stats->tree_inner = dag.tree_inner;
    stats->dag_inner = dag.inner.size();
    stats->tree_treelets = dag.tree_treelets;
    stats->dag_treelets = dag.treelets.size();
    stats->value_count = dag.values.size();
    stats->skip_level = skip;
    stats->header_bytes = sizeof(Header);
    stats->skip_bytes = skip_table_bytes(skip);
    stats->node_bytes = words * 4;
    stats->treelet_bytes = uint64_t(hd.treelet_count) * kTreeletBytes;
    stats->chunk_bytes = uint64_t(sec.chunk_count) * sizeof(ChunkInfo);
    stats->multiplier_bytes = multiplier_bytes;
    stats->total_bytes = total;
    stats->values = values.stats;
  }
  return out;
}

}  // namespace st::dagmh

namespace st {
std::vector<uint8_t> encode_dagmh(const Hierarchy& h) { return dagmh::encode(h); }
}  // namespace st
