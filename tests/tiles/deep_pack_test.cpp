// Deep tiles in packs (tiles/PACK.md "Deep tiles", deep_pack.hpp): a scene with partial
// occluders builds its opaque map from opaque_part() and appends its deep map; the pack
// answers the deep map's lookups exactly; a scene without partial occluders gets the pack
// a build without the deep step makes; hostile deep data is refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/bake/deep_build.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/deep_pack.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace deep_pack_test {

std::vector<uint8_t> file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), {}};
}

MapBuildOptions small_options() {
  MapBuildOptions o;
  o.map_level = 6;
  o.skip_level = 2;
  o.encoding = packtest::available_encodings().at(0);
  o.tile_bytes = 4096;
  return o;
}

struct DeepPack {
  std::string path;
  DeepMapBuild deep;
};

// A hairball of semi-transparent hair: opaque part (none) + deep map of level 4.
DeepPack build_hair_pack(const std::string& name) {
  const Scene s = make_procedural("procedural:hairball,count=12,segments=24,transmit=0.5");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=40,elevation=60"), s.bounds());
  DeepSampleOptions so;
  so.samples_per_side = 2;
  so.epsilon = 0.02;
  DeepPack p;
  p.deep = build_deep_tiles(DeepSampler(s, light), 4, 2, so, 4096);
  p.path = packtest::temp_path(name);
  MapBuildOptions o = small_options();
  o.before_finish = [&](PackWriter& w) { append_deep_map(w, p.deep, so.epsilon, so.samples_per_side); };
  build_map(opaque_part(s), light, o, p.path);
  return p;
}

TEST(DeepPack, DirectoryLayoutIsPinned) {
  DeepDirectory d = DeepDirectory::make(5, 2, 0.25f, 4);  // 8 x 8 tiles: 8 bitmap bytes
  d.set(1, 0);
  d.set(7, 7);
  const std::vector<uint8_t> b = d.serialize();
  ASSERT_EQ(b.size(), 32u + 8u);
  EXPECT_EQ(load_le<uint32_t>(b, 0), 0x444D5344u);  // "DSMD"
  EXPECT_EQ(load_le<uint32_t>(b, 4), 1u);
  EXPECT_EQ(load_le<uint32_t>(b, 8), 32u);
  EXPECT_EQ(load_le<uint32_t>(b, 12), 5u);
  EXPECT_EQ(load_le<uint32_t>(b, 16), 2u);
  EXPECT_EQ(load_le<uint32_t>(b, 20), 2u);
  EXPECT_EQ(load_le<float>(b, 24), 0.25f);
  EXPECT_EQ(load_le<uint32_t>(b, 28), 4u);
  EXPECT_EQ(b[32], 0x02);  // tile (1, 0): bit 1
  EXPECT_EQ(b[39], 0x80);  // tile (7, 7): bit 63
  EXPECT_EQ(d.tile_id(7, 7), kDeepTileIdBit | make_tile_id(3, 7, 7));
  EXPECT_EQ(kDeepDirectoryId, 0xFC00000000000000ull);
  const DeepDirectory r = DeepDirectory::parse(b, "t");
  EXPECT_TRUE(r.has(1, 0) && r.has(7, 7) && !r.has(0, 0));
  // Every truncation, a wrong count, a stray bit past the last tile: one clear error.
  for (size_t n = 0; n < b.size(); ++n) EXPECT_THROW(DeepDirectory::parse({b.data(), n}, "t"), FormatError) << n;
  std::vector<uint8_t> bad = b;
  store_le<uint32_t>(bad.data() + 20, 3);
  EXPECT_THROW(DeepDirectory::parse(bad, "t"), FormatError);
  DeepDirectory one = DeepDirectory::make(1, 0, 0.1f, 1);  // 4 tiles: the bitmap's top 4 bits unused
  one.set(0, 0);
  bad = one.serialize();
  bad[32] |= 0x10;
  EXPECT_THROW(DeepDirectory::parse(bad, "t"), FormatError);
  EXPECT_THROW(DeepDirectory::make(20, 2, 0.1f, 4), Error);  // 2^18 tiles a side
}

TEST(DeepPack, PackAnswersTheDeepMapAndVerifies) {
  const DeepPack p = build_hair_pack("deep_hair.pack");
  ASSERT_FALSE(p.deep.tiles.empty());
  auto pack = PackReader::open(p.path);
  EXPECT_TRUE(pack->header().flags & kFeatureDeepShadow);
  const DeepDirectory* dir = pack->deep_directory();
  ASSERT_NE(dir, nullptr);
  EXPECT_EQ(dir->level, 4u);
  EXPECT_EQ(dir->side_bits, 2u);
  EXPECT_EQ(dir->tile_count(), p.deep.tiles.size());
  EXPECT_EQ(pack->tiles().back().id, kDeepDirectoryId);
  pack->verify([&](std::span<const uint8_t> raw) { return open_encoded(pack->encoding(), raw); });
  EXPECT_NE(pack->summary().find("deep map: level 4"), std::string::npos) << pack->summary();

  // The pack's deep map answers like the tiles as built, at every texel centre and depth.
  DeepMap direct(4, 2);
  for (const DeepTileBytes& t : p.deep.tiles) direct.add_tile(t.tx, t.ty, t.bytes);
  const auto loaded = PackDeepMap::load(*pack);
  ASSERT_NE(loaded, nullptr);
  int partial = 0;
  for (uint32_t y = 0; y < 16; ++y)
    for (uint32_t x = 0; x < 16; ++x)
      for (float z : {0.0f, 0.3f, 0.5f, 0.7f, 1.0f}) {
        const double u = (x + 0.5) / 16, v = (y + 0.5) / 16;
        const auto a = loaded->map().transmittance(u, v, z), b = direct.transmittance(u, v, z);
        EXPECT_EQ(a, b);
        EXPECT_EQ(loaded->map().filtered(u, v, z, 0.1), direct.filtered(u, v, z, 0.1));
        partial += a[0] > 0.0f && a[0] < 1.0f;
      }
  EXPECT_GT(partial, 0);  // semi-transparent hair: partial transmittance somewhere
}

