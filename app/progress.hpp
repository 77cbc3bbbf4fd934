// Progress reporting for long CLI runs: a redrawn bar with rate and ETA on a terminal,
// plain periodic lines (every 10 s) when stderr is not a terminal.
#pragma once
#include <chrono>
#include <cstdint>
#include <string>

namespace st::cli {

class Progress {
 public:
  Progress(std::string what, std::string unit);
  // done/total in work units; `rate_units` is what the rate counts (e.g. texels so far).
  void update(uint64_t done, uint64_t total, uint64_t rate_units);
  void finish();

 private:
  std::string what_, unit_;
  bool tty_;
  std::chrono::steady_clock::time_point start_, last_line_;
  bool drawn_ = false;
};

}  // namespace st::cli
