// The incremental FrameParser (frame.hpp, PROTOCOL.md §3) on hostile and chunked input.
#include <gtest/gtest.h>

#include <random>

#include "proto/proto.hpp"
#include "random_messages.hpp"

namespace st::proto {
namespace {

using test::Rng;
using Bytes = std::vector<std::uint8_t>;

struct Parsed {
  std::vector<Frame> frames;
  Status error;
  std::size_t error_at = 0;  // bytes consumed in total when the error was reported
};

// Feeds `stream` in chunks whose sizes come from `next_chunk`, collecting every frame.
template <class ChunkFn>
Parsed parse_stream(const Bytes& stream, const Limits& limits, ChunkFn next_chunk,
                    Receiver receiver = Receiver::any) {
  Parsed out;
  FrameParser p(limits, receiver);
  std::size_t pos = 0;
  while (pos < stream.size()) {
    const std::size_t n = std::min(next_chunk(), stream.size() - pos);
    std::span<const std::uint8_t> chunk(stream.data() + pos, n);
    while (!chunk.empty()) {
      const auto r = p.feed(chunk);
      EXPECT_LE(r.consumed, chunk.size());
      pos += r.consumed;
      chunk = chunk.subspan(r.consumed);
      if (r.state == FrameParser::State::frame) {
        out.frames.push_back(p.take_frame());
      } else if (r.state == FrameParser::State::error) {
        out.error = p.status();
        out.error_at = pos;
        // sticky: feeding more reports the same error, consuming nothing
        const auto again = p.feed(chunk);
        EXPECT_EQ(again.state, FrameParser::State::error);
        EXPECT_EQ(again.consumed, 0u);
        EXPECT_EQ(p.status().code, out.error.code);
        return out;
      } else {
        EXPECT_TRUE(chunk.empty());
      }
    }
  }
  return out;
}

Parsed parse_all(const Bytes& stream, const Limits& limits = {},
                 Receiver receiver = Receiver::any) {
  return parse_stream(stream, limits, [&] { return stream.size() + 1; }, receiver);
}

Bytes frame_of(const Message& m, std::uint32_t id, std::uint8_t flags = 0,
               const Limits& limits = {}) {
  Bytes out;
  const Status s = encode_message(m, id, flags, limits, out);
  EXPECT_TRUE(s) << to_string(s);
  return out;
}

void expect_same_frames(const std::vector<Frame>& a, const std::vector<Frame>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].header.type, b[i].header.type) << i;
    EXPECT_EQ(a[i].header.request_id, b[i].header.request_id) << i;
    EXPECT_EQ(a[i].header.flags, b[i].header.flags) << i;
    EXPECT_EQ(a[i].payload, b[i].payload) << i;
  }
}

TEST(FrameParser, ByteByByteAndRandomChunkingGiveTheSameFrames) {
  Rng rng(1234);
  const Limits limits;
  for (int round = 0; round < 20; ++round) {
    Bytes stream;
    std::vector<Message> sent;
    const int n = 1 + static_cast<int>(rng() % 12);
    for (int i = 0; i < n; ++i) {
      Message m;
      const Bytes f = test::random_frame(rng, limits, 100 + i, &m);
      stream.insert(stream.end(), f.begin(), f.end());
      sent.push_back(std::move(m));
    }
    const Parsed whole = parse_all(stream, limits);
    ASSERT_TRUE(whole.error.ok()) << to_string(whole.error);
    ASSERT_EQ(whole.frames.size(), sent.size());
    for (std::size_t i = 0; i < sent.size(); ++i) {
      Message got;
      ASSERT_TRUE(decode_message(whole.frames[i], limits, got));
      EXPECT_EQ(got, sent[i]) << "frame " << i;
      EXPECT_EQ(whole.frames[i].header.request_id, 100 + i);
    }
    expect_same_frames(parse_stream(stream, limits, [] { return std::size_t{1}; }).frames,
                       whole.frames);
    expect_same_frames(
        parse_stream(stream, limits, [&] { return std::size_t(1 + rng() % 97); }).frames,
        whole.frames);
    expect_same_frames(
        parse_stream(stream, limits, [&] { return std::size_t(1 + rng() % 5000); }).frames,
        whole.frames);
  }
}

TEST(FrameParser, PipelinedAnswersWithOutOfOrderRequestIdsParseInStreamOrder) {
  // A server answers requests 5, 3, 9, 4 in the order it finished them.
  const std::uint32_t ids[] = {5, 3, 9, 4, 3};
  Bytes stream;
  for (std::uint32_t id : ids) {
    TileError e;
    e.tile_id = id * 10;
    e.code = ErrorCode::unknown_tile;
    const Bytes f = frame_of(e, id, kFlagFinal);
    stream.insert(stream.end(), f.begin(), f.end());
  }
  const Parsed p = parse_stream(stream, {}, [] { return std::size_t{7}; });
  ASSERT_TRUE(p.error.ok());
  ASSERT_EQ(p.frames.size(), 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(p.frames[i].header.request_id, ids[i]);
    EXPECT_TRUE(p.frames[i].header.final());
    TileError e;
    ASSERT_TRUE(decode_payload(p.frames[i].payload, {}, e));
    EXPECT_EQ(e.tile_id, ids[i] * 10u);
  }
}

