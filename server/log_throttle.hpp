// Rate limit for repeated log lines (a flood of wrong keys or corrupt tiles must not
// become a flood of log writes): each kind of line has a token bucket, `burst` lines at
// once refilled at `per_second`; a line over the budget is counted, not written, and the
// next line of that kind that is written says how many were dropped since the last one.
// Thread-safe (one mutex; log lines are rare next to tiles).
#pragma once
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace st::server {

class LogThrottle {
 public:
  using Clock = std::chrono::steady_clock;
  LogThrottle(double burst = 5, double per_second = 1) : burst_(burst), rate_(per_second) {}

  // The line to write now for `line` of kind `kind` (with the count of lines dropped
  // before it), or nullopt when it is over the budget and only counted.
  std::optional<std::string> admit(const std::string& kind, const std::string& line,
                                   Clock::time_point now = Clock::now()) {
    std::lock_guard lock(mu_);
    Bucket& b = buckets_[kind];
    if (!b.started) {
      b.started = true;
      b.tokens = burst_;
      b.last = now;
    }
    const double dt = std::chrono::duration<double>(now - b.last).count();
    b.last = now;
    b.tokens = std::min(burst_, b.tokens + dt * rate_);
    if (b.tokens < 1) {
      ++b.dropped;
      return std::nullopt;
    }
    b.tokens -= 1;
    if (b.dropped == 0) return line;
    std::string out = line + " (" + std::to_string(b.dropped) + " similar line(s) suppressed)";
    b.dropped = 0;
    return out;
  }

 private:
  struct Bucket {
    bool started = false;
    double tokens = 0;
    Clock::time_point last{};
    uint64_t dropped = 0;
  };
  std::mutex mu_;
  double burst_, rate_;
  std::map<std::string, Bucket> buckets_;  // a fixed handful of kinds
};

}  // namespace st::server
