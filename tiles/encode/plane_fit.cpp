#include "tiles/encode/plane_fit.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <tuple>
#include <unordered_map>

#include "common/bit_count.hpp"
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
  // x 2^kFracBits is exact for these floats (powers of two scale exactly: ldexp's value), and
  // a positive finite float's neighbours are its bit pattern -1 / +1 (nextafter's).
  constexpr double kScale = 0x1p60;
  static_assert(kFracBits == 60);
  if (!(lo <= hi) || lo > 1.0f) return false;
  if (lo <= 0.0f) {
    vmin = -kOne;
  } else {
    if (lo < kTiny) return false;
    const int64_t f = int64_t(double(lo) * kScale);
    const float down = std::bit_cast<float>(std::bit_cast<uint32_t>(lo) - 1);  // nextafter(lo, 0)
    const int64_t below = f - int64_t(double(down) * kScale);
    vmin = f - below / 2 + 1;
  }
  if (hi >= 1.0f) {
    vmax = 2 * kOne;
  } else if (hi <= 0.0f) {
    if (hi < 0.0f) return false;
    vmax = 0;
  } else {
    if (hi < kTiny) return false;
    const int64_t f = int64_t(double(hi) * kScale);
    const float up = std::bit_cast<float>(std::bit_cast<uint32_t>(hi) + 1);  // nextafter(hi, 2)
    const int64_t above = int64_t(double(up) * kScale) - f;
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

// Constraints [0, start) were taken already, x the point they left (a run resumed after
// constraints were appended gives the bits of a run from the start: the same steps in the
// same order). The projected constraints of each level live in a per-thread buffer.
bool seidel(int n, const LD* box, const Con* cons, size_t count, LD* x, size_t start = 0) {
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
  if (start == 0)
    for (int j = 0; j < n; ++j) x[j] = 0;
  thread_local std::vector<Con> subs[4];
  std::vector<Con>& sub = subs[n];
  for (size_t i = start; i < count; ++i) {
    const Con& h = cons[i];
    LD ax = 0;
    for (int j = 0; j < n; ++j) ax += h.a[j] * x[j];
    if (ax <= h.b + kEps * (1 + std::fabs(h.b))) continue;
    // The new point lies on a . x = b: eliminate the unknown with the largest coefficient.
    int k = 0;
    for (int j = 1; j < n; ++j)
      if (std::fabs(h.a[j]) > std::fabs(h.a[k])) k = j;
    if (std::fabs(h.a[k]) == 0) return false;  // 0 <= b violated
    sub.resize(i + 2);
    Con* out = sub.data();
    auto project = [&](const LD* ga, LD gb) {
      Con s{};
      const LD r = ga[k] / h.a[k];
      for (int j = 0, t = 0; j < n; ++j)
        if (j != k) s.a[t++] = ga[j] - r * h.a[j];
      s.b = gb - r * h.b;
      *out++ = s;
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
    if (!seidel(n - 1, sub_box, sub.data(), i + 2, y)) return false;
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

int64_t abs64(int64_t v) { return v < 0 ? (v == INT64_MIN ? INT64_MAX : -v) : v; }

// Whether plane p answers every texel of its block within [lo, hi] (the decoder's function;
// corners first, so a plane of another surface fails fast).
bool answers(const Plane& p, std::span<const float> lo, std::span<const float> hi) {
  const uint32_t side = 1u << p.shift;
  for (uint32_t i : texel_order(p.shift)) {
    const float d = p.depth(i % side, i / side);
    if (!(lo[i] <= d && d <= hi[i])) return false;
  }
  return true;
}

// One texel's two constraints on the LP's unknowns (u, v: its offset from the centre):
// vmin <= r + unit (a0 + b u + c v) <= vmax.
void push_texel_cons(std::vector<Con>& cons, LD u, LD v, int64_t vmin, int64_t vmax, int64_t r, LD unit) {
  cons.push_back(Con{{1, u, v}, LD(vmax - r) / unit});
  cons.push_back(Con{{-1, -u, -v}, -(LD(vmin - r) / unit)});
}

// The LP over `cons` solved in its box and rounded to integers: slopes bb, cc (each within
// kMaxSlope, else false) and a0, the value at (0, 0) for the centre (mx, my).
// `x`, `start`: resume the LP (seidel) after constraints were appended to those it solved.
bool solve_rounded(const std::vector<Con>& cons, int64_t r, LD unit, LD mx, LD my, LD& a0, LD& bb, LD& cc,
                   LD* x = nullptr, size_t start = 0) {
  const LD slope_box = LD(kMaxSlope) / unit;
  const LD box[3] = {LD(kOne) * 4 / unit, slope_box, slope_box};
  LD own[3];
  if (!x) x = own, start = 0;
  if (!seidel(3, box, cons.data(), cons.size(), x, start)) return false;
  bb = std::round(x[1] * unit), cc = std::round(x[2] * unit);
  if (std::fabs(bb) > LD(kMaxSlope) || std::fabs(cc) > LD(kMaxSlope)) return false;
  a0 = std::round(LD(r) + x[0] * unit - bb * mx - cc * my);
  return true;
}

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
    push_texel_cons(cons, LD(i % side) - m, LD(i / side) - m, vmin[i], vmax[i], r, unit);
  }
  LD a0, bb, cc;
  if (!solve_rounded(cons, r, unit, m, m, a0, bb, cc)) return false;
  if (std::fabs(a0) > LD(kMaxBase)) return false;
  Plane p;
  p.shift = shift;
  p.a = int64_t(a0);
  p.b = int64_t(bb);
  p.c = int64_t(cc);
  if (abs64(p.a) > kMaxBase || abs64(p.b) > kMaxSlope || abs64(p.c) > kMaxSlope) return false;
  if (!answers(p, lo, hi)) return false;  // the decoder's exact answer, texel by texel
  out = p;
  return true;
}

namespace {

// A plane in the tile's coordinates: v = a0 + b x + c y (modulo 2^64).
struct TilePlane {
  int64_t a0 = 0, b = 0, c = 0;
  float depth(uint32_t x, uint32_t y) const {
    return plane_fixed_to_float(int64_t(uint64_t(a0) + uint64_t(b) * x + uint64_t(c) * y));
  }
};

// Integers (a0, b, c) answering every texel of `texels` (y * side + x) within [lo, hi]:
// the LP of fit_block over the texels' preimages (cutting planes: a sample first, then
// the texels the found plane misses), verified texel by texel with the decoder's function.
bool fit_texels(const std::vector<uint32_t>& texels, uint32_t side, std::span<const float> lo,
                std::span<const float> hi, TilePlane& out) {
  if (texels.empty()) return false;
  uint32_t x0 = side, y0 = side, x1 = 0, y1 = 0;
  for (uint32_t t : texels)
    x0 = std::min(x0, t % side), x1 = std::max(x1, t % side), y0 = std::min(y0, t / side), y1 = std::max(y1, t / side);
  const int64_t margin = 2 * int64_t(std::max(x1 - x0, y1 - y0) + 1) + 2;
  auto bounds = [&](uint32_t t, int64_t& vmin, int64_t& vmax) {
    if (!preimage(lo[t], hi[t], vmin, vmax)) return false;
    vmin += margin, vmax -= margin;
    return vmin <= vmax;
  };
  int64_t width = std::numeric_limits<int64_t>::max(), r = 0;
  for (size_t i = 0; i < texels.size(); ++i) {
    int64_t vmin, vmax;
    if (!bounds(texels[i], vmin, vmax)) return false;
    width = std::min(width, vmax - vmin);
    if (i == 0) r = vmin / 2 + vmax / 2;
  }
  const LD unit = LD(std::max<int64_t>(width, 1));
  const LD mx = LD(x0 + x1) / 2, my = LD(y0 + y1) / 2;
  // The sample: every 16th texel and the extremes of each row of the set.
  std::vector<uint32_t> active;
  for (size_t i = 0; i < texels.size(); i += 16) active.push_back(texels[i]);
  active.push_back(texels.back());
  // Each round appends the texels missed to `active`: their constraints are appended and
  // the LP resumed where the last round left it (the bits of solving them all again).
  thread_local std::vector<Con> cons;
  cons.clear();
  size_t taken = 0;
  LD x[3];
  for (int round = 0; round < 6; ++round) {
    const size_t solved = cons.size();
    for (; taken < active.size(); ++taken) {
      const uint32_t t = active[taken];
      int64_t vmin, vmax;
      bounds(t, vmin, vmax);
      push_texel_cons(cons, LD(t % side) - mx, LD(t / side) - my, vmin, vmax, r, unit);
    }
    LD a0, bb, cc;
    if (!solve_rounded(cons, r, unit, mx, my, a0, bb, cc, x, solved)) return false;
    if (std::fabs(a0) > LD(kOne) * 4) return false;
    TilePlane q{int64_t(a0), int64_t(bb), int64_t(cc)};
    size_t missed = 0;
    for (uint32_t t : texels) {
      const float d = q.depth(t % side, t / side);
      if (!(lo[t] <= d && d <= hi[t])) {
        if (std::find(active.begin(), active.end(), t) != active.end()) return false;  // the LP's rounding
        active.push_back(t);
        if (++missed == 64) break;
      }
    }
    if (missed == 0) {
      out = q;
      return true;
    }
  }
  return false;
}

// The texels of `cand` (y * 8 + x in an 8x8 block, cand[0] the seed) that one plane grown
// from the seed answers: the texels nearest the seed first, each kept when a plane answers it
// and every texel kept before (the LP refitted over them only when the current plane misses
// it), so a block across several small triangles or a curved patch splits into the planes of
// its parts. `q` answers every texel of `kept` (fit_texels verifies with the decoder's
// function); false when no plane answers the seed alone (no preimage).
// The fits of one 8x8 block's texel lists (fit_texels of the same list gives the same plane):
// a block's seeds and rounds grow from the same texels in the same order again and again.
struct FitMemo {
  std::unordered_map<std::string, std::pair<bool, TilePlane>> fits;
  std::string key;
  bool fit(const std::vector<uint32_t>& texels, std::span<const float> lo, std::span<const float> hi, TilePlane& out) {
    key.assign(texels.begin(), texels.end());  // texels < 64: one char each
    auto [it, fresh] = fits.try_emplace(key);
    if (fresh) it->second.first = fit_texels(texels, 8, lo, hi, it->second.second);
    if (it->second.first) out = it->second.second;
    return it->second.first;
  }
};

// Every fixed-point value the decoder maps into a texel's [lo, hi] (preimage's interval
// widened by the rounding ties it excludes; unbounded below where lo <= 0, above where hi >= 1).
struct Reach {
  __int128 lo, hi;
  bool lo_open, hi_open;  // unbounded
};

std::array<Reach, 64> block_reach(std::span<const float> lo, std::span<const float> hi) {
  std::array<Reach, 64> r;
  for (uint32_t i = 0; i < 64; ++i) {
    int64_t vmin = 0, vmax = 0;
    const bool ok = preimage(lo[i], hi[i], vmin, vmax);
    r[i] = Reach{__int128(vmin) - 1, __int128(vmax) + 1, !ok || lo[i] <= 0.0f, !ok || hi[i] >= 1.0f};
  }
  return r;
}

// True when no plane answers texel t together with texels a, b, c (y * 8 + x; c = 64: the
// three collinear, t on the line of a and b): the value at t of an integer plane
// (a0 + b x + c y, no overflow within the fit's bounds) is the affine combination of its
// values at the others, m v_t = sum mu_i v_i in exact integers, and each value lies in its
// texel's Reach. An exact certificate that fit_texels fails on any set holding the four.
bool apart(const std::array<Reach, 64>& reach, uint32_t t, uint32_t a, uint32_t b, uint32_t c) {
  const int64_t xt = t % 8, yt = t / 8, xa = a % 8, ya = a / 8, xb = b % 8, yb = b / 8;
  int64_t m, mu[3];
  uint32_t id[3] = {a, b, c};
  int n = 3;
  if (c == 64) {
    const int64_t dx = xb - xa, dy = yb - ya;
    if ((xt - xa) * dy != (yt - ya) * dx || (dx == 0 && dy == 0)) return false;
    m = dx != 0 ? dx : dy;
    const int64_t k = dx != 0 ? xt - xa : yt - ya;
    mu[0] = m - k, mu[1] = k, n = 2;
  } else {
    const int64_t xc = c % 8, yc = c / 8;
    m = (xb - xa) * (yc - ya) - (xc - xa) * (yb - ya);
    if (m == 0) return false;
    mu[1] = (xt - xa) * (yc - ya) - (xc - xa) * (yt - ya);
    mu[2] = (xb - xa) * (yt - ya) - (xt - xa) * (yb - ya);
    mu[0] = m - mu[1] - mu[2];
  }
  if (m < 0) {
    m = -m;
    for (int i = 0; i < n; ++i) mu[i] = -mu[i];
  }
  // The reach of sum mu_i v_i: [low, high], each end open when some term's is.
  __int128 low = 0, high = 0;
  bool low_open = false, high_open = false;
  for (int i = 0; i < n; ++i) {
    const Reach& r = reach[id[i]];
    if (mu[i] > 0) {
      low_open |= r.lo_open, high_open |= r.hi_open;
      if (!r.lo_open) low += mu[i] * r.lo;
      if (!r.hi_open) high += mu[i] * r.hi;
    } else if (mu[i] < 0) {
      low_open |= r.hi_open, high_open |= r.lo_open;
      if (!r.hi_open) low += mu[i] * r.hi;
      if (!r.lo_open) high += mu[i] * r.lo;
    }
  }
  const Reach& rt = reach[t];
  if (!rt.hi_open && !low_open && m * rt.hi < low) return true;
  if (!rt.lo_open && !high_open && m * rt.lo > high) return true;
  return false;
}

// Whether some three or two (collinear with t) of the kept texels nearest t rule t out
// (apart): a refit over kept and t would fail, so it is not tried.
bool ruled_out(const std::array<Reach, 64>& reach, const std::vector<uint32_t>& kept, uint32_t t) {
  constexpr int kNear = 4;
  uint32_t near[kNear];
  int dn[kNear], n = 0;
  for (uint32_t k : kept) {
    if (k == t) continue;
    const int dx = int(k % 8) - int(t % 8), dy = int(k / 8) - int(t / 8), d = dx * dx + dy * dy;
    int at = n < kNear ? n++ : kNear;
    while (at > 0 && dn[at - 1] > d) {
      if (at < kNear) near[at] = near[at - 1], dn[at] = dn[at - 1];
      --at;
    }
    if (at < kNear) near[at] = k, dn[at] = d;
  }
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      if (apart(reach, t, near[i], near[j], 64)) return true;
      for (int k = j + 1; k < n; ++k)
        if (apart(reach, t, near[i], near[j], near[k])) return true;
    }
  return false;
}

bool grow_plane(const std::vector<uint32_t>& cand, std::span<const float> lo, std::span<const float> hi, TilePlane& q,
                std::vector<uint32_t>& kept, FitMemo& memo, const std::array<Reach, 64>* reach) {
  const uint32_t seed = cand.front();
  std::vector<uint32_t> order(cand.begin() + 1, cand.end());
  auto dist = [&](uint32_t t) {
    const int dx = int(t % 8) - int(seed % 8), dy = int(t / 8) - int(seed / 8);
    return dx * dx + dy * dy;
  };
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return dist(a) < dist(b); });
  kept.assign(1, seed);
  if (!memo.fit(kept, lo, hi, q)) return false;
  for (uint32_t t : order) {
    const float v = q.depth(t % 8, t / 8);
    kept.push_back(t);
    if (lo[t] <= v && v <= hi[t]) continue;
    TilePlane r;
    if (reach && ruled_out(*reach, kept, t)) kept.pop_back();
    else if (memo.fit(kept, lo, hi, r)) q = r;
    else kept.pop_back();
  }
  return true;
}

