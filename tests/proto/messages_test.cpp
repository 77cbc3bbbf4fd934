// Message codecs (messages.hpp, PROTOCOL.md §4): round trips on seeded random content,
// truncation at every length, trailing bytes, invalid fields and limits.
#include <gtest/gtest.h>

#include "proto/byte_io.hpp"
#include "proto/proto.hpp"
#include "random_messages.hpp"

namespace st::proto {
namespace {

using test::Rng;
using Bytes = std::vector<std::uint8_t>;

Bytes payload_of(const Message& m, const Limits& limits = {}) {
  Bytes out;
  const Status s = std::visit([&](const auto& v) { return encode_payload(v, limits, out); }, m);
  EXPECT_TRUE(s) << to_string(s);
  return out;
}

Status decode_as(MessageType t, std::span<const std::uint8_t> payload, const Limits& limits,
                 Message& out) {
  Frame f;
  f.header.type = t;
  f.payload.assign(payload.begin(), payload.end());
  return decode_message(f, limits, out);
}

TEST(Messages, EveryMessageRoundTripsOnRandomContent) {
  Rng rng(2026);
  const Limits limits;
  for (const MessageType t : test::all_types()) {
    for (int i = 0; i < 200; ++i) {
      const Message m = test::random_message(rng, t, limits);
      ASSERT_EQ(type_of(m), t);
      const Bytes p = payload_of(m, limits);
      Message back;
      const Status s = decode_as(t, p, limits, back);
      ASSERT_TRUE(s) << to_string(t) << ": " << to_string(s);
      ASSERT_EQ(back, m) << to_string(t) << " round " << i;
      // and re-encoding gives the same bytes (one canonical encoding)
      EXPECT_EQ(payload_of(back, limits), p);
    }
  }
}

TEST(Messages, TruncationAtEveryLengthIsRejected) {
  Rng rng(31);
  const Limits limits;
  std::size_t cases = 0;
  for (const MessageType t : test::all_types()) {
    for (int i = 0; i < 5; ++i) {
      const Bytes p = payload_of(test::random_message(rng, t, limits), limits);
      for (std::size_t len = 0; len < p.size(); ++len) {
        Message back;
        const Status s = decode_as(t, {p.data(), len}, limits, back);
        ++cases;
        ASSERT_FALSE(s.ok()) << to_string(t) << " cut at " << len << " of " << p.size();
        // Cutting inside a length-prefixed field may leave a shorter but well-formed
        // prefix only if a count/length says so, which it does not: always truncated.
        EXPECT_EQ(s.code, ErrorCode::truncated) << to_string(t) << " " << s.detail;
      }
    }
  }
  EXPECT_GT(cases, 1000u);
}

TEST(Messages, TrailingBytesAreRejected) {
  Rng rng(32);
  const Limits limits;
  for (const MessageType t : test::all_types()) {
    Bytes p = payload_of(test::random_message(rng, t, limits), limits);
    p.push_back(0);
    Message back;
    const Status s = decode_as(t, p, limits, back);
    EXPECT_EQ(s.code, ErrorCode::trailing_bytes) << to_string(t) << " " << s.detail;
    EXPECT_NE(s.detail.find(std::string(to_string(t))), std::string::npos) << s.detail;
  }
}

TEST(Messages, RandomPayloadsNeverCrashTheDecoders) {
  Rng rng(33);
  const Limits limits;
  int accepted = 0;
  for (const MessageType t : test::all_types()) {
    for (int i = 0; i < 500; ++i) {
      // mutate a valid payload: flip bytes, so that counts and lengths lie
      Bytes p = payload_of(test::random_message(rng, t, limits), limits);
      for (int k = 0; k < 3 && !p.empty(); ++k) p[rng() % p.size()] = std::uint8_t(rng());
      Message back;
      if (decode_as(t, p, limits, back)) {
        ++accepted;
        // anything accepted re-encodes to the same bytes
        EXPECT_EQ(payload_of(back, limits), p) << to_string(t);
      }
    }
  }
  EXPECT_GT(accepted, 0);
}

Status decode_bytes(MessageType t, const Bytes& p, const Limits& limits = {}) {
  Message m;
  return decode_as(t, p, limits, m);
}

TEST(Messages, GetTilesEnforcesTheBatchLimitBeforeReadingTiles) {
  Limits limits;
  limits.max_tiles_per_batch = 4;
  GetTiles g;
  for (std::uint64_t i = 0; i < 5; ++i) g.tiles.push_back({i, 0});
  Bytes out;
  EXPECT_EQ(encode_payload(g, limits, out).code, ErrorCode::limit_exceeded);
  Limits wide;
  ASSERT_TRUE(encode_payload(g, wide, out));
  EXPECT_EQ(decode_bytes(MessageType::get_tiles, out, limits).code, ErrorCode::limit_exceeded);
  // A lying count with no tiles behind it: limit first, else truncated; never allocates.
  Bytes lie = {1, 0, 0, 0, 0xff, 0xff, 0, 0};
  EXPECT_EQ(decode_bytes(MessageType::get_tiles, lie, limits).code, ErrorCode::limit_exceeded);
  Limits ceiling;
  ceiling.max_tiles_per_batch = kMaxTilesPerBatchCeiling;
  lie[4] = 0x00;
  lie[5] = 0x10;  // 4096
  EXPECT_EQ(decode_bytes(MessageType::get_tiles, lie, ceiling).code, ErrorCode::truncated);
}

TEST(Messages, GetTilesRejectsEmptyBatchesDuplicatesAndMapZero) {
  GetTiles g;
  Bytes out;
  EXPECT_EQ(encode_payload(g, {}, out).code, ErrorCode::invalid_field);
  g.tiles = {{7, 1}, {8, 2}, {7, 3}};
  EXPECT_EQ(encode_payload(g, {}, out).code, ErrorCode::invalid_field);
  g.tiles.pop_back();
  g.map_id = 0;
  EXPECT_EQ(encode_payload(g, {}, out).code, ErrorCode::invalid_field);
  // The same on the decoding side: hand-made bytes with a duplicate.
  const Bytes dup = {1, 0, 0, 0, 2, 0, 0, 0, 9, 0, 0, 0, 0, 0, 0, 0, 1, 0,
                     9, 0, 0, 0, 0, 0, 0, 0, 2, 0};
  const Status s = decode_bytes(MessageType::get_tiles, dup);
  EXPECT_EQ(s.code, ErrorCode::invalid_field);
  EXPECT_NE(s.detail.find("tiles[1]"), std::string::npos) << s.detail;
}

TEST(Messages, ReservedFieldsMustBeZero) {
  Bytes p = payload_of(GetTiles{1, {{5, 5}}});
  p[6] = 1;  // reserved u16 after the count
  const Status s = decode_bytes(MessageType::get_tiles, p);
  EXPECT_EQ(s.code, ErrorCode::invalid_field);
  EXPECT_NE(s.detail.find("byte 6"), std::string::npos) << s.detail;
}

TEST(Messages, OpenMapRejectsPathLikeNamesOnBothSides) {
  for (const std::string& name :
       {std::string(), std::string(".."), std::string(".hidden"), std::string("../etc/passwd"),
        std::string("a/b"), std::string("/abs"), std::string("C:\\x"), std::string("-rf"),
        std::string("name with space"), std::string("tab\tname"), std::string("nul\0x", 5),
        std::string(kMaxMapNameBytes + 1, 'n')}) {
    Bytes out;
    EXPECT_EQ(encode_payload(OpenMap{name}, {}, out).code, ErrorCode::bad_map_name) << name;
    // decoder: hand-made payload
    const std::string& n = name;
    Bytes p = {static_cast<std::uint8_t>(n.size())};
    p.insert(p.end(), n.begin(), n.end());
    EXPECT_EQ(decode_bytes(MessageType::open_map, p).code, ErrorCode::bad_map_name) << name;
  }
  Bytes out;
  EXPECT_TRUE(encode_payload(OpenMap{"city_2048.v2-final"}, {}, out));
}

TEST(Messages, ErrorCodesZeroAndControlCharactersAreRejected) {
  Bytes out;
  EXPECT_EQ(encode_payload(ErrorMessage{ErrorCode::ok, "x"}, {}, out).code,
            ErrorCode::invalid_field);
  EXPECT_EQ(encode_payload(ErrorMessage{ErrorCode::internal, "two\nlines"}, {}, out).code,
            ErrorCode::invalid_field);
  EXPECT_EQ(encode_payload(ErrorMessage{ErrorCode::internal, "\x1b[31mred"}, {}, out).code,
            ErrorCode::invalid_field);
  EXPECT_EQ(
      encode_payload(ErrorMessage{ErrorCode::internal, std::string(kMaxErrorMessageBytes + 1, 'a')},
                     {}, out)
          .code,
      ErrorCode::invalid_field);
  // An unknown code from a newer peer is kept, not rejected.
  const Bytes p = {0x39, 0x30, 2, 0, 'h', 'i'};
  Message m;
  ASSERT_TRUE(decode_as(MessageType::error, p, {}, m));
  EXPECT_EQ(static_cast<int>(std::get<ErrorMessage>(m).code), 0x3039);
  EXPECT_EQ(to_string(std::get<ErrorMessage>(m).code), "unknown");
}

TEST(Messages, MakeErrorAlwaysEncodes) {
  static const char raw[] = "line1\nline2\x1b[0m\0tail";
  const std::string nasty = std::string(raw, sizeof raw - 1) + std::string(3000, 'x');
  const ErrorMessage e = make_error(ErrorCode::unknown_map, nasty);
  EXPECT_EQ(e.code, ErrorCode::unknown_map);
  EXPECT_EQ(e.message.size(), kMaxErrorMessageBytes);
  EXPECT_EQ(e.message.substr(0, 12), "line1?line2?");
  Bytes out;
  ASSERT_TRUE(encode_payload(e, {}, out));
  EXPECT_EQ(make_error(ErrorCode::ok, "x").code, ErrorCode::internal);
  // From a parser failure to the Error frame a server sends before closing.
  FrameParser p({});
  const Bytes junk = {'G', 'E', 'T'};
  p.feed(junk);
  const ErrorMessage from_status = make_error(p.status());
  EXPECT_EQ(from_status.code, ErrorCode::bad_magic);
  EXPECT_NE(from_status.message.find("magic byte 0"), std::string::npos) << from_status.message;
  Bytes frame;
  EXPECT_TRUE(encode_message(from_status, kNoRequest, 0, {}, frame));
}

TEST(Messages, HelloRejectsLimitsOutsideTheHardBounds) {
  Hello h;
  Bytes out;
  ASSERT_TRUE(encode_payload(h, {}, out));
  auto with = [](auto mutate) {
    Hello x;
    mutate(x);
    Bytes b;
    return encode_payload(x, {}, b).code;
  };
  EXPECT_EQ(with([](Hello& x) { x.min_version = 0; }), ErrorCode::invalid_field);
  EXPECT_EQ(with([](Hello& x) { x.min_version = 3, x.max_version = 2; }), ErrorCode::invalid_field);
  EXPECT_EQ(with([](Hello& x) { x.max_frame_bytes = kMinFrameBytes - 1; }), ErrorCode::invalid_field);
  EXPECT_EQ(with([](Hello& x) { x.max_frame_bytes = kMaxFrameBytesCeiling + 1; }),
            ErrorCode::invalid_field);
  EXPECT_EQ(with([](Hello& x) { x.max_in_flight = 0; }), ErrorCode::invalid_field);
  EXPECT_EQ(with([](Hello& x) { x.max_tiles_per_batch = kMaxTilesPerBatchCeiling + 1; }),
            ErrorCode::invalid_field);
  // Decoder side: patch max_frame_bytes (offset 4) of a valid payload to 1 GiB.
  Bytes p = out;
  p[4] = 0, p[5] = 0, p[6] = 0, p[7] = 0x40;
  EXPECT_EQ(decode_bytes(MessageType::hello, p).code, ErrorCode::invalid_field);
}

TEST(Messages, HelloAndHelloAckLayoutsArePinned) {
  Hello h;
  h.min_version = 1;
  h.max_version = 2;
  h.max_in_flight = 0x0102;
  h.max_frame_bytes = 0x00100000;
  h.max_tiles_per_batch = 0x0304;
  h.features = 0xa1b2c3d4;
  h.client_name = "cl";
  const Bytes p = payload_of(h);
  const Bytes expect = {1, 2, 0x02, 0x01, 0, 0, 0x10, 0, 0x04, 0x03, 0, 0,
                        0xd4, 0xc3, 0xb2, 0xa1, 2, 'c', 'l'};
  EXPECT_EQ(p, expect);
  HelloAck a;
  a.nonce[0] = 0xee;
  a.nonce[31] = 0xff;
  a.server_name = "s";
  const Bytes q = payload_of(a);
  ASSERT_EQ(q.size(), 16 + kNonceBytes + 1 + 1);
  EXPECT_EQ(q[16], 0xee);
  EXPECT_EQ(q[47], 0xff);
  EXPECT_EQ(q[48], 1);
  EXPECT_EQ(q[49], 's');
}

TEST(Messages, TileDataLayoutPrefixAndViewAgree) {
  Rng rng(8);
  const Limits limits;
  for (int i = 0; i < 50; ++i) {
    TileData t = std::get<TileData>(test::random_message(rng, MessageType::tile_data, limits));
    Bytes whole;
    ASSERT_TRUE(encode_message(t, 1000 + i, kFlagFinal, limits, whole));
    // Gathered write: prefix + the tile bytes untouched == the one-piece frame.
    std::array<std::uint8_t, kTileDataPrefixBytes> prefix;
    ASSERT_TRUE(encode_tile_data_prefix(t.meta, t.payload, 1000 + i, kFlagFinal, limits, prefix));
    Bytes gathered(prefix.begin(), prefix.end());
    gathered.insert(gathered.end(), t.payload.begin(), t.payload.end());
    ASSERT_EQ(gathered, whole);
    // Fixed fields at their offsets (PROTOCOL.md §4.8).
    const std::uint8_t* f = whole.data() + kHeaderSize;
    EXPECT_EQ(load_le<std::uint64_t>(f + 0), t.meta.tile_id);
    EXPECT_EQ(load_le<std::uint32_t>(f + 8), t.meta.map_id);
    EXPECT_EQ(load_le<std::uint16_t>(f + 12), t.meta.flags);
    EXPECT_EQ(load_le<std::uint32_t>(f + 16), t.meta.uncompressed_size);
    EXPECT_EQ(load_le<std::uint32_t>(f + 20), t.meta.payload_crc32);
    EXPECT_EQ(load_le<std::uint32_t>(f + 24), t.payload.size());
    // Zero-copy view decode.
    TileMeta meta;
    std::span<const std::uint8_t> bytes;
    ASSERT_TRUE(decode_tile_data_view({whole.data() + kHeaderSize, whole.size() - kHeaderSize},
                                      meta, bytes));
    EXPECT_EQ(meta, t.meta);
    EXPECT_EQ(bytes.data(), whole.data() + kHeaderSize + kTileMetaBytes);
    EXPECT_TRUE(tile_crc_matches(meta, bytes));
  }
}

TEST(Messages, TileCrcCatchesCorruptionTheFrameCrcCannotSee) {
  // A server that read a corrupt tile from disk frames it with a valid frame CRC; only
  // the pack's CRC (carried end to end) exposes it.
  TileData t;
  t.payload = {1, 2, 3, 4, 5};
  t.meta.payload_crc32 = crc32(t.payload);
  t.payload[2] ^= 0x10;
  Bytes f;
  ASSERT_TRUE(encode_message(t, 1, kFlagFinal, {}, f));
  FrameParser p({});
  ASSERT_EQ(p.feed(f).state, FrameParser::State::frame);
  Message m;
  ASSERT_TRUE(decode_message(p.take_frame(), {}, m));
  const auto& got = std::get<TileData>(m);
  EXPECT_FALSE(tile_crc_matches(got.meta, got.payload));
}

TEST(Messages, TilePrefixRefusesTilesThatCannotFitTheFrame) {
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  TileMeta meta;
  Bytes big(kMinFrameBytes, 1);
  std::array<std::uint8_t, kTileDataPrefixBytes> prefix;
  EXPECT_EQ(encode_tile_data_prefix(meta, big, 1, kFlagFinal, limits, prefix).code,
            ErrorCode::tile_too_large);
  meta.flags = 0;  // raw tile must state its own size
  meta.uncompressed_size = 3;
  Bytes small(4, 1);
  EXPECT_EQ(encode_tile_data_prefix(meta, small, 1, kFlagFinal, limits, prefix).code,
            ErrorCode::invalid_field);
}

// PROTOCOL.md §4.8: bit 0 zlib, bit 1 index tile, bits 2..15 reserved (refused both ways).
TEST(Messages, TileDataFlagsHaveTwoBitsAndTheRestIsReserved) {
  const Limits limits;
  TileData t;
  t.payload = {9, 8, 7};
  t.meta.uncompressed_size = 100;
  t.meta.payload_crc32 = crc32(t.payload);
  for (std::uint16_t flags : {0x0001, 0x0003}) {
    t.meta.flags = flags;
    Bytes f;
    ASSERT_TRUE(encode_message(t, 1, kFlagFinal, limits, f)) << flags;
    EXPECT_EQ(load_le<std::uint16_t>(f.data() + kHeaderSize + 12), flags);
    TileMeta meta;
    std::span<const std::uint8_t> bytes;
    ASSERT_TRUE(decode_tile_data_view({f.data() + kHeaderSize, f.size() - kHeaderSize}, meta, bytes));
    EXPECT_EQ(meta.flags, flags);
  }
  t.meta.flags = kTileFlagZlib;
  Bytes good;
  ASSERT_TRUE(encode_payload(t, limits, good));
  for (int bit = 2; bit < 16; ++bit) {
    t.meta.flags = std::uint16_t(kTileFlagZlib | (1u << bit));
    Bytes out;
    EXPECT_EQ(encode_payload(t, limits, out).code, ErrorCode::invalid_field) << bit;
    std::array<std::uint8_t, kTileDataPrefixBytes> prefix;
    EXPECT_EQ(encode_tile_data_prefix(t.meta, t.payload, 1, kFlagFinal, limits, prefix).code,
              ErrorCode::invalid_field)
        << bit;
    Bytes bad = good;
    store_le<std::uint16_t>(bad.data() + 12, t.meta.flags);
    TileData d;
    EXPECT_EQ(decode_payload(bad, limits, d).code, ErrorCode::invalid_field) << bit;
  }
}

// The server buffers client frames only up to max_client_frame_bytes (PROTOCOL.md §6): the
// largest message a client may legally send must fit it exactly, whatever the limits.
TEST(Messages, MaxClientFrameBytesFitsTheLargestClientMessage) {
  for (std::uint16_t in_flight : {1, 64, 1000, 4096})
    for (std::uint16_t batch : {1, 256, 4096})
      for (std::uint32_t frame : {kMinFrameBytes, 4u << 20, kMaxFrameBytesCeiling}) {
        Limits l;
        l.max_in_flight = in_flight;
        l.max_tiles_per_batch = batch;
        l.max_frame_bytes = frame;
        const std::uint32_t bound = max_client_frame_bytes(l);
        EXPECT_GE(bound, kMinFrameBytes);
        EXPECT_LE(bound, frame);
        Cancel c;
        for (std::uint32_t i = 1; i <= in_flight; ++i) c.request_ids.push_back(i);
        c.map_id = 1;
        const std::size_t tiles = std::min<std::size_t>(0xffff, std::size_t(in_flight) * batch);
        for (std::size_t i = 0; i < tiles; ++i) c.tile_ids.push_back(i);
        GetTiles g;
        for (std::uint16_t i = 0; i < batch; ++i) g.tiles.push_back({i, 0});
        std::size_t largest = 0;
        for (const Message& m : {Message(c), Message(g)}) {
          Bytes payload;
          ASSERT_TRUE(std::visit([&](const auto& v) { return encode_payload(v, l, payload); }, m));
          largest = std::max(largest, kHeaderSize + payload.size());
        }
        // Every legal client frame that the frame limit allows passes; none needs more.
        EXPECT_EQ(bound, std::min<std::size_t>(std::max<std::size_t>(largest, kMinFrameBytes), frame))
            << in_flight << " " << batch << " " << frame;
      }
}

TEST(Messages, CancelRules) {
  Bytes out;
  EXPECT_EQ(encode_payload(Cancel{}, {}, out).code, ErrorCode::invalid_field);
  EXPECT_EQ(encode_payload(Cancel{{0}, 0, {}}, {}, out).code, ErrorCode::invalid_field);
  EXPECT_EQ(encode_payload(Cancel{{}, 0, {5}}, {}, out).code, ErrorCode::invalid_field);
  EXPECT_EQ(encode_payload(Cancel{{1}, 3, {}}, {}, out).code, ErrorCode::invalid_field);
  EXPECT_TRUE(encode_payload(Cancel{{1, 2}, 3, {5, 6}}, {}, out));
  Limits limits;
  limits.max_in_flight = 2;
  EXPECT_EQ(encode_payload(Cancel{{1, 2, 3}, 0, {}}, limits, out).code, ErrorCode::limit_exceeded);
}

TEST(Messages, MapListAndStatsRules) {
  Bytes out;
  MapList dup;
  dup.maps = {MapEntry{"a"}, MapEntry{"a"}};
  EXPECT_EQ(encode_payload(dup, {}, out).code, ErrorCode::invalid_field);
  MapList bad_name;
  bad_name.maps = {MapEntry{"../a"}};
  EXPECT_EQ(encode_payload(bad_name, {}, out).code, ErrorCode::bad_map_name);
  MapList skip;
  skip.maps = {MapEntry{"a", 0, 10, 11}};
  EXPECT_EQ(encode_payload(skip, {}, out).code, ErrorCode::invalid_field);

  Stats st;
  st.histograms = {Histogram{"latency_us", {{10, 1}, {10, 2}}}};
  EXPECT_EQ(encode_payload(st, {}, out).code, ErrorCode::invalid_field);
  st.histograms = {Histogram{"latency_us", {}}};
  EXPECT_EQ(encode_payload(st, {}, out).code, ErrorCode::invalid_field);
  st.histograms = {Histogram{"latency_us", {{10, 1}, {100, 2}, {~0ull, 3}}}};
  st.counters = {{"tiles_sent", 5}, {"bytes_sent", 1 << 20}};
  ASSERT_TRUE(encode_payload(st, {}, out));
  Message m;
  ASSERT_TRUE(decode_as(MessageType::stats, out, {}, m));
  EXPECT_EQ(std::get<Stats>(m), st);
}

}  // namespace
}  // namespace st::proto
