// Pins the pack format (pack_format.hpp, tiles/PACK.md): every header, record and index
// field at its offset, and the parsers' refusals.
#include <gtest/gtest.h>

#include <cstring>

#include "tests/tiles/interval_fields.hpp"
#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_format.hpp"

namespace st {
namespace {

constexpr size_t kDefaultTileBytesForTest = 64 * 1024;

template <class T>
T at(const uint8_t* b, size_t off) {
  T v;
  std::memcpy(&v, b + off, sizeof(T));
  return v;
}

PackHeader sample_header() {
  PackHeader h;
  h.state = PackState::complete;
  h.flags = kFeatureExitDepths | kFeatureHasTiles;
  h.encoding = Encoding::dagmh;
  h.light_kind = LightKind::spot;
  h.map_level = 12;
  h.skip_level = 6;
  h.tile_bytes = 65536;
  h.scene_hash = 0x0102030405060708ull;
  for (size_t i = 0; i < 18; ++i) h.light[i] = 0.5 * double(i) - 3;
  h.params_offset = 256;
  h.params_size = 10;
  h.journal_offset = 266;
  h.grid_offset = 1000;
  h.grid_size = CutGrid::serialized_size(6) + kPreviewHeaderBytes;  // skip grid + an empty map preview
  h.index_offset = h.grid_offset + h.grid_size;
  h.tile_count = 3;
  h.params_crc = 0x11111111;
  h.grid_crc = 0x22222222;
  h.index_crc = 0x33333333;
  return h;
}

TEST(PackFormat, HeaderOffsetsArePinned) {
  PackHeader h = sample_header();
  auto b = h.serialize();
  const uint8_t* p = b.data();
  EXPECT_EQ(std::memcmp(p, "STPACK\r\n", 8), 0);
  EXPECT_EQ(at<uint32_t>(p, 8), 2u);  // version 2: the map preview follows the skip grid
  EXPECT_EQ(at<uint32_t>(p, 12), 256u);
  EXPECT_EQ(at<uint32_t>(p, 16), 1u);
  EXPECT_EQ(at<uint32_t>(p, 20), 3u);
  EXPECT_EQ(p[24], 2);
  EXPECT_EQ(p[25], 1);
  EXPECT_EQ(p[26], 12);
  EXPECT_EQ(p[27], 6);
  EXPECT_EQ(at<uint32_t>(p, 28), 65536u);
  EXPECT_EQ(at<uint64_t>(p, 32), 0x0102030405060708ull);
  EXPECT_EQ(at<double>(p, 40), -3.0);
  EXPECT_EQ(at<double>(p, 40 + 17 * 8), 5.5);
  EXPECT_EQ(at<uint64_t>(p, 184), 256u);
  EXPECT_EQ(at<uint64_t>(p, 192), 10u);
  EXPECT_EQ(at<uint64_t>(p, 200), 266u);
  EXPECT_EQ(at<uint64_t>(p, 208), 1000u);
  EXPECT_EQ(at<uint64_t>(p, 216), h.grid_size);
  EXPECT_EQ(at<uint64_t>(p, 224), h.index_offset);
  EXPECT_EQ(at<uint64_t>(p, 232), 3u);
  EXPECT_EQ(at<uint32_t>(p, 240), 0x11111111u);
  EXPECT_EQ(at<uint32_t>(p, 244), 0x22222222u);
  EXPECT_EQ(at<uint32_t>(p, 248), 0x33333333u);
  EXPECT_EQ(at<uint32_t>(p, 252), crc32_of(std::span(b).first(252)));
  PackHeader back = PackHeader::parse(b, "x.pack");
  EXPECT_EQ(back.serialize(), b);
  EXPECT_EQ(back.file_size(), h.index_offset + 96);
}

static_assert(kFeatureWidePlaneBlocks == 1u << 16 && kKnownFeatures == 0x1FFFF, "the feature bits are format constants");

TEST(PackFormat, HeaderRefusesEveryBadField) {
  auto good = sample_header().serialize();
  EXPECT_THROW(PackHeader::parse(std::span(good).first(255), "x.pack"), FormatError);
  // Any flipped bit breaks the CRC; fields re-signed with a valid CRC are checked too.
  for (size_t off = 0; off < good.size(); ++off) {
    auto bad = good;
    bad[off] ^= 0x40;
    EXPECT_THROW(PackHeader::parse(bad, "x.pack"), FormatError) << off;
  }
  auto resigned = [&](auto mutate) {
    PackHeader h = sample_header();
    mutate(h);
    return h.serialize();
  };
  std::vector<std::array<uint8_t, kPackHeaderBytes>> cases = {
      resigned([](PackHeader& h) { h.flags |= 1u << 10; }),
      // Mixed tiles (bit 9): DAG-MH packs only.
      resigned([](PackHeader& h) { h.flags |= kFeatureMixedTiles, h.encoding = Encoding::mmh; }),
      // Packed plane tiles (bit 13): only with plane_tiles (bit 11).
      resigned([](PackHeader& h) { h.flags |= kFeaturePackedPlaneTiles; }),
      // Predicted plane labels (bit 14): only with packed_plane_tiles (bit 13).
      resigned([](PackHeader& h) { h.flags |= kFeaturePredictedPlaneLabels | kFeaturePlaneTiles; }),
      // Wide plane blocks (bit 16, version 3 plane tiles): only with plane_tiles; bit 17 is unknown.
      resigned([](PackHeader& h) { h.flags |= kFeatureWidePlaneBlocks; }),
      resigned([](PackHeader& h) { h.flags |= 1u << 17; }),
      resigned([](PackHeader& h) { h.map_level = 21; }),
      resigned([](PackHeader& h) { h.skip_level = 11; }),
      resigned([](PackHeader& h) { h.tile_bytes = 0; }),
      resigned([](PackHeader& h) { h.params_offset = 300; }),
      resigned([](PackHeader& h) { h.journal_offset = 300; }),
      resigned([](PackHeader& h) { h.grid_offset = 1001; }),
      resigned([](PackHeader& h) { h.grid_size += 8; }),
      resigned([](PackHeader& h) { h.grid_size -= 1, h.index_offset -= 1; }),  // no room for the map preview
      resigned([](PackHeader& h) { h.grid_size += kMaxPreviewBytes, h.index_offset += kMaxPreviewBytes; }),
      resigned([](PackHeader& h) { h.index_offset += 8; }),
      resigned([](PackHeader& h) { h.tile_count = ~uint64_t(0) / 2; }),
      resigned([](PackHeader& h) { h.tile_count = 0; }),  // has_tiles flag disagrees
      // The DAG-MH dictionary (bit 6): on DAG-MH packs only, and its section needs room.
      resigned([](PackHeader& h) { h.flags |= kFeatureDagmhDictionary; }),
      resigned([](PackHeader& h) { h.flags |= kFeatureDagmhDictionary, h.encoding = Encoding::mmh, h.grid_size += 64, h.index_offset += 64; }),
      // A ground-frame light (kind 2) belongs to stack packs only; kind 9 is unknown.
      resigned([](PackHeader& h) { h.light_kind = LightKind::sun_ground; }),
      resigned([](PackHeader& h) { h.light_kind = LightKind(9); }),
  };
  {  // with room for a section, the bit is accepted on a DAG-MH pack
    PackHeader h = sample_header();
    h.flags |= kFeatureDagmhDictionary;
    h.grid_size += 64, h.index_offset += 64;
    EXPECT_EQ(PackHeader::parse(h.serialize(), "x.pack").flags, h.flags);
    EXPECT_EQ(load_le<uint32_t>(h.serialize().data() + 20), 0x43u);  // exit_depths | has_tiles | bit 6
  }
  {  // mixed tiles (bit 9) are accepted on a DAG-MH pack
    PackHeader h = sample_header();
    h.flags |= kFeatureMixedTiles;
    EXPECT_EQ(uint32_t(kFeatureMixedTiles), 0x200u);  // format constant
    EXPECT_EQ(PackHeader::parse(h.serialize(), "x.pack").flags, h.flags);
  }
  for (size_t i = 0; i < cases.size(); ++i) {
    try {
      PackHeader::parse(cases[i], "x.pack");
      ADD_FAILURE() << "case " << i << " accepted";
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("x.pack: header:"), std::string::npos) << e.what();
    }
  }
  // Encoding 3 (vsdag) is known; the first unknown tag is refused with a message naming it.
  auto enc = good;
  enc[24] = 3;
  uint32_t crc = crc32_of(std::span(enc).first(252));
  std::memcpy(&enc[252], &crc, 4);
  EXPECT_EQ(PackHeader::parse(enc, "x.pack").encoding, Encoding::vsdag);
  enc[24] = 4;
  crc = crc32_of(std::span(enc).first(252));
  std::memcpy(&enc[252], &crc, 4);
  try {
    PackHeader::parse(enc, "x.pack");
    ADD_FAILURE() << "encoding 4 accepted";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown encoding 4"), std::string::npos) << e.what();
  }
}

TEST(PackFormat, RecordOffsetsArePinnedAndTornRecordsRefused) {
  TileRecord t{TileKind::index, make_tile_id(7, 100, 3), 1234, 5678, 0xdeadbeef};
  auto tb = t.serialize();
  EXPECT_EQ(at<uint32_t>(tb.data(), 0), kTileRecordMagic);
  EXPECT_EQ(std::memcmp(tb.data(), "TREC", 4), 0);
  EXPECT_EQ(tb[4], 2);
  EXPECT_EQ(at<uint64_t>(tb.data(), 8), t.id);
  EXPECT_EQ(at<uint32_t>(tb.data(), 16), 1234u);
  EXPECT_EQ(at<uint32_t>(tb.data(), 20), 5678u);
  EXPECT_EQ(at<uint32_t>(tb.data(), 24), 0xdeadbeefu);
  EXPECT_EQ(at<uint32_t>(tb.data(), 28), crc32_of(std::span(tb).first(28)));
  CellRecord c{3, 4, GridEntry{0.75f, EntryKind::index, 2}, 0.5f, 1.0f};
  auto cb = c.serialize();
  EXPECT_EQ(std::memcmp(cb.data(), "CREC", 4), 0);
  EXPECT_EQ(cb[4], 2);
  EXPECT_EQ(cb[5], 2);
  EXPECT_EQ(at<uint32_t>(cb.data(), 8), 3u);
  EXPECT_EQ(at<uint32_t>(cb.data(), 12), 4u);
  EXPECT_EQ(at<float>(cb.data(), 16), 0.75f);
  EXPECT_EQ(at<float>(cb.data(), 20), 0.5f);
  EXPECT_EQ(at<float>(cb.data(), 24), 1.0f);
  TileRecord t2;
  CellRecord c2;
  ASSERT_EQ(parse_record(tb, &t2, &c2), RecordType::tile);
  EXPECT_EQ(t2.serialize(), tb);
  ASSERT_EQ(parse_record(cb, &t2, &c2), RecordType::cell);
  EXPECT_EQ(c2.serialize(), cb);
  for (size_t off = 0; off < kRecordBytes; ++off) {
    auto bad = tb;
    bad[off] ^= 1;
    EXPECT_EQ(parse_record(bad, &t2, &c2), RecordType::none) << off;
    bad = cb;
    bad[off] ^= 1;
    EXPECT_EQ(parse_record(bad, &t2, &c2), RecordType::none) << off;
  }
}

TEST(PackFormat, PayloadsOnlyIndexMustTileTheJournal) {
  // Feature payloads_only: payloads back to back from the journal's start in index
  // order, ending less than 8 bytes (the padding) before the grid.
  std::vector<TileIndexEntry> e = {{make_tile_id(2, 1, 1), 300, 10, 20, 1, TileKind::encoded},
                                   {make_tile_id(3, 0, 0), 310, 30, 40, 2, TileKind::index}};
  EXPECT_EQ(parse_index(serialize_index(e), 9000, 300, 340, 65536, "x.pack", true).size(), 2u);
  EXPECT_EQ(parse_index(serialize_index(e), 9000, 300, 347, 65536, "x.pack", true).size(), 2u);
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 348, 65536, "x.pack", true), FormatError);  // a gap at the end
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 340, 65536, "x.pack"), FormatError);  // no room for records
  e[1].offset = 311;  // a gap between
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 341, 65536, "x.pack", true), FormatError);
  e[1].offset = 305;  // overlapping
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 340, 65536, "x.pack", true), FormatError);
  e[0].offset = 301, e[1].offset = 311;  // not at the journal's start
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 341, 65536, "x.pack", true), FormatError);

  // The compact index: "STIZ", the stream's size, a zlib stream of the 21-byte columns;
  // offsets implied. Round trip, then hostile sections.
  e[0].offset = 300, e[1].offset = 310;
  const std::vector<uint8_t> c = serialize_compact_index(e, 6);
  EXPECT_EQ(at<uint32_t>(c.data(), 0), kCompactIndexMagic);
  EXPECT_EQ(std::memcmp(c.data(), "STIZ", 4), 0);
  EXPECT_EQ(at<uint32_t>(c.data(), 4), c.size() - 8);
  const std::vector<uint8_t> cols = zlib_decompress({c.data() + 8, c.size() - 8}, 42, "cols");
  EXPECT_EQ(at<uint64_t>(cols.data(), 8), e[1].id - e[0].id);  // ids as deltas
  EXPECT_EQ(at<uint32_t>(cols.data(), 16 + 4), 30u);             // stored sizes
  EXPECT_EQ(at<uint32_t>(cols.data(), 24 + 4), 40u);             // raw sizes
  EXPECT_EQ(at<uint32_t>(cols.data(), 32 + 4), 2u);              // CRCs
  EXPECT_EQ(cols[41], 2);                                        // kinds
  const auto back = parse_compact_index(c, 2, 9000, 300, 340, 65536, "x.pack");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(serialize_index(back), serialize_index(e));
  EXPECT_THROW(parse_compact_index(c, 3, 9000, 300, 340, 65536, "x.pack"), FormatError);  // another count
  EXPECT_THROW(parse_compact_index(c, 2, 9000, 300, 360, 65536, "x.pack"), FormatError);  // payloads short of the grid
  std::vector<uint8_t> bad = c;
  bad.push_back(0);  // a byte past the stream
  EXPECT_THROW(parse_compact_index(bad, 2, 9000, 300, 340, 65536, "x.pack"), FormatError);
  bad = c;
  bad[0] ^= 1;
  EXPECT_THROW(parse_compact_index(bad, 2, 9000, 300, 340, 65536, "x.pack"), FormatError);
  EXPECT_THROW(parse_compact_index({c.data(), 7}, 2, 9000, 300, 340, 65536, "x.pack"), FormatError);
  EXPECT_THROW(parse_compact_index(c, uint64_t(1) << 40, 9000, 300, 340, 65536, "x.pack"), FormatError);
}

