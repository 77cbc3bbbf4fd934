// The pack-wide DAG-MH dictionary (tiles/PACK.md "DAG-MH dictionary",
// tiles/core/pack_dictionary.hpp): a pack written with it answers bit-identically to the
// same pack without it on every texel, its section sits where the format says, a corrupt
// dictionary is refused in one line, and resumed or merged builds write the same pack.
#include <gtest/gtest.h>

#include <bit>
#include <filesystem>
#include <fstream>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_merge.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace pack_dictionary_test {

std::vector<uint8_t> slurp(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

struct DictSetup {
  Hierarchy h;
  CutParams cut;
  PackParams pack;
};

// A city field cut into small DAG-MH tiles (many of them share roof and footprint shapes).
DictSetup make_setup() {
  DictSetup s;
  const uint32_t level = fields::small_test_scale() ? 7 : 8;
  s.h = build_hierarchy(fields::city_field(1u << level, 5));
  s.cut.map_level = level;
  s.cut.skip_level = 3;
  s.cut.tile_bytes = 512;
  s.cut.codec = TileCodec::of(Encoding::dagmh);
  s.pack = PackParams::from(LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{0, 0, 0}, {1, 1, 1}}),
                            s.cut);
  s.pack.build_params = {{"scene", "city_field"}};
  return s;
}

std::shared_ptr<const PackReader> write(const DictSetup& s, const std::string& name, bool dictionary) {
  const std::string path = packtest::temp_path(name);
  PackParams pp = s.pack;
  pp.dagmh_dictionary = dictionary;
  write_pack(path, s.h, s.cut, pp);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  EXPECT_FALSE(std::filesystem::exists(path + ".final.tmp"));
  return PackReader::open(path);
}

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

TEST(PackDictionary, AnswersBitIdenticallyToThePackWithoutIt) {
  const DictSetup s = make_setup();
  const auto off = write(s, "dict_off.pack", false), on = write(s, "dict_on.pack", true);
  EXPECT_FALSE(off->header().flags & kFeatureDagmhDictionary);
  EXPECT_EQ(off->dictionary(), nullptr);
  ASSERT_TRUE(on->header().flags & kFeatureDagmhDictionary);
  ASSERT_NE(on->dictionary(), nullptr);
  ASSERT_EQ(on->tiles().size(), off->tiles().size());
  uint64_t raw_on = 0, raw_off = 0, v2 = 0;
  for (size_t i = 0; i < on->tiles().size(); ++i) {
    const TileIndexEntry &a = on->tiles()[i], &b = off->tiles()[i];
    ASSERT_EQ(a.id, b.id);
    raw_on += a.raw_size, raw_off += b.raw_size;
    if (a.kind != TileKind::encoded) continue;
    const std::vector<uint8_t> raw = on->read_raw(a.id);
    if (!(raw[10] & dagmh::kFlagDictionary)) continue;
    ++v2;
    try {  // a version-2 tile is refused without its dictionary, naming why
      open_encoded(Encoding::dagmh, raw);
      ADD_FAILURE() << "a version-2 tile opened without the dictionary";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("dictionary"), std::string::npos) << e.what();
    }
  }
  EXPECT_GT(v2, on->tiles().size() / 4) << "tiles rewritten";
  EXPECT_LT(raw_on + on->dictionary()->bytes().size(), raw_off);
  EXPECT_EQ(on->preview().serialize(), off->preview().serialize());
  EXPECT_NO_THROW(on->verify(on->tile_opener()));
  // Every texel of every level, and PCF, through the page table and the tiles.
  PackEvaluator a(on, 64), b(off, 64);
  EXPECT_EQ(packtest::first_difference(a, s.cut.map_level,
                                       [&](uint32_t l, uint64_t x, uint64_t y) { return b.depth(l, x, y); }),
            "");
  const uint64_t side = uint64_t(1) << s.cut.map_level;
  for (uint64_t i = 0; i < 300; ++i) {
    const uint64_t x = (i * 97) % side, y = (i * 41) % side;
    const float r = float(i % 13) / 12.0f;
    EXPECT_EQ(bits(a.pcf(s.cut.map_level, x, y, 5, r)), bits(b.pcf(s.cut.map_level, x, y, 5, r)));
  }
  EXPECT_NE(on->summary().find("DAG-MH dictionary"), std::string::npos);
}

