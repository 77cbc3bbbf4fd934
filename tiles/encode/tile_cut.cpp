#include "tiles/encode/tile_cut.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "common/error.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_format.hpp"

namespace st {

TileCodec TileCodec::of(Encoding e) {
  TileCodec c;
  c.encoding = e;
  c.encode = [e](const Hierarchy& h) { return st::encode(h, e); };
  c.open = [e](std::span<const uint8_t> bytes) { return open_encoded(e, bytes); };
  return c;
}

// Which encoding a mixed tile's subtree is likely to store smaller in, from the share of
// its valued nodes whose interval has zero width (open geometry under the default rule:
// hi = lo). MMH merges translated planar patches with their values where DAG-MH shares
// only the topology and stores every such value raw; wide intervals (closed objects,
// static intervals) let DAG-MH's value chunks share a base. Measured per tile on the city,
// Quake 3 oa_dm1 (default and static intervals) and an open town at 4096^2: from 0.9 up
// MMH stored smaller in 3,201 of 3,216 tiles, below 0.7 DAG-MH in 2,253 of 2,562, and
// the packs chosen this way were within 0.92% of the per-tile best and 0.73-1.00 times
// the MMH pack (tiles/PACK.md "Mixed tiles").
namespace {
constexpr double kMmhLikelyZeroWidth = 0.9, kDagmhLikelyZeroWidth = 0.7;

int predict_dagmh_or_mmh(const Hierarchy& h) {
  uint64_t valued = 0, zero = 0;
  for (const auto& level : h.levels)
    for (const HNode& n : level)
      if (n.has_value) ++valued, zero += n.lo == n.hi;
  if (valued == 0) return 0;
  const double share = double(zero) / double(valued);
  return share >= kMmhLikelyZeroWidth ? 1 : share < kDagmhLikelyZeroWidth ? -1 : 0;
}
}  // namespace

TileCodec TileCodec::dagmh_or_mmh(bool exhaustive) {
  TileCodec c = of(Encoding::dagmh);
  c.alternative = [](const Hierarchy& h) { return encode_mmh(h); };
  if (!exhaustive) c.choose = predict_dagmh_or_mmh;
  return c;
}

TileCodec::Fit TileCodec::encode_within(const Hierarchy& h, size_t bound, bool may_refuse) const {
  Fit f;
  const int pick = alternative && choose ? choose(h) : 0;
  if (pick > 0) {
    std::vector<uint8_t> alt = alternative(h);
    if (alt.size() <= bound) {
      f.bytes = std::move(alt);
      return f;
    }
    f.smallest = alt.size();
  }
  try {
    std::vector<uint8_t> bytes = encode(h);
    if (bytes.size() <= bound) f.bytes = std::move(bytes);
    else f.smallest = std::min(f.smallest, bytes.size());
  } catch (const Error&) {
    if (!may_refuse) throw;
  }
  if ((alternative && pick == 0) || (pick < 0 && f.bytes.empty())) {
    // The second encoding where it stores smaller (what a pack keeps is the zlib stream).
    std::vector<uint8_t> alt = alternative(h);
    if (alt.size() <= bound &&
        (f.bytes.empty() || zlib_compress(alt, kEncodingChoiceZlibLevel).size() <
                                zlib_compress(f.bytes, kEncodingChoiceZlibLevel).size()))
      f.bytes = std::move(alt);
    else if (f.bytes.empty())
      f.smallest = std::min(f.smallest, alt.size());
  }
  return f;
}

uint32_t default_skip_level(uint32_t map_level) { return std::min<uint32_t>((map_level + 1) / 2, 8); }

void CutParams::validate() const {
  if (map_level > kMaxLevel) throw Error("cut: map level " + std::to_string(map_level) + " > 20");
  if (skip_level > std::min(map_level, kMaxSkipLevel))
    throw Error("cut: skip level " + std::to_string(skip_level) + " must be <= min(map level, 10)");
  if (tile_bytes < kMinTileBytes || tile_bytes > kMaxTileBytes)
    throw Error("cut: tile_bytes " + std::to_string(tile_bytes) + " outside " + tile_bytes_bounds());
  if (!codec.encode || !codec.open) throw Error("cut: codec without encode/open");
}

void check_hierarchy(const Hierarchy& h, const char* what) {
  auto fail = [&](const std::string& msg) { throw Error(std::string(what) + ": " + msg); };
  if (h.depth > kMaxLevel) fail("depth " + std::to_string(h.depth) + " > 20");
  if (h.levels.size() != size_t(h.depth) + 1) fail("levels.size() != depth + 1");
  if (h.levels[0].size() != 1 || h.levels[0][0].morton != 0 || !h.levels[0][0].has_value)
    fail("root missing or not valued");
  for (uint32_t l = 0; l <= h.depth; ++l) {
    const auto& lv = h.levels[l];
    const auto* next = l < h.depth ? &h.levels[l + 1] : nullptr;
    size_t k = 0;
    for (size_t j = 0; j < lv.size(); ++j) {
      const HNode& n = lv[j];
      if (j > 0 && n.morton <= lv[j - 1].morton) fail("level " + std::to_string(l) + " not sorted by morton");
      if (l < 32 && (n.morton >> (2 * l)) != 0) fail("morton out of range at level " + std::to_string(l));
      if (n.has_value > 1) fail("bad has_value");
      if (n.has_value && (std::isnan(n.value) || std::isnan(n.lo) || std::isnan(n.hi))) fail("NaN value");
      if (!n.has_value && n.child_mask == 0) fail("empty node without children");
      if (n.child_mask && !next) fail("children below the finest level");
      for (uint32_t c = 0; c < 4; ++c) {
        if (!(n.child_mask >> c & 1)) continue;
        if (k >= next->size() || (*next)[k].morton != ((n.morton << 2) | c))
          fail("child list of level " + std::to_string(l + 1) + " disagrees with the masks");
        ++k;
      }
      if (n.child_mask >> 4) fail("bad child mask");
    }
    if (next && k != next->size()) fail("orphan nodes at level " + std::to_string(l + 1));
  }
}

SplitResult split_hierarchy(const Hierarchy& h, uint32_t d) {
  ST_CHECK(d <= h.depth && d <= kMaxSkipLevel && h.levels.size() == size_t(h.depth) + 1);
  SplitResult s;
  s.grid.levels = d;
  s.grid.coarse.resize(CutGrid::coarse_count(d));
  // Dense values of levels 0..d, top-down: a node's value answers its level unless a
  // descendant level stores its own (ARCHITECTURE.md "Definitions").
  std::vector<float> prev{h.levels[0][0].value}, cur;
  for (uint32_t j = 1; j <= d; ++j) {
    std::copy(prev.begin(), prev.end(), s.grid.coarse.begin() + CutGrid::coarse_count(j - 1));
    size_t side = size_t(1) << j;
    cur.resize(side * side);
    for (size_t y = 0; y < side; ++y)
      for (size_t x = 0; x < side; ++x) cur[y * side + x] = prev[(y >> 1) * (side >> 1) + (x >> 1)];
    for (const HNode& n : h.levels[j])
      if (n.has_value) cur[size_t(morton_compact(n.morton >> 1)) * side + morton_compact(n.morton)] = n.value;
    prev.swap(cur);
  }
  size_t side = size_t(1) << d, count = side * side;
  s.grid.entries.resize(count);
  s.lo.resize(count);
  s.hi.resize(count);
  for (size_t i = 0; i < count; ++i) {
    s.grid.entries[i] = GridEntry{prev[i], EntryKind::constant, 0};
    s.lo[i] = s.hi[i] = prev[i];
  }
  s.subtrees.resize(count);
  const uint32_t sub_depth = h.depth - d;
  std::vector<size_t> ptr(h.levels.size(), 0);
  for (const HNode& n : h.levels[d]) {
    size_t i = size_t(morton_compact(n.morton >> 1)) * side + morton_compact(n.morton);
    if (n.has_value) {
      s.lo[i] = n.lo;
      s.hi[i] = n.hi;
    }
    if (!n.child_mask) continue;
    auto sub = std::make_unique<Hierarchy>();
    sub->depth = sub_depth;
    sub->levels.resize(size_t(sub_depth) + 1);
    HNode root = n;
    root.morton = 0;
    if (!root.has_value) {  // an empty node inherits its ancestor's value, narrowed to [v, v]
      root.has_value = 1;
      root.value = root.lo = root.hi = prev[i];
    }
    sub->levels[0].push_back(root);
    for (uint32_t lev = d + 1; lev <= h.depth; ++lev) {
      const uint32_t shift = 2 * (lev - d);
      const uint64_t mask = (uint64_t(1) << shift) - 1;
      const auto& src = h.levels[lev];
      auto& dst = sub->levels[lev - d];
      size_t& p = ptr[lev];
      size_t begin = p;
      while (p < src.size() && (src[p].morton >> shift) == n.morton) ++p;
      dst.assign(src.begin() + begin, src.begin() + p);
      for (HNode& m : dst) m.morton &= mask;
    }
    s.subtrees[i] = std::move(sub);
  }
  return s;
}

namespace {

// Index levels for a subtree whose encoding is `bytes` > tile_bytes: enough that the
// children average one tile (log4 of the excess), at least 1, at most the subtree's depth
// and kMaxIndexLevels, and small enough that the index tile itself fits one tile.
uint32_t choose_index_levels(size_t bytes, uint32_t tile_bytes, uint32_t depth) {
  uint32_t d = 1;
  while (d < kMaxIndexLevels && (size_t(tile_bytes) << (2 * d)) < bytes) ++d;
  d = std::min(d, depth);
  while (d > 1 && CutGrid::serialized_size(d) > tile_bytes) --d;
  return d;
}

// Cuts the subtree rooted at (level, x, y), appending its tiles to `out` (children before
// the index tile that points at them) and returning its entry.
GridEntry cut_subtree(const CutParams& p, Hierarchy&& h, uint32_t level, uint32_t x, uint32_t y,
                      std::vector<CutTile>& out) {
  const HNode root = h.levels[0][0];
  if (root.child_mask == 0) return GridEntry{root.value, EntryKind::constant, 0};
  const uint64_t id = make_tile_id(level, x, y);
  // An encoder may refuse a subtree too large for its format (e.g. offsets that no longer
  // fit): it is cut deeper like any oversized subtree. A small one is a real error.
  TileCodec::Fit fit = p.codec.encode_within(h, p.tile_bytes, h.depth > kMaxIndexLevels || bool(p.codec.alternative));
  std::vector<uint8_t>& fits = fit.bytes;
  const size_t encoded_size = fit.smallest;
  if (!fits.empty()) {
    out.push_back(CutTile{id, TileKind::encoded, std::move(fits)});
    return GridEntry{root.value, EntryKind::tile, 0};
  }
  const uint32_t d = choose_index_levels(encoded_size, p.tile_bytes, h.depth);
  SplitResult s = split_hierarchy(h, d);
  h = Hierarchy{};  // the children hold copies: free the parent before recursing
  const uint32_t side = 1u << d;
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      auto& sub = s.subtrees[size_t(j) * side + i];
      if (!sub) continue;
      s.grid.entry(i, j) = cut_subtree(p, std::move(*sub), level + d, (x << d) + i, (y << d) + j, out);
      sub.reset();
    }
  out.push_back(CutTile{id, TileKind::index, s.grid.serialize()});
  return GridEntry{root.value, EntryKind::index, uint8_t(d)};
}

}  // namespace

