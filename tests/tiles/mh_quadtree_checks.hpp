// Checks shared by the MH quadtree and MMH tests: an encoded tree read back through the
// Evaluator interface against the hierarchy it came from and the texel intervals.
// Each returns "" when the property holds, else a one-line description of the first
// failure.
#pragma once
#include <algorithm>
#include <bit>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tests/tiles/mh_build_checks.hpp"
#include "common/error.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"

namespace st::mhtest {

inline std::string at_texel(uint32_t l, uint64_t x, uint64_t y, float got) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "level %u texel (%llu, %llu): got %.9g", l, (unsigned long long)x,
                (unsigned long long)y, double(got));
  return buf;
}

// Every level, every texel: bit-identical to the hierarchy's depth(l, x, y) (the MH
// quadtree stores the hierarchy's values as they are; -0.0 stays -0.0).
inline std::string check_equals_hierarchy(const Evaluator& ev, const Hierarchy& h) {
  if (ev.finest_level() != h.depth) return "finest_level differs from the hierarchy depth";
  const auto maps = fields::expand_levels(h);
  for (uint32_t l = 0; l <= h.depth; ++l)
    for (uint64_t m = 0; m < maps[l].size(); ++m) {
      const uint64_t x = morton_compact(m), y = morton_compact(m >> 1);
      const float got = ev.depth(l, x, y);
      if (std::bit_cast<uint32_t>(got) != std::bit_cast<uint32_t>(maps[l][m]))
        return at_texel(l, x, y, got) + ", hierarchy has " + std::to_string(maps[l][m]);
    }
  return "";
}

// Every level, every texel: inside [lo, hi] of the hierarchy node that answers there
// (the deepest valued node on its root path), the contract MMH keeps while it changes
// values inside those intervals.
inline std::string check_within_answering_intervals(const Evaluator& ev, const Hierarchy& h) {
  if (ev.finest_level() != h.depth) return "finest_level differs from the hierarchy depth";
  std::vector<float> lo{h.levels[0][0].lo}, hi{h.levels[0][0].hi};
  for (uint32_t l = 0; l <= h.depth; ++l) {
    if (l > 0) {
      std::vector<float> nlo(size_t(1) << (2 * l)), nhi(nlo.size());
      for (size_t m = 0; m < nlo.size(); ++m) nlo[m] = lo[m >> 2], nhi[m] = hi[m >> 2];
      for (const HNode& n : h.levels[l])
        if (n.has_value) nlo[n.morton] = n.lo, nhi[n.morton] = n.hi;
      lo.swap(nlo);
      hi.swap(nhi);
    }
    for (uint64_t m = 0; m < lo.size(); ++m) {
      const uint64_t x = morton_compact(m), y = morton_compact(m >> 1);
      const float got = ev.depth(l, x, y);
      if (!(lo[m] <= got && got <= hi[m]))
        return at_texel(l, x, y, got) + " outside its node's [" + std::to_string(lo[m]) + ", " +
               std::to_string(hi[m]) + "]";
    }
  }
  return "";
}

// Lossless at the finest level and every coarser level within [min lo, max hi] of the
// texels below it (ARCHITECTURE.md "Definitions", "Multiresolution").
inline std::string check_lossless_all_levels(const Evaluator& ev, const IntervalTile& tile) {
  const uint32_t depth = tile.level;
  if (ev.finest_level() != depth) return "finest_level differs from the tile level";
  const size_t side = size_t(1) << depth;
  std::vector<float> lo(side * side), hi(side * side);
  for (size_t y = 0; y < side; ++y)
    for (size_t x = 0; x < side; ++x) {
      const Interval& v = tile.at(uint32_t(x), uint32_t(y));
      const float got = ev.depth(depth, x, y);
      if (!(v.lo <= got && got <= v.hi))
        return at_texel(depth, x, y, got) + " outside the texel's [" + std::to_string(v.lo) + ", " +
               std::to_string(v.hi) + "]";
      lo[y * side + x] = v.lo, hi[y * side + x] = v.hi;
    }
  for (uint32_t l = depth; l-- > 0;) {
    const size_t s = size_t(1) << l;
    std::vector<float> nlo(s * s), nhi(s * s);
    for (size_t y = 0; y < s; ++y)
      for (size_t x = 0; x < s; ++x) {
        const size_t a = 2 * y * 2 * s + 2 * x, b = a + 2 * s;
        nlo[y * s + x] = std::min({lo[a], lo[a + 1], lo[b], lo[b + 1]});
        nhi[y * s + x] = std::max({hi[a], hi[a + 1], hi[b], hi[b + 1]});
        const float got = ev.depth(l, x, y);
        if (!(nlo[y * s + x] <= got && got <= nhi[y * s + x])) return at_texel(l, x, y, got) + " outside [min lo, max hi]";
      }
    lo.swap(nlo);
    hi.swap(nhi);
  }
  return "";
}