TEST(PackFormat, IndexOffsetsArePinnedAndEntriesChecked) {
  std::vector<TileIndexEntry> e = {{make_tile_id(2, 1, 1), 400, 10, 20, 0xabcdef01, TileKind::encoded},
                                   {make_tile_id(3, 0, 0), 500, 30, 40, 7, TileKind::index}};
  std::vector<uint8_t> b = serialize_index(e);
  ASSERT_EQ(b.size(), 64u);
  EXPECT_EQ(at<uint64_t>(b.data(), 32 + 0), e[1].id);
  EXPECT_EQ(at<uint64_t>(b.data(), 32 + 8), 500u);
  EXPECT_EQ(at<uint32_t>(b.data(), 32 + 16), 30u);
  EXPECT_EQ(at<uint32_t>(b.data(), 32 + 20), 40u);
  EXPECT_EQ(at<uint32_t>(b.data(), 32 + 24), 7u);
  EXPECT_EQ(b[32 + 28], 2);
  auto back = parse_index(b, 9000, 300, 600, 65536, "x.pack");
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].crc, 0xabcdef01u);
  EXPECT_THROW(parse_index(b, 9000, 300, 520, 65536, "x.pack"), FormatError);  // payload past the journal
  EXPECT_THROW(parse_index(b, 9000, 450, 600, 65536, "x.pack"), FormatError);  // payload before it
  EXPECT_THROW(parse_index(b, 9000, 300, 600, 39, "x.pack"), FormatError);      // raw > tile_bytes
  std::swap(e[0], e[1]);
  EXPECT_THROW(parse_index(serialize_index(e), 9000, 300, 600, 65536, "x.pack"), FormatError);  // unsorted
  try {
    auto bad = b;
    bad[32 + 29] = 1;
    parse_index(bad, 9000, 300, 600, 65536, "x.pack");
    ADD_FAILURE();
  } catch (const FormatError& err) {
    EXPECT_NE(std::string(err.what()).find("entry 1"), std::string::npos) << err.what();
    EXPECT_NE(std::string(err.what()).find("at byte 9061"), std::string::npos) << err.what();
  }
}

