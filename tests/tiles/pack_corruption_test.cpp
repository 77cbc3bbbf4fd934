// Hostile packs (pack_reader.hpp): every truncation and every flipped byte of a small
// pack gives a clear st::FormatError (never a crash, another exception or silent
// garbage); corrupt tiles are named by id and byte offset.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"

namespace st {
namespace {

struct Small {
  Encoding encoding;
  Hierarchy h;
  std::vector<uint8_t> bytes;
  std::vector<float> answers;  // of the intact pack, every level
};

Small small_pack(Encoding e) {
  Small s{e, build_hierarchy(fields::city_field(32, 4)), {}, {}};
  CutParams cut;
  cut.map_level = 5;
  cut.skip_level = 2;
  cut.tile_bytes = 128;  // index tiles too
  cut.codec = TileCodec::of(e);
  PackParams pp = PackParams::from(LightSpace::fit(LightSpec::parse("sun:azimuth=0,elevation=45"),
                                                   Aabb{{0, 0, 0}, {1, 1, 1}}),
                                   cut);
  pp.build_params = {{"scene", "small"}};
  std::string path = packtest::temp_path("small.pack");
  write_pack(path, s.h, cut, pp);
  std::ifstream f(path, std::ios::binary);
  s.bytes.assign(std::istreambuf_iterator<char>(f), {});
  s.answers = packtest::all_answers(PackEvaluator(PackReader::open_memory(s.bytes, "small.pack")));
  return s;
}

// Opens, verifies and evaluates every texel; returns the FormatError message or "".
std::string open_verify_eval(const Small& s, std::vector<uint8_t> bytes) {
  try {
    auto reader = std::shared_ptr<PackReader>(PackReader::open_memory(std::move(bytes), "small.pack"));
    reader->verify(TileCodec::of(s.encoding).open);
    PackEvaluator ev(reader, 4);
    std::string diff = packtest::first_difference(ev, s.answers);
    return diff.empty() ? "" : "SILENT GARBAGE: " + diff;
  } catch (const FormatError& e) {
    return e.what();
  }
}

TEST(PackCorruption, EveryTruncationIsAFormatError) {
  for (Encoding e : packtest::available_encodings()) {
    Small s = small_pack(e);
    ASSERT_EQ(open_verify_eval(s, s.bytes), "");
    const size_t step = fields::small_test_scale() ? 5 : 1;
    for (size_t n = 0; n < s.bytes.size(); n += step) {
      std::string msg = open_verify_eval(s, std::vector<uint8_t>(s.bytes.begin(), s.bytes.begin() + n));
      ASSERT_NE(msg, "") << "prefix of " << n << " bytes accepted";
      ASSERT_EQ(msg.find("SILENT"), std::string::npos) << msg;
      ASSERT_NE(msg.find("small.pack"), std::string::npos) << msg;
    }
    std::vector<uint8_t> longer = s.bytes;
    longer.push_back(0);
    EXPECT_NE(open_verify_eval(s, longer).find("trailing"), std::string::npos);
  }
}

TEST(PackCorruption, EveryFlippedByteIsAFormatErrorNamingTheTile) {
  for (Encoding e : packtest::available_encodings()) {
    Small s = small_pack(e);
    auto reader = PackReader::open_memory(s.bytes, "small.pack");
    ASSERT_FALSE(reader->tiles().empty());
    auto in_payload = [&](size_t off) -> const TileIndexEntry* {
      for (const TileIndexEntry& t : reader->tiles())
        if (off >= t.offset && off < t.offset + t.stored_size) return &t;
      return nullptr;
    };
    const size_t step = fields::small_test_scale() ? 3 : 1;
    for (size_t off = 0; off < s.bytes.size(); off += step) {
      std::vector<uint8_t> bad = s.bytes;
      bad[off] ^= uint8_t(1u << (off % 8));
      std::string msg = open_verify_eval(s, bad);
      ASSERT_NE(msg, "") << "flip at byte " << off << " accepted";
      ASSERT_EQ(msg.find("SILENT"), std::string::npos) << "flip at byte " << off << ": " << msg;
      if (const TileIndexEntry* t = in_payload(off)) {
        ASSERT_NE(msg.find(describe_tile(t->id)), std::string::npos) << msg;
        ASSERT_NE(msg.find("at byte " + std::to_string(t->offset)), std::string::npos) << msg;
      }
    }
  }
}

// Without verify(), a lookup that reaches a corrupt tile throws naming it; lookups that
// do not reach it keep answering.
TEST(PackCorruption, LookupsNameTheCorruptTile) {
  for (Encoding e : packtest::available_encodings()) {
    Small s = small_pack(e);
    auto clean = PackReader::open_memory(s.bytes, "small.pack");
    const TileIndexEntry victim = clean->tiles().back();
    std::vector<uint8_t> bad = s.bytes;
    bad[victim.offset + victim.stored_size / 2] ^= 0x10;
    auto reader = std::shared_ptr<PackReader>(PackReader::open_memory(bad, "small.pack"));
    PackEvaluator ev(reader);
    TileAddress a = tile_address(victim.id);
    try {
      ev.depth(5, uint64_t(a.x) << (5 - a.level), uint64_t(a.y) << (5 - a.level));
      ADD_FAILURE() << "corrupt tile answered";
    } catch (const FormatError& err) {
      EXPECT_NE(std::string(err.what()).find(describe_tile(victim.id)), std::string::npos) << err.what();
      EXPECT_NE(std::string(err.what()).find("CRC32 mismatch"), std::string::npos) << err.what();
    }
    EXPECT_EQ(packtest::bits(ev.depth(0, 0, 0)), packtest::bits(s.h.depth_at(0, 0, 0)));
  }
}

TEST(PackCorruption, FilesOnDiskTruncatedOrMissing) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  Small s = small_pack(encodings[0]);
  std::string path = packtest::temp_path("truncated.pack");
  {
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(s.bytes.data()), std::streamsize(s.bytes.size() - 40));
  }
  try {
    PackReader::open(path);
    ADD_FAILURE() << "truncated file opened";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  EXPECT_THROW(PackReader::open(path + ".missing"), Error);
  EXPECT_THROW(PackReader::open(SHADOWTILE_TEST_TMP), Error);  // a directory
}

}  // namespace
}  // namespace st
