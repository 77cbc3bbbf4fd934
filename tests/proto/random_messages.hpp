// Seeded generators of valid random messages for the proto round-trip, truncation and
// bit-flip tests.
#pragma once
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "proto/proto.hpp"

namespace st::proto::test {

using Rng = std::mt19937_64;

// Every message type of version 1, in wire order.
const std::vector<MessageType>& all_types();

std::string random_map_name(Rng& rng);
std::string random_text(Rng& rng, std::size_t max_bytes);
std::vector<std::uint8_t> random_bytes(Rng& rng, std::size_t max_bytes);

// A valid message of `type` under `limits` (counts within them, names valid, ...). Sizes
// stay small enough that the frame fits limits.max_frame_bytes.
Message random_message(Rng& rng, MessageType type, const Limits& limits);

// One whole frame of a random valid message of a random type; `request_id` echoed.
std::vector<std::uint8_t> random_frame(Rng& rng, const Limits& limits, std::uint32_t request_id,
                                       Message* message = nullptr);

}  // namespace st::proto::test