TEST(DeepPack, SceneWithoutPartialOccludersIsUnchanged) {
  const Scene s = make_procedural("procedural:boxes");
  ASSERT_FALSE(s.any_partial());
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  const std::string a = packtest::temp_path("deep_none_a.pack"), b = packtest::temp_path("deep_none_b.pack");
  MapBuildOptions o = small_options();
  build_map(s, light, o, a);
  DeepSampleOptions so;
  DeepMapBuild empty = build_deep_tiles(DeepSampler(s, light), 3, 1, so);
  EXPECT_TRUE(empty.tiles.empty());
  o.before_finish = [&](PackWriter& w) { append_deep_map(w, empty, 0.1, 1); };
  build_map(s, light, o, b);
  // Cells are appended in thread order, so two builds differ in journal offsets alone:
  // same size, header flags, params, skip grid and every tile's bytes (no deep record).
  auto pa = PackReader::open(a), pack = PackReader::open(b);
  EXPECT_EQ(pa->file_size(), pack->file_size());
  EXPECT_EQ(pa->header().flags, pack->header().flags);
  EXPECT_EQ(pa->params(), pack->params());
  EXPECT_TRUE(std::ranges::equal(pa->grid_bytes(), pack->grid_bytes()));
  ASSERT_EQ(pa->tiles().size(), pack->tiles().size());
  for (const TileIndexEntry& e : pa->tiles()) EXPECT_EQ(pa->read_raw(e.id), pack->read_raw(e.id));
  EXPECT_FALSE(pack->header().flags & kFeatureDeepShadow);
  EXPECT_EQ(pack->deep_directory(), nullptr);
  EXPECT_EQ(PackDeepMap::load(*pack), nullptr);
}

TEST(DeepPack, ReaderRefusesInconsistentDeepData) {
  const DeepPack p = build_hair_pack("deep_hostile.pack");
  const std::vector<uint8_t> good = file_bytes(p.path);
  auto refuses = [](std::vector<uint8_t> bytes, const char* why) {
    store_le<uint32_t>(bytes.data() + 252, crc32_of({bytes.data(), 252}));
    EXPECT_THROW(PackReader::open_memory(bytes, "hostile.pack"), FormatError) << why;
  };
  // The flag cleared while deep tiles remain; the flag on a pack with no directory.
  std::vector<uint8_t> b = good;
  store_le<uint32_t>(b.data() + 20, load_le<uint32_t>(b, 20) & ~uint32_t(kFeatureDeepShadow));
  refuses(b, "deep tiles without the feature");
  // Index entry kinds swapped to opaque on a deep id (the compact index rewritten, its
  // CRC fixed: tiles/PACK.md "Payloads only").
  const PackHeader h = PackHeader::parse({good.data(), 256}, "h");
  ASSERT_TRUE(h.flags & kFeaturePayloadsOnly);
  const std::vector<TileIndexEntry> entries = PackReader::open_memory(good, "good.pack")->tiles();
  auto with_index = [&](const std::vector<TileIndexEntry>& e) {
    std::vector<uint8_t> out(good.begin(), good.begin() + long(h.index_offset));
    const std::vector<uint8_t> index = serialize_compact_index(e, 6);
    out.insert(out.end(), index.begin(), index.end());
    store_le<uint32_t>(out.data() + 248, crc32_of(index));
    return out;
  };
  std::vector<TileIndexEntry> e = entries;
  e.back().kind = TileKind::encoded;
  refuses(with_index(e), "directory entry of kind encoded");
  // A deep tile the directory does not list (level 1, not D - b = 2; ids stay sorted).
  e = entries;
  e[e.size() - 2].id = kDeepTileIdBit | make_tile_id(1, 0, 0);
  b = with_index(e);
  refuses(b, "deep tile outside the directory");
}

TEST(DeepPack, WriterRefusesMisplacedDeepTiles) {
  const Scene s = make_procedural("procedural:boxes");
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
  MapBuildOptions o = small_options();
  const std::vector<uint8_t> raw(16, 1);
  // A directory without tiles, an opaque id of kind deep, a tile over tile_bytes.
  o.before_finish = [&](PackWriter& w) {
    EXPECT_THROW(w.append_deep_tile(make_tile_id(1, 0, 0), TileKind::deep, raw), Error);
    EXPECT_THROW(w.append_deep_tile(kDeepDirectoryId, TileKind::deep, raw), Error);
    EXPECT_THROW(w.append_deep_tile(kDeepTileIdBit, TileKind::deep, std::vector<uint8_t>(5000, 0)), Error);
    w.append_deep_tile(kDeepDirectoryId, TileKind::deep_directory, raw);
  };
  EXPECT_THROW(build_map(s, light, o, packtest::temp_path("deep_refused.pack")), Error);
}

}  // namespace deep_pack_test
}  // namespace st
