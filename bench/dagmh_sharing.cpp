// What a pack-wide dictionary would save on a DAG-MH pack (DAG-MH 2021 §3.1-§3.4): each
// tile is encoded alone, so a subtree topology, treelet bitmap or value chunk that occurs
// in many tiles is stored in each of them. This reads every encoded tile of a pack, keys
// every item by its full content (compared in full through the hash map's equality, never
// by hash alone) and reports, per section, the bytes held by items that occur in two or
// more tiles and the net saving of moving them into one dictionary that a client fetches
// once: sum over tiles of their copies, minus one copy each (the dictionary itself).
//
//   bench_dagmh_sharing PACK... [--mmh PACK] [--check] [--json PATH]
//
// Then it builds the dictionary (tiles/encode/dagmh_dictionary.hpp: every node and
// treelet found in >= 2 tiles) and reports what it actually gives: the tiles' raw and
// zlib (level 6, as a pack stores them) bytes before and after, the dictionary's, and with
// --mmh the same map's MMH pack's tile bytes for the ratio DAG-MH / MMH. --check looks up
// every texel of every level of every tile in the original and the rewritten tile and
// requires bit-equal depths (the rewrite changes references only). It also times 2^20
// random finest-level lookups over all tiles with and without the dictionary.
//
// Items:
// - inner nodes, keyed by subtree topology (flags + the keys of their children, so two
//   nodes are equal iff their whole subtrees are; DAG-MH §3.1); a node in >= 2 tiles has
//   all its descendants in >= 2 tiles, so the shared set is closed downward (a dictionary
//   can hold whole subtrees);
// - treelets, keyed by their 85-bit bitmap (§3.2);
// - value chunks, keyed by (base, mask, c_l, c_f, factor bits, their multiplier bits)
//   (§3.4; the chunk's bit offset is the tile's own and not part of the key);
// - single values (float bits): how many distinct depth values the pack holds against the
//   values stored, the bound on any value dictionary.
// Raw (decoded) bytes throughout: what a client's tile cache holds.
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "bench/options.hpp"
#include "common/error.hpp"
#include "bench/dagmh_dict_figures.hpp"
#include "bench/timing.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/pack_reader.hpp"

namespace {

using namespace st::dagmh;

// Bytes of items keyed by content, with the number of tiles each occurs in.
struct Items {
  struct Item {
    uint32_t id = 0, tiles = 0, last_tile = ~0u;
    uint64_t bytes = 0;
  };
  std::unordered_map<std::string, Item> map;
  uint64_t total_bytes = 0;  // sum over tiles of the bytes each tile stores

  // Returns the item's id; counts the tile once per item.
  uint32_t add(const std::string& key, uint64_t bytes, uint32_t tile, bool count_bytes = true) {
    auto [it, fresh] = map.try_emplace(key);
    if (fresh) it->second.id = uint32_t(map.size() - 1), it->second.bytes = bytes;
    if (it->second.last_tile != tile) {
      it->second.last_tile = tile;
      ++it->second.tiles;
    }
    if (count_bytes) total_bytes += bytes;
    return it->second.id;
  }

  struct Summary {
    uint64_t stored = 0, distinct = 0, shared_items = 0, in_shared = 0, dictionary = 0;
    int64_t net() const { return int64_t(in_shared) - int64_t(dictionary); }
  };
  // in_shared: bytes the tiles hold in items found in >= 2 tiles; dictionary: one copy
  // of each of those. Needs per-tile counting (tiles counts tiles, not occurrences).
  Summary summary(const std::vector<uint64_t>& per_item_tile_bytes) const {
    Summary s;
    s.stored = total_bytes;
    for (const auto& [key, item] : map) {
      s.distinct += item.bytes;
      if (item.tiles >= 2) {
        ++s.shared_items;
        s.in_shared += per_item_tile_bytes[item.id];
        s.dictionary += item.bytes;
      }
    }
    return s;
  }
};

std::string bytes_key(const void* p, size_t n) { return std::string(static_cast<const char*>(p), n); }

struct Analysis {
  uint64_t tiles = 0, raw_bytes = 0, header = 0, skip = 0, nodes = 0, treelets = 0, chunks = 0, multipliers = 0;
  uint64_t values = 0;
  Items node_items, treelet_items, chunk_items;
  std::vector<uint64_t> node_tile_bytes, treelet_tile_bytes, chunk_tile_bytes;  // by item id
  std::unordered_set<uint32_t> distinct_values;

  static void bump(std::vector<uint64_t>& v, uint32_t id, uint64_t bytes) {
    if (v.size() <= id) v.resize(id + 1, 0);
    v[id] += bytes;
  }

