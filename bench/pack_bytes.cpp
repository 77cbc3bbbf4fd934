// Where a pack's bytes go (tiles/PACK.md): the container's sections (header, params,
// journal tile records and payloads, cell records (none in a payloads-only pack), skip grid, map preview, DAG-MH
// dictionary, tile index) and, for DAG-MH tiles, the sections inside them
// (tiles/core/DAGMH.md: header, skip table, inner nodes, treelets, chunk infos,
// multipliers), raw and as stored. A section's stored share is its marginal cost: the
// tile's zlib size (level 6, as packs store tiles) minus that of the tile without it,
// summed over tiles (so the shares need not add up to the stored total). MH and MMH
// tiles (an MH/MMH pack's, or the MMH tiles of a DAG-MH pack with mixed tiles) are split
// the same way into header, node words (structure: child masks, offsets), values and
// padding, found by walking each tree from its root (tiles/core/mh_quadtree_format.hpp).
// Plane tiles (tiles/core/PLANES.md) count their header and plane records as the section
// "planes" (marginal stored: the tile's zlib size minus its inner buffer's) and their inner
// buffer with the MH/MMH or DAG-MH tiles. Planes shared across tiles: how many table planes
// recur in other tiles, as stored (a at the tile's origin) and as the map's plane (a moved
// to the map's origin), with those planes' marginal stored bytes; and a pool built tile by
// tile that reuses an earlier tile's plane wherever it gives the same float at every texel
// the plane answers (what a pack-wide table could share if the fit chose planes across
// tiles), with the pool's records as one zlib stream.
//
//   bench_pack_bytes PACK... [--json PATH]
#include <bit>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <tuple>
#include <nlohmann/json.hpp>
#include <span>
#include <string>
#include <vector>

#include "bench/options.hpp"
#include "common/error.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/mh_quadtree_format.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/plane_tile.hpp"

