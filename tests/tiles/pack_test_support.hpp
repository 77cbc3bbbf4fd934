// Shared helpers of the cut and pack tests: which encodings this build links, sub-tiles
// of interval fields, bit-exact comparisons of evaluators against hierarchies.
#pragma once
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/encode/hierarchy.hpp"
#include "tiles/core/interval.hpp"
#include "tiles/encode/tile_cut.hpp"

namespace st::packtest {

// The encodings whose encoder and opener are linked into this build.
inline std::vector<Encoding> available_encodings() {
  std::vector<Encoding> out;
  Hierarchy h;
  h.depth = 0;
  h.levels.resize(1);
  h.levels[0].push_back(HNode{0, 0.5f, 0.5f, 0.5f, 0, 1});
  for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
    try {
      auto bytes = encode(h, e);
      open_encoded(e, bytes);
      out.push_back(e);
    } catch (const Error&) {
    }
  }
  return out;
}

// Encodings that keep every hierarchy value bit-exactly (MH §3.2). MMH and DAG-MH may
// re-pick values inside the admissible intervals, so a pack of them answers like its
// tiles' encodings (and the lossless invariant), not like Hierarchy::depth_at.
inline bool exact_values(Encoding e) { return e == Encoding::mh; }

// Texels [x0, x0 + side) x [y0, y0 + side) of `t` as a tile of their own.
inline IntervalTile sub_tile(const IntervalTile& t, uint32_t x0, uint32_t y0, uint32_t side) {
  IntervalTile s;
  s.level = t.level;
  s.x0 = x0;
  s.y0 = y0;
  s.width = s.height = side;
  s.data.resize(size_t(side) * side);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) s.at(i, j) = t.at(x0 + i, y0 + j);
  return s;
}

inline uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

// "" if ev.depth(l, x, y) equals expected(l, x, y) bit-exactly on every texel of every
// level, else the first difference.
template <class Expected>
std::string first_difference(const Evaluator& ev, uint32_t finest, Expected&& expected) {
  for (uint32_t l = 0; l <= finest; ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) {
        float got = ev.depth(l, x, y), want = expected(l, x, y);
        if (bits(got) != bits(want)) {
          char buf[160];
          std::snprintf(buf, sizeof buf, "level %u texel (%llu, %llu): got %.9g, want %.9g", l,
                        (unsigned long long)x, (unsigned long long)y, got, want);
          return buf;
        }
      }
  return "";
}

inline std::string first_difference(const Evaluator& ev, const Hierarchy& h, uint32_t up_to_level = ~0u) {
  return first_difference(ev, std::min(h.depth, up_to_level),
                          [&](uint32_t l, uint64_t x, uint64_t y) { return h.depth_at(l, x, y); });
}

// Every level's answers, level by level, row-major (to compare two evaluators).
inline std::vector<float> all_answers(const Evaluator& ev) {
  std::vector<float> out;
  for (uint32_t l = 0; l <= ev.finest_level(); ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) out.push_back(ev.depth(l, x, y));
  return out;
}
inline std::string first_difference(const Evaluator& ev, const std::vector<float>& want) {
  size_t i = 0;
  return first_difference(ev, ev.finest_level(), [&](uint32_t, uint64_t, uint64_t) { return want.at(i++); });
}

// A fresh path under the test tmp directory.
inline std::string temp_path(const std::string& name) {
  std::filesystem::path dir = std::filesystem::path(SHADOWTILE_TEST_TMP) / "packs";
  std::filesystem::create_directories(dir);
  std::filesystem::path p = dir / name;
  std::filesystem::remove(p);
  std::filesystem::remove(p.string() + ".tmp");
  return p.string();
}

}  // namespace st::packtest