  void add_tile(std::span<const uint8_t> buf, uint32_t tile) {
    const View view = validate(buf);
    const Header h = load_header(buf.data());
    const Sections s = sections_of(h, buf.size());
    ++tiles;
    raw_bytes += buf.size();
    header += sizeof(Header);
    skip += s.nodes - s.skip;
    nodes += uint64_t(h.node_words) * 4;
    treelets += uint64_t(h.treelet_count) * kTreeletBytes;
    chunks += uint64_t(s.chunk_count) * sizeof(ChunkInfo);
    multipliers += s.end - s.multipliers;
    values += h.value_count;
    // Treelets: bitmap bytes.
    std::vector<uint32_t> treelet_id(h.treelet_count);
    for (uint32_t t = 0; t < h.treelet_count; ++t) {
      treelet_id[t] = treelet_items.add(bytes_key(view.treelets + size_t(t) * kTreeletBytes, kTreeletBytes),
                                        kTreeletBytes, tile);
      bump(treelet_tile_bytes, treelet_id[t], kTreeletBytes);
    }
    // Inner nodes: starts in order, then keys from the last (children point forward).
    std::vector<uint32_t> starts;
    for (uint32_t w = 0; w < h.node_words;) {
      starts.push_back(w);
      w += node_words(st::load_le<uint32_t>(view.nodes + size_t(w) * 4));
    }
    std::unordered_map<uint32_t, uint32_t> node_id;  // word offset -> item id
    for (size_t k = starts.size(); k-- > 0;) {
      const uint8_t* node = view.nodes + size_t(starts[k]) * 4;
      const uint32_t flags = st::load_le<uint32_t>(node);
      std::string key(reinterpret_cast<const char*>(&flags), 4);
      uint32_t rank = 0;
      for (uint32_t c = 0; c < 4; ++c) {
        if (!((flags >> c) & 1)) continue;
        const uint32_t ref = st::load_le<uint32_t>(node + 4 + 8 * rank++);
        const uint32_t child = (flags >> (kNodeTreeletShift + c)) & 1 ? treelet_id[ref] : node_id.at(ref);
        key.append(reinterpret_cast<const char*>(&child), 4);
      }
      const uint64_t bytes = uint64_t(node_words(flags)) * 4;
      node_id[starts[k]] = node_items.add(key, bytes, tile);
      bump(node_tile_bytes, node_id[starts[k]], bytes);
    }
    // Value chunks: info without its bit offset, plus the multiplier bits.
    for (uint32_t c = 0; c < s.chunk_count; ++c) {
      const ChunkInfo info = load_chunk(view.chunks, c);
      const uint32_t k = info.factor_bits(), n = uint32_t(std::popcount(info.mask));
      std::string key;
      key.append(reinterpret_cast<const char*>(&info.base), 4);
      key.append(reinterpret_cast<const char*>(&info.mask), 4);
      key.append(reinterpret_cast<const char*>(&info.c_l), 4);
      key.append(reinterpret_cast<const char*>(&info.c_f), 4);
      key.push_back(char(k));
      for (uint32_t j = 0; j < n; ++j) {
        const uint64_t pos = uint64_t(info.bit_offset()) + uint64_t(j) * k;
        const uint64_t word = st::load_le<uint64_t>(view.multipliers + (pos >> 3)) >> (pos & 7);
        const uint32_t i = k == 0 ? 0 : uint32_t(word & ((uint64_t(1) << k) - 1));
        key.append(reinterpret_cast<const char*>(&i), 4);
      }
      const uint64_t bytes = sizeof(ChunkInfo) + (uint64_t(n) * k + 7) / 8;
      const uint32_t id = chunk_items.add(key, bytes, tile);
      bump(chunk_tile_bytes, id, bytes);
    }
    for (uint32_t i = 0; i < h.value_count; ++i) distinct_values.insert(std::bit_cast<uint32_t>(view.value(i)));
  }
};

}  // namespace