// Up to `max_planes` planes that together answer every texel of an 8x8 block (a labelled
// block's palette and labels), chosen greedily as a set cover: each round takes, of the
// candidates, the one answering the most texels no plane taken answers yet. Candidates: the
// tile's known planes (`known`, resolved to the block's corner), one plane fitted to all the
// texels left (the others unconstrained), and planes grown (grow_plane) from up to
// `max_seeds` (1..3) seeds among them, spread apart (the first left texel, then each next
// the farthest from those before). `fresh[k]`: palette entry k is not one of `known`. Every
// texel's label names the first palette plane that answers it (the decoder's function).
// False when some texel is left after `max_planes`.
bool cover_block(std::span<const float> lo, std::span<const float> hi, uint32_t start, const std::vector<Plane>& known,
                 uint32_t max_planes, uint32_t max_seeds, bool rule_out, std::vector<Plane>& palette, uint8_t* label,
                 std::vector<uint8_t>& fresh) {
  auto mask_of = [&](const Plane& q) {
    uint64_t m = 0;
    for (uint32_t i = 0; i < 64; ++i) {
      const float v = q.depth(i % 8, i / 8);
      if (lo[i] <= v && v <= hi[i]) m |= uint64_t(1) << i;
    }
    return m;
  };
  std::vector<uint64_t> known_mask(known.size());
  for (size_t k = 0; k < known.size(); ++k) known_mask[k] = mask_of(known[k]);
  palette.clear();
  fresh.clear();
  uint64_t left = ~uint64_t(0);
  std::vector<uint32_t> cand, kept;
  std::vector<float> slo(lo.begin(), lo.begin() + 64), shi(hi.begin(), hi.begin() + 64);
  FitMemo memo;
  const std::array<Reach, 64> reach = block_reach(lo, hi);
  while (left && palette.size() < max_planes) {
    Plane best;
    uint64_t best_mask = 0;
    bool best_fresh = false;
    auto offer = [&](const Plane& q, uint64_t m, bool is_fresh) {
      if (std::popcount(m & left) > std::popcount(best_mask & left)) best = q, best_mask = m, best_fresh = is_fresh;
    };
    for (size_t k = 0; k < known.size(); ++k) offer(known[k], known_mask[k], false);
    if ((best_mask & left) != left) {
      for (uint32_t i = 0; i < 64; ++i) {
        const bool open = left >> i & 1;
        slo[i] = open ? lo[i] : 0.0f, shi[i] = open ? hi[i] : 1.0f;
      }
      Plane q;
      if (fit_block(slo, shi, kLabelShift, q)) offer(q, mask_of(q), true);
    }
    if ((best_mask & left) != left) {
      uint32_t seeds[3], n_seeds = 0;
      seeds[n_seeds++] = uint32_t(std::countr_zero(left));
      while (n_seeds < std::clamp<uint32_t>(max_seeds, 1, 3)) {
        int far = -1;
        uint32_t pick = 0;
        for (uint32_t i = 0; i < 64; ++i) {
          if (!(left >> i & 1)) continue;
          int dmin = INT32_MAX;
          for (uint32_t k = 0; k < n_seeds; ++k) {
            const int dx = int(i % 8) - int(seeds[k] % 8), dy = int(i / 8) - int(seeds[k] / 8);
            dmin = std::min(dmin, dx * dx + dy * dy);
          }
          if (dmin > far) far = dmin, pick = i;
        }
        if (far <= 0) break;
        seeds[n_seeds++] = pick;
      }
      for (uint32_t k = 0; k < n_seeds; ++k) {
        cand.assign(1, seeds[k]);
        for (uint32_t i = 0; i < 64; ++i)
          if ((left >> i & 1) && i != seeds[k]) cand.push_back(i);
        TilePlane t;
        if (!grow_plane(cand, lo, hi, t, kept, memo, rule_out ? &reach : nullptr)) continue;
        const Plane q{0, kLabelShift, t.a0, t.b, t.c};
        if (abs64(q.a) > kMaxBase || abs64(q.b) > kMaxSlope || abs64(q.c) > kMaxSlope) continue;
        offer(q, mask_of(q), true);
      }
    }
    if (!(best_mask & left)) return false;
    best.start = start;
    best.shift = kLabelShift;
    palette.push_back(best);
    fresh.push_back(best_fresh);
    left &= ~best_mask;
  }
  if (left) return false;
  uint64_t masks[kWidePalette * 2];  // max_planes: at most 15 (the stats' count)
  for (size_t k = 0; k < palette.size(); ++k) masks[k] = mask_of(palette[k]);
  for (uint32_t i = 0; i < 64; ++i) {
    uint32_t k = 0;
    while (!(masks[k] >> i & 1)) ++k;
    label[i] = uint8_t(k);
  }
  return true;
}