// pcf() against the base class's r*r independent lookups, bit-exactly, for every kernel
// size at the given centres of one level.
inline std::string check_pcf(const Evaluator& ev, uint32_t level, const std::vector<std::pair<uint64_t, uint64_t>>& at,
                             const std::vector<float>& receivers) {
  for (auto [x, y] : at)
    for (uint32_t r = 1; r <= Evaluator::kMaxPcf; ++r)
      for (float rec : receivers) {
        const float fast = ev.pcf(level, x, y, r, rec);
        const float ref = ev.Evaluator::pcf(level, x, y, r, rec);
        if (std::bit_cast<uint32_t>(fast) != std::bit_cast<uint32_t>(ref))
          return "pcf level " + std::to_string(level) + " at (" + std::to_string(x) + ", " + std::to_string(y) +
                 ") r " + std::to_string(r) + " receiver " + std::to_string(rec) + ": " + std::to_string(fast) +
                 " != " + std::to_string(ref);
      }
  return "";
}

}  // namespace st::mhtest

namespace st::mhtest {

// Hostile input: every truncation of `bytes` must be rejected with st::FormatError, and
// every corrupted copy must either be rejected or answer lookups at every level and PCF
// without reading out of bounds (the asan preset checks that part). Returns the number
// of corrupted copies that still opened.
template <class Open>
size_t check_hostile(const std::vector<uint8_t>& bytes, Open open, uint32_t flips, uint64_t seed, std::string& err) {
  for (size_t len = 0; len < bytes.size(); ++len) {
    std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(len));
    try {
      open(std::span<const uint8_t>(cut));
      err = "truncation to " + std::to_string(len) + " bytes was accepted";
      return 0;
    } catch (const FormatError&) {
    }
  }
  std::vector<uint8_t> longer = bytes;
  longer.push_back(0);
  try {
    open(std::span<const uint8_t>(longer));
    err = "a trailing byte was accepted";
    return 0;
  } catch (const FormatError&) {
  }
  uint64_t s = seed;
  auto next = [&s] {
    s += 0x9E3779B97F4A7C15ull;
    uint64_t z = s;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  };
  size_t opened = 0;
  for (uint32_t f = 0; f < flips; ++f) {
    std::vector<uint8_t> bad = bytes;
    const uint32_t nflips = 1 + uint32_t(next() % 3);
    for (uint32_t k = 0; k < nflips; ++k) bad[next() % bad.size()] ^= uint8_t(1u << (next() % 8));
    std::unique_ptr<Evaluator> ev;
    try {
      ev = open(std::span<const uint8_t>(bad));
    } catch (const FormatError&) {
      continue;
    }
    ++opened;
    const uint32_t finest = ev->finest_level();
    for (uint32_t l = 0; l <= finest; ++l) {
      const uint64_t side = uint64_t(1) << l;
      for (uint64_t y = 0; y < side; ++y)
        for (uint64_t x = 0; x < side; ++x) (void)ev->depth(l, x, y);
      (void)ev->pcf(l, side / 2, side / 2, 5, 0.5f);
      (void)ev->pcf(l, 0, side - 1, 9, 0.5f);
    }
  }
  return opened;
}

}  // namespace st::mhtest
