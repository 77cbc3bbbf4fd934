// "Never allocates more than the limit": measures the largest single heap allocation
// the parser and decoders make on hostile input, by replacing the global operator new in
// this test binary (it only records a maximum while a test asks it to).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "proto/byte_io.hpp"
#include "proto/proto.hpp"
#include "random_messages.hpp"

// The replacement pairs malloc with free by construction; GCC cannot see that once it
// inlines the replaced operators and warns (a false positive under -O2 -fsanitize).
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

namespace {
std::atomic<bool> g_tracking{false};
std::atomic<std::size_t> g_largest{0};
}  // namespace

void* operator new(std::size_t n) {
  if (g_tracking.load(std::memory_order_relaxed)) {
    std::size_t seen = g_largest.load(std::memory_order_relaxed);
    while (n > seen && !g_largest.compare_exchange_weak(seen, n)) {
    }
  }
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace st::proto {
namespace {

using Bytes = std::vector<std::uint8_t>;

// The largest allocation `fn` makes.
template <class Fn>
std::size_t largest_allocation(Fn fn) {
  g_largest = 0;
  g_tracking = true;
  fn();
  g_tracking = false;
  return g_largest;
}

TEST(AllocationBounds, ParserNeverAllocatesBeyondTheFrameLimit) {
  Limits limits;
  limits.max_frame_bytes = kMinFrameBytes;
  for (std::uint32_t claimed : {0xffffffffu, 0x80000000u, limits.max_payload_bytes() + 1,
                                limits.max_payload_bytes()}) {
    FrameHeader h;
    h.type = MessageType::tile_data;
    h.payload_length = claimed;
    std::array<std::uint8_t, kHeaderSize> b;
    write_header(h, b);
    const std::size_t biggest = largest_allocation([&] {
      FrameParser p(limits, Receiver::client);
      p.feed(b);
    });
    EXPECT_LE(biggest, limits.max_payload_bytes()) << "claimed " << claimed;
    // The control: a legal maximal frame allocates its first 16 KiB on the header alone
    // and its whole payload only once the bytes arrive (so the counter works).
    if (claimed == limits.max_payload_bytes()) {
      EXPECT_EQ(biggest, std::min<std::size_t>(claimed, 16384));
      const Bytes body(claimed, 0);
      const std::size_t with_body = largest_allocation([&] {
        FrameParser p(limits, Receiver::client);
        p.feed(b);
        p.feed(body);
      });
      EXPECT_EQ(with_body, claimed);
    } else {
      EXPECT_LT(biggest, 4096u) << claimed;
    }
  }
}

TEST(AllocationBounds, LyingCountsAllocateNothingBig) {
  Limits wide;
  wide.max_tiles_per_batch = kMaxTilesPerBatchCeiling;
  wide.max_in_flight = kMaxInFlightCeiling;
  struct Case {
    MessageType type;
    Bytes payload;
  };
  const Case cases[] = {
      {MessageType::map_list, {0xff, 0x0f, 0, 0}},                        // 4095 maps, no bytes
      {MessageType::get_tiles, {1, 0, 0, 0, 0x00, 0x10, 0, 0}},            // 4096 tiles
      {MessageType::cancel, {0x00, 0x10, 0xff, 0xff, 1, 0, 0, 0}},         // 4096 + 65535 ids
      {MessageType::stats, {0x00, 0x04, 0x40, 0, 0, 0, 0, 0}},             // 1024 counters
      {MessageType::map_info, {1, 0, 0, 0, 0xff, 0xff, 0xff, 0xff}},       // 4 GiB blob
      {MessageType::tile_data, Bytes(24, 0)},                              // + length below
      {MessageType::error, {1, 0, 0xff, 0xff}},                            // 64 KiB text
  };
  for (Case c : cases) {
    if (c.type == MessageType::tile_data) c.payload.insert(c.payload.end(), {0xff, 0xff, 0xff, 0xff});
    Frame f;
    f.header.type = c.type;
    f.payload = c.payload;
    Status s;
    const std::size_t biggest = largest_allocation([&] {
      Message m;
      s = decode_message(f, wide, m);
    });
    EXPECT_FALSE(s.ok()) << to_string(c.type);
    EXPECT_LE(biggest, 1024u) << to_string(c.type) << ": " << to_string(s);
  }
}

TEST(AllocationBounds, DecodersAllocateAtMostAFewTimesThePayload) {
  test::Rng rng(404);
  const Limits limits;
  for (const MessageType t : test::all_types()) {
    for (int i = 0; i < 200; ++i) {
      Bytes p;
      ASSERT_TRUE(std::visit([&](const auto& v) { return encode_payload(v, limits, p); },
                             test::random_message(rng, t, limits)));
      for (int k = 0; k < 2 && !p.empty(); ++k) p[rng() % p.size()] = std::uint8_t(rng());
      Frame f;
      f.header.type = t;
      f.payload = p;
      const std::size_t biggest = largest_allocation([&] {
        Message m;
        (void)decode_message(f, limits, m);
      });
      // In-memory elements are at most ~3x their wire size (MapEntry: 18 bytes on the
      // wire, a std::string and fields in memory); hash sets for duplicate checks too.
      EXPECT_LE(biggest, 4 * p.size() + 4096) << to_string(t);
    }
  }
}

}  // namespace
}  // namespace st::proto
