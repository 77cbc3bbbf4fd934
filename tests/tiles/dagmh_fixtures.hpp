// Test fixtures for the DAG-MH tests: hand-built and random hierarchies (any interval
// per valued node, independent of the MH construction) and a dense reference of the
// admissible interval answering for every texel of every level.
#pragma once
#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/hierarchy.hpp"

namespace st::dagmh_test {

// A random well-formed hierarchy of the given depth: nodes appear with probability
// `p_child` per child slot, valued with probability `p_value` (empty nodes always get a
// valued descendant), intervals from `interval(rng)`. Built depth-first, so every level
// is in morton order.
inline Hierarchy random_hierarchy(uint32_t depth, uint64_t seed, double p_child, double p_value,
                                  const std::function<Interval(fields::Rng&)>& interval) {
  Hierarchy h;
  h.depth = depth;
  h.levels.resize(depth + 1);
  fields::Rng rng(seed);
  // Returns whether the subtree holds a value.
  auto grow = [&](auto&& self, uint32_t level, uint64_t morton, bool must_value) -> void {
    HNode n;
    n.morton = morton;
    const bool valued = must_value || level == depth || rng.uniform() < p_value;
    const size_t at = h.levels[level].size();
    h.levels[level].push_back(n);
    uint8_t mask = 0;
    if (level < depth) {
      for (uint32_t c = 0; c < 4; ++c) {
        const bool force = !valued && c == 3 && mask == 0;  // empty nodes need a child
        if (force || rng.uniform() < p_child) {
          mask |= uint8_t(1u << c);
          self(self, level + 1, morton * 4 + c, false);
        }
      }
    }
    HNode& me = h.levels[level][at];
    me.child_mask = mask;
    me.has_value = valued || mask == 0;
    if (me.has_value) {
      const Interval iv = interval(rng);
      me.lo = iv.lo, me.hi = iv.hi, me.value = iv.lo;
    }
  };
  grow(grow, 0, 0, true);
  return h;
}

// Intervals: a mix of wide, narrow and zero-width ones in [0, 1).
inline Interval mixed_interval(fields::Rng& rng) {
  const float a = float(rng.uniform());
  switch (rng.below(4)) {
    case 0: return {a, a};
    case 1: return {a, std::min(1.0f, a + float(rng.uniform(0, 1e-4)))};
    case 2: return {a, std::min(1.0f, a + float(rng.uniform(0, 0.05)))};
    default: return {a * 0.5f, a};
  }
}

// Dense reference: out[l][y * 2^l + x] = the admissible interval of the deepest valued
// node on the root path to (l, x, y) (hierarchy.hpp "Meaning").
inline std::vector<std::vector<Interval>> admissible_levels(const Hierarchy& h) {
  std::vector<std::vector<Interval>> out(h.depth + 1);
  for (uint32_t l = 0; l <= h.depth; ++l) {
    const uint64_t side = uint64_t(1) << l;
    out[l].resize(side * side);
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x)
        out[l][y * side + x] = l == 0 ? Interval{} : out[l - 1][(y / 2) * (side / 2) + x / 2];
    for (const HNode& n : h.levels[l]) {
      if (!n.has_value) continue;
      const uint64_t x = morton_compact(n.morton), y = morton_compact(n.morton >> 1);
      out[l][y * side + x] = {n.lo, n.hi};
    }
  }
  return out;
}

// The admissible interval answering for (l, x, y), by binary search in the node lists
// (for big sparse hierarchies where admissible_levels would be too large).
inline Interval admissible_at(const Hierarchy& h, uint32_t level, uint64_t x, uint64_t y) {
  Interval iv{h.levels[0][0].lo, h.levels[0][0].hi};
  for (uint32_t l = 1; l <= level && l <= h.depth; ++l) {
    const uint64_t code = morton_encode(uint32_t(x >> (level - l)), uint32_t(y >> (level - l)));
    const auto& lv = h.levels[l];
    auto it = std::lower_bound(lv.begin(), lv.end(), code,
                               [](const HNode& n, uint64_t c) { return n.morton < c; });
    if (it == lv.end() || it->morton != code) break;
    if (it->has_value) iv = {it->lo, it->hi};
  }
  return iv;
}

// Bytes and their evaluator together (the evaluator references the bytes).
struct Opened {
  std::vector<uint8_t> bytes;
  std::unique_ptr<Evaluator> eval;
};
inline Opened encode_and_open(const Hierarchy& h) {
  Opened o;
  o.bytes = encode_dagmh(h);
  o.eval = open_dagmh(o.bytes);
  return o;
}

}  // namespace st::dagmh_test
