// Bottom-up construction of the octree of a shadow-map stack (MH 2016 §4 with §3.1
// Alg. 2). Working state as in mh_build.cpp: one dense array per level < L in code order
// (node P's children are the codes (P << a) | 0..2^a-1 of the next level) holding the
// node's interval and two child masks; level L is the stack itself.
//
// The level step is the 2x2 step of mh_level_step.hpp widened to eight slots: the
// parent's interval is [max lo, min hi] over its children if non-empty (all covered);
// otherwise the mode of MH Fig. 3, the child lower bound lying inside the most child
// intervals (ties: most covered children without stored descendants, then the lowest
// slot), with I the intersection of the covered children. A child is covered iff its
// interval contains I; covered children vanish, or turn empty if they have descendants.
#include "tiles/encode/mh_octree_build.hpp"

#include <algorithm>
#include <cfloat>
#include <cstdio>
#include <memory>
#include <string>

#include "common/error.hpp"
#include "tiles/encode/mh_internal.hpp"

namespace st {
namespace {

constexpr uint32_t kMaxSliceLevel = 14;  // slices are at most 2^14 texels a side
constexpr float kNeutralLo = -FLT_MAX, kNeutralHi = FLT_MAX;  // placeholder interval (header)

inline uint32_t pop8(uint32_t m) { return moct::popcount16(m & 0xFFu); }

// The slot <-> compact mapping (the bits a step adds: Geometry::step_bits).
inline uint32_t slot_of(const moct::Geometry& g, uint32_t l, uint32_t comp) {
  return g.splits_xy(l) ? comp : comp << 2;  // xy (+w): slot = comp; w only: comp is cw
}

struct Step {
  float lo, hi;
  uint8_t present, valued;  // slot masks
};

// The eight-slot level step (see the file comment). `slots`: the slots this level uses.
inline Step level_step(const float lo[8], const float hi[8], uint32_t slots, uint32_t desc) {
  float l = -FLT_MAX, h = FLT_MAX;
  for (uint32_t m = slots; m; m &= m - 1) {
    const uint32_t c = uint32_t(__builtin_ctz(m));
    l = std::max(l, lo[c]), h = std::min(h, hi[c]);
  }
  if (l <= h) return {l, h, uint8_t(desc), 0};
  uint32_t best = 0, best_mask = 0, best_score = 0;
  for (uint32_t mi = slots; mi; mi &= mi - 1) {
    const uint32_t i = uint32_t(__builtin_ctz(mi));
    uint32_t mask = 0;
    for (uint32_t mj = slots; mj; mj &= mj - 1) {
      const uint32_t j = uint32_t(__builtin_ctz(mj));
      mask |= uint32_t(lo[j] <= lo[i] && lo[i] <= hi[j]) << j;
    }
    const uint32_t score = pop8(mask) * 16 + pop8(mask & ~desc);
    if (score > best_score) best_score = score, best = i, best_mask = mask;
  }
  float ih = FLT_MAX;
  for (uint32_t m = best_mask; m; m &= m - 1) ih = std::min(ih, hi[__builtin_ctz(m)]);
  const uint32_t valued = slots & ~best_mask;
  return {lo[best], ih, uint8_t(valued | (best_mask & desc)), uint8_t(valued)};
}

struct Dense {
  std::vector<size_t> base;  // base[l]: offset of level l (levels 0..L-1)
  std::unique_ptr<float[]> lo, hi;
  std::unique_ptr<uint8_t[]> present, valued;
  explicit Dense(const moct::Geometry& g) : base(g.depth() + 1, 0) {
    for (uint32_t l = 0; l < g.depth(); ++l) base[l + 1] = base[l] + (size_t(1) << (2 * g.xy_bits(l) + g.w_bits(l)));
    const size_t count = base[g.depth()];
    lo.reset(new float[count]), hi.reset(new float[count]);
    present.reset(new uint8_t[count]), valued.reset(new uint8_t[count]);
  }
  void store(size_t i, const Step& s) { lo[i] = s.lo, hi[i] = s.hi, present[i] = s.present, valued[i] = s.valued; }
};

inline bool interval_ok(const Interval& v) { return (v.lo >= -FLT_MAX) && (v.lo <= v.hi) && (v.hi <= FLT_MAX); }

// The child (x, y, w) of slot c at level l + 1 of the node (x, y, w) at level l.
inline void child_coords(const moct::Geometry& g, uint32_t l, uint32_t c, uint64_t& x, uint64_t& y, uint64_t& w) {
  if (g.splits_xy(l)) x = 2 * x + (c & 1), y = 2 * y + (c >> 1 & 1);
  if (g.splits_w(l)) w = 2 * w + (c >> 2 & 1);
}

Interval texel(const IntervalStack& s, uint64_t x, uint64_t y, uint64_t w) {
  if (w >= s.slices) return {kNeutralLo, kNeutralHi};
  return s.at(x, y, w);
}

void validate_stack(const IntervalStack& s, uint32_t k) {
  if (s.level > kMaxSliceLevel)
    throw Error("build_octree: slices of 2^" + std::to_string(s.level) + " texels a side exceed 2^" +
                std::to_string(kMaxSliceLevel));
  if (k > moct::kMaxWLevel || s.slices < 1 || s.slices > (1u << k))
    throw Error("build_octree: " + std::to_string(s.slices) + " slices, expected 1.." +
                std::to_string(1u << std::min<uint32_t>(k, moct::kMaxWLevel)));
  const size_t want = size_t(s.side() * s.side()) * s.slices;
  if (s.data.size() != want)
    throw Error("build_octree: the stack holds " + std::to_string(s.data.size()) + " intervals, expected " +
                std::to_string(want));
  bool ok = true;
  for (const Interval& v : s.data) ok &= interval_ok(v);
  if (ok) return;
  for (size_t i = 0; i < s.data.size(); ++i) {
    if (interval_ok(s.data[i])) continue;
    const size_t area = size_t(s.side() * s.side());
    char bounds[64];
    std::snprintf(bounds, sizeof bounds, "[%.9g, %.9g]", double(s.data[i].lo), double(s.data[i].hi));
    throw Error("build_octree: texel (" + std::to_string(i % s.side()) + ", " + std::to_string(i % area / s.side()) +
                ") of slice " + std::to_string(i / area) + ": interval " + bounds + " is not finite with lo <= hi");
  }
}

}  // namespace

uint64_t oct_code(const moct::Geometry& g, uint32_t l, uint64_t x, uint64_t y, uint64_t w) {
  uint64_t code = 0;
  for (uint32_t j = 0; j < l; ++j) {
    uint32_t comp = 0;
    if (g.splits_xy(j)) {
      const uint32_t b = g.xy_bits(l) - g.xy_bits(j + 1);
      comp = uint32_t((x >> b) & 1) | uint32_t((y >> b) & 1) << 1;
      if (g.splits_w(j)) comp |= uint32_t((w >> (g.w_bits(l) - g.w_bits(j + 1))) & 1) << 2;
    } else {
      comp = uint32_t((w >> (g.w_bits(l) - g.w_bits(j + 1))) & 1);
    }
    code = (code << g.step_bits(j)) | comp;
  }
  return code;
}

void oct_coords(const moct::Geometry& g, uint32_t l, uint64_t code, uint64_t& x, uint64_t& y, uint64_t& w) {
  x = y = w = 0;
  for (uint32_t j = l; j-- > 0;) {
    const uint32_t a = g.step_bits(j);
    const uint32_t c = slot_of(g, j, uint32_t(code & ((1u << a) - 1)));
    code >>= a;
    if (g.splits_xy(j)) {
      const uint32_t b = g.xy_bits(l) - g.xy_bits(j + 1);
      x |= uint64_t(c & 1) << b, y |= uint64_t(c >> 1 & 1) << b;
    }
    if (g.splits_w(j)) w |= uint64_t(c >> 2 & 1) << (g.w_bits(l) - g.w_bits(j + 1));
  }
}

size_t OctHierarchy::node_count() const {
  size_t n = 0;
  for (const auto& lv : levels) n += lv.size();
  return n;
}

size_t OctHierarchy::valued_count() const {
  size_t n = 0;
  for (const auto& lv : levels)
    for (const OctNode& v : lv) n += v.has_value;
  return n;
}

float OctHierarchy::depth_at(uint32_t l, uint64_t x, uint64_t y, uint64_t w) const {
  float v = levels[0][0].value;
  for (uint32_t j = 1; j <= l && j < levels.size(); ++j) {
    const uint64_t code = oct_code(geo, j, x >> (geo.xy_bits(l) - geo.xy_bits(j)), y >> (geo.xy_bits(l) - geo.xy_bits(j)),
                                   w >> (geo.w_bits(l) - geo.w_bits(j)));
    const auto& lv = levels[j];
    auto it = std::lower_bound(lv.begin(), lv.end(), code, [](const OctNode& n, uint64_t c) { return n.code < c; });
    if (it == lv.end() || it->code != code) break;
    if (it->has_value) v = it->value;
  }
  return v;
}

OctHierarchy build_octree(const IntervalStack& stack, std::optional<uint32_t> w_level) {
  uint32_t k = 0;
  while (k < 31 && (1u << k) < stack.slices) ++k;
  if (w_level) k = *w_level;
  validate_stack(stack, k);
  OctHierarchy h;
  h.geo = moct::Geometry{stack.level, k};
  h.slices = stack.slices;
  const moct::Geometry& g = h.geo;
  const uint32_t L = g.depth();
  h.levels.resize(L + 1);
  if (L == 0) {
    const Interval& t = stack.data[0];
    h.levels[0].push_back(OctNode{0, mh_detail::central_roundest(t.lo, t.hi), t.lo, t.hi, 0, 1});
    return h;
  }
  Dense d(g);
  // Level L - 1 from the stack.
  {
    const uint32_t l = L - 1, slots = g.slot_set(l);
    const size_t count = size_t(1) << (2 * g.xy_bits(l) + g.w_bits(l)), out = d.base[l];
    float lo[8] = {}, hi[8] = {};
    for (size_t m = 0; m < count; ++m) {
      uint64_t px = 0, py = 0, pw = 0;
      oct_coords(g, l, m, px, py, pw);
      for (uint32_t s = slots; s; s &= s - 1) {
        const uint32_t c = uint32_t(__builtin_ctz(s));
        uint64_t x = px, y = py, w = pw;
        child_coords(g, l, c, x, y, w);
        const Interval t = texel(stack, x, y, w);
        lo[c] = t.lo, hi[c] = t.hi;
      }
      d.store(out + m, level_step(lo, hi, slots, 0));
    }
  }
  for (uint32_t l = L - 1; l-- > 0;) {
    const uint32_t a = g.step_bits(l), slots = g.slot_set(l);
    const size_t count = size_t(1) << (2 * g.xy_bits(l) + g.w_bits(l)), out = d.base[l], in = d.base[l + 1];
    float lo[8] = {}, hi[8] = {};
    for (size_t m = 0; m < count; ++m) {
      uint32_t desc = 0;
      for (uint32_t comp = 0; comp < (1u << a); ++comp) {
        const size_t i = in + (m << a) + comp;
        const uint32_t c = slot_of(g, l, comp);
        lo[c] = d.lo[i], hi[c] = d.hi[i];
        desc |= uint32_t(d.present[i] != 0) << c;
      }
      d.store(out + m, level_step(lo, hi, slots, desc));
    }
  }
  // Emit present nodes level by level, parents in code order and children in slot order,
  // which keeps every level sorted by code.
  h.levels[0].push_back(
      OctNode{0, mh_detail::central_roundest(d.lo[0], d.hi[0]), d.lo[0], d.hi[0], d.present[0], 1});
  for (uint32_t l = 1; l <= L; ++l) {
    const auto& parents = h.levels[l - 1];
    auto& nodes = h.levels[l];
    size_t total = 0;
    for (const OctNode& p : parents) total += pop8(p.child_mask);
    nodes.reserve(total);
    const uint32_t pl = l - 1, a = g.step_bits(pl);
    for (const OctNode& p : parents) {
      const uint32_t vmask = d.valued[d.base[pl] + p.code];
      uint64_t px = 0, py = 0, pw = 0;
      if (l == L) oct_coords(g, pl, p.code, px, py, pw);
      for (uint32_t mask = p.child_mask; mask; mask &= mask - 1) {
        const uint32_t c = uint32_t(__builtin_ctz(mask));
        const uint32_t comp = g.splits_xy(pl) ? c : c >> 2;
        const uint64_t code = (p.code << a) | comp;
        if (l < L) {
          const size_t i = d.base[l] + code;
          if (vmask >> c & 1)
            nodes.push_back(
                OctNode{code, mh_detail::central_roundest(d.lo[i], d.hi[i]), d.lo[i], d.hi[i], d.present[i], 1});
          else
            nodes.push_back(OctNode{code, 0, 0, 0, d.present[i], 0});
        } else {
          uint64_t x = px, y = py, w = pw;
          child_coords(g, pl, c, x, y, w);
          ST_CHECK(w < stack.slices);  // placeholders are always covered
          const Interval& t = stack.at(x, y, w);
          nodes.push_back(OctNode{code, mh_detail::central_roundest(t.lo, t.hi), t.lo, t.hi, 0, 1});
        }
      }
    }
  }
  return h;
}

std::vector<std::vector<float>> octree_top_values(const moct::Geometry& g, uint32_t lb, const std::vector<Interval>& iv,
                                                  const std::vector<uint8_t>& child_mask, size_t* present_nodes) {
  const size_t nb = size_t(1) << (2 * g.xy_bits(lb) + g.w_bits(lb));
  if (lb > g.depth() || iv.size() != nb || child_mask.size() != nb)
    throw Error("octree_top_values: level " + std::to_string(lb) + " needs " + std::to_string(nb) + " nodes");
  // lo/hi/present (child mask)/valued (mask of valued children) per level, code order.
  std::vector<std::vector<float>> lo(lb + 1), hi(lb + 1);
  std::vector<std::vector<uint8_t>> present(lb + 1), valued(lb + 1);
  lo[lb].resize(nb), hi[lb].resize(nb), present[lb] = child_mask, valued[lb].assign(nb, 0);
  for (size_t i = 0; i < nb; ++i) lo[lb][i] = iv[i].lo, hi[lb][i] = iv[i].hi;
  for (uint32_t l = lb; l-- > 0;) {
    const uint32_t a = g.step_bits(l), slots = g.slot_set(l);
    const size_t count = size_t(1) << (2 * g.xy_bits(l) + g.w_bits(l));
    lo[l].resize(count), hi[l].resize(count), present[l].resize(count), valued[l].resize(count);
    float clo[8] = {}, chi[8] = {};
    for (size_t m = 0; m < count; ++m) {
      uint32_t desc = 0;
      for (uint32_t comp = 0; comp < (1u << a); ++comp) {
        const size_t i = (m << a) + comp;
        const uint32_t c = slot_of(g, l, comp);
        clo[c] = lo[l + 1][i], chi[c] = hi[l + 1][i];
        desc |= uint32_t(present[l + 1][i] != 0) << c;
      }
      const Step s = level_step(clo, chi, slots, desc);
      lo[l][m] = s.lo, hi[l][m] = s.hi, present[l][m] = s.present, valued[l][m] = s.valued;
    }
  }
  // Top-down: the root is valued; a child is valued iff its parent is present and its
  // slot is in the parent's valued mask (build_octree's emission); others inherit.
  std::vector<std::vector<float>> v(lb + 1);
  std::vector<std::vector<uint8_t>> is_present(lb + 1);
  v[0] = {mh_detail::central_roundest(lo[0][0], hi[0][0])};
  is_present[0] = {1};
  for (uint32_t l = 1; l <= lb; ++l) {
    const uint32_t a = g.step_bits(l - 1);
    const size_t count = lo[l].size();
    v[l].resize(count), is_present[l].assign(count, 0);
    for (size_t i = 0; i < count; ++i) {
      const size_t p = i >> a;
      const uint32_t c = slot_of(g, l - 1, uint32_t(i & ((size_t(1) << a) - 1)));
      const bool here = is_present[l - 1][p] && (present[l - 1][p] >> c & 1);
      is_present[l][i] = here;
      v[l][i] = here && (valued[l - 1][p] >> c & 1) ? mh_detail::central_roundest(lo[l][i], hi[l][i]) : v[l - 1][p];
    }
  }
  if (present_nodes) {
    *present_nodes = 0;
    for (uint32_t l = 0; l < lb; ++l)
      for (uint8_t b : is_present[l]) *present_nodes += b;
  }
  return v;
}

}  // namespace st
