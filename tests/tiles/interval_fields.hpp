// Random depth-interval fields for property tests (shared by the construction and the
// encoders' tests), and the lossless-invariant check every encoding is tested against.
//
// Every generator is deterministic in (side, seed): it uses its own PRNG (SplitMix64),
// never <random> distributions, whose output differs between standard libraries.
// Fields are square, `side` a power of two, level = log2(side), origin (0, 0).
#pragma once
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "tiles/core/interval.hpp"

namespace st::fields {

// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast, passes BigCrush; good enough here.
class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  uint64_t next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double a, double b) { return a + (b - a) * uniform(); }
  uint32_t below(uint32_t n) { return uint32_t((next() >> 32) * n >> 32); }  // [0, n)

 private:
  uint64_t state_;
};

// Independent random intervals in [0, 1): a quarter zero-width, the rest of random width.
// Nearly incompressible: the worst case for node counts.
IntervalTile uniform_field(uint32_t side, uint64_t seed);

// City-like: flat ground blocks (zero-width, piecewise constant) under closed box
// buildings whose intervals run from the roof to the ground (wide closed intervals),
// with a lit (kLitDepth) border where no geometry is.
IntervalTile city_field(uint32_t side, uint64_t seed);

// Terrain-like: smooth slopes (sums of low-frequency waves) with zero-width intervals, as
// open geometry gives.
IntervalTile terrain_field(uint32_t side, uint64_t seed);

// Special values, in blocks and single texels: zero-width intervals, [0,0], [1,1],
// subnormals, -0.0 against 0.0, huge dynamic range (1e-30 .. 1e30, both signs), the lit
// sentinel, the extreme finite floats.
IntervalTile special_values_field(uint32_t side, uint64_t seed);

// A realistic scene: terrain slopes (open, zero-width in the west half; a closed slab in
// the east half), closed buildings, open trees (noisy zero-width blobs), a lit border. Used for the big tests and the construction benchmark.
IntervalTile scene_field(uint32_t side, uint64_t seed);

// Every texel the same interval.
IntervalTile constant_field(uint32_t side, Interval value);

struct NamedField {
  std::string name;
  IntervalTile tile;
};
// All generators above (constant = [0.25, 0.5]) at one size.
std::vector<NamedField> all_fields(uint32_t side, uint64_t seed);

// Lossless invariant (ARCHITECTURE.md "Definitions"): returns "" if value(i, j) lies in tile.at(i, j)
// bit-exactly for every texel, else a one-line description of the first failure.
std::string first_violation(const IntervalTile& tile, const std::function<float(uint32_t, uint32_t)>& value);

// True when SHADOWTILE_TEST_SCALE=small (the asan preset): tests shrink their sizes.
bool small_test_scale();

}  // namespace st::fields