namespace {

// A plane tile's inner buffer (tiles/core/PLANES.md), or the tile itself.
std::vector<uint8_t> inner_of(std::vector<uint8_t> raw) {
  if (!st::is_plane_buffer(raw)) return raw;
  const std::span<const uint8_t> in = st::validate_plane_tile(raw).inner;
  return {in.begin(), in.end()};
}

struct Part {
  const char* name;
  uint64_t raw = 0, stored = 0;
};

// Word classes of an MH/MMH tile: 0 header, 1 node words, 2 values, 3 padding.
std::vector<uint8_t> mh_word_classes(const std::vector<uint8_t>& raw) {
  namespace q = st::mhq;
  const uint32_t levels = raw[q::kOffLevels];
  const bool relative = raw[q::kOffFlags] & q::kFlagRelative, root_leaf = raw[q::kOffFlags] & q::kFlagRootLeaf;
  const size_t tree = q::tree_offset(levels), words = (raw.size() - tree) / 4;
  std::vector<uint8_t> cls(words, 3);
  auto word = [&](size_t w) { return st::load_le<uint32_t>(raw.data() + tree + 4 * w); };
  if (root_leaf) {
    cls[0] = 2;
    return cls;
  }
  cls[0] = 1, cls[1] = 2;
  std::vector<std::pair<size_t, uint32_t>> todo{{0, 0}};  // node word, level
  std::vector<bool> seen(words, false);
  while (!todo.empty()) {
    auto [p, level] = todo.back();
    todo.pop_back();
    if (seen[p]) continue;  // a merged (shared) block is counted once
    seen[p] = true;
    const uint32_t nw = word(p), mask = nw & 0xFF;
    if (!mask) continue;
    const uint32_t shift = relative ? (nw >> 12) & 0xF : raw[q::kOffShifts + level];
    size_t c0 = ((p >> shift) + (nw >> 16)) << shift;
    for (uint32_t c = 0; c < 4; ++c) {
      const uint32_t code = mask >> (2 * c) & 3;
      if (code == q::kCodeLeaf) cls[c0] = 2;
      if (code == q::kCodeEmpty || code == q::kCodeInner) {
        cls[c0] = 1;
        todo.push_back({c0, level + 1});
      }
      if (code == q::kCodeInner) cls[c0 + 1] = 2;
      c0 += q::code_words(code);
    }
  }
  return cls;
}

void row(const char* name, uint64_t bytes, uint64_t total) {
  std::printf("  %-34s %12llu  %5.1f%%\n", name, (unsigned long long)bytes, 100.0 * double(bytes) / double(total));
}

nlohmann::json measure(const std::string& path) {
  auto reader = st::PackReader::open(path);
  const st::PackHeader& h = reader->header();
  const uint64_t file = reader->file_size();
  uint64_t records = 0, payload = 0, tile_raw = 0, encoded_tiles = 0;
  const bool payloads_only = h.flags & st::kFeaturePayloadsOnly;  // no journal records (tiles/PACK.md)
  for (const auto& e : reader->tiles()) {
    records += payloads_only ? 0 : st::kRecordBytes;
    payload += e.stored_size;
    tile_raw += e.raw_size;
  }
  const uint64_t journal = h.grid_offset - h.journal_offset;
  const uint64_t cells_and_pad = journal - records - payload;
  const uint64_t grid = st::CutGrid::serialized_size(h.skip_level);
  const uint64_t preview = reader->preview().serialized_size();
  const uint64_t dict = reader->grid_bytes().size() - grid - preview;  // the dictionary section (zlib inside)
  const bool compressed = h.flags & st::kFeatureCompressedGrid;
  const uint64_t index = payloads_only ? file - h.index_offset : h.tile_count * st::kIndexEntryBytes;  // compact: the rest
  std::printf("%s: %llu bytes, %llu tiles, encoding %u, K = %u\n", path.c_str(), (unsigned long long)file,
              (unsigned long long)h.tile_count, unsigned(h.encoding), unsigned(h.skip_level));
  row("header + params", h.journal_offset, file);
  row("tile records (32 B each)", records, file);
  row("tile payloads (zlib)", payload, file);
  row("cell records + padding", cells_and_pad, file);
  if (compressed) {
    row("grid section (one zlib stream)", h.grid_size, file);
    std::printf("  %-34s %12llu / %llu / %llu\n", "  inflated: skip grid / preview / dict", (unsigned long long)grid,
                (unsigned long long)preview, (unsigned long long)dict);
  } else {
    row("skip grid", grid, file);
    row("map preview", preview, file);
    row("dagmh dictionary (stored)", dict, file);
  }
  row(payloads_only ? "tile index (compact)" : "tile index (32 B each)", index, file);
  std::printf("  tiles raw %llu, stored/raw %.3f\n", (unsigned long long)tile_raw, double(payload) / double(tile_raw));
  nlohmann::json out = {{"pack", path},           {"file", file},        {"tiles", h.tile_count},
                        {"header_params", h.journal_offset}, {"tile_records", records}, {"payloads", payload},
                        {"cell_records", cells_and_pad}, {"grid_section_stored", h.grid_size}, {"skip_grid", grid}, {"preview", preview},
                        {"dictionary", dict},     {"index", index},      {"tiles_raw", tile_raw}};
  // Plane tiles: header, plane table and block records, raw and marginal stored; as STPN
  // and packed (plane_pack.hpp, STPL, as the pack stores them with predicted_plane_labels):
  // the table's, the records' and the labelled blocks' own marginal shares of each.
  uint64_t plane_tiles = 0, planes = 0, table = 0, labelled = 0, plane_texels = 0, plane_raw = 0, plane_stored = 0;
  uint64_t table_variant_stored[5] = {}, sig_bits_total = 0; int64_t mtf_saved = 0; uint64_t mtf_longer = 0; uint64_t packed_stored = 0, table_stored = 0, records_stored = 0, labels_stored = 0, packed_table_stored = 0;
  Part packed_parts[5] = {{"kinds"}, {"indices"}, {"palettes"}, {"palette planes"}, {"labels"}};
  auto without = [](std::span<const uint8_t> b, size_t from, size_t to) {
    std::vector<uint8_t> out(b.begin(), b.begin() + long(from));
    out.insert(out.end(), b.begin() + long(to), b.end());
    return st::zlib_compress(out, 6).size();
  };
  // Planes shared across tiles: each table plane as stored (a at the tile's texel (0, 0))
  // and as the map's plane (a moved to the map's texel (0, 0): the tiles' finest texels are
  // the map's), counted by how many tiles hold it.
  using Key = std::tuple<uint64_t, uint64_t, uint64_t>;
  std::map<Key, uint32_t> stored_tiles, map_tiles;
  std::vector<std::pair<uint64_t, std::vector<Key>>> tile_planes;  // tile id, its planes as the map's
  for (const auto& e : reader->tiles()) {
    if (e.kind != st::TileKind::encoded) continue;
    const std::vector<uint8_t> raw = reader->read_raw(e.id);
    if (!st::is_plane_buffer(raw)) continue;
    const st::PlaneTileView v = st::validate_plane_tile(raw);
    const st::TileAddress ta = st::tile_address(e.id);
    const uint64_t x0 = uint64_t(ta.x) << (h.map_level - ta.level), y0 = uint64_t(ta.y) << (h.map_level - ta.level);
    std::map<Key, bool> seen_stored, seen_map;
    tile_planes.push_back({e.id, {}});
    for (uint32_t i = 0; i < v.table_count; ++i) {
      const uint8_t* t = v.table.data() + 24 * size_t(i);
      const uint64_t a = st::load_le<uint64_t>(t), b = st::load_le<uint64_t>(t + 8), c = st::load_le<uint64_t>(t + 16);
      const Key k{a, b, c}, m{a - b * x0 - c * y0, b, c};
      if (!seen_stored[k]) seen_stored[k] = true, ++stored_tiles[k];
      if (!seen_map[m]) seen_map[m] = true, ++map_tiles[m];
      tile_planes.back().second.push_back(m);
    }
  }
  {
    uint64_t in_other_stored = 0, in_other_map = 0, shared_keys = 0, planes_all = 0, dup_stored = 0, dup_whole = 0;
    std::map<Key, bool> counted;
    for (const auto& [id, ks] : tile_planes) {
      const std::vector<uint8_t> raw = reader->read_raw(id);
      const st::PlaneTileView v = st::validate_plane_tile(raw);
      std::vector<uint8_t> kept(raw.begin(), raw.begin() + st::planes::kHeaderSize);
      for (uint32_t i = 0; i < v.table_count; ++i) {
        const uint8_t* t = v.table.data() + 24 * size_t(i);
        const Key k{st::load_le<uint64_t>(t), st::load_le<uint64_t>(t + 8), st::load_le<uint64_t>(t + 16)};
        ++planes_all;
        in_other_stored += stored_tiles[k] > 1;
        const bool shared = map_tiles[ks[i]] > 1;
        in_other_map += shared;
        if (shared && !counted[ks[i]]) counted[ks[i]] = true, ++shared_keys;
        if (!shared) kept.insert(kept.end(), t, t + 24);
      }
      kept.insert(kept.end(), raw.begin() + long(st::planes::kHeaderSize + v.table.size()), raw.end());
      const uint64_t whole = st::zlib_compress(raw, 6).size();
      dup_whole += whole;
      dup_stored += whole - st::zlib_compress(kept, 6).size();
    }
    if (planes_all)
      std::printf("  table planes %llu: stored record also in another tile %llu; the map's plane also in another tile %llu "
                  "(%llu distinct such planes), their marginal stored bytes (STPN) %llu of %llu\n",
                  (unsigned long long)planes_all, (unsigned long long)in_other_stored, (unsigned long long)in_other_map,
                  (unsigned long long)shared_keys, (unsigned long long)dup_stored, (unsigned long long)dup_whole);
  }
  // Planes a pack-wide table could share if the fit chose them across tiles: tile by tile
  // (id order), each table plane joins a pool unless a pool plane (from an earlier tile)
  // gives the same float at every texel the plane answers in its tile (the decoder's
  // function; the pack is exact, so that plane answers them too).
  {
    struct Pooled {
      uint64_t a, b, c;  // a at the map's texel (0, 0)
    };
    std::vector<Pooled> pool;
    std::multimap<int64_t, size_t> by_b;
    uint64_t all = 0, reused = 0;
    const int64_t slack = int64_t(1) << 34;
    for (const auto& [id, ks] : tile_planes) {
      const std::vector<uint8_t> raw = reader->read_raw(id);
      const st::PlaneTileView v = st::validate_plane_tile(raw);
      const st::TileAddress ta = st::tile_address(id);
      const uint64_t x0 = uint64_t(ta.x) << (h.map_level - ta.level), y0 = uint64_t(ta.y) << (h.map_level - ta.level);
      std::map<Key, uint32_t> index;  // stored record -> table index
      for (uint32_t i = 0; i < v.table_count; ++i) {
        const uint8_t* t = v.table.data() + 24 * size_t(i);
        index[Key{st::load_le<uint64_t>(t), st::load_le<uint64_t>(t + 8), st::load_le<uint64_t>(t + 16)}] = i;
      }
      std::vector<std::vector<std::pair<uint32_t, uint32_t>>> texels(v.table_count);  // tile coordinates
      for (uint32_t i = 0; i < v.plane_count; ++i) {
        const uint32_t start = v.block_start(i), side = 1u << v.block_shift(i);
        const uint32_t bx = st::morton_compact(start), by = st::morton_compact(uint64_t(start) >> 1);
        for (uint32_t y = by; y < by + side; ++y)
          for (uint32_t x = bx; x < bx + side; ++x) {
            const st::planes::Plane p = v.plane_at(i, x, y);
            texels[index.at(Key{uint64_t(p.origin_a(bx, by)), uint64_t(p.b), uint64_t(p.c)})].push_back({x, y});
          }
      }
      for (uint32_t i = 0; i < v.table_count; ++i) {
        ++all;
        const Key& m = ks[i];
        const auto [a, b, c] = m;
        auto value = [&](uint64_t pa, uint64_t pb, uint64_t pc, uint32_t x, uint32_t y) {
          return int64_t(pa + pb * (x0 + x) + pc * (y0 + y));
        };
        bool found = false;
        if (!texels[i].empty()) {
          const auto [fx, fy] = texels[i][0];
          const int64_t v0 = value(a, b, c, fx, fy);
          for (auto it = by_b.lower_bound(int64_t(b) - slack); it != by_b.end() && it->first <= int64_t(b) + slack && !found; ++it) {
            const Pooled& q = pool[it->second];
            if (std::llabs(int64_t(q.c - c)) > slack) continue;
            const int64_t q0 = value(q.a, q.b, q.c, fx, fy);
            if (std::llabs(q0 - v0) > (int64_t(1) << 40)) continue;
            found = true;
            for (const auto& [x, y] : texels[i])
              if (st::planes::plane_fixed_to_float(value(q.a, q.b, q.c, x, y)) !=
                  st::planes::plane_fixed_to_float(value(a, b, c, x, y))) {
                found = false;
                break;
              }
          }
        }
        if (found) {
          ++reused;
        } else {
          by_b.emplace(int64_t(b), pool.size());
          pool.push_back({a, b, c});
        }
      }
    }
    std::vector<uint8_t> records;
    for (const Pooled& q : pool)
      for (uint64_t w : {q.a, q.b, q.c})
        for (int k = 0; k < 8; ++k) records.push_back(uint8_t(w >> (8 * k)));
    if (all)
      std::printf("  a pack-wide pool of planes chosen across tiles: %llu of %llu table planes answered by an earlier tile's; "
                  "pool %llu planes, %zu bytes raw, %zu zlib\n",
                  (unsigned long long)reused, (unsigned long long)all, (unsigned long long)pool.size(), records.size(),
                  st::zlib_compress(records, 6).size());
  }
  for (const auto& e : reader->tiles()) {
    if (e.kind != st::TileKind::encoded) continue;
    const std::vector<uint8_t> raw = reader->read_raw(e.id);
    if (!st::is_plane_buffer(raw)) continue;
    const st::PlaneTileView v = st::validate_plane_tile(raw);
    ++plane_tiles;
    planes += v.plane_count;
    table += v.table_count;
    for (uint32_t i = 0; i < v.plane_count; ++i)  // label_count counts slots: a wide block takes two
      labelled += v.records[8 * i + 5] != st::planes::kKindPlane;
    for (uint32_t i = 0; i < v.plane_count; ++i) plane_texels += uint64_t(1) << (2 * v.plane(i).shift);
    plane_raw += raw.size() - v.inner.size();
    const uint64_t whole = st::zlib_compress(raw, 6).size(), inner = st::zlib_compress(v.inner, 6).size();
    plane_stored += whole - inner;
    const size_t t_at = st::planes::kHeaderSize, r_at = t_at + v.table.size(), l_at = r_at + v.records.size();
    table_stored += whole - without(raw, t_at, r_at);
    records_stored += whole - without(raw, r_at, l_at);
    labels_stored += whole - without(raw, l_at, l_at + v.labels.size());
    st::PlanePackParts pp;
    const std::vector<uint8_t> packed = st::pack_plane_tile(raw, &pp);
    if (packed.empty()) continue;
    const uint64_t packed_whole = st::zlib_compress(packed, 6).size();
    packed_stored += packed_whole - inner;
    packed_table_stored += packed_whole - without(packed, t_at, r_at);
    {  // table transforms (offline measurement): 0 transposed, 1 delta prev + transposed, 2 first-use order, a at corner
      const uint32_t T = v.table_count;
      std::vector<uint64_t> first(T, ~uint64_t(0));
      for (uint32_t i = 0; i < v.plane_count; ++i) {
        const uint8_t* r = v.records.data() + 8 * size_t(i);
        const uint64_t start = st::load_le<uint32_t>(r);
        const uint32_t idx = st::load_le<uint16_t>(r + 6);
        if (r[5] == st::planes::kKindPlane) {
          first[idx] = std::min(first[idx], start);
        } else {
          const uint8_t* l = v.labels.data() + size_t(idx) * 24;
          const uint32_t n = r[5] == st::planes::kKindWide ? 8 : 4;
          for (uint32_t k = 0; k < n; ++k) { const uint32_t e = st::load_le<uint16_t>(l + 2 * k); if (e < T) first[e] = std::min(first[e], start); }
        }
      }
      auto tv = [&](uint32_t i, int f) { return st::load_le<uint64_t>(v.table.data() + 24 * size_t(i) + 8 * size_t(f)); };
      auto zz = [](uint64_t d) { return (d << 1) ^ uint64_t(int64_t(d) >> 63); };
      for (int variant = 0; variant < 4; ++variant) {
        std::vector<uint32_t> order(T);
        for (uint32_t i = 0; i < T; ++i) order[i] = i;
        if (variant >= 2) std::stable_sort(order.begin(), order.end(), [&](uint32_t x, uint32_t y) { return first[x] < first[y]; });
        std::vector<uint64_t> vals(3 * size_t(T));
        for (uint32_t k = 0; k < T; ++k) {
          const uint32_t p = order[k];
          const uint64_t st0 = first[p] == ~uint64_t(0) ? 0 : first[p];
          const uint64_t x0 = st::morton_compact(st0), y0 = st::morton_compact(st0 >> 1);
          uint64_t pa = 0, pb = 0, pc = 0;
          if (k > 0 && variant >= 1) { const uint32_t q = order[k - 1]; pa = tv(q, 0), pb = tv(q, 1), pc = tv(q, 2); }
          uint64_t a = tv(p, 0), b = tv(p, 1), c = tv(p, 2);
          if (variant == 3) { a = a + b * x0 + c * y0; pa = pa + pb * x0 + pc * y0; }
          vals[3 * k] = variant == 0 ? a : zz(a - pa);
          vals[3 * k + 1] = variant == 0 ? b : zz(b - pb);
          vals[3 * k + 2] = variant == 0 ? c : zz(c - pc);
        }
        std::vector<uint8_t> alt = packed;
        for (uint32_t f = 0; f < 3; ++f)
          for (uint32_t byte = 0; byte < 8; ++byte)
            for (uint32_t k = 0; k < T; ++k) alt[t_at + (size_t(f) * 8 + byte) * T + k] = uint8_t(vals[3 * k + f] >> (8 * byte));
        table_variant_stored[variant] += packed_whole - st::zlib_compress(alt, 6).size();
      }
      {  // bit-packed: per coefficient (tz, significant length) bytes, then the significant bits less the leading one
        std::vector<uint8_t> heads, bits;
        uint64_t acc = 0;
        uint32_t nacc = 0;
        auto put = [&](uint64_t val, uint32_t n) {
          for (uint32_t i = 0; i < n; ++i) {
            acc |= ((val >> i) & 1u) << nacc;
            if (++nacc == 8) bits.push_back(uint8_t(acc)), acc = 0, nacc = 0;
          }
        };
        for (uint32_t k = 0; k < T; ++k)
          for (int f = 0; f < 3; ++f) {
            const uint64_t raw64 = tv(k, f);
            const uint32_t tz = raw64 == 0 ? 0 : uint32_t(std::countr_zero(raw64));
            const uint64_t m = zz(uint64_t(int64_t(raw64) >> tz));
            const uint32_t len = m == 0 ? 0 : uint32_t(64 - std::countl_zero(m));
            heads.push_back(uint8_t(tz)), heads.push_back(uint8_t(len));
            sig_bits_total += len;
            if (len > 1) put(m, len - 1);
          }
        if (nacc) bits.push_back(uint8_t(acc));
        std::vector<uint8_t> alt = packed;
        std::fill(alt.begin() + long(t_at), alt.begin() + long(r_at), uint8_t(0));
        std::vector<uint8_t> seq;
        for (int f = 0; f < 6; ++f) for (uint32_t k = 0; k < T; ++k) seq.push_back(heads[6 * size_t(k) + size_t(f)]);
        seq.insert(seq.end(), bits.begin(), bits.end());
        std::copy(seq.begin(), seq.end(), alt.begin() + long(t_at));
        table_variant_stored[4] += int64_t(packed_whole) - int64_t(st::zlib_compress(alt, 6).size());
      }
    }
    {  // plane references as "next new" / move-to-front ranks (offline measurement)
      std::vector<uint32_t> mtf;
      uint32_t next_new = 0;
      std::vector<uint8_t> idx_codes, pal_codes;
      auto code = [&](uint32_t e, std::vector<uint8_t>& out) {
        if (e == next_new) { out.push_back(0); ++next_new; mtf.insert(mtf.begin(), e); return; }
        auto it = std::find(mtf.begin(), mtf.end(), e);
        const size_t rank = size_t(it - mtf.begin());
        if (rank < 254) out.push_back(uint8_t(1 + rank)); else { out.push_back(255); out.push_back(uint8_t(e)); out.push_back(uint8_t(e >> 8)); }
        if (it != mtf.end()) mtf.erase(it);
        mtf.insert(mtf.begin(), e);
      };
      for (uint32_t i = 0; i < v.plane_count; ++i) {
        const uint8_t* r = v.records.data() + 8 * size_t(i);
        const uint32_t idx = st::load_le<uint16_t>(r + 6);
        if (r[5] == st::planes::kKindPlane) { code(idx, idx_codes); continue; }
        const uint8_t* l = v.labels.data() + size_t(idx) * 24;
        const uint32_t n = r[5] == st::planes::kKindWide ? 8 : 4;
        uint32_t seen[8]; uint32_t ns = 0;
        for (uint32_t k = 0; k < n; ++k) {
          const uint32_t e = st::load_le<uint16_t>(l + 2 * k);
          if (n == 4) { bool dup = false; for (uint32_t d = 0; d < ns; ++d) dup |= seen[d] == e; if (dup) continue; seen[ns++] = e; }
          code(e, pal_codes);
        }
      }
      std::vector<uint8_t> alt = packed;
      const size_t i_at = r_at + pp.kinds, end_planes = i_at + pp.indices + pp.palettes + pp.planes;
      std::vector<uint8_t> mid(alt.begin() + long(i_at + pp.indices), alt.begin() + long(i_at + pp.indices + pp.palettes));
      std::vector<uint8_t> seq = idx_codes;
      seq.insert(seq.end(), mid.begin(), mid.end());
      seq.insert(seq.end(), pal_codes.begin(), pal_codes.end());
      if (seq.size() <= end_planes - i_at) {
        std::copy(seq.begin(), seq.end(), alt.begin() + long(i_at));
        std::fill(alt.begin() + long(i_at + seq.size()), alt.begin() + long(end_planes), uint8_t(0));
        mtf_saved += int64_t(packed_whole) - int64_t(st::zlib_compress(alt, 6).size());
      } else {
        ++mtf_longer;
      }
    }
    size_t at = r_at;
    const size_t sizes[5] = {pp.kinds, pp.indices, pp.palettes, pp.planes, pp.labels};
    for (int k = 0; k < 5; ++k) {
      packed_parts[k].raw += sizes[k];
      packed_parts[k].stored += packed_whole - without(packed, at, at + sizes[k]);
      at += sizes[k];
    }
  }
  if (plane_tiles) {
    std::printf("  plane tiles: %llu, blocks %llu (%llu labelled) over %llu texels, %llu table planes; planes section raw %llu, marginal stored %llu\n",
                (unsigned long long)plane_tiles, (unsigned long long)planes, (unsigned long long)labelled,
                (unsigned long long)plane_texels, (unsigned long long)table,
                (unsigned long long)plane_raw, (unsigned long long)plane_stored);
    std::printf("    STPN marginal stored: table %llu, block records %llu, labelled blocks %llu; packed (STPL: labels predicted, implied inner header fields left out) planes section %llu (table %llu)\n",
                (unsigned long long)table_stored, (unsigned long long)records_stored, (unsigned long long)labels_stored,
                (unsigned long long)packed_stored, (unsigned long long)packed_table_stored);
    std::printf("    table variants (stored bytes saved): transposed %lld, delta+transposed %lld, first-use order %lld, a at corner %lld\n",
                (long long)table_variant_stored[0], (long long)table_variant_stored[1], (long long)table_variant_stored[2], (long long)table_variant_stored[3]);
    std::printf("    bit-packed table (heads by column, then significant bits): stored bytes saved %lld; significant bits %llu (%.1f a plane)\n",
                (long long)table_variant_stored[4], (unsigned long long)sig_bits_total, double(sig_bits_total) / double(table));
    std::printf("    references as next-new/MTF ranks: stored bytes saved %lld (%llu tiles longer)\n", (long long)mtf_saved, (unsigned long long)mtf_longer);
    std::printf("    packed parts raw / marginal stored:");
    for (const Part& p : packed_parts)
      std::printf(" %s %llu / %llu;", p.name, (unsigned long long)p.raw, (unsigned long long)p.stored);
    std::printf("\n");
    out["plane_tiles"] = {{"tiles", plane_tiles}, {"blocks", planes}, {"labelled", labelled}, {"table_planes", table}, {"texels", plane_texels},
                          {"raw", plane_raw}, {"stored", plane_stored}, {"table_stored", table_stored},
                          {"records_stored", records_stored}, {"labels_stored", labels_stored},
                          {"packed_stored", packed_stored}, {"packed_table_stored", packed_table_stored}};
  }
  // MH / MMH tiles: header, node words, values, padding (raw and marginal stored).
  Part mh_parts[4] = {{"header"}, {"node words"}, {"values"}, {"padding"}};
  uint64_t mh_tiles = 0, mh_stored = 0, mh_raw = 0;
  for (const auto& e : reader->tiles()) {
    if (e.kind != st::TileKind::encoded || h.encoding == st::Encoding::vsdag) continue;
    const std::vector<uint8_t> raw = inner_of(reader->read_raw(e.id));
    if (st::load_le<uint32_t>(raw.data()) != st::mhq::kMagicMh && !st::is_mmh_buffer(raw)) continue;
    ++mh_tiles;
    mh_raw += raw.size();
    const size_t tree = st::mhq::tree_offset(raw[st::mhq::kOffLevels]);
    const std::vector<uint8_t> cls = mh_word_classes(raw);
    const uint64_t full = st::zlib_compress(raw, 6).size();
    mh_stored += full;
    mh_parts[0].raw += tree;
    mh_parts[0].stored += full - st::zlib_compress(std::span(raw).subspan(tree), 6).size();
    for (uint8_t k = 1; k < 4; ++k) {
      std::vector<uint8_t> without(raw.begin(), raw.begin() + long(tree));
      for (size_t w = 0; w < cls.size(); ++w) {
        if (cls[w] == k) {
          mh_parts[k].raw += 4;
          continue;
        }
        without.insert(without.end(), raw.begin() + long(tree + 4 * w), raw.begin() + long(tree + 4 * w + 4));
      }
      mh_parts[k].stored += full - st::zlib_compress(without, 6).size();
    }
  }
  if (mh_tiles) {
    std::printf("  MH/MMH tiles: %llu, raw %llu, stored %llu; section: raw / marginal stored\n",
                (unsigned long long)mh_tiles, (unsigned long long)mh_raw, (unsigned long long)mh_stored);
    nlohmann::json sections = nlohmann::json::object();
    for (const Part& p : mh_parts) {
      std::printf("    %-14s %10llu  %10llu\n", p.name, (unsigned long long)p.raw, (unsigned long long)p.stored);
      sections[p.name] = {{"raw", p.raw}, {"stored", p.stored}};
    }
    out["mh_tiles"] = {{"tiles", mh_tiles}, {"raw", mh_raw}, {"stored", mh_stored}, {"sections", sections}};
  }
  if (h.encoding != st::Encoding::dagmh) return out;
  Part parts[6] = {{"header"}, {"skip table"}, {"inner nodes"}, {"treelets"}, {"chunk infos"}, {"multipliers"}};
  uint64_t stored_sum = 0;
  uint32_t skip_hist[7] = {};
  uint64_t k_hist[33] = {}, mask_zero = 0, mask_full = 0, values_in_chunks = 0;
  for (const auto& e : reader->tiles()) {
    if (e.kind != st::TileKind::encoded) continue;
    const std::vector<uint8_t> raw = inner_of(reader->read_raw(e.id));
    if (st::is_mmh_buffer(raw)) continue;  // a mixed tile: counted with the MH/MMH tiles above
    ++encoded_tiles;
    const st::dagmh::Header th = st::dagmh::load_header(raw.data());
    const st::dagmh::Sections ts = st::dagmh::sections_of(th, raw.size());
    ++skip_hist[std::min<uint32_t>(th.skip_level, 6)];
    const uint64_t cut[7] = {0, ts.skip, ts.nodes, ts.treelets, ts.chunks, ts.multipliers, ts.end};
    for (uint32_t c = 0; c < ts.chunk_count; ++c) {
      st::dagmh::ChunkInfo ci;
      std::memcpy(&ci, raw.data() + ts.chunks + sizeof ci * size_t(c), sizeof ci);
      ++k_hist[std::min<uint32_t>(ci.factor_bits(), 32)];
      if (ci.mask == 0) ++mask_zero;
      if (ci.mask == 0xFFFFFFFFu) ++mask_full;
      values_in_chunks += std::popcount(ci.mask);
    }
    const uint64_t full = st::zlib_compress(raw, 6).size();
    stored_sum += full;
    for (int s = 0; s < 6; ++s) {
      parts[s].raw += cut[s + 1] - cut[s];
      std::vector<uint8_t> without(raw.begin(), raw.begin() + long(cut[s]));
      without.insert(without.end(), raw.begin() + long(cut[s + 1]), raw.end());
      parts[s].stored += full - st::zlib_compress(without, 6).size();
    }
  }
  std::printf("  DAG-MH tiles: %llu, stored %llu; section: raw / marginal stored\n",
              (unsigned long long)encoded_tiles, (unsigned long long)stored_sum);
  nlohmann::json sections = nlohmann::json::object();
  for (const Part& p : parts) {
    std::printf("    %-14s %10llu  %10llu\n", p.name, (unsigned long long)p.raw, (unsigned long long)p.stored);
    sections[p.name] = {{"raw", p.raw}, {"stored", p.stored}};
  }
  std::printf("    skip levels:");
  for (int s = 0; s < 7; ++s) std::printf(" S%d %u", s, skip_hist[s]);
  std::printf("\n");
  std::printf("    chunks: mask 0 %llu, mask full %llu, multipliers %llu; k:", (unsigned long long)mask_zero,
              (unsigned long long)mask_full, (unsigned long long)values_in_chunks);
  for (int k = 0; k < 33; ++k)
    if (k_hist[k]) std::printf(" %d:%llu", k, (unsigned long long)k_hist[k]);
  std::printf("\n");
  out["dagmh_sections"] = sections;
  out["dagmh_tiles"] = {{"tiles", encoded_tiles}, {"stored", stored_sum}};
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    std::vector<std::string> packs;
    std::string json_path;
    st::bench::Options opt("bench_pack_bytes", "Where a pack's bytes go, section by section");
    opt.rest("PACK", packs, "Packs (at least one)").value("--json", json_path, "Write the rows as JSON to PATH");
    opt.parse(argc, argv);
    if (packs.empty()) opt.fail("give at least one PACK");
    nlohmann::json all = nlohmann::json::array();
    for (const auto& p : packs) all.push_back(measure(p));
    if (!json_path.empty()) std::ofstream(json_path) << all.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_pack_bytes: %s\n", e.what());
    return 1;
  }
}