int main(int argc, char** argv) {
  try {
    std::vector<std::string> packs, mmh_packs;
    std::string json_path;
    bool check = false;
    st::bench::Options opt("bench_dagmh_sharing", "What a pack-wide dictionary saves on DAG-MH packs (DAG-MH 2021, 3.1-3.4)");
    opt.rest("PACK", packs, "DAG-MH packs (at least one)")
        .each("--mmh", mmh_packs, "The MMH pack of the same map, one per PACK, in order (repeat the option)")
        .flag("--check", check, "Every texel of every tile bit-equal with and without the dictionary")
        .value("--json", json_path, "Write the rows as JSON to PATH");
    opt.parse(argc, argv);
    if (packs.empty()) opt.fail("give at least one PACK");
    if (!mmh_packs.empty() && mmh_packs.size() != packs.size()) throw st::Error("--mmh: give one per pack, in order");
    std::vector<nlohmann::json> dict_rows;
    nlohmann::json out = nlohmann::json::array();
    std::printf("%-28s %6s %10s | %-10s %10s %10s %10s %10s %7s\n", "pack", "tiles", "raw B", "section",
                "stored", "distinct", "in shared", "dict", "net %");
    for (size_t pi = 0; pi < packs.size(); ++pi) {
      const auto& path = packs[pi];
      const auto reader = st::PackReader::open(path);
      if (reader->encoding() != st::Encoding::dagmh) throw st::Error(path + ": not a DAG-MH pack");
      Analysis a;
      uint32_t tile = 0;
      std::vector<std::vector<uint8_t>> raw_tiles;
      for (const auto& e : reader->tiles())
        if (e.kind == st::TileKind::encoded) {
          raw_tiles.push_back(reader->read_raw(e.id));
          a.add_tile(raw_tiles.back(), tile++);
        }
      const auto sn = a.node_items.summary(a.node_tile_bytes);
      const auto st_ = a.treelet_items.summary(a.treelet_tile_bytes);
      const auto sc = a.chunk_items.summary(a.chunk_tile_bytes);
      nlohmann::json j{{"pack", path},
                       {"tiles", a.tiles},
                       {"raw_bytes", a.raw_bytes},
                       {"sections",
                        {{"header", a.header},
                         {"skip", a.skip},
                         {"nodes", a.nodes},
                         {"treelets", a.treelets},
                         {"chunks", a.chunks},
                         {"multipliers", a.multipliers}}},
                       {"values", a.values},
                       {"distinct_values", a.distinct_values.size()}};
      auto row = [&](const char* name, const Items::Summary& s) {
        std::printf("%-28s %6llu %10llu | %-10s %10llu %10llu %10llu %10llu %6.1f%%\n", path.substr(path.rfind('/') + 1).c_str(),
                    (unsigned long long)a.tiles, (unsigned long long)a.raw_bytes, name,
                    (unsigned long long)s.stored, (unsigned long long)s.distinct,
                    (unsigned long long)s.in_shared, (unsigned long long)s.dictionary,
                    100.0 * double(s.net()) / double(a.raw_bytes));
        j[name] = {{"stored", s.stored},       {"distinct", s.distinct},     {"shared_items", s.shared_items},
                   {"in_shared", s.in_shared}, {"dictionary", s.dictionary}, {"net_saving", s.net()}};
      };
      row("nodes", sn);
      row("treelets", st_);
      row("chunks", sc);
      const int64_t total = sn.net() + st_.net() + sc.net();
      std::printf("  sections: header %llu skip %llu nodes %llu treelets %llu chunk infos %llu multipliers %llu; "
                  "values %llu (%zu distinct)\n",
                  (unsigned long long)a.header, (unsigned long long)a.skip, (unsigned long long)a.nodes,
                  (unsigned long long)a.treelets, (unsigned long long)a.chunks, (unsigned long long)a.multipliers,
                  (unsigned long long)a.values, a.distinct_values.size());
      std::printf("  net saving of one pack-wide dictionary of all three: %lld B = %.1f%% of the tiles' raw bytes\n",
                  (long long)total, 100.0 * double(total) / double(a.raw_bytes));
      j["net_saving_all"] = total;

      // The dictionary itself.
      st::dagmh::SharedTiles shared;
      const st::bench::DictFigures f = st::bench::dict_figures(raw_tiles, &shared);
      const uint64_t dict_raw = f.dict_raw;
      uint64_t mmh_raw = 0, mmh_zlib = 0;
      if (!mmh_packs.empty()) {
        const auto m = st::PackReader::open(mmh_packs[pi]);
        for (const auto& e : m->tiles())
          if (e.kind == st::TileKind::encoded) mmh_raw += e.raw_size, mmh_zlib += e.stored_size;
      }
      // Lookup cost: the same random finest-level texels of random tiles through the
      // version 1 and the rewritten tiles (thread CPU, median of 5 passes, alternating).
      double ns_before = 0, ns_after = 0;
      {
        const auto dict = dict_raw ? st::dagmh::Dictionary::open(shared.dictionary) : nullptr;
        std::vector<std::unique_ptr<st::Evaluator>> before, after;
        for (size_t t = 0; t < raw_tiles.size(); ++t) {
          before.push_back(st::open_dagmh(raw_tiles[t]));
          after.push_back(st::open_dagmh(shared.tiles[t], dict));
        }
        struct Q {
          uint32_t tile, level;
          uint64_t x, y;
        };
        std::vector<Q> qs(1u << 20);
        uint64_t state = 0x9E3779B97F4A7C15ull;
        auto next = [&]() { return state = state * 6364136223846793005ull + 1442695040888963407ull, state >> 33; };
        for (Q& q : qs) {
          q.tile = uint32_t(next() % before.size());
          q.level = before[q.tile]->finest_level();
          q.x = next() & ((uint64_t(1) << q.level) - 1), q.y = next() & ((uint64_t(1) << q.level) - 1);
        }
        auto pass = [&](const std::vector<std::unique_ptr<st::Evaluator>>& ev, double& sink) {
          const double c0 = st::bench::thread_cpu_now();
          float sum = 0;
          for (const Q& q : qs) sum += ev[q.tile]->depth(q.level, q.x, q.y);
          const double c1 = st::bench::thread_cpu_now();
          sink += sum;
          return (c1 - c0) * 1e9 / double(qs.size());
        };
        std::vector<double> tb, ta;
        double sink = 0;
        for (int r = 0; r < 5; ++r) tb.push_back(pass(before, sink)), ta.push_back(pass(after, sink));
        std::sort(tb.begin(), tb.end()), std::sort(ta.begin(), ta.end());
        ns_before = tb[2], ns_after = ta[2];
        if (sink == 12345) std::printf(" ");
      }
      uint64_t checked = 0;
      if (check) {
        const auto dict = dict_raw ? st::dagmh::Dictionary::open(shared.dictionary) : nullptr;
        for (size_t t = 0; t < raw_tiles.size(); ++t) {
          const auto before = st::open_dagmh(raw_tiles[t]);
          const auto after = st::open_dagmh(shared.tiles[t], dict);
          for (uint32_t level = 0; level <= before->finest_level(); ++level)
            for (uint64_t y = 0; y < (uint64_t(1) << level); ++y)
              for (uint64_t x = 0; x < (uint64_t(1) << level); ++x, ++checked)
                if (std::bit_cast<uint32_t>(before->depth(level, x, y)) != std::bit_cast<uint32_t>(after->depth(level, x, y)))
                  throw st::Error(path + ": tile " + std::to_string(t) + " answers differently with the dictionary at level " +
                                  std::to_string(level));
        }
      }
      const std::string name = path.substr(path.rfind('/') + 1);
      nlohmann::json d{{"pack", name},
                       {"tiles_rewritten", f.tiles_rewritten},
                       {"raw_before", f.raw_before},
                       {"raw_after", f.raw_after},
                       {"dictionary_raw", f.dict_raw},
                       {"zlib_before", f.zlib_before},
                       {"zlib_after", f.zlib_after},
                       {"dictionary_zlib", f.dict_zlib},
                       {"mmh_raw", mmh_raw},
                       {"mmh_zlib", mmh_zlib},
                       {"texels_checked", checked},
                       {"lookup_ns_before", ns_before},
                       {"lookup_ns_after", ns_after}};
      j["dictionary"] = d;
      dict_rows.push_back(d);
      out.push_back(j);
    }
    std::printf("\nwith the dictionary (tiles/encode/dagmh_dictionary.hpp; dict = its bytes, counted once):\n");
    std::printf("%-28s %10s %10s %9s %7s | %10s %10s %9s %7s | %12s %12s\n", "pack", "raw before", "raw after",
                "dict raw", "after%", "zlib bef.", "zlib aft.", "dict zlib", "after%", "DAG/MMH raw", "DAG/MMH zlib");
    for (const auto& d : dict_rows) {
      const double rb = d["raw_before"], ra = double(d["raw_after"]) + double(d["dictionary_raw"]);
      const double zb = d["zlib_before"], za = double(d["zlib_after"]) + double(d["dictionary_zlib"]);
      const double mr = d["mmh_raw"], mz = d["mmh_zlib"];
      char ratio_raw[64] = "-", ratio_zlib[64] = "-";
      if (mr > 0) std::snprintf(ratio_raw, sizeof ratio_raw, "%.3f->%.3f", rb / mr, ra / mr);
      if (mz > 0) std::snprintf(ratio_zlib, sizeof ratio_zlib, "%.3f->%.3f", zb / mz, za / mz);
      std::printf("%-28s %10.0f %10llu %9llu %6.1f%% | %10.0f %10llu %9llu %6.1f%% | %12s %12s\n",
                  std::string(d["pack"]).c_str(), rb, (unsigned long long)d["raw_after"], (unsigned long long)d["dictionary_raw"],
                  100 * ra / rb, zb, (unsigned long long)d["zlib_after"], (unsigned long long)d["dictionary_zlib"], 100 * za / zb,
                  ratio_raw, ratio_zlib);
      std::printf("  random finest-level lookups over all tiles: %.1f ns without, %.1f ns with the dictionary "
                  "(thread CPU, median of 5)\n", double(d["lookup_ns_before"]), double(d["lookup_ns_after"]));
      if (check) std::printf("  %llu texel lookups bit-equal with and without the dictionary\n", (unsigned long long)d["texels_checked"]);
    }
    if (!json_path.empty()) std::ofstream(json_path) << out.dump(2) << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_dagmh_sharing: %s\n", e.what());
    return 1;
  }
}
