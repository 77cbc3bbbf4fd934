// The TileData prefix from a known tile CRC equals the one computed over the bytes, and
// crc32_combine equals the CRC of the concatenation, for random lengths and contents.
#include <gtest/gtest.h>

#include <random>

#include "proto/frame.hpp"
#include "proto/tile_prefix.hpp"

namespace st::proto {
namespace {

std::vector<uint8_t> random_bytes(std::mt19937_64& rng, size_t n) {
  std::vector<uint8_t> b(n);
  for (auto& x : b) x = uint8_t(rng());
  return b;
}

TEST(TilePrefix, Crc32CombineEqualsTheCrcOfTheConcatenation) {
  std::mt19937_64 rng(11);
  for (int i = 0; i < 300; ++i) {
    const size_t la = rng() % 100, lb = i < 5 ? size_t(i) : rng() % (i % 10 == 0 ? 70000 : 3000);
    const auto a = random_bytes(rng, la), b = random_bytes(rng, lb);
    std::vector<uint8_t> ab = a;
    ab.insert(ab.end(), b.begin(), b.end());
    ASSERT_EQ(crc32_combine(crc32(a), crc32(b), b.size()), crc32(ab)) << la << " + " << lb;
  }
}

TEST(TilePrefix, KnownCrcGivesTheSameBytesAndFailures) {
  std::mt19937_64 rng(12);
  Limits limits;
  for (int i = 0; i < 200; ++i) {
    const auto tile = random_bytes(rng, 1 + rng() % 5000);
    TileMeta m;
    m.tile_id = rng() >> 20;
    m.map_id = 1 + uint32_t(rng() % 64);
    m.uncompressed_size = uint32_t(tile.size() * 3);
    m.payload_crc32 = crc32(tile);
    const uint8_t flags = i % 2 ? kFlagFinal : 0;
    std::array<uint8_t, kTileDataPrefixBytes> want{}, got{};
    const Status sw = encode_tile_data_prefix(m, tile, uint32_t(i + 1), flags, limits, want);
    const Status sg = encode_tile_data_prefix(m, uint32_t(tile.size()), crc32(tile), uint32_t(i + 1), flags, limits, got);
    ASSERT_EQ(bool(sw), bool(sg));
    ASSERT_EQ(want, got);
  }
  Limits small;
  small.max_frame_bytes = kMinFrameBytes;
  TileMeta m;
  m.uncompressed_size = 1u << 20;
  std::array<uint8_t, kTileDataPrefixBytes> out{};
  const Status s = encode_tile_data_prefix(m, uint32_t(kMinFrameBytes), 0, 1, 0, small, out);
  EXPECT_EQ(s.code, ErrorCode::tile_too_large);
  EXPECT_EQ(encode_tile_data_prefix(m, 10, 0, 1, 0x80, limits, out).code, ErrorCode::bad_flags);
}

}  // namespace
}  // namespace st::proto