TileCutter::TileCutter(CutParams params) : params_(std::move(params)) { params_.validate(); }

CutCell TileCutter::cut_cell(uint32_t cx, uint32_t cy, Hierarchy&& cell) const {
  const uint32_t k = params_.skip_level;
  if ((uint64_t(cx) >> k) || (uint64_t(cy) >> k))
    throw Error("cut: cell (" + std::to_string(cx) + ", " + std::to_string(cy) + ") outside the " +
                std::to_string(1u << k) + "^2 skip grid");
  if (cell.depth != params_.map_level - k)
    throw Error("cut: cell hierarchy has depth " + std::to_string(cell.depth) + ", expected " +
                std::to_string(params_.map_level - k));
  check_hierarchy(cell, "cut: cell hierarchy");
  CutCell c;
  c.cx = cx;
  c.cy = cy;
  c.lo = cell.levels[0][0].lo;
  c.hi = cell.levels[0][0].hi;
  c.entry = cut_subtree(params_, std::move(cell), k, cx, cy, c.tiles);
  return c;
}

CutGrid TileCutter::coarse_grid(std::span<const CellRecord> cells, const CoarseBuilder& build_coarse) const {
  const uint32_t k = params_.skip_level;
  const size_t side = size_t(1) << k;
  if (cells.size() != side * side)
    throw Error("cut: " + std::to_string(cells.size()) + " cells done, the skip grid has " +
                std::to_string(side * side));
  IntervalTile roots;
  roots.level = k;
  roots.width = roots.height = uint32_t(side);
  roots.data.resize(side * side);
  std::vector<GridEntry> entries(side * side);
  std::vector<uint8_t> seen(side * side, 0);
  for (const CellRecord& c : cells) {
    if (c.cx >= side || c.cy >= side) throw Error("cut: cell outside the skip grid");
    size_t i = size_t(c.cy) * side + c.cx;
    if (seen[i]++) throw Error("cut: cell (" + std::to_string(c.cx) + ", " + std::to_string(c.cy) + ") repeated");
    roots.data[i] = Interval{c.lo, c.hi};
    entries[i] = c.entry;
  }
  CutGrid g;
  if (k > 0) {
    // MH §3.1 tiled construction: the cells' root bounds form a 2^K map compressed again.
    Hierarchy coarse = build_coarse ? build_coarse(roots) : build_hierarchy(roots);
    if (coarse.depth != k) throw Error("cut: coarse hierarchy has the wrong depth");
    check_hierarchy(coarse, "cut: coarse hierarchy");
    g = split_hierarchy(coarse, k).grid;
  } else {
    g.levels = 0;
  }
  g.entries = std::move(entries);  // each cell keeps its own root value at level K
  return g;
}

CutGrid cut_hierarchy(const Hierarchy& h, const CutParams& params, const std::function<void(CutCell&&)>& sink) {
  params.validate();
  if (h.depth != params.map_level)
    throw Error("cut: hierarchy depth " + std::to_string(h.depth) + " != map level " + std::to_string(params.map_level));
  check_hierarchy(h, "cut: hierarchy");
  const uint32_t k = params.skip_level;
  SplitResult s = split_hierarchy(h, k);
  const uint32_t side = 1u << k;
  for (uint32_t cy = 0; cy < side; ++cy)
    for (uint32_t cx = 0; cx < side; ++cx) {
      size_t i = size_t(cy) * side + cx;
      CutCell c;
      c.cx = cx;
      c.cy = cy;
      c.entry = s.grid.entries[i];
      c.lo = s.lo[i];
      c.hi = s.hi[i];
      if (s.subtrees[i]) {
        c.entry = cut_subtree(params, std::move(*s.subtrees[i]), k, cx, cy, c.tiles);
        s.subtrees[i].reset();
      }
      s.grid.entries[i] = c.entry;
      sink(std::move(c));
    }
  return std::move(s.grid);
}

}  // namespace st
