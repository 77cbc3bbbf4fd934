// libFuzzer harness for the pack reader (pack_reader.hpp) and PackEvaluator. Input:
// byte 0 is a control byte (bit 0: first rewrite every CRC the mutated bytes' own
// offsets and sizes delimit; without it the fuzzer rarely gets past the CRCs into the
// parsers behind them), the rest a whole pack file. Flow: PackReader::open_memory; for the first tiles of the index
// read_raw (CRC, zlib, size checks), open encoded tiles with the pack's encoding (and its
// DAG-MH dictionary, whose section CRC is repaired too) and probe them, parse index tiles with read_index_tile; verify() with the real opener;
// then a PackEvaluator answers lookups at every level and PCF (evaluator_probe.hpp).
// A stack pack (tiles/PACK.md "Stack packs"; seeds in both layouts: journal records, plain
// index and raw grid, or payloads only, compact index and compressed grid) is verified
// instead, and one verify() accepts answers lookups of every slice (StackMap); one more seed
// splits cells below the skip level (feature stack_split_cells).
// Every rejection must be an st::FormatError (the reader's documented error for corrupt
// data); anything else escaping, a crash or a sanitizer report is a finding.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>

#include "proto/byte_io.hpp"
#include "proto/frame.hpp"
#include "tests/fuzz/evaluator_probe.hpp"
#include "tests/fuzz/seed_support.hpp"
#include "tiles/core/encoding.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "common/error.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/encode/mh_octree_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out = pack_files(11);
  // Stack packs: a small stack of 3 slices, 2^4 a side, in both layouts.
  st::IntervalStack s;
  s.level = 4;
  s.slices = 3;
  s.data.resize(16 * 16 * 3);
  for (size_t i = 0; i < s.data.size(); ++i) {
    const float d = (i * 2654435761u) % 7 < 3 ? 0.25f + float((i * 40503u) % 97) / 200.0f : 1.0f;
    s.data[i] = st::Interval{d, d};
  }
  st::StackCut cut = st::cut_stack(st::build_octree(s), 1, 512);
  const st::LightSet set = st::LightSet::fit(st::LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=3"),
                                             st::Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const st::LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  for (const bool finished : {true, false}) {
    st::StackPackParams p;
    p.payloads_only = p.compress_grid = finished;
    const std::string path =
        (std::filesystem::temp_directory_path() / ("shadowtile_stack_seed_" + std::to_string(::getpid()) + ".pack")).string();
    st::write_stack_pack(path, cut, p);
    std::ifstream f(path, std::ios::binary);
    out.emplace_back(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    std::filesystem::remove(path);
  }
  {
    // The same stack with split cells (feature stack_split_cells, grid version 2): a tile
    // bound that level 1's cells overflow, split down two levels.
    const std::string base =
        (std::filesystem::temp_directory_path() / ("shadowtile_split_seed_" + std::to_string(::getpid()))).string();
    st::StackSpill spill(base + ".spill", s.level, s.slices, 0);
    for (uint32_t w = 0; w < s.slices; ++w)
      spill.write_rows(w, 0, 16, std::span<const st::Interval>(s.data.data() + w * 256, 256));
    st::BlockedStackCut split(spill, 1u, 100, base + ".tiles", nullptr, st::StackCells::octree, true);
    split.grid.light_kind = cut.grid.light_kind;
    split.grid.lights = cut.grid.lights;
    split.grid.spec = cut.grid.spec;
    st::write_stack_pack(base + ".pack", split.grid, split.tile_count(), [&](size_t i) { return split.tile(i); },
                         st::StackPackParams{});
    std::ifstream f(base + ".pack", std::ios::binary);
    out.emplace_back(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    std::filesystem::remove(base + ".pack");
  }
  for (Bytes& b : out) b.insert(b.begin(), std::uint8_t(1));
  return out;
}

namespace {

constexpr size_t kMaxTilesProbed = 8;

using st::proto::crc32;
using st::proto::load_le;
using st::proto::store_le;

// crc32 of b[off, off + len) if that lies inside b, else 0.
uint32_t crc_of(const std::vector<uint8_t>& b, uint64_t off, uint64_t len) {
  if (off > b.size() || len > b.size() - off) return 0;
  return crc32({b.data() + off, size_t(len)});
}

// The DAG-MH dictionary section (pack_dictionary.hpp) ends the grid section: the first
// "STDD" header (at a 4-byte step) whose stored size reaches exactly the section's end
// gets its CRC field rewritten over its bytes, when the feature bit is set.
void repair_dictionary_crc(std::vector<uint8_t>& b, uint64_t grid_off, uint64_t grid_size) {
  if (!(load_le<uint32_t>(&b[20]) & st::kFeatureDagmhDictionary)) return;
  if (grid_off > b.size() || grid_size > b.size() - grid_off) return;
  const uint64_t end = grid_off + grid_size;
  for (uint64_t at = grid_off; at + st::kPackDictionaryHeaderBytes <= end; at += 4) {
    if (load_le<uint32_t>(&b[at]) != st::kPackDictionaryMagic) continue;
    const uint64_t n = load_le<uint32_t>(&b[at + 8]);
    if (at + st::kPackDictionaryHeaderBytes + n != end) continue;
    store_le<uint32_t>(&b[at + 12], crc_of(b, at + st::kPackDictionaryHeaderBytes, n));
    return;
  }
}

// Rewrites the CRCs of a pack (pack_format.hpp layout) from its own offsets and sizes,
// bounds-checked, innermost first: journal record payloads and headers, index entries
// (a payloads-only pack's compact index inflated, its CRC column rewritten, deflated
// again), then the params/grid/index CRCs and the header CRC.
void repair_crcs(std::vector<uint8_t>& b) {
  if (b.size() < st::kPackHeaderBytes) return;
  const uint64_t params_off = load_le<uint64_t>(&b[184]), params_size = load_le<uint64_t>(&b[192]);
  const uint64_t journal = load_le<uint64_t>(&b[200]), grid_off = load_le<uint64_t>(&b[208]);
  const uint64_t grid_size = load_le<uint64_t>(&b[216]), index_off = load_le<uint64_t>(&b[224]);
  const uint64_t tiles = load_le<uint64_t>(&b[232]);
  for (uint64_t pos = journal; pos <= b.size() && b.size() - pos >= st::kRecordBytes;) {
    uint8_t* r = &b[pos];
    const uint32_t magic = load_le<uint32_t>(r);
    if (magic == st::kTileRecordMagic) {
      const uint32_t stored = load_le<uint32_t>(r + 16);
      store_le<uint32_t>(r + 24, crc_of(b, pos + st::kRecordBytes, stored));
      store_le<uint32_t>(r + 28, crc32({r, 28}));
      pos += st::kRecordBytes + stored;
    } else if (magic == st::kCellRecordMagic) {
      store_le<uint32_t>(r + 28, crc32({r, 28}));
      pos += st::kRecordBytes;
    } else {
      break;
    }
  }
  const bool compact = load_le<uint32_t>(&b[20]) & st::kFeaturePayloadsOnly;
  if (compact && index_off <= b.size() && b.size() - index_off >= st::kCompactIndexHeaderBytes &&
      tiles <= (b.size() - index_off) * 8) {
    // The compact index (tiles/PACK.md "Payloads only"): inflate its columns, rewrite the
    // CRC column over the implied payloads, deflate it again; its CRC covers the rest.
    try {
      const std::span<const uint8_t> z(b.data() + index_off + st::kCompactIndexHeaderBytes,
                                       b.size() - index_off - st::kCompactIndexHeaderBytes);
      std::vector<uint8_t> cols = st::zlib_decompress(z, uint32_t(tiles * st::kCompactIndexEntryBytes), "fuzz");
      uint64_t off = journal;
      for (uint64_t i = 0; i < tiles; ++i) {
        const uint32_t stored = load_le<uint32_t>(&cols[8 * tiles + 4 * i]);
        store_le<uint32_t>(&cols[16 * tiles + 4 * i], crc_of(b, off, stored));
        off += stored;
      }
      const std::vector<uint8_t> nz = st::zlib_compress(cols, 6);
      b.resize(index_off + st::kCompactIndexHeaderBytes);
      store_le<uint32_t>(&b[index_off + 4], uint32_t(nz.size()));
      b.insert(b.end(), nz.begin(), nz.end());
    } catch (const st::Error&) {
    }
    store_le<uint32_t>(&b[248], crc_of(b, index_off, b.size() - index_off));
  } else if (index_off <= b.size() && tiles <= (b.size() - index_off) / st::kIndexEntryBytes) {
    for (uint64_t i = 0; i < tiles; ++i) {
      uint8_t* e = &b[index_off + i * st::kIndexEntryBytes];
      store_le<uint32_t>(e + 24, crc_of(b, load_le<uint64_t>(e + 8), load_le<uint32_t>(e + 16)));
    }
    store_le<uint32_t>(&b[248], crc_of(b, index_off, tiles * st::kIndexEntryBytes));
  }
  store_le<uint32_t>(&b[240], crc_of(b, params_off, params_size));
  repair_dictionary_crc(b, grid_off, grid_size);
  store_le<uint32_t>(&b[244], crc_of(b, grid_off, grid_size));
  store_le<uint32_t>(&b[252], crc32({b.data(), 252}));
}

void probe_tiles(const st::PackReader& reader, uint64_t hash) {
  size_t n = 0;
  for (const st::TileIndexEntry& t : reader.tiles()) {
    if (n++ == kMaxTilesProbed) break;
    try {
      if (t.kind == st::TileKind::encoded) {
        const std::vector<uint8_t> raw = reader.read_raw(t.id);
        FUZZ_CHECK(raw.size() == t.raw_size);
        auto ev = reader.open_tile(raw);  // with the pack's DAG-MH dictionary, if any
        st::fuzz::probe_evaluator(*ev, hash, 8);
      } else {
        // The parent entry is not at hand here: try each depth an index tile may have
        // (the PackEvaluator below reaches them through their real parents).
        for (uint8_t d = 1; d <= st::kMaxIndexLevels; ++d) {
          try {
            const st::CutGrid g =
                reader.read_index_tile(t.id, st::GridEntry{0.0f, st::EntryKind::index, d});
            FUZZ_CHECK(g.levels == d);
          } catch (const st::FormatError&) {
          }
        }
      }
    } catch (const st::FormatError&) {
    }
  }
}

// The map preview as a client with no tile uses it: every answer is a number, and in a
// verified pack it equals the full pack's answer at level min(level, K + p).
void probe_preview(const st::PackReader& reader, const st::PackEvaluator& ev, bool verified, uint64_t hash) {
  const uint32_t k = reader.skip_level(), top = reader.map_level(), p = reader.preview().levels();
  for (uint32_t i = 0; i < 32; ++i) {
    hash = hash * 6364136223846793005ull + 1442695040888963407ull;
    const uint32_t level = k + uint32_t((hash >> 33) % (top - k + 1));
    const uint64_t mask = (uint64_t(1) << level) - 1, x = (hash >> 7) & mask, y = (hash >> 29) & mask;
    const st::PageHit hit = st::walk_page_table(reader.grid(), level, x, y,
                                                [](uint64_t, const st::GridEntry&) -> const st::CutGrid* { return nullptr; });
    const float got = reader.preview().coarse_answer(k, hit, level, x, y);
    FUZZ_CHECK(!std::isnan(got));
    if (verified) {
      const uint32_t at = std::min(level, k + p);
      const float want = ev.depth(at, x >> (level - at), y >> (level - at));
      FUZZ_CHECK(std::memcmp(&got, &want, sizeof got) == 0);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  std::vector<std::uint8_t> pack(data + 1, data + size);
  if (data[0] & 1) repair_crcs(pack);
  std::shared_ptr<const st::PackReader> reader;
  try {
    reader = st::PackReader::open_memory(std::move(pack), "fuzz.pack");
  } catch (const st::FormatError&) {
    return 0;
  }
  FUZZ_CHECK(reader->map_level() <= st::kMaxLevel);
  if (const st::StackGrid* g = reader->stack()) {
    FUZZ_CHECK(g->entries.size() >= g->cells(g->skip_level));
    FUZZ_CHECK(g->split() == bool(reader->header().flags & st::kFeatureStackSplitCells));
    size_t n = 0;
    for (const st::TileIndexEntry& t : reader->tiles()) {
      if (n++ == kMaxTilesProbed) break;
      try {
        FUZZ_CHECK(reader->read_raw(t.id).size() == t.raw_size);
      } catch (const st::FormatError&) {
      }
    }
    try {
      reader->verify();
    } catch (const st::FormatError&) {
      return 0;
    }
    st::fuzz::note_accepted();
    // A verified stack answers every texel of every slice with a number.
    const st::ResidentStack rs(*reader);
    uint64_t hash = st::fuzz::input_hash(data, size);
    for (uint32_t i = 0; i < 64; ++i) {
      hash = hash * 6364136223846793005ull + 1442695040888963407ull;
      const uint32_t level = uint32_t((hash >> 40) % (g->geo.n + 1));
      const uint64_t mask = (uint64_t(1) << level) - 1;
      FUZZ_CHECK(!std::isnan(rs.map().depth((hash >> 7) & mask, (hash >> 29) & mask, uint32_t((hash >> 50) % g->slices), level)));
    }
    return 0;
  }
  FUZZ_CHECK(reader->skip_level() <= reader->map_level());
  FUZZ_CHECK(reader->grid().levels == reader->skip_level());
  const uint64_t hash = st::fuzz::input_hash(data, size);
  probe_tiles(*reader, hash);
  bool verified = true;
  try {
    reader->verify(reader->tile_opener());
  } catch (const st::FormatError&) {
    verified = false;
  }
  if (verified) st::fuzz::note_accepted();
  try {
    st::PackEvaluator ev(reader, 4);
    st::fuzz::probe_evaluator(ev, hash);
    probe_preview(*reader, ev, verified, hash);
  } catch (const st::FormatError&) {
    // A pack that verify() accepted must answer every lookup.
    FUZZ_CHECK(!verified);
  }
  return 0;
}