// The distinct planes of a tile's blocks and palettes (tile coordinates), each with the
// texels it answers and the corners of the blocks that use it.
struct PlaneUses {
  struct Use {
    std::vector<uint32_t> texels;
    std::vector<uint32_t> corners;  // the corners (y * side + x) of the blocks that use it
    TilePlane plane;
    bool alive = true;
  };
  std::map<std::tuple<int64_t, int64_t, int64_t>, uint32_t> id;
  std::vector<Use> uses;

  PlaneUses(const PlaneSplit& out, uint32_t side) {
    for (const Plane& p : out.planes) {
      const uint32_t x0 = morton_compact(p.start), y0 = morton_compact(uint64_t(p.start) >> 1), w = 1u << p.shift;
      Use& u = use_of(p, x0, y0);
      u.corners.push_back(y0 * side + x0);
      for (uint32_t y = y0; y < y0 + w; ++y)
        for (uint32_t x = x0; x < x0 + w; ++x) u.texels.push_back(y * side + x);
    }
    for (const LabelBlock& lb : out.labelled) {
      const uint32_t x0 = morton_compact(lb.start), y0 = morton_compact(uint64_t(lb.start) >> 1);
      for (uint32_t k = 0; k < lb.palette.size(); ++k) {
        Use& u = use_of(lb.palette[k], x0, y0);
        u.corners.push_back(y0 * side + x0);
        for (uint32_t i = 0; i < 64; ++i)
          if (lb.label[i] == k) u.texels.push_back((y0 + i / 8) * side + x0 + i % 8);
      }
    }
  }
  Use& use_of(const Plane& p, uint32_t x0, uint32_t y0) {
    const TilePlane t{p.origin_a(x0, y0), p.b, p.c};
    auto [it, fresh] = id.emplace(std::make_tuple(t.a0, t.b, t.c), uint32_t(uses.size()));
    if (fresh) uses.push_back(Use{{}, {}, t, true});
    return uses[it->second];
  }
  // Every block and palette entry takes the plane of the use `owner` names for its own.
  void apply(PlaneSplit& out, const std::vector<uint32_t>& owner) const {
    auto remap = [&](Plane& p, uint32_t x0, uint32_t y0) {
      const auto it = id.find(std::make_tuple(p.origin_a(x0, y0), p.b, p.c));
      ST_CHECK(it != id.end());
      const TilePlane& q = uses[owner[it->second]].plane;
      p.b = q.b, p.c = q.c;
      p.a = int64_t(uint64_t(q.a0) + uint64_t(q.b) * x0 + uint64_t(q.c) * y0);
    };
    for (Plane& p : out.planes) remap(p, morton_compact(p.start), morton_compact(uint64_t(p.start) >> 1));
    for (LabelBlock& lb : out.labelled)
      for (Plane& q : lb.palette) remap(q, morton_compact(lb.start), morton_compact(uint64_t(lb.start) >> 1));
  }
};

