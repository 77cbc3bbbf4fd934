// Sharing DAG-MH structure across tiles (DAG-MH 2021 §3.1 applied to a whole pack; format:
// tiles/core/DAGMH.md "Dictionary"). Each tile is encoded alone, so a subtree topology or
// treelet bitmap that occurs in many tiles is stored in each; this pass, run over a
// pack's encoded tiles, moves every inner node and treelet that occurs in at least
// `min_tiles` tiles into one dictionary and rewrites the tiles that used them as version
// 2, whose references past their own nodes / treelets name the dictionary's. Values are
// untouched (they are per place, and almost never repeat across tiles: bench_dagmh_sharing
// measured 0.2% of the city's value bytes in repeated chunks), so every lookup of a
// rewritten tile reaches the same value index and answers bit-identically.
#pragma once
#include <cstdint>
#include <vector>

namespace st::dagmh {

struct SharedTiles {
  std::vector<uint8_t> dictionary;          // DictHeader buffer; empty if nothing is shared
  std::vector<std::vector<uint8_t>> tiles;  // same order; unchanged (no dictionary flag) where they share nothing
  uint64_t bytes_before = 0, bytes_after = 0;  // the tiles' raw bytes (dictionary not included)
  uint64_t tiles_rewritten = 0, dict_nodes = 0, dict_treelets = 0;
};

// Builds the dictionary of `tiles` (DAG-MH buffers without the dictionary flag; each is validated) and the
// rewritten tiles; every rewritten tile is validated against the dictionary before it is
// returned. min_tiles >= 2. Throws st::Error on a malformed tile or one already flagged.
SharedTiles share_across_tiles(const std::vector<std::vector<uint8_t>>& tiles, uint32_t min_tiles = 2);

}  // namespace st::dagmh
