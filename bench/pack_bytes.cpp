// Where a pack's bytes go (tiles/PACK.md): the container's sections (header, params,
// journal tile records and payloads, cell records (none in a payloads-only pack), skip grid, map preview, DAG-MH
// dictionary, tile index) and, for DAG-MH tiles, the sections inside them
// (tiles/core/DAGMH.md: header, skip table, inner nodes, treelets, chunk infos,
// multipliers), raw and as stored. A section's stored share is its marginal cost: the
// tile's zlib size (level 6, as packs store tiles) minus that of the tile without it,
// summed over tiles (so the shares need not add up to the stored total).
//
//   bench_pack_bytes PACK... [--json PATH]
#include <bit>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_reader.hpp"

namespace {

struct Part {
  const char* name;
  uint64_t raw = 0, stored = 0;
};

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
  if (h.encoding != st::Encoding::dagmh) return out;
  Part parts[6] = {{"header"}, {"skip table"}, {"inner nodes"}, {"treelets"}, {"chunk infos"}, {"multipliers"}};
  uint64_t stored_sum = 0;
  uint32_t skip_hist[7] = {};
  uint64_t k_hist[33] = {}, mask_zero = 0, mask_full = 0, values_in_chunks = 0;
  for (const auto& e : reader->tiles()) {
    if (e.kind != st::TileKind::encoded) continue;
    ++encoded_tiles;
    const std::vector<uint8_t> raw = reader->read_raw(e.id);
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
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    std::vector<std::string> packs;
    std::string json_path;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "--json" && i + 1 < argc) json_path = argv[++i];
      else packs.push_back(a);
    }
    if (packs.empty()) throw st::Error("usage: bench_pack_bytes PACK... [--json PATH]");
    nlohmann::json all = nlohmann::json::array();
    for (const auto& p : packs) all.push_back(measure(p));
    if (!json_path.empty()) std::ofstream(json_path) << all.dump(2) << "\n";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_pack_bytes: %s\n", e.what());
    return 1;
  }
}
