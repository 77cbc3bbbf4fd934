// What the DAG-MH pack dictionary (tiles/encode/dagmh_dictionary.hpp) gives on a pack's
// encoded tiles: raw and zlib bytes (level 6, as a pack stores them) of the tiles before
// and after, and of the dictionary, which a client fetches once and keeps. Shared by
// bench_dagmh_sharing and bench_build.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st::bench {

struct DictFigures {
  uint64_t tiles = 0, tiles_rewritten = 0;
  uint64_t raw_before = 0, raw_after = 0, dict_raw = 0;
  uint64_t zlib_before = 0, zlib_after = 0, dict_zlib = 0;
  uint64_t raw_with() const { return raw_after + dict_raw; }
  uint64_t zlib_with() const { return zlib_after + dict_zlib; }
};

inline std::vector<std::vector<uint8_t>> encoded_tiles_of(const std::string& pack) {
  const auto reader = PackReader::open(pack);
  std::vector<std::vector<uint8_t>> out;
  for (const auto& e : reader->tiles())
    if (e.kind == TileKind::encoded) out.push_back(reader->read_raw(e.id));
  return out;
}

inline DictFigures dict_figures(const std::vector<std::vector<uint8_t>>& raw_tiles,
                                dagmh::SharedTiles* keep = nullptr) {
  dagmh::SharedTiles shared = dagmh::share_across_tiles(raw_tiles);
  DictFigures f;
  f.tiles = raw_tiles.size();
  f.tiles_rewritten = shared.tiles_rewritten;
  f.raw_before = shared.bytes_before;
  f.raw_after = shared.bytes_after;
  f.dict_raw = shared.dictionary.size();
  for (size_t t = 0; t < raw_tiles.size(); ++t) {
    f.zlib_before += zlib_compress(raw_tiles[t], 6).size();
    f.zlib_after += zlib_compress(shared.tiles[t], 6).size();
  }
  f.dict_zlib = f.dict_raw ? zlib_compress(shared.dictionary, 6).size() : 0;
  if (keep) *keep = std::move(shared);
  return f;
}

}  // namespace st::bench
