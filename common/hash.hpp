// Hashing and random numbers with identical output on every platform and standard
// library (unlike std::hash and std::uniform_*_distribution), so procedural scenes,
// synthetic cameras and sampled verification are reproducible from a seed.
//
// splitmix64 (Steele, Lea, Flood 2014): `mix64` is its finalizer (spreads small dense
// keys such as tile ids over all 64 bits), `splitmix64` the generator step.
#pragma once
#include <cstdint>

namespace st {

inline constexpr uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Advances `state` and returns the next value of the sequence.
inline constexpr uint64_t splitmix64(uint64_t& state) { return mix64(state += 0x9E3779B97F4A7C15ull); }

// A uniform double in [0, 1) from the top 53 bits.
inline double unit_random(uint64_t& state) { return double(splitmix64(state) >> 11) * 0x1p-53; }

// A small seeded generator for code that wants an object.
class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  uint64_t next() { return splitmix64(state_); }
  double uniform() { return unit_random(state_); }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Integer in [lo, hi]; the modulo bias (< 2^-50 for our ranges) does not matter here.
  int range(int lo, int hi) { return lo + int(next() % uint64_t(hi - lo + 1)); }
  bool chance(double p) { return uniform() < p; }

 private:
  uint64_t state_;
};

}  // namespace st
