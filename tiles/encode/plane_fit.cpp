#include "tiles/encode/plane_fit.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/core/morton.hpp"

namespace st {

namespace {

using namespace planes;
using LD = long double;

// The fixed-point values that plane_fixed_to_float maps into [lo, hi], shrunk to exclude the
// rounding midpoints (ties): false when the interval is empty, reaches above 1, or has an end
// in (0, 2^-30) (tiny depths: left to the inner encoding).
bool preimage(float lo, float hi, int64_t& vmin, int64_t& vmax) {
  constexpr float kTiny = 0x1p-30f;
  if (!(lo <= hi) || lo > 1.0f) return false;
  if (lo <= 0.0f) {
    vmin = -kOne;
  } else {
    if (lo < kTiny) return false;
    const int64_t f = int64_t(std::ldexp(double(lo), int(kFracBits)));
    const int64_t below = f - int64_t(std::ldexp(double(std::nextafter(lo, 0.0f)), int(kFracBits)));
    vmin = f - below / 2 + 1;
  }
  if (hi >= 1.0f) {
    vmax = 2 * kOne;
  } else if (hi <= 0.0f) {
    if (hi < 0.0f) return false;
    vmax = 0;
  } else {
    if (hi < kTiny) return false;
    const int64_t f = int64_t(std::ldexp(double(hi), int(kFracBits)));
    const int64_t above = int64_t(std::ldexp(double(std::nextafter(hi, 2.0f)), int(kFracBits))) - f;
    vmax = f + above / 2 - 1;
  }
  return vmin <= vmax;
}

// Seidel's randomized incremental LP (feasibility: zero objective) in n <= 3 unknowns,
// each within |x_j| <= box[j]; constraints a . x <= b taken in order. In 1D it returns the
// middle of the feasible interval. Long double: the fit is verified exactly afterwards, the
// LP only has to find a point.
struct Con {
  LD a[3];
  LD b;
};

bool seidel(int n, const LD* box, const Con* cons, size_t count, LD* x) {
  constexpr LD kEps = 1e-15L;
  if (n == 1) {
    LD lo = -box[0], hi = box[0];
    for (size_t i = 0; i < count; ++i) {
      const Con& c = cons[i];
      const LD tol = kEps * (1 + std::fabs(c.b));
      if (c.a[0] > tol) hi = std::min(hi, c.b / c.a[0]);
      else if (c.a[0] < -tol) lo = std::max(lo, c.b / c.a[0]);
      else if (c.b < -tol) return false;
      if (lo > hi) return false;
    }
    x[0] = (lo + hi) / 2;
    return true;
  }
  for (int j = 0; j < n; ++j) x[j] = 0;
  std::vector<Con> sub;
  for (size_t i = 0; i < count; ++i) {
    const Con& h = cons[i];
    LD ax = 0;
    for (int j = 0; j < n; ++j) ax += h.a[j] * x[j];
    if (ax <= h.b + kEps * (1 + std::fabs(h.b))) continue;
    // The new point lies on a . x = b: eliminate the unknown with the largest coefficient.
    int k = 0;
    for (int j = 1; j < n; ++j)
      if (std::fabs(h.a[j]) > std::fabs(h.a[k])) k = j;
    if (std::fabs(h.a[k]) == 0) return false;  // 0 <= b violated
    sub.clear();
    auto project = [&](const LD* ga, LD gb) {
      Con s{};
      const LD r = ga[k] / h.a[k];
      for (int j = 0, t = 0; j < n; ++j)
        if (j != k) s.a[t++] = ga[j] - r * h.a[j];
      s.b = gb - r * h.b;
      sub.push_back(s);
    };
    LD e[3] = {0, 0, 0};
    e[k] = 1;
    project(e, box[k]);
    e[k] = -1;
    project(e, box[k]);
    for (size_t g = 0; g < i; ++g) project(cons[g].a, cons[g].b);
    LD sub_box[2], y[2];
    for (int j = 0, t = 0; j < n; ++j)
      if (j != k) sub_box[t++] = box[j];
    if (!seidel(n - 1, sub_box, sub.data(), sub.size(), y)) return false;
    LD rest = h.b;
    for (int j = 0, t = 0; j < n; ++j)
      if (j != k) {
        x[j] = y[t++];
        rest -= h.a[j] * x[j];
      }
    x[k] = rest / h.a[k];
  }
  return true;
}

// A fixed permutation of a block's texels (the LP's expected time needs a random order;
// a fixed one keeps builds deterministic).
const std::vector<uint32_t>& texel_order(uint32_t shift) {
  static const std::vector<std::vector<uint32_t>> orders = [] {
    std::vector<std::vector<uint32_t>> o(kMaxShift + 1);
    for (uint32_t s = 0; s <= kMaxShift; ++s) {
      const uint32_t side = 1u << s, n = side * side;
      auto& v = o[s];
      // The four corners first: a block across two surfaces fails in a few constraints.
      const uint32_t corners[4] = {0, side - 1, (side - 1) * side, n - 1};
      std::vector<uint8_t> taken(n, 0);
      for (uint32_t c : corners)
        if (!taken[c]) v.push_back(c), taken[c] = 1;
      std::vector<uint32_t> rest;
      for (uint32_t i = 0; i < n; ++i)
        if (!taken[i]) rest.push_back(i);
      uint64_t state = 0x9E3779B97F4A7C15ull;
      for (size_t i = rest.size(); i > 1; --i) {  // Fisher-Yates with a fixed xorshift
        state ^= state << 13, state ^= state >> 7, state ^= state << 17;
        std::swap(rest[i - 1], rest[state % i]);
      }
      v.insert(v.end(), rest.begin(), rest.end());
    }
    return o;
  }();
  return orders[shift];
}

int64_t abs64(int64_t v) { return v < 0 ? -v : v; }

}  // namespace

bool fit_block(std::span<const float> lo, std::span<const float> hi, uint32_t shift, Plane& out) {
  if (shift < kMinShift || shift > kMaxShift) return false;
  const uint32_t side = 1u << shift, n = side * side;
  if (lo.size() < n || hi.size() < n) return false;
  std::vector<int64_t> vmin(n), vmax(n);
  const int64_t margin = 2 * int64_t(side) + 2;  // rounding (a, b, c) to integers moves v by < 2 side
  for (uint32_t i = 0; i < n; ++i) {
    if (!preimage(lo[i], hi[i], vmin[i], vmax[i])) return false;
    vmin[i] += margin;
    vmax[i] -= margin;
    if (vmin[i] > vmax[i]) return false;
  }
  // Unknowns: v = r + unit (a0 + b (x - m) + c (y - m)), m the block's centre, r a reference.
  const int64_t r = vmin[0] / 2 + vmax[0] / 2;
  int64_t width = std::numeric_limits<int64_t>::max();
  for (uint32_t i = 0; i < n; ++i) width = std::min(width, vmax[i] - vmin[i]);
  const LD unit = LD(std::max<int64_t>(width, 1));
  const LD m = LD(side - 1) / 2;
  std::vector<Con> cons;
  cons.reserve(2 * size_t(n));
  for (uint32_t i : texel_order(shift)) {
    const LD u = LD(i % side) - m, v = LD(i / side) - m;
    cons.push_back(Con{{1, u, v}, LD(vmax[i] - r) / unit});
    cons.push_back(Con{{-1, -u, -v}, -(LD(vmin[i] - r) / unit)});
  }
  const LD slope_box = LD(kMaxSlope) / unit;
  const LD box[3] = {LD(kOne) * 4 / unit, slope_box, slope_box};
  LD x[3];
  if (!seidel(3, box, cons.data(), cons.size(), x)) return false;
  const LD bb = std::round(x[1] * unit), cc = std::round(x[2] * unit);
  if (std::fabs(bb) > LD(kMaxSlope) || std::fabs(cc) > LD(kMaxSlope)) return false;
  const LD a0 = std::round(LD(r) + x[0] * unit - bb * m - cc * m);
  if (std::fabs(a0) > LD(kMaxBase)) return false;
  Plane p;
  p.shift = shift;
  p.a = int64_t(a0);
  p.b = int64_t(bb);
  p.c = int64_t(cc);
  if (abs64(p.a) > kMaxBase || abs64(p.b) > kMaxSlope || abs64(p.c) > kMaxSlope) return false;
  for (uint32_t i = 0; i < n; ++i) {  // the decoder's exact answer, texel by texel
    const float d = p.depth(i % side, i / side);
    if (!(lo[i] <= d && d <= hi[i])) return false;
  }
  out = p;
  return true;
}

PlaneSplit fit_planes(const Hierarchy& h, const PlaneFitOptions& o) {
  PlaneSplit out;
  out.pruned = h;
  const uint32_t d = h.depth;
  if (d < std::max(o.min_shift, kMinShift) || d > std::min<uint32_t>(o.max_tile_depth, kMaxLevels - 1) ||
      h.levels.size() != size_t(d) + 1)
    return out;
  const uint32_t side = 1u << d;
  // Every finest texel's admissible interval: the deepest valued node answering it.
  std::vector<float> lo(size_t(side) * side), hi(size_t(side) * side);
  for (uint32_t l = 0; l <= d; ++l) {
    const uint32_t s = d - l, w = 1u << s;
    for (const HNode& n : h.levels[l]) {
      if (!n.has_value) continue;
      const uint32_t x0 = morton_compact(n.morton) << s, y0 = morton_compact(n.morton >> 1) << s;
      for (uint32_t y = y0; y < y0 + w; ++y) {
        std::fill_n(lo.begin() + size_t(y) * side + x0, w, n.lo);
        std::fill_n(hi.begin() + size_t(y) * side + x0, w, n.hi);
      }
    }
  }
  // Valued nodes in each subtree (the node's own value excluded), bottom-up.
  const auto first = h.first_child_index();
  std::vector<std::vector<uint32_t>> below(d + 1);
  for (uint32_t l = d + 1; l-- > 0;) {
    below[l].assign(h.levels[l].size(), 0);
    if (l == d) continue;
    for (size_t j = 0; j < h.levels[l].size(); ++j) {
      const HNode& n = h.levels[l][j];
      uint32_t sum = 0;
      for (uint32_t c = 0, k = first[l][j]; c < uint32_t(std::popcount(unsigned(n.child_mask))); ++c, ++k)
        sum += below[l + 1][k] + h.levels[l + 1][k].has_value;
      below[l][j] = sum;
    }
  }
  // Top-down: a node's block is tried before its children's.
  std::vector<std::vector<uint8_t>> cut(d + 1);
  for (uint32_t l = 0; l <= d; ++l) cut[l].assign(h.levels[l].size(), 0);
  std::vector<float> blo, bhi;
  auto visit = [&](auto&& self, uint32_t l, size_t j) -> void {
    const HNode& n = h.levels[l][j];
    if (!n.child_mask) return;
    const uint32_t s = d - l;
    if (s < o.min_shift || s < kMinShift) return;
    if (s <= kMaxShift && below[l][j] >= o.min_stored_nodes) {
      const uint32_t w = 1u << s;
      const uint32_t x0 = morton_compact(n.morton) << s, y0 = morton_compact(n.morton >> 1) << s;
      blo.resize(size_t(w) * w);
      bhi.resize(size_t(w) * w);
      for (uint32_t y = 0; y < w; ++y) {
        std::copy_n(lo.begin() + size_t(y0 + y) * side + x0, w, blo.begin() + size_t(y) * w);
        std::copy_n(hi.begin() + size_t(y0 + y) * side + x0, w, bhi.begin() + size_t(y) * w);
      }
      Plane p;
      if (fit_block(blo, bhi, s, p)) {
        p.start = uint32_t(n.morton << (2 * s));
        out.planes.push_back(p);
        out.texels += uint64_t(w) * w;
        cut[l][j] = 1;
        return;
      }
    }
    for (uint32_t c = 0, k = first[l][j]; c < uint32_t(std::popcount(unsigned(n.child_mask))); ++c, ++k)
      self(self, l + 1, k);
  };
  visit(visit, 0, 0);
  if (out.planes.empty()) return out;
  std::sort(out.planes.begin(), out.planes.end(), [](const Plane& a, const Plane& b) { return a.start < b.start; });
  // Prune: drop the blocks' descendants, then empty nodes left without children.
  std::vector<std::vector<uint8_t>> drop(d + 1);
  for (uint32_t l = 0; l <= d; ++l) drop[l].assign(h.levels[l].size(), 0);
  std::vector<std::vector<uint8_t>> mask(d + 1);
  for (uint32_t l = 0; l <= d; ++l) {
    mask[l].resize(h.levels[l].size());
    for (size_t j = 0; j < h.levels[l].size(); ++j) mask[l][j] = cut[l][j] ? 0 : h.levels[l][j].child_mask;
  }
  for (uint32_t l = 0; l < d; ++l)
    for (size_t j = 0; j < h.levels[l].size(); ++j)
      for (uint32_t c = 0, k = first[l][j]; c < uint32_t(std::popcount(unsigned(h.levels[l][j].child_mask))); ++c, ++k)
        drop[l + 1][k] = drop[l][j] || cut[l][j];
  for (uint32_t l = d; l > 0; --l)  // bottom-up: an empty node whose children all went goes too
    for (size_t j = 0; j < h.levels[l - 1].size(); ++j) {
      const HNode& pn = h.levels[l - 1][j];
      for (uint32_t c = 0, k = first[l - 1][j]; c < 4; ++c) {
        if (!(pn.child_mask >> c & 1)) continue;
        if (!drop[l][k] && !h.levels[l][k].has_value && mask[l][k] == 0) drop[l][k] = 1;
        if (drop[l][k]) mask[l - 1][j] &= uint8_t(~(1u << c));
        ++k;
      }
    }
  for (uint32_t l = 0; l <= d; ++l) {
    auto& dst = out.pruned.levels[l];
    dst.clear();
    for (size_t j = 0; j < h.levels[l].size(); ++j) {
      if (drop[l][j]) continue;
      HNode n = h.levels[l][j];
      n.child_mask = mask[l][j];
      dst.push_back(n);
    }
  }
  return out;
}

std::vector<uint8_t> wrap_planes(const std::vector<Plane>& ps, uint32_t finest_level, std::span<const uint8_t> inner) {
  ST_CHECK(!ps.empty() && ps.size() <= kMaxPlanes && finest_level + 1 <= kMaxLevels);
  const size_t size = kHeaderSize + ps.size() * kRecordSize + inner.size();
  if (size > 0xFFFFFFFFull) throw Error("plane tile: " + std::to_string(size) + " bytes do not fit its 32-bit size");
  std::vector<uint8_t> out(size, 0);
  store_le<uint32_t>(out.data() + kOffMagic, kMagic);
  store_le<uint16_t>(out.data() + kOffVersion, kVersion);
  out[kOffLevels] = uint8_t(finest_level + 1);
  store_le<uint32_t>(out.data() + kOffPlaneCount, uint32_t(ps.size()));
  store_le<uint32_t>(out.data() + kOffByteSize, uint32_t(size));
  for (size_t i = 0; i < ps.size(); ++i) {
    uint8_t* r = out.data() + kHeaderSize + i * kRecordSize;
    store_le<uint32_t>(r + kOffStart, ps[i].start);
    store_le<uint32_t>(r + kOffShift, ps[i].shift);
    store_le<uint64_t>(r + kOffA, uint64_t(ps[i].a));
    store_le<uint64_t>(r + kOffB, uint64_t(ps[i].b));
    store_le<uint64_t>(r + kOffC, uint64_t(ps[i].c));
  }
  std::copy(inner.begin(), inner.end(), out.begin() + ptrdiff_t(kHeaderSize + ps.size() * kRecordSize));
  return out;
}

}  // namespace st