TEST(PackDictionary, SectionOffsetsArePinned) {
  EXPECT_EQ(uint32_t(kFeatureDagmhDictionary), 64u);  // header flags bit 6
  const DictSetup s = make_setup();
  const auto on = write(s, "dict_pinned.pack", true);
  const std::span<const uint8_t> g = on->grid_bytes();
  const size_t skip = CutGrid::serialized_size(s.cut.skip_level), preview = on->preview().serialized_size();
  const size_t d = skip + preview;
  const std::span<const uint8_t> dict = on->dictionary()->bytes();
  const uint32_t stored = load_le<uint32_t>(g.data() + d + 8);
  ASSERT_EQ(g.size(), d + 16 + stored);  // the section ends the grid section
  EXPECT_EQ(std::memcmp(g.data() + d, "STDD", 4), 0);
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 4), dict.size());
  EXPECT_LT(stored, dict.size());  // a zlib stream of it
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 12), crc32_of(g.subspan(d + 16, stored)));
  EXPECT_EQ(zlib_decompress(g.subspan(d + 16, stored), uint32_t(dict.size()), "x"),
            std::vector<uint8_t>(dict.begin(), dict.end()));
  EXPECT_EQ(std::memcmp(dict.data(), "DGMD", 4), 0);
  const GridSectionParts parts = split_grid_section(g, s.cut.skip_level, true, "x");
  EXPECT_EQ(parts.skip_grid.size(), skip);
  EXPECT_EQ(parts.preview.size(), preview);
  EXPECT_EQ(parts.dictionary.data(), g.data() + d + 16);
  EXPECT_EQ(parts.dictionary_raw, dict.size());
  // The header admits the feature on DAG-MH packs alone.
  PackHeader h = on->header();
  h.encoding = Encoding::mmh;
  EXPECT_THROW(PackHeader::parse(h.serialize(), "x.pack"), FormatError);
}

// `good` (a pack file) with its grid section's dictionary section replaced by one holding
// `raw` (any bytes), every CRC and offset after it made to match.
std::vector<uint8_t> with_dictionary(const std::vector<uint8_t>& good, const PackReader& r, std::span<const uint8_t> raw) {
  const PackHeader& h = r.header();
  const uint64_t section = h.grid_offset + CutGrid::serialized_size(h.skip_level) + r.preview().serialized_size();
  std::vector<uint8_t> b(good.begin(), good.begin() + long(section));
  const std::vector<uint8_t> d = dictionary_section(raw, 6);
  b.insert(b.end(), d.begin(), d.end());
  const uint64_t grid_size = b.size() - h.grid_offset;
  b.insert(b.end(), good.begin() + long(h.index_offset), good.end());
  store_le<uint64_t>(b.data() + 216, grid_size);
  store_le<uint64_t>(b.data() + 224, h.grid_offset + grid_size);
  store_le<uint32_t>(b.data() + 244, crc32_of({b.data() + h.grid_offset, size_t(grid_size)}));
  store_le<uint32_t>(b.data() + 252, crc32_of({b.data(), 252}));
  return b;
}

// The section header's file offset.
uint64_t section_of(const PackReader& r) {
  const PackHeader& h = r.header();
  return h.grid_offset + CutGrid::serialized_size(h.skip_level) + r.preview().serialized_size();
}

void resign(std::vector<uint8_t>& b, const PackReader& r) {
  const PackHeader& h = r.header();
  store_le<uint32_t>(b.data() + 244, crc32_of({b.data() + h.grid_offset, size_t(h.grid_size)}));
  store_le<uint32_t>(b.data() + 252, crc32_of({b.data(), 252}));
}

