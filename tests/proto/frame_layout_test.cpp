// Pins the frame header layout (wire_format.hpp, PROTOCOL.md §2) byte by byte, and the
// example dump printed in PROTOCOL.md §9.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "proto/proto.hpp"

namespace st::proto {
namespace frame_layout_test {

std::string hex(std::span<const std::uint8_t> b) {
  std::string s;
  char buf[4];
  for (std::size_t i = 0; i < b.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%02x", b[i]);
    if (i) s += (i % 16 == 0) ? "\n" : " ";
    s += buf;
  }
  return s;
}

TEST(FrameLayout, EveryHeaderFieldSitsAtItsDocumentedOffset) {
  EXPECT_EQ(kHeaderSize, 24u);
  EXPECT_EQ(kOffMagic, 0u);
  EXPECT_EQ(kOffVersion, 4u);
  EXPECT_EQ(kOffFlags, 5u);
  EXPECT_EQ(kOffType, 6u);
  EXPECT_EQ(kOffRequestId, 8u);
  EXPECT_EQ(kOffPayloadLength, 12u);
  EXPECT_EQ(kOffPayloadCrc, 16u);
  EXPECT_EQ(kOffHeaderCrc, 20u);

  FrameHeader h;
  h.version = 0x01;
  h.flags = kFlagFinal;
  h.type = static_cast<MessageType>(0x0a0b);
  h.request_id = 0x11223344;
  h.payload_length = 0x55667788;
  h.payload_crc32 = 0x99aabbcc;
  std::array<std::uint8_t, kHeaderSize> b{};
  write_header(h, b);
  const std::uint8_t expect[20] = {'S',  'T',  'W',  'P',  0x01, 0x01, 0x0b, 0x0a, 0x44, 0x33,
                                   0x22, 0x11, 0x88, 0x77, 0x66, 0x55, 0xcc, 0xbb, 0xaa, 0x99};
  for (std::size_t i = 0; i < 20; ++i) EXPECT_EQ(b[i], expect[i]) << "byte " << i;
  const std::uint32_t crc = crc32(std::span<const std::uint8_t>(b.data(), 20));
  EXPECT_EQ(b[20], crc & 0xff);
  EXPECT_EQ(b[21], (crc >> 8) & 0xff);
  EXPECT_EQ(b[22], (crc >> 16) & 0xff);
  EXPECT_EQ(b[23], crc >> 24);
}

TEST(FrameLayout, Crc32IsTheIsoHdlcPolynomial) {
  // The standard check value of CRC-32/ISO-HDLC (zlib, PNG): crc("123456789").
  const std::string s = "123456789";
  EXPECT_EQ(crc32({reinterpret_cast<const std::uint8_t*>(s.data()), s.size()}), 0xCBF43926u);
  EXPECT_EQ(crc32({}), 0u);
}

TEST(FrameLayout, TypeAndErrorCodeValuesAreFrozen) {
  EXPECT_EQ(static_cast<int>(MessageType::hello), 0x0001);
  EXPECT_EQ(static_cast<int>(MessageType::hello_ack), 0x0002);
  EXPECT_EQ(static_cast<int>(MessageType::error), 0x0003);
  EXPECT_EQ(static_cast<int>(MessageType::list_maps), 0x0010);
  EXPECT_EQ(static_cast<int>(MessageType::map_list), 0x0011);
  EXPECT_EQ(static_cast<int>(MessageType::open_map), 0x0012);
  EXPECT_EQ(static_cast<int>(MessageType::map_info), 0x0013);
  EXPECT_EQ(static_cast<int>(MessageType::get_tiles), 0x0020);
  EXPECT_EQ(static_cast<int>(MessageType::tile_data), 0x0021);
  EXPECT_EQ(static_cast<int>(MessageType::tile_error), 0x0022);
  EXPECT_EQ(static_cast<int>(MessageType::cancel), 0x0023);
  EXPECT_EQ(static_cast<int>(MessageType::ping), 0x0030);
  EXPECT_EQ(static_cast<int>(MessageType::pong), 0x0031);
  EXPECT_EQ(static_cast<int>(MessageType::get_stats), 0x0040);
  EXPECT_EQ(static_cast<int>(MessageType::stats), 0x0041);
  EXPECT_EQ(static_cast<int>(MessageType::auth), 0x0050);
  EXPECT_EQ(static_cast<int>(MessageType::auth_ok), 0x0051);
  EXPECT_EQ(kFeatureAuth, 1u);
  EXPECT_EQ(kFeatureTileKind, 2u);
  EXPECT_EQ(kTileFlagZlib, 1u);   // TileData flags (offset 12 of the payload)
  EXPECT_EQ(kTileFlagIndex, 2u);
  EXPECT_EQ(kKnownTileFlags, 3u);
  EXPECT_EQ(static_cast<int>(ErrorCode::bad_magic), 1);
  EXPECT_EQ(static_cast<int>(ErrorCode::payload_checksum), 4);
  EXPECT_EQ(static_cast<int>(ErrorCode::cancelled), 20);
  EXPECT_EQ(static_cast<int>(ErrorCode::handshake_required), 25);
  EXPECT_EQ(static_cast<int>(ErrorCode::auth_required), 26);
  EXPECT_EQ(static_cast<int>(ErrorCode::auth_failed), 27);
  int known = 0;
  for (unsigned t = 0; t <= 0xffff; ++t) known += is_known_type(static_cast<std::uint16_t>(t));
  EXPECT_EQ(known, 17);
  for (int c = 0; c <= 27; ++c) EXPECT_NE(to_string(static_cast<ErrorCode>(c)), "unknown") << c;
}

// The dumps in PROTOCOL.md §9 are these frames; if this test changes, update the spec.
TEST(FrameLayout, ExampleDumpsOfTheSpec) {
  const Limits limits;
  std::vector<std::uint8_t> ping;
  ASSERT_TRUE(encode_message(Ping{0x0102030405060708ull}, 7, 0, limits, ping));
  EXPECT_EQ(hex(ping),
            "53 54 57 50 01 00 30 00 07 00 00 00 08 00 00 00\n"
            "25 ed cc a5 e4 29 91 a8 08 07 06 05 04 03 02 01");

  std::vector<std::uint8_t> open;
  ASSERT_TRUE(encode_message(OpenMap{"city"}, 2, 0, limits, open));
  EXPECT_EQ(hex(open),
            "53 54 57 50 01 00 12 00 02 00 00 00 05 00 00 00\n"
            "f5 8c bd 3f 33 dd 82 ce 04 63 69 74 79");

  std::vector<std::uint8_t> tiles;
  GetTiles g;
  g.map_id = 1;
  g.tiles = {{0x2a, 5}, {0x2b, 1}};
  ASSERT_TRUE(encode_message(g, 3, 0, limits, tiles));
  EXPECT_EQ(hex(tiles),
            "53 54 57 50 01 00 20 00 03 00 00 00 1c 00 00 00\n"
            "b8 08 12 23 90 f4 b7 ce 01 00 00 00 02 00 00 00\n"
            "2a 00 00 00 00 00 00 00 05 00 2b 00 00 00 00 00\n"
            "00 00 01 00");
}

}  // namespace frame_layout_test
}  // namespace st::proto