// Whether q answers every texel within [lo, hi] (the decoder's function) and keeps every
// block corner within |a'| <= 2^61 (plane_format.hpp).
bool answers_all(const TilePlane& q, const std::vector<uint32_t>& texels, const std::vector<uint32_t>& corners,
                 uint32_t side, std::span<const float> lo, std::span<const float> hi) {
  if (abs64(q.b) > kMaxSlope || abs64(q.c) > kMaxSlope) return false;
  for (uint32_t t : corners)
    if (abs64(int64_t(uint64_t(q.a0) + uint64_t(q.b) * (t % side) + uint64_t(q.c) * (t / side))) > kMaxBase)
      return false;
  for (uint32_t t : texels) {
    const float v = q.depth(t % side, t / side);
    if (!(lo[t] <= v && v <= hi[t])) return false;
  }
  return true;
}

// One surface, one plane: merges the tile's planes whose texels one plane can answer
// together (refitted over their union), largest first, so the table holds fewer entries.
void merge_surfaces(PlaneSplit& out, uint32_t d, std::span<const float> lo, std::span<const float> hi) {
  const uint32_t side = 1u << d;
  PlaneUses all(out, side);
  auto& uses = all.uses;
  if (uses.size() < 2) return;
  std::vector<uint32_t> order(uses.size());
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return uses[a].texels.size() > uses[b].texels.size(); });
  // How far (in units of the texel's preimage width) q misses texel t: 0 inside.
  auto miss = [&](const TilePlane& q, uint32_t t) -> LD {
    int64_t vmin, vmax;
    if (!preimage(lo[t], hi[t], vmin, vmax)) return 1e30L;
    const LD v = LD(q.a0) + LD(q.b) * LD(t % side) + LD(q.c) * LD(t / side);
    const LD w = LD(std::max<int64_t>(vmax - vmin, 1));
    return v < LD(vmin) ? (LD(vmin) - v) / w : v > LD(vmax) ? (v - LD(vmax)) / w : 0;
  };
  std::vector<uint32_t> owner(uses.size());  // the use each one merged into (itself if none)
  for (uint32_t i = 0; i < owner.size(); ++i) owner[i] = i;
  std::vector<uint32_t> both_texels, both_corners;
  bool any = false;
  // Work bound: the refits' unions together at most 4 tiles' texels (curved surfaces offer
  // many near planes that no refit joins).
  uint64_t budget = 4ull * side * side;
  for (size_t ia = 0; ia < order.size(); ++ia) {
    PlaneUses::Use& a = uses[order[ia]];
    if (!a.alive) continue;
    int refits = 0;
    for (size_t ib = ia + 1; ib < order.size(); ++ib) {
      PlaneUses::Use& b = uses[order[ib]];
      if (!b.alive) continue;
      bool merged = answers_all(a.plane, b.texels, b.corners, side, lo, hi);
      if (!merged && refits < 4 && budget >= a.texels.size() + b.texels.size()) {
        // Near enough to be the same surface: a few widths off at b's first and last texels.
        if (miss(a.plane, b.texels.front()) > 64 || miss(a.plane, b.texels.back()) > 64) continue;
        ++refits;
        budget -= a.texels.size() + b.texels.size();
        both_texels = a.texels;
        both_texels.insert(both_texels.end(), b.texels.begin(), b.texels.end());
        both_corners = a.corners;
        both_corners.insert(both_corners.end(), b.corners.begin(), b.corners.end());
        TilePlane q;
        if (fit_texels(both_texels, side, lo, hi, q) && answers_all(q, both_texels, both_corners, side, lo, hi)) {
          a.plane = q;
          merged = true;
        }
      }
      if (!merged) continue;
      a.texels.insert(a.texels.end(), b.texels.begin(), b.texels.end());
      a.corners.insert(a.corners.end(), b.corners.begin(), b.corners.end());
      b.alive = false;
      owner[order[ib]] = order[ia];
      any = true;
    }
  }
  if (any) all.apply(out, owner);
}

// Fewer significant bits: each plane becomes one that answers the same texels with as many
// trailing zero bits in b and c as any near multiple allows, then in a0 (the LP returns some
// point of a plane's feasible set, whose low bits are arbitrary; zeros deflate to almost
// nothing, and planes of one surface may become equal). For b, c multiples of 2^k (the two
// nearest each, k from the largest down) the admissible a0 is an interval, exact in 128-bit
// integers from the texels' preimages (extreme texels first, then all); a0 is its point with
// the most trailing zeros; the result is checked with the decoder's function on every texel.
void round_planes(PlaneSplit& out, uint32_t d, std::span<const float> lo, std::span<const float> hi) {
  using I128 = __int128;
  const uint32_t side = 1u << d;
  PlaneUses all(out, side);
  std::vector<uint32_t> owner(all.uses.size());
  std::vector<int64_t> vmin, vmax;
  bool any = false;
  auto floor_to = [](I128 v, int k) { return v >= 0 ? (v >> k) << k : -(((-v + (I128(1) << k) - 1) >> k) << k); };
  for (uint32_t u = 0; u < all.uses.size(); ++u) {
    owner[u] = u;
    PlaneUses::Use& use = all.uses[u];
    const std::vector<uint32_t>& ts = use.texels;
    vmin.resize(ts.size());
    vmax.resize(ts.size());
    bool ok = true;
    for (size_t i = 0; i < ts.size() && ok; ++i) ok = preimage(lo[ts[i]], hi[ts[i]], vmin[i], vmax[i]);
    if (!ok || ts.empty()) continue;
    // The texels at the extremes of x, y, x + y and x - y: the bounds that bind first.
    size_t ext[8] = {};
    auto key = [&](size_t i, int f) -> int64_t {
      const int64_t x = ts[i] % side, y = ts[i] / side;
      const int64_t v[4] = {x, y, x + y, x - y};
      return v[f];
    };
    for (size_t i = 1; i < ts.size(); ++i)
      for (int f = 0; f < 4; ++f) {
        if (key(i, f) < key(ext[2 * f], f)) ext[2 * f] = i;
        if (key(i, f) > key(ext[2 * f + 1], f)) ext[2 * f + 1] = i;
      }
    // The a0 interval [alo, ahi] for slopes (b, c) over texels i of `idx` (all when null).
    auto a_range = [&](I128 b, I128 c, const size_t* idx, size_t n, I128& alo, I128& ahi) {
      for (size_t j = 0; j < n && alo <= ahi; ++j) {
        const size_t i = idx ? idx[j] : j;
        const I128 off = b * (ts[i] % side) + c * (ts[i] / side);
        alo = std::max(alo, I128(vmin[i]) - off);
        ahi = std::min(ahi, I128(vmax[i]) - off);
      }
      return alo <= ahi;
    };
    bool done = false;
    for (int k = 52; k >= 0 && !done; --k) {
      const I128 step = I128(1) << k, fb = floor_to(use.plane.b, k), fc = floor_to(use.plane.c, k);
      for (int combo = 0; combo < 4 && !done; ++combo) {
        const I128 b = fb + (combo & 1 ? step : 0), c = fc + (combo & 2 ? step : 0);
        if (b > kMaxSlope || b < -kMaxSlope || c > kMaxSlope || c < -kMaxSlope) continue;
        I128 alo = -(I128(1) << 100), ahi = I128(1) << 100;
        if (!a_range(b, c, ext, 8, alo, ahi) || !a_range(b, c, nullptr, ts.size(), alo, ahi)) continue;
        I128 a0 = alo;
        for (int j = 62; j > 0; --j) {
          const I128 m = -floor_to(-alo, j);  // the least multiple of 2^j at or above alo
          if (m <= ahi) {
            a0 = m;
            break;
          }
        }
        if (a0 > INT64_MAX || a0 < INT64_MIN) continue;
        const TilePlane q{int64_t(a0), int64_t(b), int64_t(c)};
        if (!answers_all(q, ts, use.corners, side, lo, hi)) continue;
        done = true;
        if (q.a0 != use.plane.a0 || q.b != use.plane.b || q.c != use.plane.c) use.plane = q, any = true;
      }
    }
  }
  if (any) all.apply(out, owner);
}

}  // namespace

