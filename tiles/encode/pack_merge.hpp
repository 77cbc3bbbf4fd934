// Builds split across processes or machines: a shard is one slice of a map's level-K
// cells (`build --shard i/N` writes it as a part file); merge_parts() joins the parts of
// every shard into the pack a single build writes (tiles/PACK.md "Part files").
//
//   BuildShard s = BuildShard::parse("3/16");            // cells with morton % 16 == 3
//   MergeReport r = merge_parts({"p0.part", ..., "p15.part"}, "map.pack");
//
// Shards interleave along the Z curve (cell c with morton(cx, cy) % N == i): cost varies
// with the scene's density region by region, and interleaving gives every shard a
// similar mix, so a batch system's array jobs finish close together.
//
// Errors: st::Error naming the part and what is wrong (a part of another map or build,
// a record that fails its CRC, a shard held twice, a shard or cell missing).
#pragma once
#include <cstdint>
#include <span>
#include <string>

#include "tiles/core/morton.hpp"

namespace st {

struct BuildShard {
  uint32_t index = 0, count = 1;  // 0 <= index < count <= kMaxShards
  static constexpr uint32_t kMaxShards = 1u << 20;

  // "i/N"; st::Error naming the text otherwise.
  static BuildShard parse(const std::string& text);
  std::string to_string() const { return std::to_string(index) + "/" + std::to_string(count); }
  bool holds(uint32_t cx, uint32_t cy) const { return morton_encode(cx, cy) % count == index; }
  // Cells of a 2^K x 2^K grid this shard holds.
  uint64_t cell_count(uint32_t skip_level) const;
};

// The build parameter a part file carries (tiles/PACK.md).
inline constexpr const char* kShardParam = "shard";

struct MergeReport {
  uint32_t shard_count = 0;
  uint64_t cells = 0, tiles = 0, bytes_copied = 0;
  uint64_t dictionary_bytes = 0;  // the DAG-MH dictionary rebuilt over all parts' tiles (0: none)
};

// Joins part files into `out_path` (written as "<out_path>.tmp", renamed when complete):
// every shard 0..N-1 exactly once, every part complete for its shard, all of the same map
// and build parameters. Tile payloads are copied as they are stored (every CRC checked on
// the way); the coarse levels are built over the cells' root intervals with the build's
// construction, so the result equals a single-process build's pack tile for tile.
// Parts never carry a DAG-MH dictionary (it spans every shard's tiles): with
// `dagmh_dictionary` (DAG-MH parts only) the merge builds it over all the tiles as a
// single build's finish does (PackParams::dagmh_dictionary), so the pack still equals
// the one-go build made with the same choice.
MergeReport merge_parts(std::span<const std::string> part_paths, const std::string& out_path,
                        bool dagmh_dictionary = false);

}  // namespace st
