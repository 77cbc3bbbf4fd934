// The benchmarks' timing loops, written once: wall and thread-CPU clocks, medians over
// repeated runs, and kinds timed side by side. The machine the figures come from is shared
// (load above the core count at times), so thread CPU time is the steadier figure and the
// benches report it beside wall time.
#pragma once
#include <time.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <utility>
#include <vector>

namespace st::bench {

using Clock = std::chrono::steady_clock;

inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

inline double thread_cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// The median (the mean of the two middle values for an even count); 0 when empty.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// Wall and thread-CPU seconds of one call.
struct Timing {
  double wall = 0, cpu = 0;
};
inline Timing time_of(const std::function<void()>& f) {
  const double c0 = thread_cpu_now();
  const auto t0 = Clock::now();
  f();
  return {seconds_since(t0), thread_cpu_now() - c0};
}

// Medians of wall and of CPU time over `reps` calls, each taken separately.
inline Timing median_time(int reps, const std::function<void()>& f) {
  std::vector<double> wall, cpu;
  for (int r = 0; r < reps; ++r) {
    const Timing t = time_of(f);
    wall.push_back(t.wall), cpu.push_back(t.cpu);
  }
  return {median(wall), median(cpu)};
}

// Median thread-CPU seconds of `reps` calls.
inline double median_cpu(int reps, const std::function<void()>& f) { return median_time(reps, f).cpu; }

// Kinds timed side by side: each round runs every kind once, in turn, so that a change in
// the shared machine's load falls on all of them alike; each kind's figure is its median
// over the rounds (thread CPU nanoseconds per item, `count` items a run).
class SideBySide {
 public:
  template <class F>
  void add(double& result, size_t count, F body) {
    kinds_.push_back({&result, count, std::function<void()>(std::move(body)), {}});
  }
  void run(int reps) {
    for (int r = 0; r < reps; ++r)
      for (Kind& k : kinds_) {
        const double t0 = thread_cpu_now();
        k.body();
        k.t.push_back((thread_cpu_now() - t0) * 1e9 / double(k.count));
      }
    for (Kind& k : kinds_) *k.result = median(k.t);
  }

 private:
  struct Kind {
    double* result;
    size_t count;
    std::function<void()> body;
    std::vector<double> t;
  };
  std::vector<Kind> kinds_;
};

}  // namespace st::bench
