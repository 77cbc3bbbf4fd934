// A token bucket per network (IPv4 /24, IPv6 /64) for TLS handshakes (internal to
// server/). A TLS handshake costs the server a private-key operation (an RSA-4096
// signature is ~5 ms of CPU, on the I/O thread), so a few clients opening connections as
// fast as they can would make every other client wait behind their handshakes. Each
// network may start `rate` handshakes a second, `burst` at once; a connection over that
// is closed before its handshake starts (counted as rejected). An honest client needs
// one handshake per connection and reconnects with backoff, so it stays far under it.
//
// Memory: one entry per network seen recently; past kMaxEntries the entries whose bucket
// has refilled (they carry nothing) are dropped, so a spray over many networks costs at
// most kMaxEntries entries plus those still draining.
// Thread safety: none; the server calls it under ServerCore::mu.
#pragma once
#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>

namespace st::server {

class HandshakeLimiter {
 public:
  using Clock = std::chrono::steady_clock;
  using Prefix = std::array<uint8_t, 16>;
  static constexpr size_t kMaxEntries = 4096;

  // rate <= 0: no limit.
  HandshakeLimiter(double rate, double burst) : rate_(rate), burst_(std::max(1.0, burst)) {}

  // True (and one token taken) if `prefix` may start a handshake at `now`.
  bool admit(const Prefix& prefix, Clock::time_point now) {
    if (rate_ <= 0) return true;
    auto [it, fresh] = buckets_.try_emplace(prefix, Bucket{burst_, now});
    Bucket& b = it->second;
    if (!fresh) {
      b.tokens = std::min(burst_, b.tokens + rate_ * std::chrono::duration<double>(now - b.at).count());
      b.at = now;
    }
    const bool ok = b.tokens >= 1;
    if (ok) b.tokens -= 1;
    if (buckets_.size() > kMaxEntries) prune(now);
    return ok;
  }
  size_t entries() const { return buckets_.size(); }

 private:
  struct Bucket {
    double tokens;
    Clock::time_point at;
  };
  void prune(Clock::time_point now) {
    for (auto it = buckets_.begin(); it != buckets_.end();)
      if (it->second.tokens + rate_ * std::chrono::duration<double>(now - it->second.at).count() >= burst_)
        it = buckets_.erase(it);
      else
        ++it;
  }
  double rate_, burst_;
  std::map<Prefix, Bucket> buckets_;
};

}  // namespace st::server