namespace {

// Labels as the packed form stores them smallest (tiles/core/plane_pack.hpp, STPL): a
// texel that several palette planes answer may take any of them. For each labelled block
// (after the merge and rounding, with the final planes; every texel checked with the
// decoder's function): its palette ordered by the texels each plane answers, most first;
// then the fewest of its palette planes that answer every texel (any
// subset, smallest first), and of those subsets and the labellings each prediction mode
// gives (none: the lowest entry answering; least, greatest: the plane the mode predicts
// where it answers, else the lowest), the one whose labels the best mode leaves the fewest
// texels unpredicted (the first such: deterministic). The palette keeps the planes used, in
// order; a block left with one plane becomes a plane block, one left with at most 4 a
// labelled block of 2-bit labels. The cover's search is unchanged.
void relabel_blocks(PlaneSplit& out, uint32_t d, std::span<const float> lo, std::span<const float> hi) {
  const uint32_t side = 1u << d;
  std::vector<LabelBlock> kept;
  kept.reserve(out.labelled.size());
  for (LabelBlock& lb : out.labelled) {
    const uint32_t n = uint32_t(lb.palette.size());
    const uint32_t x0 = morton_compact(lb.start), y0 = morton_compact(uint64_t(lb.start) >> 1);
    uint32_t ans[64];
    int64_t val[kWidePalette][64];
    bool ok = n >= 1 && n <= kWidePalette;
    for (uint32_t i = 0; i < 64 && ok; ++i) {
      const size_t t = size_t(y0 + i / 8) * side + x0 + i % 8;
      ans[i] = 0;
      for (uint32_t e = 0; e < n; ++e) {
        val[e][i] = lb.palette[e].fixed(i % 8, i / 8);
        const float v = plane_fixed_to_float(val[e][i]);
        if (lo[t] <= v && v <= hi[t]) ans[i] |= 1u << e;
      }
      ok = lb.label[i] < n && (ans[i] >> lb.label[i] & 1u);
    }
    if (!ok) {  // not what the cover gives: kept as it is
      kept.push_back(std::move(lb));
      continue;
    }
    {  // the palette in order of the texels each plane answers, most first (then the lowest
       // entries, the ones the labels take where nothing predicts, are the commonest)
      uint32_t order[kWidePalette], count[kWidePalette] = {};
      for (uint32_t e = 0; e < n; ++e) {
        order[e] = e;
        for (uint32_t i = 0; i < 64; ++i) count[e] += ans[i] >> e & 1u;
      }
      std::stable_sort(order, order + n, [&](uint32_t x, uint32_t y) { return count[x] > count[y]; });
      std::vector<Plane> palette(n);
      int64_t v[kWidePalette][64];
      for (uint32_t e = 0; e < n; ++e) palette[e] = lb.palette[order[e]], std::copy_n(val[order[e]], 64, v[e]);
      for (uint32_t i = 0; i < 64; ++i) {
        uint32_t a = 0;
        for (uint32_t e = 0; e < n; ++e) a |= (ans[i] >> order[e] & 1u) << e;
        ans[i] = a;
      }
      lb.palette = std::move(palette);
      for (uint32_t e = 0; e < n; ++e) std::copy_n(v[e], 64, val[e]);
    }
    bool covers[1u << kWidePalette] = {};  // the subsets of the palette answering every texel
    uint32_t k = n + 1;
    for (uint32_t set = 1; set < (1u << n); ++set) {
      bool all = true;
      for (uint32_t i = 0; i < 64 && all; ++i) all = (ans[i] & set) != 0;
      covers[set] = all;
      if (all) k = std::min(k, bit_count(set));
    }
    uint32_t best_set = 0, best_misses = 65;
    uint8_t best[64] = {};
    for (uint32_t set = 1; set < (1u << n); ++set) {
      if (!covers[set] || bit_count(set) != k) continue;
      const uint32_t low = uint32_t(std::countr_zero(set));
      uint8_t pred[3][64];  // each mode's prediction over `set` (ties: the lower entry)
      for (uint32_t i = 0; i < 64; ++i) {
        pred[0][i] = uint8_t(low);
        pred[1][i] = pred[2][i] = uint8_t(low);
        for (uint32_t e = low + 1; e < n; ++e) {
          if (!(set >> e & 1u)) continue;
          if (val[e][i] < val[pred[1][i]][i]) pred[1][i] = uint8_t(e);
          if (val[e][i] > val[pred[2][i]][i]) pred[2][i] = uint8_t(e);
        }
      }
      for (uint32_t m = 0; m < 3 && (m == 0 || k <= kPalette); ++m) {
        uint8_t lab[64];
        for (uint32_t i = 0; i < 64; ++i)
          lab[i] = (ans[i] >> pred[m][i] & 1u) ? pred[m][i] : uint8_t(std::countr_zero(ans[i] & set));
        uint32_t misses = 65;
        for (uint32_t q = 0; q < 3; ++q) {
          uint32_t miss = 0;
          for (uint32_t i = 0; i < 64; ++i) miss += lab[i] != pred[q][i];
          misses = std::min(misses, miss);
        }
        if (k > kPalette) misses = 0;  // wide: no prediction, the lowest entries
        if (misses < best_misses) {
          best_misses = misses, best_set = set;
          std::copy_n(lab, 64, best);
        }
      }
    }
    uint8_t position[kWidePalette] = {};
    std::vector<Plane> palette;
    for (uint32_t e = 0; e < n; ++e)
      if (best_set >> e & 1u) position[e] = uint8_t(palette.size()), palette.push_back(lb.palette[e]);
    if (palette.size() == 1) {
      Plane p = palette[0];
      p.start = lb.start, p.shift = kLabelShift;
      out.planes.push_back(p);
      continue;
    }
    lb.palette = std::move(palette);
    for (uint32_t i = 0; i < 64; ++i) lb.label[i] = position[best[i]];
    kept.push_back(std::move(lb));
  }
  out.labelled = std::move(kept);
}

// After the prune: a valued node above the blocks (not the root, not a finest texel) whose
// value its nearest valued ancestor's value A could stand for is made empty (or dropped with
// no children left). A stands for it when every position the node's value answers lies in
// its bounds: a finest texel its admissible [lo, hi] (so every texel stays exact), a coarser
// position [min lo, max hi] of the texels below it (hierarchy.hpp: every level stays a
// complete map). Positions a block's plane answers (finer than the block) or a deeper valued
// node answers are not the node's. The ancestor's [lo, hi] is narrowed to those bounds (the
// encoders may pick any value inside); a node kept (below the root) gets the bounds of its
// positions as its [lo, hi], and may move its value into a descendant's bounds to take it.
// Nodes are visited coarse to fine, so a node's A is the answer after the drops above it.
// What it saves: the inner tree's values above plane blocks (a block's own level, the levels
// above it), and the map preview's nodes that now answer their parent's value (tiles/PACK.md
// "Map preview": only nodes differing from their parent are stored).
void drop_coarse_values(Hierarchy& t, uint32_t d, std::span<const float> lo, std::span<const float> hi,
                        const std::vector<Plane>& blocks, const std::vector<LabelBlock>& labelled) {
  if (d < 2) return;
  const uint32_t side = 1u << d;
  // Per finest texel, the shift of the block holding it (0: none).
  std::vector<uint8_t> bshift(size_t(side) * side, 0);
  auto mark = [&](uint32_t start, uint32_t shift) {
    const uint32_t x0 = morton_compact(start), y0 = morton_compact(start >> 1), w = 1u << shift;
    for (uint32_t y = y0; y < y0 + w; ++y) std::fill_n(bshift.begin() + size_t(y) * side + x0, w, uint8_t(shift));
  };
  for (const Plane& p : blocks) mark(p.start, p.shift);
  for (const LabelBlock& b : labelled) mark(b.start, kLabelShift);
  // [min lo, max hi] of the texels below each position, per level (dense).
  std::vector<std::vector<float>> mn(d + 1), mx(d + 1);
  mn[d].assign(lo.begin(), lo.end());
  mx[d].assign(hi.begin(), hi.end());
  for (uint32_t l = d; l-- > 0;) {
    const uint32_t w = 1u << l;
    mn[l].resize(size_t(w) * w), mx[l].resize(size_t(w) * w);
    for (uint32_t y = 0; y < w; ++y)
      for (uint32_t x = 0; x < w; ++x) {
        const size_t c0 = size_t(2 * y) * (2 * w) + 2 * x, c1 = c0 + 2 * w;
        mn[l][size_t(y) * w + x] = std::min({mn[l + 1][c0], mn[l + 1][c0 + 1], mn[l + 1][c1], mn[l + 1][c1 + 1]});
        mx[l][size_t(y) * w + x] = std::max({mx[l + 1][c0], mx[l + 1][c0 + 1], mx[l + 1][c1], mx[l + 1][c1 + 1]});
      }
  }
  // Present nodes per level (dense): index into t.levels[l], or -1.
  std::vector<std::vector<int32_t>> at(d + 1);
  for (uint32_t l = 0; l <= d; ++l) {
    const uint32_t w = 1u << l;
    at[l].assign(size_t(w) * w, -1);
    for (size_t j = 0; j < t.levels[l].size(); ++j) {
      const uint64_t m = t.levels[l][j].morton;
      at[l][size_t(morton_compact(m >> 1)) * w + morton_compact(m)] = int32_t(j);
    }
  }
  auto valued = [&](uint32_t l, uint32_t x, uint32_t y) {
    const int32_t j = at[l][(size_t(y) << l) + x];
    return j >= 0 && t.levels[l][size_t(j)].has_value;
  };
  // The intersection of the bounds of every position (l, x, y) the node at level l0 answers.
  auto bounds = [&](auto&& self, uint32_t l, uint32_t x, uint32_t y, uint32_t l0, float& blo, float& bhi) -> void {
    if (l > l0) {
      if (bshift[(size_t(y) << (d - l)) * side + (size_t(x) << (d - l))] > d - l) return;  // a plane's
      if (valued(l, x, y)) return;
    }
    const size_t i = (size_t(y) << l) + x;
    blo = std::max(blo, mn[l][i]), bhi = std::min(bhi, mx[l][i]);
    if (l == d || blo > bhi) return;
    for (uint32_t c = 0; c < 4; ++c) self(self, l + 1, 2 * x + (c & 1), 2 * y + (c >> 1), l0, blo, bhi);
  };
  // Per valued node below the root, once visited and kept: whether its value may move
  // within [lo, hi] (its [lo, hi] is then the bounds of every position it answers).
  std::vector<std::vector<uint8_t>> movable(d + 1);
  for (uint32_t l = 0; l <= d; ++l) movable[l].assign(t.levels[l].size(), 0);
  for (uint32_t l = 1; l < d; ++l)
    for (size_t j = 0; j < t.levels[l].size(); ++j) {
      HNode& n = t.levels[l][j];
      if (!n.has_value) continue;
      const uint32_t x = morton_compact(n.morton), y = morton_compact(n.morton >> 1);
      uint32_t ul = 0;
      size_t uj = 0;
      for (uint32_t k = l; k-- > 0;)  // the nearest valued ancestor (the root is valued)
        if (valued(k, x >> (l - k), y >> (l - k))) {
          ul = k, uj = size_t(at[k][(size_t(y >> (l - k)) << k) + (x >> (l - k))]);
          break;
        }
      HNode& up = t.levels[ul][uj];
      float blo = -std::numeric_limits<float>::infinity(), bhi = std::numeric_limits<float>::infinity();
      bounds(bounds, l, x, y, l, blo, bhi);
      const float klo = std::max(up.lo, blo), khi = std::min(up.hi, bhi);
      // The ancestor takes this node's positions when its value is in their bounds, or can
      // move into them (not the root: the skip grid's entry holds its value).
      const bool inside = up.lo <= up.value && up.value <= up.hi;
      if (inside && ((blo <= up.value && up.value <= bhi) || (movable[ul][uj] && klo <= khi))) {
        // The encoders choose the ancestor's value within its [lo, hi] (MMH merges, DAG-MH
        // value codes), so that narrows to the bounds of every position it answers.
        up.lo = klo, up.hi = khi;
        up.value = std::clamp(up.value, klo, khi);
        n.has_value = 0;
        continue;
      }
      // Kept: any value within the bounds of its positions is as exact as its own (the
      // hierarchy's [lo, hi] only knew its texels, which blocks may answer now).
      if (blo <= n.value && n.value <= bhi) n.lo = blo, n.hi = bhi, movable[l][j] = 1;
    }
  // Bottom-up: an empty node without children goes, and its parent's bit.
  for (uint32_t l = d; l > 0; --l) {
    std::vector<HNode>& lv = t.levels[l];
    size_t kept = 0;
    for (size_t j = 0; j < lv.size(); ++j) {
      const HNode& n = lv[j];
      if (!n.has_value && n.child_mask == 0) {
        const uint32_t x = morton_compact(n.morton), y = morton_compact(n.morton >> 1);
        HNode& pn = t.levels[l - 1][size_t(at[l - 1][(size_t(y >> 1) << (l - 1)) + (x >> 1)])];
        pn.child_mask &= uint8_t(~(1u << ((x & 1) | (y & 1) << 1)));
        continue;
      }
      lv[kept++] = n;
    }
    lv.resize(kept);
  }
}

}  // namespace

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
  // Level by level, the largest blocks first over the whole tile; a node's block is tried
  // when no ancestor's was taken. A block first tries the planes already taken (the most
  // recently used first, each checked on every texel with the decoder's function), so the
  // blocks of one surface share one table entry (plane_format.hpp); else its own fit.
  struct Known {
    int64_t a0, b, c;  // a at the tile's origin
  };
  std::vector<Known> known;
  constexpr size_t kReuseTries = 64;
  const uint32_t min_reused = std::min(o.min_reused_nodes, o.min_stored_nodes);
  std::vector<std::vector<uint8_t>> cut(d + 1), under(d + 1);
  for (uint32_t l = 0; l <= d; ++l) cut[l].assign(h.levels[l].size(), 0), under[l].assign(h.levels[l].size(), 0);
  std::vector<float> blo, bhi;
  // Why each 8x8 block (level d - 3) was not labelled (PlaneFitStats::left_blocks), 0xFF: it was.
  std::vector<uint8_t> reason8;
  if (o.stats && d >= kLabelShift) reason8.assign(h.levels[d - kLabelShift].size(), 0xFF);
  for (uint32_t l = 0; l <= d; ++l) {
    const uint32_t s = d - l, w = 1u << s;
    const bool sized = s >= std::max(o.min_shift, kMinShift) && s <= kMaxShift;
    for (size_t j = 0; j < h.levels[l].size(); ++j) {
      const HNode& n = h.levels[l][j];
      if (!under[l][j] && n.child_mask && sized && below[l][j] >= min_reused) {
        const uint32_t x0 = morton_compact(n.morton) << s, y0 = morton_compact(n.morton >> 1) << s;
        blo.resize(size_t(w) * w);
        bhi.resize(size_t(w) * w);
        for (uint32_t y = 0; y < w; ++y) {
          std::copy_n(lo.begin() + size_t(y0 + y) * side + x0, w, blo.begin() + size_t(y) * w);
          std::copy_n(hi.begin() + size_t(y0 + y) * side + x0, w, bhi.begin() + size_t(y) * w);
        }
        Plane p;
        p.shift = s;
        bool taken = false;
        for (size_t t = known.size(), tries = 0; t-- > 0 && tries < kReuseTries; ++tries) {
          p.b = known[t].b, p.c = known[t].c;
          p.a = int64_t(uint64_t(known[t].a0) + uint64_t(p.b) * x0 + uint64_t(p.c) * y0);
          if (abs64(p.a) > kMaxBase || !answers(p, blo, bhi)) continue;
          std::rotate(known.begin() + ptrdiff_t(t), known.begin() + ptrdiff_t(t) + 1, known.end());
          taken = true;
          break;
        }
        if (!taken && below[l][j] >= o.min_stored_nodes && fit_block(blo, bhi, s, p)) {
          known.push_back(Known{p.origin_a(x0, y0), p.b, p.c});
          taken = true;
        }
        if (!taken && s == kLabelShift && below[l][j] >= o.min_labelled_nodes) {
          // Labels (grow_labels): at most max_palette planes (past 4: a wide block) chosen as a
          // set cover of the block's texels from the known planes, a fit to the texels left and planes grown from seeds among
          // them (cover_block). Without: each texel takes the first palette plane that answers
          // it, else the most recently used known plane that does; the texels none answers get
          // a plane fitted to them alone (the block's other texels unconstrained).
          LabelBlock lb;
          lb.start = uint32_t(n.morton << (2 * s));
          auto fits = [&](const Plane& q, uint32_t i) {
            const float v = q.depth(i % 8, i / 8);
            return blo[i] <= v && v <= bhi[i];
          };
          constexpr uint8_t kNone = 0xFF;
          bool preimages = true;
          for (uint32_t i = 0; i < 64 && preimages; ++i) {
            int64_t a, b;
            preimages = preimage(blo[i], bhi[i], a, b);
          }
          uint32_t missing = 0;
          for (uint32_t i = 0; i < 64 && preimages && !o.grow_labels; ++i) {
            size_t k = 0;
            while (k < lb.palette.size() && !fits(lb.palette[k], i)) ++k;
            if (k == lb.palette.size() && k < kPalette) {
              bool found = false;
              for (size_t t = known.size(), tries = 0; t-- > 0 && tries < kReuseTries && !found; ++tries) {
                Plane q;
                q.shift = s, q.start = lb.start, q.b = known[t].b, q.c = known[t].c;
                q.a = int64_t(uint64_t(known[t].a0) + uint64_t(q.b) * x0 + uint64_t(q.c) * y0);
                if (abs64(q.a) > kMaxBase || !fits(q, i)) continue;
                lb.palette.push_back(q);
                found = true;
              }
              if (!found) k = kNone;
            } else if (k == lb.palette.size()) {
              k = kNone;
            }
            lb.label[i] = uint8_t(k);
            missing += k == kNone;
          }
          // Without grow_labels, one more plane for the texels still missing, fitted to them all.
          std::vector<uint32_t> cand, kept;
          auto next_plane = [&](Plane& q) {
            std::vector<float> slo(blo), shi(bhi);
            for (uint32_t i = 0; i < 64; ++i)
              if (lb.label[i] != kNone) slo[i] = 0.0f, shi[i] = 1.0f;
            return fit_block(slo, shi, s, q);
          };
          bool ok = preimages;
          std::vector<Plane> resolved;
          std::vector<uint8_t> fresh;
          if (o.grow_labels && ok) {
            for (size_t t = known.size(), tries = 0; t-- > 0 && tries < kReuseTries; ++tries) {
              Plane q;
              q.shift = s, q.start = lb.start, q.b = known[t].b, q.c = known[t].c;
              q.a = int64_t(uint64_t(known[t].a0) + uint64_t(q.b) * x0 + uint64_t(q.c) * y0);
              if (abs64(q.a) <= kMaxBase) resolved.push_back(q);
            }
            ok = cover_block(blo, bhi, lb.start, resolved, std::clamp<uint32_t>(o.max_palette, 1, kWidePalette),
                             o.grow_seeds, o.rule_out, lb.palette, lb.label, fresh);
            if (ok)
              for (size_t k = 0; k < lb.palette.size(); ++k)
                if (fresh[k]) known.push_back(Known{lb.palette[k].origin_a(x0, y0), lb.palette[k].b, lb.palette[k].c});
            missing = ok ? 0 : 1;
          }
          while (missing && ok && !o.grow_labels) {
            ok = false;
            if (lb.palette.size() == kPalette) break;
            Plane q;
            if (!next_plane(q)) break;
            q.start = lb.start;
            uint32_t got = 0;
            for (uint32_t i = 0; i < 64; ++i)
              if (lb.label[i] == kNone && fits(q, i)) lb.label[i] = uint8_t(lb.palette.size()), --missing, ++got;
            if (got == 0) break;
            known.push_back(Known{q.origin_a(x0, y0), q.b, q.c});
            lb.palette.push_back(q);
            ok = true;
          }
          ok = ok && missing == 0 && !lb.palette.empty();
          if (o.stats) {
            uint32_t need = 16;
            if (ok) need = uint32_t(lb.palette.size());
            else if (preimages && o.stats->count_needs) {
              // How many planes the growth would need: on past the palette, up to 16.
              need = uint32_t(lb.palette.size());
              if (o.grow_labels) {
                std::vector<Plane> pal;
                uint8_t lab[64];
                need = cover_block(blo, bhi, lb.start, resolved, 15, o.grow_seeds, o.rule_out, pal, lab, fresh) ? uint32_t(pal.size()) : 16;
              }
              std::vector<uint8_t> open(o.grow_labels ? 0 : 64);
              for (uint32_t i = 0; i < open.size(); ++i) open[i] = lb.label[i] == kNone;
              while (need < 16 && !o.grow_labels) {
                cand.clear();
                for (uint32_t i = 0; i < 64; ++i)
                  if (open[i]) cand.push_back(i);
                if (cand.empty()) break;
                TilePlane t;
                FitMemo memo;
                const std::array<Reach, 64> reach = block_reach(blo, bhi);
                if (!grow_plane(cand, blo, bhi, t, kept, memo, o.rule_out ? &reach : nullptr)) {
                  need = 16;
                  break;
                }
                for (uint32_t i : kept) open[i] = 0;
                ++need;
              }
            }
            o.stats->need_blocks[need]++;
            o.stats->need_values[need] += below[l][j];
            if (!ok) reason8[j] = preimages ? 2 : 1;
          }
          if (ok) {
            out.labelled.push_back(std::move(lb));
            out.texels += 64;
            cut[l][j] = 1;
          }
        } else if (!taken && s == kLabelShift && o.stats) {
          reason8[j] = 0;
        }
        if (taken) {
          p.start = uint32_t(n.morton << (2 * s));
          out.planes.push_back(p);
          out.texels += uint64_t(w) * w;
          cut[l][j] = 1;
        }
      }
      if (l < d)
        for (uint32_t c = 0, k = first[l][j]; c < uint32_t(std::popcount(unsigned(n.child_mask))); ++c, ++k)
          under[l + 1][k] = under[l][j] || cut[l][j];
    }
  }
  if (o.stats) {
    PlaneFitStats& st = *o.stats;
    st.tiles++;
    uint64_t values = 0, kept = 0;
    for (uint32_t l = 0; l <= d; ++l)
      for (size_t j = 0; j < h.levels[l].size(); ++j) {
        values += h.levels[l][j].has_value;
        kept += h.levels[l][j].has_value && !under[l][j];
      }
    uint64_t leaves = 0, leaves_kept = 0;
    for (size_t j = 0; j < h.levels[d].size(); ++j)
      leaves += h.levels[d][j].has_value, leaves_kept += h.levels[d][j].has_value && !under[d][j];
    st.values_before += values, st.values_after += kept;
    st.leaves_before += leaves, st.leaves_after += leaves_kept;
    st.plane_blocks += out.planes.size(), st.labelled_blocks += out.labelled.size();
    for (const LabelBlock& lb : out.labelled) st.wide_blocks += lb.palette.size() > kPalette;
    if (!reason8.empty()) {
      // Valued nodes left below each 8x8 block (not under a block of its own), bottom-up.
      const uint32_t l8 = d - kLabelShift;
      std::vector<uint64_t> rem(h.levels[d].size(), 0), up;
      for (uint32_t l = d; l-- > l8;) {
        up.assign(h.levels[l].size(), 0);
        for (size_t j = 0; j < h.levels[l].size(); ++j)
          for (uint32_t c = 0, k = first[l][j]; c < uint32_t(std::popcount(unsigned(h.levels[l][j].child_mask))); ++c, ++k)
            if (!cut[l + 1][k]) up[j] += rem[k] + h.levels[l + 1][k].has_value;
        rem.swap(up);
      }
      for (size_t j = 0; j < reason8.size(); ++j)
        if (reason8[j] != 0xFF && !cut[l8][j] && !under[l8][j] && rem[j]) {
          st.left_blocks[reason8[j]]++;
          st.left_values[reason8[j]] += rem[j];
        }
    }
  }
  if (out.planes.empty() && out.labelled.empty()) return out;
  if (o.merge_surfaces) merge_surfaces(out, d, lo, hi);
  if (o.round_planes) round_planes(out, d, lo, hi);
  relabel_blocks(out, d, lo, hi);
  std::sort(out.planes.begin(), out.planes.end(), [](const Plane& a, const Plane& b) { return a.start < b.start; });
  std::sort(out.labelled.begin(), out.labelled.end(),
            [](const LabelBlock& a, const LabelBlock& b) { return a.start < b.start; });
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
  if (o.drop_coarse_values) drop_coarse_values(out.pruned, d, lo, hi, out.planes, out.labelled);
  return out;
}