TEST(FrameParser, TruncationAtEveryLengthNeedsMoreNeverAFrameOrCrash) {
  Rng rng(77);
  const Limits limits;
  for (const MessageType t : test::all_types()) {
    const Bytes f = frame_of(test::random_message(rng, t, limits), 1);
    for (std::size_t len = 0; len < f.size(); ++len) {
      FrameParser p(limits);
      const auto r = p.feed({f.data(), len});
      EXPECT_EQ(r.state, FrameParser::State::need_more) << to_string(t) << " len " << len;
      EXPECT_EQ(r.consumed, len);
    }
    FrameParser p(limits);
    EXPECT_EQ(p.feed(f).state, FrameParser::State::frame);
  }
}

TEST(FrameParser, EverySingleBitFlipIsDetected) {
  Rng rng(99);
  const Limits limits;
  std::size_t checked = 0;
  for (const MessageType t : test::all_types()) {
    Message m = test::random_message(rng, t, limits);
    const Bytes f = frame_of(m, 42, kFlagFinal);
    for (std::size_t bit = 0; bit < f.size() * 8; ++bit) {
      Bytes bad = f;
      bad[bit / 8] ^= std::uint8_t(1u << (bit % 8));
      FrameParser p(limits);
      const auto r = p.feed(bad);
      ++checked;
      // Only a flip that makes payload_length smaller could leave a "frame" - but that
      // flip lies in the header, covered by header_crc32. So: always a typed error, or
      // (a larger length) need-more, never a frame.
      ASSERT_NE(r.state, FrameParser::State::frame) << to_string(t) << " bit " << bit;
      if (r.state == FrameParser::State::error) {
        const ErrorCode c = p.status().code;
        const std::size_t byte = bit / 8;
        if (byte < 4) EXPECT_EQ(c, ErrorCode::bad_magic);
        else if (byte == kOffVersion) EXPECT_EQ(c, ErrorCode::unsupported_version);
        else if (byte < kHeaderSize) EXPECT_EQ(c, ErrorCode::header_checksum);
        else EXPECT_EQ(c, ErrorCode::payload_checksum);
      } else {
        ADD_FAILURE() << "bit flip " << bit << " in " << to_string(t) << " not detected";
      }
    }
  }
  EXPECT_GT(checked, 10000u);
}

TEST(FrameParser, OversizedLengthIsRejectedBeforeAnyPayloadIsBuffered) {
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  FrameHeader h;
  h.type = MessageType::tile_data;
  h.request_id = 1;
  h.payload_length = limits.max_payload_bytes() + 1;
  std::array<std::uint8_t, kHeaderSize> b;
  write_header(h, b);
  FrameParser p(limits);
  const auto r = p.feed(b);  // the header alone: no payload byte exists yet
  EXPECT_EQ(r.state, FrameParser::State::error);
  EXPECT_EQ(r.consumed, kHeaderSize);
  EXPECT_EQ(p.status().code, ErrorCode::oversized_frame);
  EXPECT_NE(p.status().detail.find("payload_length"), std::string::npos) << p.status().detail;

  // A 4 GiB claim, too: rejected the same way, nothing allocated (ASan would see it).
  h.payload_length = 0xffffffffu;
  write_header(h, b);
  FrameParser q(limits);
  EXPECT_EQ(q.feed(b).state, FrameParser::State::error);
  EXPECT_EQ(q.status().code, ErrorCode::oversized_frame);

  // Exactly at the limit is fine.
  h.payload_length = limits.max_payload_bytes();
  write_header(h, b);
  FrameParser ok(limits);
  EXPECT_EQ(ok.feed(b).state, FrameParser::State::need_more);
}

TEST(FrameParser, EncoderRefusesFramesAboveTheLimit) {
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  TileData t;
  t.payload.assign(limits.max_payload_bytes() - kTileMetaBytes + 1, 7);
  t.meta.payload_crc32 = crc32(t.payload);
  Bytes out = {1, 2, 3};
  const Status s = encode_message(t, 1, kFlagFinal, limits, out);
  EXPECT_EQ(s.code, ErrorCode::oversized_frame);
  EXPECT_EQ(out, (Bytes{1, 2, 3}));
  t.payload.pop_back();
  EXPECT_TRUE(encode_message(t, 1, kFlagFinal, limits, out));
  EXPECT_EQ(out.size(), 3 + limits.max_frame_bytes);
}

Bytes header_bytes(std::uint16_t type, std::uint8_t flags = 0, std::uint8_t version = 1) {
  std::array<std::uint8_t, kHeaderSize> b;
  FrameHeader h;
  h.type = static_cast<MessageType>(type);
  h.flags = flags;
  h.version = version;
  write_header(h, b);
  return Bytes(b.begin(), b.end());
}

