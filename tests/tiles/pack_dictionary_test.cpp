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
#include "tiles/build/mh_build.hpp"
#include "tiles/build/pack_merge.hpp"
#include "tiles/build/pack_writer.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_dictionary.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace {

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
  EXPECT_FALSE(std::filesystem::exists(path + ".dict.tmp"));
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
    if (load_le<uint32_t>(raw.data() + 4) != dagmh::kVersionDictionary) continue;
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
  ASSERT_EQ(g.size(), d + 16 + dict.size());  // the section ends the grid section
  EXPECT_EQ(std::memcmp(g.data() + d, "STDD", 4), 0);
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 4), dict.size());
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 8), crc32_of(dict));
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 8), on->dictionary()->crc());
  EXPECT_EQ(load_le<uint32_t>(g.data() + d + 12), 0u);
  EXPECT_TRUE(std::equal(dict.begin(), dict.end(), g.begin() + long(d + 16)));
  EXPECT_EQ(std::memcmp(g.data() + d + 16, "DGMD", 4), 0);
  const GridSectionParts parts = split_grid_section(g, s.cut.skip_level, true, "x");
  EXPECT_EQ(parts.skip_grid.size(), skip);
  EXPECT_EQ(parts.preview.size(), preview);
  EXPECT_EQ(parts.dictionary.data(), g.data() + d + 16);
  // The header admits the feature on DAG-MH packs alone.
  PackHeader h = on->header();
  h.encoding = Encoding::mmh;
  EXPECT_THROW(PackHeader::parse(h.serialize(), "x.pack"), FormatError);
}

// Byte offsets in a pack file of the dictionary section and the grid CRC's coverage.
struct Layout {
  uint64_t grid_offset, grid_size, section;  // section: the "STDD" header's file offset
};
Layout layout_of(const PackReader& r) {
  const PackHeader& h = r.header();
  return {h.grid_offset, h.grid_size, h.grid_offset + h.grid_size - 16 - r.dictionary()->bytes().size()};
}
void resign(std::vector<uint8_t>& b, const Layout& l, bool section_crc) {
  if (section_crc) {
    const uint32_t n = load_le<uint32_t>(b.data() + l.section + 4);
    store_le<uint32_t>(b.data() + l.section + 8, crc32_of({b.data() + l.section + 16, n}));
  }
  store_le<uint32_t>(b.data() + 244, crc32_of({b.data() + l.grid_offset, size_t(l.grid_size)}));
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
  const DictSetup s = make_setup();
  const auto on = write(s, "dict_corrupt.pack", true);
  const std::vector<uint8_t> good = slurp(on->name());
  const Layout l = layout_of(*on);
  const uint64_t dict = l.section + 16;  // the DGMD header; its nodes follow at +32
  auto open = [](std::vector<uint8_t> b) { return PackReader::open_memory(std::move(b), "bad.pack"); };
  ASSERT_NO_THROW(open(good));
  {  // a flipped byte the section CRC catches (grid CRC made to match)
    auto b = good;
    b[dict + 40] ^= 0x10;
    resign(b, l, false);
    expect_refused([&] { open(b); }, "DAG-MH dictionary CRC mismatch");
  }
  {  // every CRC right, a child reference out of range
    auto b = good;
    ASSERT_GT(on->dictionary()->node_words(), 0u);
    store_le<uint32_t>(b.data() + dict + 32 + 4, 0x3FFFFFF0u);
    resign(b, l, true);
    expect_refused([&] { open(b); }, "dagmh dictionary:");
  }
  {  // every CRC right, the size field disagreeing with the section
    auto b = good;
    store_le<uint32_t>(b.data() + l.section + 4, load_le<uint32_t>(b.data() + l.section + 4) - 4);
    resign(b, l, false);
    expect_refused([&] { open(b); }, "DAG-MH dictionary size");
  }
  {  // the feature bit cleared: the grid section no longer parses
    auto b = good;
    store_le<uint32_t>(b.data() + 20, load_le<uint32_t>(b.data() + 20) & ~uint32_t(kFeatureDagmhDictionary));
    resign(b, l, false);
    EXPECT_THROW(open(b), FormatError);
  }
  if (on->dictionary()->treelet_count() > 0) {
    // A valid dictionary, but not the one the tiles were written against: the pack opens,
    // every version-2 tile is refused by its dictionary CRC (verify, lookups).
    auto b = good;
    const uint64_t treelet = dict + 32 + 4ull * on->dictionary()->node_words();
    // Move one set bit of treelet 0 to a clear position: the same value count, so the
    // dictionary still validates, but its CRC is no longer the one the tiles name.
    uint64_t w = load_le<uint32_t>(b.data() + treelet) | uint64_t(load_le<uint32_t>(b.data() + treelet + 4)) << 32;
    ASSERT_NE(w, 0u);
    ASSERT_NE(w, ~uint64_t(0));
    w ^= (uint64_t(1) << std::countr_zero(w)) | (uint64_t(1) << std::countr_one(w));
    store_le<uint32_t>(b.data() + treelet, uint32_t(w));
    store_le<uint32_t>(b.data() + treelet + 4, uint32_t(w >> 32));
    resign(b, l, true);
    std::shared_ptr<const PackReader> r = open(b);
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
  // Killed halfway; a stale "<name>.dict.tmp" of an earlier finish lies around.
  const std::string path = packtest::temp_path("dict_resume.pack");
  {
    auto w = PackWriter::create(path, s.pack);
    for (size_t i = 0; i < cells.size() / 2; ++i) w->append_cell(cells[i]);
  }
  std::ofstream(path + ".dict.tmp") << "half a pack";
  {
    auto w = PackWriter::resume(path, s.pack);
    for (const CutCell& c : cells)
      if (!w->is_done(c.cx, c.cy)) w->append_cell(c);
    w->finish(grid);
  }
  EXPECT_EQ(slurp(path), want);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
  EXPECT_FALSE(std::filesystem::exists(path + ".dict.tmp"));

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

}  // namespace
}  // namespace st