std::vector<uint8_t> wrap_planes(const std::vector<Plane>& ps, uint32_t finest_level, std::span<const uint8_t> inner,
                                 const std::vector<LabelBlock>& labelled) {
  const size_t blocks = ps.size() + labelled.size();
  ST_CHECK(blocks >= 1 && blocks <= kMaxPlanes && finest_level + 1 <= kMaxLevels);
  // The table: one entry per distinct plane (a at the tile's origin, b, c), in order of first use.
  struct Entry {
    int64_t a, b, c;
    bool operator<(const Entry& o) const { return std::tie(a, b, c) < std::tie(o.a, o.b, o.c); }
  };
  std::map<Entry, uint32_t> index;
  std::vector<Entry> table;
  auto entry = [&](const Plane& p, uint32_t start) {
    const Entry e{p.origin_a(morton_compact(start), morton_compact(uint64_t(start) >> 1)), p.b, p.c};
    auto [it, fresh] = index.emplace(e, uint32_t(table.size()));
    if (fresh) table.push_back(e);
    return it->second;
  };
  // Block records in order of start: (start, shift, kind, index).
  struct Rec {
    uint32_t start, shift;
    uint8_t kind;
    uint32_t index;
  };
  std::vector<Rec> recs;
  recs.reserve(blocks);
  size_t i = 0, k = 0, slots = 0;
  std::vector<uint32_t> palettes;  // kWidePalette entries a labelled block (a narrow one's first kPalette used)
  while (i < ps.size() || k < labelled.size()) {
    if (k == labelled.size() || (i < ps.size() && ps[i].start < labelled[k].start)) {
      recs.push_back(Rec{ps[i].start, ps[i].shift, kKindPlane, entry(ps[i], ps[i].start)});
      ++i;
    } else {
      const LabelBlock& lb = labelled[k];
      ST_CHECK(!lb.palette.empty() && lb.palette.size() <= kWidePalette);
      const bool wide = lb.palette.size() > kPalette;
      for (uint32_t t = 0; t < kWidePalette; ++t) palettes.push_back(entry(lb.palette[std::min<size_t>(t, lb.palette.size() - 1)], lb.start));
      recs.push_back(Rec{lb.start, kLabelShift, wide ? kKindWide : kKindLabels, uint32_t(slots)});
      slots += wide ? kWideSlots : 1;
      ++k;
    }
  }
  if (table.size() > kMaxTable) throw Error("plane tile: " + std::to_string(table.size()) + " planes, at most 65535");
  if (slots > kMaxTable) throw Error("plane tile: " + std::to_string(slots) + " label slots, at most 65535");
  const bool any_wide = slots > labelled.size();
  const size_t blocks_at = kHeaderSize + table.size() * kEntrySize;
  const size_t labels_at = blocks_at + blocks * kRecordSize;
  const size_t inner_at = labels_at + slots * kLabelSize;
  const size_t size = inner_at + inner.size();
  if (size > 0xFFFFFFFFull) throw Error("plane tile: " + std::to_string(size) + " bytes do not fit its 32-bit size");
  std::vector<uint8_t> out(size, 0);
  store_le<uint32_t>(out.data() + kOffMagic, kMagic);
  store_le<uint16_t>(out.data() + kOffVersion, any_wide ? kVersion : kVersionNarrow);
  out[kOffLevels] = uint8_t(finest_level + 1);
  store_le<uint32_t>(out.data() + kOffPlaneCount, uint32_t(blocks));
  store_le<uint32_t>(out.data() + kOffByteSize, uint32_t(size));
  store_le<uint32_t>(out.data() + kOffTableCount, uint32_t(table.size()));
  store_le<uint32_t>(out.data() + kOffLabelCount, uint32_t(slots));
  for (size_t t = 0; t < table.size(); ++t) {
    uint8_t* e = out.data() + kHeaderSize + t * kEntrySize;
    store_le<uint64_t>(e + kOffA, uint64_t(table[t].a));
    store_le<uint64_t>(e + kOffB, uint64_t(table[t].b));
    store_le<uint64_t>(e + kOffC, uint64_t(table[t].c));
  }
  for (size_t r = 0; r < recs.size(); ++r) {
    uint8_t* o = out.data() + blocks_at + r * kRecordSize;
    store_le<uint32_t>(o + kOffStart, recs[r].start);
    o[kOffShift] = uint8_t(recs[r].shift);
    o[kOffKind] = recs[r].kind;
    store_le<uint16_t>(o + kOffIndex, uint16_t(recs[r].index));
  }
  uint8_t* o = out.data() + labels_at;
  for (size_t b = 0; b < labelled.size(); ++b) {
    const bool wide = labelled[b].palette.size() > kPalette;
    for (uint32_t t = 0; t < (wide ? kWidePalette : kPalette); ++t)
      store_le<uint16_t>(o + 2 * t, uint16_t(palettes[b * kWidePalette + t]));
    for (uint32_t t = 0; t < 64; ++t) {
      const uint32_t label = labelled[b].label[t];
      ST_CHECK(label < labelled[b].palette.size());
      if (wide)
        for (uint32_t bit = 0; bit < kWideLabelBits; ++bit) o[kOffWideBits + 8 * bit + t / 8] |= uint8_t((label >> bit & 1u) << (t % 8));
      else
        o[kOffLabelBits + t / 4] |= uint8_t(label << (2 * (t % 4)));
    }
    o += wide ? kWideSize : kLabelSize;
  }
  std::copy(inner.begin(), inner.end(), out.begin() + ptrdiff_t(inner_at));
  return out;
}

}  // namespace st