TEST(FrameParser, UnknownTypesFlagsAndVersionsGiveTypedErrors) {
  for (std::uint16_t t : {0x0000, 0x0004, 0x0042, 0x00ff, 0x1234, 0xffff}) {
    const Parsed p = parse_all(header_bytes(t));
    EXPECT_EQ(p.error.code, ErrorCode::unknown_type) << t;
    EXPECT_TRUE(p.frames.empty());
  }
  for (std::uint8_t f : {0x02, 0x80, 0xff}) {
    EXPECT_EQ(parse_all(header_bytes(0x0030, f)).error.code, ErrorCode::bad_flags) << int(f);
  }
  // A future version is refused at byte 4, before a whole header arrives.
  const Bytes v2 = header_bytes(0x0030, 0, 2);
  FrameParser p({});
  const auto r = p.feed({v2.data(), 5});
  EXPECT_EQ(r.state, FrameParser::State::error);
  EXPECT_EQ(p.status().code, ErrorCode::unsupported_version);
  EXPECT_EQ(parse_all(header_bytes(0x0030, 0, 0)).error.code, ErrorCode::unsupported_version);
}

TEST(FrameParser, BadMagicIsReportedAtTheFirstWrongByte) {
  const Bytes http = {'G', 'E', 'T', ' ', '/', ' ', 'H', 'T', 'T', 'P'};
  FrameParser p({});
  const auto r = p.feed(http);
  EXPECT_EQ(r.state, FrameParser::State::error);
  EXPECT_EQ(r.consumed, 1u);
  EXPECT_EQ(p.status().code, ErrorCode::bad_magic);
  // Garbage after a valid frame: the frame, then the error.
  Bytes stream = frame_of(Ping{1}, 1);
  stream.push_back('S');
  stream.push_back('X');
  const Parsed q = parse_all(stream);
  EXPECT_EQ(q.frames.size(), 1u);
  EXPECT_EQ(q.error.code, ErrorCode::bad_magic);
  EXPECT_NE(q.error.detail.find("stream byte 33"), std::string::npos) << q.error.detail;
}

TEST(FrameParser, ReceiverRejectsMessagesOfTheWrongDirection) {
  const Bytes ack = frame_of(HelloAck{}, 1);
  EXPECT_EQ(parse_all(ack, {}, Receiver::server).error.code, ErrorCode::unexpected_type);
  EXPECT_TRUE(parse_all(ack, {}, Receiver::client).error.ok());
  const Bytes get = frame_of(GetStats{}, 1);
  EXPECT_EQ(parse_all(get, {}, Receiver::client).error.code, ErrorCode::unexpected_type);
  EXPECT_TRUE(parse_all(get, {}, Receiver::server).error.ok());
  const Bytes ping = frame_of(Ping{5}, 0);
  EXPECT_TRUE(parse_all(ping, {}, Receiver::client).error.ok());
  EXPECT_TRUE(parse_all(ping, {}, Receiver::server).error.ok());
}

TEST(FrameParser, RandomGarbageNeverCrashesAndNeverYieldsAFrame) {
  Rng rng(5);
  for (int i = 0; i < 2000; ++i) {
    Bytes junk = test::random_bytes(rng, 200);
    if (junk.size() >= 4 && (i & 1)) std::copy(kMagic.begin(), kMagic.end(), junk.begin());
    if (junk.size() >= 5 && (i & 2)) junk[4] = 1;
    const Parsed p = parse_stream(junk, {}, [&] { return std::size_t(1 + rng() % 16); });
    EXPECT_TRUE(p.frames.empty());
  }
}

TEST(FrameParser, NewLimitsApplyFromTheNextHeader) {
  Limits big;
  big.max_frame_bytes = 1 << 20;
  TileData t;
  t.payload.assign(100000, 3);
  t.meta.payload_crc32 = crc32(t.payload);
  const Bytes f = frame_of(t, 1, kFlagFinal, big);
  FrameParser p(big);
  ASSERT_EQ(p.feed(f).state, FrameParser::State::frame);
  p.take_frame();
  Limits small = big;
  small.max_frame_bytes = kMinFrameBytes;
  p.set_limits(small);
  EXPECT_EQ(p.feed(f).state, FrameParser::State::error);
  EXPECT_EQ(p.status().code, ErrorCode::oversized_frame);
}

TEST(FrameParser, ParseHeaderChecksInTheSameOrder) {
  const Bytes f = frame_of(Ping{9}, 77, kFlagFinal);
  FrameHeader h;
  ASSERT_TRUE(parse_header(std::span<const std::uint8_t, kHeaderSize>(f.data(), kHeaderSize),
                           {}, h));
  EXPECT_EQ(h.type, MessageType::ping);
  EXPECT_EQ(h.request_id, 77u);
  EXPECT_EQ(h.payload_length, 8u);
  EXPECT_TRUE(h.final());
  Bytes bad = f;
  bad[kOffRequestId] ^= 1;
  EXPECT_EQ(parse_header(std::span<const std::uint8_t, kHeaderSize>(bad.data(), kHeaderSize), {},
                         h)
                .code,
            ErrorCode::header_checksum);
}

}  // namespace
}  // namespace st::proto