// One line naming the pack and containing `want`.
void expect_refused(const std::function<void()>& f, const std::string& want) {
  try {
    f();
    ADD_FAILURE() << "accepted; wanted an error with '" << want << "'";
  } catch (const FormatError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(want), std::string::npos) << m;
    EXPECT_NE(m.find("bad.pack"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
}

TEST(PackDictionary, CorruptDictionaryIsRefusedInOneLine) {
  DictSetup s = make_setup();
  s.pack.compress_grid = false;  // the section's bytes are patched in place below
  const auto on = write(s, "dict_corrupt.pack", true);
  const std::vector<uint8_t> good = slurp(on->name());
  const uint64_t sec = section_of(*on);
  const std::span<const uint8_t> raw = on->dictionary()->bytes();
  auto open = [](std::vector<uint8_t> b) { return PackReader::open_memory(std::move(b), "bad.pack"); };
  ASSERT_NO_THROW(open(good));
  ASSERT_NO_THROW(open(with_dictionary(good, *on, raw)));
  {  // a flipped stored byte the section CRC catches (grid CRC made to match)
    auto b = good;
    b[sec + 20] ^= 0x10;
    resign(b, *on);
    expect_refused([&] { open(b); }, "DAG-MH dictionary CRC mismatch");
  }
  {  // the stored size disagreeing with the section
    auto b = good;
    store_le<uint32_t>(b.data() + sec + 8, load_le<uint32_t>(b.data() + sec + 8) - 1);
    resign(b, *on);
    expect_refused([&] { open(b); }, "DAG-MH dictionary size");
  }
  {  // the raw size disagreeing with what the stream inflates to
    auto b = good;
    store_le<uint32_t>(b.data() + sec + 4, load_le<uint32_t>(b.data() + sec + 4) + 4);
    resign(b, *on);
    expect_refused([&] { open(b); }, "DAG-MH dictionary");
  }
  {  // every CRC right, a child reference out of range
    ASSERT_GT(on->dictionary()->node_words(), 0u);
    std::vector<uint8_t> d(raw.begin(), raw.end());
    store_le<uint32_t>(d.data() + 32 + 4, 0x3FFFFFF0u);
    expect_refused([&] { open(with_dictionary(good, *on, d)); }, "dagmh dictionary:");
  }
  {  // every CRC right, a truncated dictionary
    std::vector<uint8_t> d(raw.begin(), raw.end() - 12);
    expect_refused([&] { open(with_dictionary(good, *on, d)); }, "dagmh dictionary:");
  }
  {  // the feature bit cleared: the grid section no longer parses
    auto b = good;
    store_le<uint32_t>(b.data() + 20, load_le<uint32_t>(b.data() + 20) & ~uint32_t(kFeatureDagmhDictionary));
    resign(b, *on);
    EXPECT_THROW(open(b), FormatError);
  }
  if (on->dictionary()->treelet_count() > 0) {
    // A valid dictionary, but not the one the tiles were written against: the pack opens,
    // every version-2 tile is refused by its dictionary CRC (verify, lookups).
    std::vector<uint8_t> d(raw.begin(), raw.end());
    const uint64_t treelet = 32 + 4ull * on->dictionary()->node_words();
    // Move one set bit of treelet 0 to a clear position: the same value count, so the
    // dictionary still validates, but its CRC is no longer the one the tiles name.
    uint64_t w = load_le<uint32_t>(d.data() + treelet) | uint64_t(load_le<uint32_t>(d.data() + treelet + 4)) << 32;
    ASSERT_NE(w, 0u);
    ASSERT_NE(w, ~uint64_t(0));
    w ^= (uint64_t(1) << std::countr_zero(w)) | (uint64_t(1) << std::countr_one(w));
    store_le<uint32_t>(d.data() + treelet, uint32_t(w));
    store_le<uint32_t>(d.data() + treelet + 4, uint32_t(w >> 32));
    std::shared_ptr<const PackReader> r = open(with_dictionary(good, *on, d));
    expect_refused([&] { r->verify(r->tile_opener()); }, "dictionary_crc");
    PackEvaluator ev(r, 8);
    bool refused = false;
    const uint32_t L = s.cut.map_level;
    for (uint64_t y = 0; y < (uint64_t(1) << L) && !refused; y += 3)
      for (uint64_t x = 0; x < (uint64_t(1) << L) && !refused; x += 3) try {
          ev.depth(L, x, y);
        } catch (const FormatError&) {
          refused = true;
        }
    EXPECT_TRUE(refused);
  }
}

TEST(PackDictionary, ResumedAndMergedBuildsWriteTheSamePack) {
  DictSetup s = make_setup();
  s.pack.dagmh_dictionary = true;
  std::vector<CutCell> cells;
  const CutGrid grid = cut_hierarchy(s.h, s.cut, [&](CutCell&& c) { cells.push_back(std::move(c)); });
  const std::string ref = packtest::temp_path("dict_ref.pack");
  {
    auto w = PackWriter::create(ref, s.pack);
    for (const CutCell& c : cells) w->append_cell(c);
    w->finish(grid);
    EXPECT_GT(w->dictionary_outcome().bytes, 0u);
    EXPECT_GT(w->dictionary_outcome().tiles_rewritten, 0u);
  }
  const std::vector<uint8_t> want = slurp(ref);
  // Killed halfway; a stale "<name>.final.tmp" of an earlier finish lies around.
  const std::string path = packtest::temp_path("dict_resume.pack");
  {
    auto w = PackWriter::create(path, s.pack);
    for (size_t i = 0; i < cells.size() / 2; ++i) w->append_cell(cells[i]);
  }
  std::ofstream(path + ".final.tmp") << "half a pack";
  {
    auto w = PackWriter::resume(path, s.pack);
    for (const CutCell& c : cells)
      if (!w->is_done(c.cx, c.cy)) w->append_cell(c);
    w->finish(grid);
  }
  EXPECT_EQ(slurp(path), want);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  EXPECT_FALSE(std::filesystem::exists(path + ".final.tmp"));

  // Two part files merged with the dictionary rebuilt: the same grid section (dictionary
  // included) and the same tiles as the one-go build.
  std::vector<std::string> parts;
  for (uint32_t i = 0; i < 2; ++i) {
    const BuildShard shard{i, 2};
    PackParams pp = s.pack;
    pp.build_params.push_back({kShardParam, shard.to_string()});
    std::sort(pp.build_params.begin(), pp.build_params.end());
    parts.push_back(packtest::temp_path("dict_part" + std::to_string(i) + ".part"));
    auto w = PackWriter::create(parts.back(), pp);
    for (const CutCell& c : cells)
      if (shard.holds(c.cx, c.cy)) w->append_cell(c);
    w->finish_part();
  }
  std::swap(parts[0], parts[1]);  // any order
  const std::string merged = packtest::temp_path("dict_merged.pack");
  EXPECT_GT(merge_parts(parts, merged, true).dictionary_bytes, 0u);
  const auto a = PackReader::open(merged), b = PackReader::open(ref);
  EXPECT_TRUE(std::ranges::equal(a->grid_bytes(), b->grid_bytes()));
  ASSERT_EQ(a->tiles().size(), b->tiles().size());
  for (size_t i = 0; i < a->tiles().size(); ++i) EXPECT_EQ(a->read_raw(a->tiles()[i].id), b->read_raw(b->tiles()[i].id));
  EXPECT_NO_THROW(a->verify(a->tile_opener()));
  // Without it the merged pack keeps self-contained tiles.
  const std::string plain = packtest::temp_path("dict_merged_off.pack");
  EXPECT_EQ(merge_parts(parts, plain, false).dictionary_bytes, 0u);
  EXPECT_EQ(PackReader::open(plain)->dictionary(), nullptr);
}

}  // namespace pack_dictionary_test
}  // namespace st
