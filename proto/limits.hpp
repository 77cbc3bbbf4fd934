// Limits negotiated by the handshake (PROTOCOL.md §6) and the in-flight request tracker.
// Both sides enforce the same numbers: the sender never emits what the receiver would
// reject, the receiver never trusts the sender to have done so.
#pragma once
#include <cstddef>
#include <cstdint>
#include <vector>

#include "proto/status.hpp"
#include "proto/wire_format.hpp"

namespace st::proto {

// Hard bounds every implementation accepts (FORMAT CONSTANTS). A Hello/HelloAck asking
// outside them is rejected with invalid_field.
inline constexpr std::uint32_t kMinFrameBytes = 64 * 1024;          // handshake always fits
inline constexpr std::uint32_t kMaxFrameBytesCeiling = 64u << 20;   // 64 MiB
inline constexpr std::uint16_t kMaxInFlightCeiling = 4096;
inline constexpr std::uint16_t kMaxTilesPerBatchCeiling = 4096;

struct Limits {
  // Largest whole frame (header + payload) this side accepts; the parser rejects a larger
  // payload_length from the header alone, before buffering a single payload byte.
  std::uint32_t max_frame_bytes = 4u << 20;
  // Requests a client may have unanswered at once (answers still owed by the server).
  std::uint16_t max_in_flight = 64;
  // Tiles in one GetTiles; also caps Cancel's tile list.
  std::uint16_t max_tiles_per_batch = 256;
  // Frame header versions the parser accepts. Before the handshake: [1, 1]; after it:
  // [v, v] for the negotiated v.
  std::uint8_t min_version = kHandshakeVersion;
  std::uint8_t max_version = kHandshakeVersion;

  std::uint32_t max_payload_bytes() const {
    return max_frame_bytes > kHeaderSize ? max_frame_bytes - std::uint32_t(kHeaderSize) : 0;
  }
};

// ok unless a field lies outside the hard bounds above or min_version > max_version.
Status validate(const Limits& limits);

// The limits a side enforces before the handshake completes, from its own `local` ones:
// version-1 frames of at most kMinFrameBytes (the Hello and HelloAck always fit), whatever
// larger frames the handshake may grant afterwards. Client and server use the same rule.
Limits handshake_limits(const Limits& local);

// The limits both sides use after the handshake: the smaller of each pair, at `version`.
Limits negotiate(const Limits& a, const Limits& b, std::uint8_t version);

// Highest version in both ranges, or 0 if the ranges do not meet.
std::uint8_t choose_version(std::uint8_t a_min, std::uint8_t a_max, std::uint8_t b_min,
                            std::uint8_t b_max);

// Tracks request ids awaiting their FINAL answer frame. The client calls begin() before
// sending a request and end() when a FINAL frame with that id arrives; the server calls
// begin() on receipt (refusing with too_many_in_flight) and end() when it sends FINAL.
// Refuses id 0 (kNoRequest), duplicates and more than `capacity` ids at once.
// Not thread-safe: one tracker per connection, used from that connection's strand.
class InFlight {
 public:
  explicit InFlight(std::uint16_t capacity);

  // ok, or too_many_in_flight / duplicate_request_id / invalid_field (id 0).
  Status begin(std::uint32_t request_id);
  // true if the id was in flight (and is now released); false for an unknown id, which
  // the caller should treat as a protocol error by the peer (an answer nobody asked for).
  bool end(std::uint32_t request_id);
  bool contains(std::uint32_t request_id) const;

  std::size_t size() const { return ids_.size(); }
  std::uint16_t capacity() const { return capacity_; }
  bool full() const { return ids_.size() >= capacity_; }
  // After a renegotiation lowers the limit, ids already in flight stay; begin() refuses
  // until size() drops below the new capacity.
  void set_capacity(std::uint16_t capacity) { capacity_ = capacity; }
  void clear() { ids_.clear(); }

 private:
  std::uint16_t capacity_;
  std::vector<std::uint32_t> ids_;  // sorted; capacity is small (<= 4096)
};

}  // namespace st::proto
