// libFuzzer harness for every message decoder of proto (messages.hpp), the payloads the
// frame parser hands over once the CRCs check. Input: byte 0 picks the message type
// (bits 0-3 and 5, modulo the alternatives of Message) and the limits (bit 4: small
// limits); the rest is the payload.
// Checks, beyond no crash / no sanitizer report:
// - a payload that decodes re-encodes to the same bytes and decodes to an equal value;
// - decoding through decode_message (a Frame with that type) agrees with decode_payload;
// - limits are monotonic: what decodes under the small limits decodes under the defaults;
// - TileData: decode_tile_data_view agrees with decode_payload;
// - make_error turns any bytes (as text) into an Error that encodes and decodes.
#include <span>
#include <string_view>
#include <utility>

#include "proto/byte_io.hpp"
#include "proto/proto.hpp"
#include "tests/fuzz/seed_support.hpp"

namespace {

using namespace st::proto;

template <std::size_t... I>
Message make_alternative(std::size_t index, std::index_sequence<I...>) {
  static const Message kAll[] = {Message(std::in_place_index<I>)...};
  return kAll[index];
}

Message empty_message(std::size_t index) {
  return make_alternative(index % std::variant_size_v<Message>,
                          std::make_index_sequence<std::variant_size_v<Message>>{});
}

Limits small_limits() {
  Limits l;
  l.max_frame_bytes = kMinFrameBytes;
  l.max_tiles_per_batch = 16;
  l.max_in_flight = 8;
  return l;
}

Status decode_as(std::span<const std::uint8_t> payload, const Limits& limits, Message& m) {
  return std::visit([&](auto& v) { return decode_payload(payload, limits, v); }, m);
}

}  // namespace

std::vector<st::fuzz::Bytes> st::fuzz::seeds() {
  std::vector<Bytes> out;
  for (std::uint64_t s : {1u, 2u}) {
    for (const Bytes& frame : message_frames(s)) {
      const std::uint16_t type = load_le<std::uint16_t>(frame.data() + kOffType);
      std::size_t index = 0;
      while (index < std::variant_size_v<Message> &&
             static_cast<std::uint16_t>(type_of(empty_message(index))) != type)
        ++index;
      Bytes seed = {std::uint8_t((index & 0x0f) | ((index & 0x10) << 1) | (s == 2 ? 0x10 : 0))};
      seed.insert(seed.end(), frame.begin() + kHeaderSize, frame.end());
      out.push_back(std::move(seed));
    }
  }
  return out;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::uint8_t control = data[0];
  const std::vector<std::uint8_t> payload(data + 1, data + size);
  const Limits limits = (control & 0x10) ? small_limits() : Limits{};

  const std::size_t type_index = (control & 0x0f) | ((control & 0x20) >> 1);
  Message m = empty_message(type_index);
  const Status s = decode_as(payload, limits, m);

  // The same payload in a Frame through decode_message.
  Frame frame;
  frame.header.type = type_of(m);
  frame.header.payload_length = std::uint32_t(payload.size());
  frame.payload = payload;
  Message via_frame;
  const Status sf = decode_message(frame, limits, via_frame);
  FUZZ_CHECK(sf.ok() == s.ok());
  if (s) FUZZ_CHECK(via_frame == m);

  if (s) {
    st::fuzz::note_accepted();
    std::vector<std::uint8_t> again;
    FUZZ_CHECK(std::visit([&](const auto& v) { return encode_payload(v, limits, again); }, m).ok());
    FUZZ_CHECK(again == payload);
    Message back = empty_message(type_index);
    FUZZ_CHECK(decode_as(again, limits, back).ok() && back == m);
    if (control & 0x10) {
      Message wide = empty_message(type_index);
      FUZZ_CHECK(decode_as(payload, Limits{}, wide).ok() && wide == m);
    }
  }
  if (type_of(m) == MessageType::tile_data) {
    TileMeta meta;
    std::span<const std::uint8_t> view;
    const Status sv = decode_tile_data_view(payload, meta, view);
    if (s) {
      const TileData& td = std::get<TileData>(m);
      FUZZ_CHECK(sv.ok() && meta == td.meta);
      FUZZ_CHECK(std::equal(view.begin(), view.end(), td.payload.begin(), td.payload.end()));
      FUZZ_CHECK(tile_crc_matches(meta, view) == tile_crc_matches(td.meta, td.payload));
    }
  }
  // Any text (here: the payload bytes) becomes an Error frame that encodes and decodes.
  const std::string_view text(reinterpret_cast<const char*>(payload.data()), payload.size());
  const ErrorMessage e = make_error(ErrorCode::internal, text);
  std::vector<std::uint8_t> wire;
  FUZZ_CHECK(encode_message(Message{e}, 0, kFlagFinal, limits, wire).ok());
  ErrorMessage e_back;
  FUZZ_CHECK(decode_payload(std::span<const std::uint8_t>(wire).subspan(kHeaderSize), limits, e_back).ok());
  FUZZ_CHECK(e_back == e);
  if (!s) {
    const ErrorMessage from_status = make_error(s);
    FUZZ_CHECK(from_status.code != ErrorCode::ok);
    std::vector<std::uint8_t> w2;
    FUZZ_CHECK(encode_payload(from_status, limits, w2).ok());
  }
  return 0;
}
