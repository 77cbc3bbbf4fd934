#include "tiles/encode/stack_pack.hpp"

#include "tiles/core/stack_slices.hpp"

#include <algorithm>
#include <array>
#include <span>
#include <cstdio>
#include <fstream>

#include "common/error.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/stack_slices_encode.hpp"

namespace st {
namespace {

// Dense values of levels 0..K: the value of the deepest valued node on each node's path.
std::vector<std::vector<float>> dense_values(const OctHierarchy& h, const StackGrid& sg, uint32_t K) {
  const moct::Geometry& g = h.geo;
  std::vector<std::vector<float>> v(K + 1);
  v[0] = {h.levels[0][0].value};
  for (uint32_t l = 1; l <= K; ++l) {
    const uint32_t a = g.xy_bits(l), b = g.w_bits(l);
    const uint32_t dx = g.splits_xy(l - 1), dw = g.splits_w(l - 1);
    v[l].resize(sg.cells(l));
    for (uint64_t w = 0; w < (uint64_t(1) << b); ++w)
      for (uint64_t y = 0; y < (uint64_t(1) << a); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << a); ++x)
          v[l][sg.index(l, x, y, w)] = v[l - 1][sg.index(l - 1, x >> dx, y >> dx, w >> dw)];
    for (const OctNode& nd : h.levels[l]) {
      if (!nd.has_value) continue;
      uint64_t x, y, w;
      oct_coords(g, l, nd.code, x, y, w);
      v[l][sg.index(l, x, y, w)] = nd.value;
    }
  }
  return v;
}

}  // namespace

uint32_t default_stack_skip_level(const moct::Geometry& g) {
  StackGrid sg;
  sg.geo = g;
  uint32_t K = (g.depth() + 1) / 2;
  while (K > 0 && sg.cells(K) > (uint64_t(1) << 18)) --K;
  return K;
}

StackCut cut_stack(const OctHierarchy& h, std::optional<uint32_t> skip_level, uint32_t tile_bytes) {
  const moct::Geometry& g = h.geo;
  const uint32_t L = g.depth();
  uint32_t K = skip_level.value_or(default_stack_skip_level(g));
  if (K > L) throw Error("stack cut: skip level " + std::to_string(K) + " exceeds the octree depth " + std::to_string(L));
  for (;; ++K) {
    StackCut cut;
    StackGrid& sg = cut.grid;
    sg.geo = g;
    sg.slices = h.slices;
    sg.skip_level = K;
    if (sg.cells(K) > kStackMaxCells)
      throw Error("stack cut: skip level " + std::to_string(K) + " has " + std::to_string(sg.cells(K)) +
                  " cells, above the 2^22 a stack grid holds; raise --tile-bytes");
    auto vals = dense_values(h, sg, K);
    sg.entries.resize(sg.cells(K));
    for (uint64_t i = 0; i < sg.entries.size(); ++i) sg.entries[i].value = vals[K][i];
    sg.coarse.assign(vals.begin(), vals.begin() + K);
    // Each present level-K node with children becomes a tile: its descendants at level
    // K + j are the codes with its code as prefix, contiguous in every sorted level.
    std::vector<size_t> cursor(L + 1, 0);
    uint64_t largest = 0, largest_cell = 0;
    for (const OctNode& root : h.levels[K]) {
      if (!root.child_mask) continue;
      uint64_t x, y, w;
      oct_coords(g, K, root.code, x, y, w);
      const uint64_t cell = sg.index(K, x, y, w);
      sg.entries[cell].kind = 1;
      const OctHierarchy sub = cell_subtree(h, K, root, vals[K][cell], cursor);
      cut.tiles.emplace_back(cell, encode_octree(sub));
      if (cut.tiles.back().second.size() > largest) largest = cut.tiles.back().second.size(), largest_cell = cell;
    }
    cut.max_tile_bytes = largest;
    sg.link();
    std::sort(cut.tiles.begin(), cut.tiles.end(), [](auto& a, auto& b) { return a.first < b.first; });
    if (largest <= tile_bytes) return cut;
    if (K + 1 >= L)
      throw Error("stack cut: cell " + std::to_string(largest_cell) + " encodes to " + std::to_string(largest) +
                  " bytes, above --tile-bytes " + std::to_string(tile_bytes) + " even one level above the leaves");
  }
}

OctHierarchy cell_subtree(const OctHierarchy& h, uint32_t K, const OctNode& root, float inherited,
                          std::vector<size_t>& cursor) {
  const moct::Geometry& g = h.geo;
  const uint32_t L = g.depth();
  OctHierarchy sub;
  sub.geo = moct::Geometry{g.n - g.xy_bits(K), g.k - g.w_bits(K)};
  sub.slices = 1u << sub.geo.k;
  sub.levels.resize(L - K + 1);
  OctNode r = root;
  r.code = 0;
  if (!r.has_value) r.value = r.lo = r.hi = inherited, r.has_value = 1;
  sub.levels[0].push_back(r);
  uint32_t bits = 0;
  for (uint32_t l = K + 1; l <= L; ++l) {
    bits += g.step_bits(l - 1);
    const auto& lv = h.levels[l];
    size_t& c = cursor[l];
    while (c < lv.size() && (lv[c].code >> bits) < root.code) ++c;
    for (; c < lv.size() && (lv[c].code >> bits) == root.code; ++c) {
      OctNode nd = lv[c];
      nd.code &= (uint64_t(1) << bits) - 1;
      sub.levels[l - K].push_back(nd);
    }
  }
  return sub;
}

