// Limits validation/negotiation and the in-flight tracker (PROTOCOL.md §6).
#include "proto/limits.hpp"

#include <algorithm>
#include <string>

namespace st::proto {

Status validate(const Limits& l) {
  if (l.max_frame_bytes < kMinFrameBytes || l.max_frame_bytes > kMaxFrameBytesCeiling)
    return Status::fail(ErrorCode::invalid_field,
                        "max_frame_bytes " + std::to_string(l.max_frame_bytes) +
                            " outside [" + std::to_string(kMinFrameBytes) + ", " +
                            std::to_string(kMaxFrameBytesCeiling) + "]");
  if (l.max_in_flight < 1 || l.max_in_flight > kMaxInFlightCeiling)
    return Status::fail(ErrorCode::invalid_field,
                        "max_in_flight " + std::to_string(l.max_in_flight) + " outside [1, " +
                            std::to_string(kMaxInFlightCeiling) + "]");
  if (l.max_tiles_per_batch < 1 || l.max_tiles_per_batch > kMaxTilesPerBatchCeiling)
    return Status::fail(ErrorCode::invalid_field,
                        "max_tiles_per_batch " + std::to_string(l.max_tiles_per_batch) +
                            " outside [1, " + std::to_string(kMaxTilesPerBatchCeiling) + "]");
  if (l.min_version < 1 || l.min_version > l.max_version)
    return Status::fail(ErrorCode::invalid_field,
                        "version range [" + std::to_string(l.min_version) + ", " +
                            std::to_string(l.max_version) + "] is empty or contains 0");
  return {};
}

Limits handshake_limits(const Limits& local) {
  Limits l = local;
  l.max_frame_bytes = kMinFrameBytes;
  l.min_version = l.max_version = kHandshakeVersion;
  return l;
}

Limits negotiate(const Limits& a, const Limits& b, std::uint8_t version) {
  Limits n;
  n.max_frame_bytes = std::min(a.max_frame_bytes, b.max_frame_bytes);
  n.max_in_flight = std::min(a.max_in_flight, b.max_in_flight);
  n.max_tiles_per_batch = std::min(a.max_tiles_per_batch, b.max_tiles_per_batch);
  n.min_version = version;
  n.max_version = version;
  return n;
}

std::uint8_t choose_version(std::uint8_t a_min, std::uint8_t a_max, std::uint8_t b_min,
                            std::uint8_t b_max) {
  const std::uint8_t lo = std::max(a_min, b_min);
  const std::uint8_t hi = std::min(a_max, b_max);
  return (lo <= hi && lo >= 1) ? hi : 0;
}

InFlight::InFlight(std::uint16_t capacity) : capacity_(capacity) { ids_.reserve(capacity); }

Status InFlight::begin(std::uint32_t request_id) {
  if (request_id == kNoRequest)
    return Status::fail(ErrorCode::invalid_field, "request_id 0 is reserved");
  auto it = std::lower_bound(ids_.begin(), ids_.end(), request_id);
  if (it != ids_.end() && *it == request_id)
    return Status::fail(ErrorCode::duplicate_request_id,
                        "request_id " + std::to_string(request_id) + " already in flight");
  if (ids_.size() >= capacity_)
    return Status::fail(ErrorCode::too_many_in_flight,
                        std::to_string(ids_.size()) + " requests in flight, limit " +
                            std::to_string(capacity_));
  ids_.insert(it, request_id);
  return {};
}

bool InFlight::end(std::uint32_t request_id) {
  auto it = std::lower_bound(ids_.begin(), ids_.end(), request_id);
  if (it == ids_.end() || *it != request_id) return false;
  ids_.erase(it);
  return true;
}

bool InFlight::contains(std::uint32_t request_id) const {
  return std::binary_search(ids_.begin(), ids_.end(), request_id);
}

}  // namespace st::proto
