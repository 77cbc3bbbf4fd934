// PackWriter::finish with the pack-wide DAG-MH dictionary (tiles/PACK.md "DAG-MH
// dictionary"; DAG-MH 2021 §3.1 applied across tiles, tiles/core/DAGMH.md "Dictionary").
//
// The journal in "<path>.tmp" holds the tiles as each cell encoded them (unflagged) and
// stays untouched: finish() writes the pack afresh (PackWriter::write_finished) with the
// rewritten tiles in place of theirs. The tiles are shared in tile-id order, so the
// dictionary depends on the tiles alone, never on the order cells were appended in (a
// merged, resumed or MPI-built pack gets the same bytes).
#include "tiles/encode/pack_writer.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <unordered_map>

#include "common/error.hpp"
#include "tiles/encode/pack_file_io.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st {

std::vector<uint8_t> PackWriter::share_dictionary(RewrittenTiles& rewritten_tiles, bool must_pay) {
  const std::string what = tmp_path();
  DictionaryOutcome& out = dictionary_;
  out = DictionaryOutcome{};
  rewritten_tiles.clear();
  if (params_.encoding != Encoding::dagmh) {
    out.skipped = "the encoding is " + to_string(params_.encoding) + ", not dagmh";
    return {};
  }
  // 1. Every encoded tile's raw bytes, in id order (tiles_ is sorted).
  std::vector<size_t> which;
  for (size_t i = 0; i < tiles_.size(); ++i)
    if (tiles_[i].kind == TileKind::encoded) which.push_back(i), out.raw_before += tiles_[i].raw_size;
  out.tiles = which.size();
  if (which.size() < 2) {
    out.skipped = "fewer than two encoded tiles";
    return {};
  }
  if (out.raw_before > params_.dictionary_max_input_bytes) {
    out.skipped = "the encoded tiles hold " + std::to_string(out.raw_before) + " raw bytes, above the dictionary pass's " +
                  std::to_string(params_.dictionary_max_input_bytes) + " (PackParams::dictionary_max_input_bytes)";
    return {};
  }
  std::vector<std::vector<uint8_t>> raw;
  std::vector<size_t> dagmh_tiles;
  for (size_t k = 0; k < which.size(); ++k) {
    const TileIndexEntry& t = tiles_[which[k]];
    std::vector<uint8_t> stored(t.stored_size);
    pack_io::pread_all(fd_, t.offset, stored, what);
    if (crc32_of(stored) != t.crc) throw Error(what + ": " + describe_tile(t.id) + " fails its CRC on the read back");
    std::vector<uint8_t> bytes = zlib_decompress(stored, t.raw_size, what + ": " + describe_tile(t.id));
    // A mixed tile (tiles/PACK.md "Mixed tiles") or a plane tile (tiles/core/PLANES.md) shares nothing.
    if (is_mmh_buffer(bytes) || is_plane_buffer(bytes) || is_packed_plane_tile(bytes)) {
      out.raw_after += t.raw_size;
      continue;
    }
    dagmh_tiles.push_back(which[k]);
    raw.push_back(std::move(bytes));
  }
  which = std::move(dagmh_tiles);
  if (which.size() < 2) {
    out.skipped = "fewer than two DAG-MH tiles";
    return {};
  }
  // 2. Share; a dictionary above the pack bound shares only subtrees found in more tiles.
  dagmh::SharedTiles shared;
  for (out.min_tiles = 2;; out.min_tiles *= 2) {
    shared = dagmh::share_across_tiles(raw, out.min_tiles);
    if (shared.dictionary.size() <= kMaxPackDictionaryBytes) break;
    if (out.min_tiles > (1u << 30)) throw Error(what + ": the DAG-MH dictionary does not fit its bound");
  }
  if (shared.dictionary.empty() || shared.tiles_rewritten == 0) {
    out.skipped = "no subtree occurs in two tiles";
    return {};
  }
  for (size_t k = 0; k < which.size(); ++k) {
    // A rewritten tile never grows (its own nodes are a subset, its skip table no
    // larger); should one, the original (unflagged, valid in any pack) is kept.
    if (shared.tiles[k].size() > params_.tile_bytes || shared.tiles[k] == raw[k]) {
      out.raw_after += tiles_[which[k]].raw_size;
      continue;
    }
    out.raw_after += shared.tiles[k].size();
    rewritten_tiles.emplace_back(tiles_[which[k]].id, std::move(shared.tiles[k]));  // in id order
  }
  if (must_pay) {
    // Mixed tiles: the pack must stay no larger than the MMH pack tile for tile, so the
    // dictionary goes in only when its stored section costs less than it saves.
    uint64_t saved = 0;
    for (const auto& [id, bytes] : rewritten_tiles) {
      const auto t = std::lower_bound(tiles_.begin(), tiles_.end(), id,
                                      [](const TileIndexEntry& e, uint64_t i) { return e.id < i; });
      const uint64_t now = zlib_compress(bytes, params_.compression_level).size();
      saved += t->stored_size > now ? t->stored_size - now : 0;
    }
    const uint64_t cost = kPackDictionaryHeaderBytes + zlib_compress(shared.dictionary, params_.compression_level).size();
    if (saved <= cost) {
      rewritten_tiles.clear();
      out.raw_after = out.raw_before;
      out.skipped = "it would store " + std::to_string(cost) + " bytes to save " + std::to_string(saved) +
                    " in the DAG-MH tiles of a pack with mixed tiles";
      return {};
    }
  }
  out.bytes = shared.dictionary.size();
  out.tiles_rewritten = rewritten_tiles.size();
  return std::move(shared.dictionary);
}

}  // namespace st