TEST(PackFormat, ParamsAndZlib) {
  PackParamList p = {{"zeta", "1"}, {"alpha", "a=b c"}};
  std::vector<uint8_t> b = serialize_params(p);
  EXPECT_EQ(std::string(b.begin(), b.end()), "alpha=a=b c\nzeta=1\n");
  PackParamList want = {{"alpha", "a=b c"}, {"zeta", "1"}};
  EXPECT_EQ(parse_params(b, "x"), want);
  EXPECT_THROW(serialize_params({{"Bad Key", "1"}}), Error);
  EXPECT_THROW(serialize_params({{"k", "a\nb"}}), Error);
  EXPECT_THROW(serialize_params({{"k", "1"}, {"k", "2"}}), Error);
  std::vector<uint8_t> unterminated(b.begin(), b.end() - 1);
  EXPECT_THROW(parse_params(unterminated, "x"), FormatError);

  fields::Rng rng(2);
  std::vector<uint8_t> raw(5000);
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = uint8_t(i % 7 == 0 ? rng.next() : i / 64);
  std::vector<uint8_t> z = zlib_compress(raw, 6);
  EXPECT_LT(z.size(), raw.size());
  EXPECT_EQ(zlib_decompress(z, uint32_t(raw.size()), "t"), raw);
  EXPECT_THROW(zlib_decompress(z, uint32_t(raw.size()) - 1, "t"), FormatError);
  EXPECT_THROW(zlib_decompress(z, uint32_t(raw.size()) + 1, "t"), FormatError);
  std::vector<uint8_t> trailing = z;
  trailing.push_back(0);
  EXPECT_THROW(zlib_decompress(trailing, uint32_t(raw.size()), "t"), FormatError);
  // Incompressible tiles stay within the bound readers accept, at every level.
  std::vector<uint8_t> noise(kDefaultTileBytesForTest);
  for (auto& v : noise) v = uint8_t(rng.next());
  for (int level : {0, 1, 6, 12}) {
    std::vector<uint8_t> zn = zlib_compress(noise, level);
    EXPECT_LE(zn.size(), max_stored_size(noise.size())) << level;
    EXPECT_EQ(zlib_decompress(zn, uint32_t(noise.size()), "t"), noise);
  }
  for (size_t n = 0; n < z.size(); n += 13)
    EXPECT_THROW(zlib_decompress(std::span(z).first(n), uint32_t(raw.size()), "t"), FormatError) << n;
}

}  // namespace
}  // namespace st