uint64_t write_stack_pack(const std::string& path, const StackCut& cut, const StackPackParams& p) {
  return write_stack_pack(path, cut.grid, cut.tiles.size(), [&](size_t i) { return cut.tiles[i]; }, p);
}

uint64_t write_stack_pack(const std::string& path, const StackGrid& sg, size_t count,
                          const std::function<std::pair<uint64_t, std::vector<uint8_t>>(size_t)>& tile,
                          const StackPackParams& p) {
  if (p.tile_bytes < kMinTileBytes || p.tile_bytes > kMaxTileBytes)
    throw Error("stack pack: tile_bytes " + std::to_string(p.tile_bytes) + " outside " + tile_bytes_bounds());
  if (sg.lights.size() != sg.slices) throw Error("stack pack: the grid has no light per slice");
  PackHeader h;
  h.state = PackState::complete;
  h.flags = p.flags | kFeatureStack | (count == 0 ? 0u : uint32_t(kFeatureHasTiles));
  if (sg.split()) h.flags |= kFeatureStackSplitCells;  // stack_grid.hpp "Split cells"
  h.encoding = Encoding::mh;
  h.light_kind = sg.light_kind;
  h.map_level = sg.geo.n;
  h.skip_level = sg.skip_level;
  h.tile_bytes = p.tile_bytes;
  h.scene_hash = p.scene_hash;
  h.light = sg.lights[0];
  const std::vector<uint8_t> params = serialize_params(p.build_params);
  h.params_offset = kPackHeaderBytes;
  h.params_size = params.size();
  h.params_crc = crc32_of(params);
  h.journal_offset = h.params_offset + h.params_size;
  const std::string tmp = path + ".tmp";
  std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
  auto put = [&](std::span<const uint8_t> b) {
    f.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
  };
  const std::array<uint8_t, kPackHeaderBytes> blank{};
  put(blank);
  put(params);
  std::vector<TileIndexEntry> index;
  uint64_t journal = 0;
  for (size_t i = 0; i < count; ++i) {
    const auto [cell, raw] = tile(i);
    if (is_slice_tiles(raw)) h.flags |= kFeatureStackSliceTiles;
    TileRecord r;
    r.kind = TileKind::encoded;
    r.id = sg.tile_id(cell);
    // A per-slice cell is stored grouped (the same bytes, like with like; readers ungroup).
    const std::vector<uint8_t> grouped = p.group_slice_tiles ? group_slice_tiles(raw) : std::vector<uint8_t>{};
    const bool is_grouped = p.group_slice_tiles && is_grouped_slice_tiles(grouped);
    if (is_grouped) h.flags |= kFeatureStackGroupedTiles;
    if (is_slice_tiles(raw)) {  // plane slices (stack_slices.hpp): plane_tiles, and what their packed forms need
      uint32_t planes = 0;
      if (is_grouped) {
        std::vector<uint8_t> back = grouped;
        ungroup_slice_tiles(back, &planes);
      }
      const SliceTiles t = SliceTiles::open(raw);
      if (planes || t.has_planes()) h.flags |= kFeaturePlaneTiles | planes;
      if (t.has_wide_planes()) h.flags |= kFeatureWidePlaneBlocks;  // version 3 plane slices
    }
    const std::vector<uint8_t> stored = zlib_compress(is_grouped ? std::span<const uint8_t>(grouped) : std::span<const uint8_t>(raw), p.compression_level);
    r.stored_size = uint32_t(stored.size());
    r.raw_size = uint32_t(raw.size());
    r.crc = crc32_of(stored);
    if (!p.payloads_only) {
      const auto rec = r.serialize();
      put(rec);
      journal += rec.size();
    }
    index.push_back({r.id, h.journal_offset + journal, r.stored_size, r.raw_size, r.crc, TileKind::encoded});
    put(stored);
    journal += stored.size();
  }
  const std::array<uint8_t, 8> zeros{};
  const uint64_t pad = (8 - (h.journal_offset + journal) % 8) % 8;
  put(std::span<const uint8_t>(zeros.data(), pad));
  journal += pad;
  std::vector<uint8_t> grid = sg.serialize();
  if (p.compress_grid) {  // tiles/PACK.md "Compressed grid section"
    h.flags |= kFeatureCompressedGrid;
    grid = compress_grid_section(grid, p.compression_level);
  }
  if (p.payloads_only) h.flags |= kFeaturePayloadsOnly;  // tiles/PACK.md "Payloads only"
  const std::vector<uint8_t> idx = p.payloads_only ? serialize_compact_index(index, p.compression_level) : serialize_index(index);
  h.grid_offset = h.journal_offset + journal;
  h.grid_size = grid.size();
  h.grid_crc = crc32_of(grid);
  h.index_offset = h.grid_offset + h.grid_size;
  h.tile_count = index.size();
  h.index_crc = crc32_of(idx);
  put(grid);
  put(idx);
  const auto head = h.serialize();
  f.seekp(0);
  put(head);
  f.close();
  if (!f) throw Error("stack pack: cannot write '" + tmp + "'");
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw Error("stack pack: cannot rename '" + tmp + "' to '" + path + "'");
  return h.index_offset + idx.size();
}

}  // namespace st
