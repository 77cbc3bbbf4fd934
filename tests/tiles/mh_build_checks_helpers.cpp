#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/mh_build_checks.hpp"

namespace st::fields {
namespace {

std::string fmt(const char* f, double a, double b = 0, double c = 0, double d = 0, double e = 0) {
  char buf[256];
  std::snprintf(buf, sizeof buf, f, a, b, c, d, e);
  return buf;
}

// Min lo / max hi of the texels below each node, per level, morton order.
struct Envelope {
  std::vector<std::vector<float>> lo, hi;
};
Envelope envelope(const IntervalTile& tile, uint32_t depth) {
  Envelope e;
  e.lo.resize(depth + 1), e.hi.resize(depth + 1);
  size_t count = size_t(1) << (2 * depth);
  e.lo[depth].resize(count), e.hi[depth].resize(count);
  for (size_t m = 0; m < count; ++m) {
    const Interval& v = tile.at(morton_compact(m), morton_compact(m >> 1));
    e.lo[depth][m] = v.lo, e.hi[depth][m] = v.hi;
  }
  for (uint32_t l = depth; l-- > 0;) {
    count >>= 2;
    e.lo[l].resize(count), e.hi[l].resize(count);
    for (size_t m = 0; m < count; ++m) {
      const float* lo = &e.lo[l + 1][4 * m];
      const float* hi = &e.hi[l + 1][4 * m];
      e.lo[l][m] = std::min({lo[0], lo[1], lo[2], lo[3]});
      e.hi[l][m] = std::max({hi[0], hi[1], hi[2], hi[3]});
    }
  }
  return e;
}

}  // namespace

std::vector<std::vector<float>> expand_levels(const Hierarchy& h) {
  std::vector<std::vector<float>> out(h.depth + 1);
  out[0].assign(1, h.levels[0][0].value);
  for (uint32_t l = 1; l <= h.depth; ++l) {
    out[l].resize(size_t(1) << (2 * l));
    for (size_t m = 0; m < out[l].size(); ++m) out[l][m] = out[l - 1][m >> 2];
    for (const HNode& n : h.levels[l])
      if (n.has_value) out[l][n.morton] = n.value;
  }
  return out;
}

std::string check_well_formed(const Hierarchy& h) {
  if (h.levels.size() != size_t(h.depth) + 1) return "levels.size() != depth + 1";
  if (h.levels[0].size() != 1 || h.levels[0][0].morton != 0 || !h.levels[0][0].has_value)
    return "level 0 is not one valued root";
  for (uint32_t l = 0; l <= h.depth; ++l) {
    const auto& lv = h.levels[l];
    size_t children = 0;
    for (size_t j = 0; j < lv.size(); ++j) {
      const HNode& n = lv[j];
      std::string at = "level " + std::to_string(l) + " node " + std::to_string(j) + ": ";
      if (n.morton >> (2 * l) != 0) return at + "morton out of range";
      if (j > 0 && lv[j - 1].morton >= n.morton) return at + "morton not strictly increasing";
      if (n.child_mask > 0xF) return at + "child mask has bits above 3";
      if (l == h.depth && n.child_mask) return at + "finest-level node with children";
      if (!n.has_value && !n.child_mask) return at + "empty node without children";
      if (n.has_value && !(std::isfinite(n.value) && n.lo <= n.value && n.value <= n.hi))
        return at + fmt("value %.9g not in [%.9g, %.9g]", n.value, n.lo, n.hi);
      children += size_t(__builtin_popcount(n.child_mask));
    }
    if (l == h.depth) break;
    const auto& next = h.levels[l + 1];
    if (next.size() != children)
      return "level " + std::to_string(l + 1) + " holds " + std::to_string(next.size()) +
             " nodes, parents' masks say " + std::to_string(children);
    size_t k = 0;
    for (const HNode& n : lv)
      for (uint32_t c = 0; c < 4; ++c)
        if (n.child_mask >> c & 1) {
          if (next[k].morton != 4 * n.morton + c)
            return "level " + std::to_string(l + 1) + " node " + std::to_string(k) + " is not the child its parent's mask says";
          ++k;
        }
  }
  return "";
}

std::string check_lossless(const Hierarchy& h, const IntervalTile& tile) {
  if (tile.width != (1u << h.depth) || tile.height != tile.width) return "tile size does not match depth";
  auto levels = expand_levels(h);
  const auto& fine = levels[h.depth];
  return first_violation(tile, [&](uint32_t i, uint32_t j) { return fine[morton_encode(i, j)]; });
}

std::string check_levels_complete(const Hierarchy& h, const IntervalTile& tile) {
  auto levels = expand_levels(h);
  Envelope e = envelope(tile, h.depth);
  for (uint32_t l = 0; l <= h.depth; ++l)
    for (size_t m = 0; m < levels[l].size(); ++m) {
      float v = levels[l][m];
      if (!(e.lo[l][m] <= v && v <= e.hi[l][m]))
        return "level " + std::to_string(l) +
               fmt(" node (%g, %g): value %.9g outside the envelope [%.9g, %.9g]", morton_compact(m),
                   morton_compact(m >> 1), v, e.lo[l][m], e.hi[l][m]);
    }
  return "";
}

std::string check_admissible(const Hierarchy& h, const IntervalTile& tile, bool exact) {
  // Answering node per texel: propagate global node ids down the levels.
  std::vector<std::vector<uint32_t>> ids(h.depth + 1);
  std::vector<const HNode*> nodes;
  ids[0].assign(1, 0);
  nodes.push_back(&h.levels[0][0]);
  for (uint32_t l = 1; l <= h.depth; ++l) {
    ids[l].resize(size_t(1) << (2 * l));
    for (size_t m = 0; m < ids[l].size(); ++m) ids[l][m] = ids[l - 1][m >> 2];
    for (const HNode& n : h.levels[l])
      if (n.has_value) {
        ids[l][n.morton] = uint32_t(nodes.size());
        nodes.push_back(&n);
      }
  }
  std::vector<float> lo(nodes.size(), -INFINITY), hi(nodes.size(), INFINITY);
  std::vector<uint8_t> used(nodes.size(), 0);
  const auto& fine = ids[h.depth];
  for (size_t m = 0; m < fine.size(); ++m) {
    const Interval& v = tile.at(morton_compact(m), morton_compact(m >> 1));
    uint32_t id = fine[m];
    lo[id] = std::max(lo[id], v.lo), hi[id] = std::min(hi[id], v.hi), used[id] = 1;
  }
  for (size_t id = 0; id < nodes.size(); ++id) {
    const HNode& n = *nodes[id];
    if (!used[id]) {
      if (!exact) continue;
      return fmt("valued node #%g (morton %g) answers for no texel", double(id), double(n.morton));
    }
    bool ok = exact ? (n.lo == lo[id] && n.hi == hi[id]) : (lo[id] <= n.lo && n.hi <= hi[id]);
    if (!ok)
      return fmt("valued node #%g: [lo, hi] = [%.9g, %.9g], texels it answers for give [%.9g, %.9g]", double(id), n.lo,
                 n.hi, lo[id], hi[id]);
  }
  return "";
}

}  // namespace st::fields
