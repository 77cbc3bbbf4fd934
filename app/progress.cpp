#include "app/progress.hpp"

#include <unistd.h>

#include <cstdio>

namespace st::cli {

Progress::Progress(std::string what, std::string unit)
    : what_(std::move(what)), unit_(std::move(unit)), tty_(isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()), last_line_(start_) {}

void Progress::update(uint64_t done, uint64_t total, uint64_t rate_units) {
  auto now = std::chrono::steady_clock::now();
  double elapsed = std::chrono::duration<double>(now - start_).count();
  if (!tty_ && std::chrono::duration<double>(now - last_line_).count() < 10 && done < total) return;
  last_line_ = now;
  double frac = total ? double(done) / double(total) : 1.0;
  double rate = elapsed > 0 ? double(rate_units) / elapsed : 0;
  double eta = frac > 0 ? elapsed * (1 - frac) / frac : 0;
  char line[256];
  if (tty_) {
    const int width = 30;
    int filled = int(frac * width);
    std::string bar(size_t(filled), '#');
    bar.resize(width, '.');
    std::snprintf(line, sizeof line, "\r%s [%s] %5.1f%%  %.2f M%s/s  ETA %.0fs   ", what_.c_str(),
                  bar.c_str(), frac * 100, rate / 1e6, unit_.c_str(), eta);
    std::fputs(line, stderr);
    drawn_ = true;
  } else {
    std::snprintf(line, sizeof line, "%s: %llu/%llu (%.1f%%), %.2f M%s/s, ETA %.0fs\n", what_.c_str(),
                  (unsigned long long)done, (unsigned long long)total, frac * 100, rate / 1e6,
                  unit_.c_str(), eta);
    std::fputs(line, stderr);
  }
  std::fflush(stderr);
}

void Progress::finish() {
  if (tty_ && drawn_) std::fputs("\n", stderr);
  drawn_ = false;
}

}  // namespace st::cli
