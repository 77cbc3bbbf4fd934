// Tiled construction (MH §3.1 "Tiled construction"): the roots of finished tiles'
// hierarchies form the intervals of a coarse map; its hierarchy becomes the top k levels
// of one hierarchy of depth k + n, and the tiles' nodes hang below it.
//
// Splice rules. A tile root's interval is the intersection of the texels it answers for
// (or, from top-down, a window inside it), so any value the coarse hierarchy gives that
// coarse texel is valid for them. Where the coarse hierarchy stores the coarse texel,
// the tile's root stays as it is (valued, with its children). Where the coarse texel is
// covered by a coarser node, the tile root loses its value: it becomes an empty node if
// it has children, and disappears if it is a leaf. Empty roots need their ancestors
// present, so the coarse levels are merged with the parents of the level below, adding
// empty nodes where the coarse hierarchy had none (MH §3.2: empty nodes exist only to
// connect valued descendants).
#include <algorithm>
#include <cfloat>
#include <cstdint>
#include <string>
#include <utility>

#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/mh_internal.hpp"

namespace st {
namespace {

constexpr uint32_t kMaxGridLevel = 14;  // the coarse map is built like a tile

void validate_tiles(const std::vector<Hierarchy>& tiles, uint32_t grid_level) {
  if (grid_level > kMaxGridLevel)
    throw Error("stitch_tiles: grid level " + std::to_string(grid_level) + " exceeds " + std::to_string(kMaxGridLevel));
  const size_t expected = size_t(1) << (2 * grid_level);
  if (tiles.size() != expected)
    throw Error("stitch_tiles: " + std::to_string(tiles.size()) + " tiles for a grid of level " +
                std::to_string(grid_level) + ", expected " + std::to_string(expected));
  const uint32_t n = tiles[0].depth;
  if (grid_level + n > kMaxLevel)
    throw Error("stitch_tiles: depth " + std::to_string(grid_level) + " + " + std::to_string(n) + " exceeds level " +
                std::to_string(kMaxLevel));
  for (size_t t = 0; t < tiles.size(); ++t) {
    const Hierarchy& h = tiles[t];
    std::string at = "stitch_tiles: tile " + std::to_string(t) + " (" + std::to_string(t % (size_t(1) << grid_level)) +
                     ", " + std::to_string(t >> grid_level) + "): ";
    if (h.depth != n) throw Error(at + "depth " + std::to_string(h.depth) + ", tile 0 has " + std::to_string(n));
    if (h.levels.size() != size_t(n) + 1) throw Error(at + "holds " + std::to_string(h.levels.size()) + " levels");
    if (h.levels[0].size() != 1 || !h.levels[0][0].has_value) throw Error(at + "has no single valued root");
    const HNode& r = h.levels[0][0];
    if (!(r.lo <= r.hi) || !(r.lo >= -FLT_MAX) || !(r.hi <= FLT_MAX))
      throw Error(at + "root interval [" + std::to_string(r.lo) + ", " + std::to_string(r.hi) + "] is not finite");
    if (r.child_mask == 0 && n > 0 && !h.levels[1].empty()) throw Error(at + "leaf root with nodes below it");
  }
}

}  // namespace

Hierarchy stitch_tiles(std::vector<Hierarchy>&& tiles, uint32_t grid_level, MhConstruction method) {
  validate_tiles(tiles, grid_level);
  const uint32_t k = grid_level, n = tiles[0].depth;
  const uint32_t side = 1u << k;

  IntervalTile coarse;
  coarse.level = k;
  coarse.width = coarse.height = side;
  coarse.data.resize(tiles.size());
  for (size_t t = 0; t < tiles.size(); ++t) coarse.data[t] = Interval{tiles[t].levels[0][0].lo, tiles[t].levels[0][0].hi};
  Hierarchy top = build_hierarchy(coarse, method);

  Hierarchy out;
  out.depth = k + n;
  out.levels.resize(size_t(k) + n + 1);

  // Level k: stored coarse texels keep their tile's root; covered ones with children
  // become empty; covered leaves vanish.
  {
    auto& level = out.levels[k];
    const auto& stored = top.levels[k];
    size_t s = 0;
    for (uint64_t m = 0; m < tiles.size(); ++m) {
      const HNode& root = tiles[size_t(morton_compact(m >> 1)) * side + morton_compact(m)].levels[0][0];
      bool valued = s < stored.size() && stored[s].morton == m;
      if (valued) ++s;
      if (!valued && root.child_mask == 0) continue;
      HNode node = root;
      node.morton = m;
      if (!valued) node.has_value = 0, node.value = node.lo = node.hi = 0;
      level.push_back(node);
    }
    ST_CHECK(s == stored.size());
  }
  // Levels k-1 .. 0: the coarse nodes merged with the parents the level below needs;
  // child masks recomputed from the level below.
  for (uint32_t l = k; l-- > 0;) {
    const auto& below = out.levels[l + 1];
    const auto& coarse_nodes = top.levels[l];
    auto& level = out.levels[l];
    level.reserve(coarse_nodes.size());
    size_t i = 0, j = 0;
    while (i < coarse_nodes.size() || j < below.size()) {
      uint64_t p = UINT64_MAX;
      if (i < coarse_nodes.size()) p = coarse_nodes[i].morton;
      if (j < below.size()) p = std::min(p, below[j].morton >> 2);
      HNode node;
      node.morton = p;
      if (i < coarse_nodes.size() && coarse_nodes[i].morton == p) node = coarse_nodes[i++];
      node.child_mask = 0;
      for (; j < below.size() && (below[j].morton >> 2) == p; ++j) node.child_mask |= uint8_t(1u << (below[j].morton & 3));
      ST_CHECK(node.has_value || node.child_mask != 0);
      level.push_back(node);
    }
  }
  ST_CHECK(out.levels[0].size() == 1 && out.levels[0][0].has_value);

  // Levels k+1 .. k+n: each present tile's level, its morton codes prefixed by the
  // tile's; tiles in morton order keep every level sorted. A tile's level is released as
  // soon as it is copied, so the peak is one level above the output.
  std::vector<size_t> present;  // tile indices in morton order
  present.reserve(out.levels[k].size());
  for (const HNode& node : out.levels[k]) present.push_back(size_t(morton_compact(node.morton >> 1)) * side + morton_compact(node.morton));
  for (uint32_t j = 1; j <= n; ++j) {
    auto& level = out.levels[k + j];
    size_t total = 0;
    for (size_t t : present) total += tiles[t].levels[j].size();
    level.reserve(total);
    for (size_t t : present) {
      const uint64_t prefix = morton_encode(uint32_t(t % side), uint32_t(t / side)) << (2 * j);
      for (HNode node : tiles[t].levels[j]) {
        node.morton |= prefix;
        level.push_back(node);
      }
      std::vector<HNode>().swap(tiles[t].levels[j]);
    }
  }
  return out;
}

}  // namespace st
