// Voxel shadow DAG construction (voxelized shadows 2014 §6.1 top down against a min-max
// pyramid, then common-subtree merging bottom up); see vsdag_encode.hpp.
#include "tiles/encode/vsdag_encode.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/vsdag_evaluator.hpp"

namespace st {

using namespace vsdag;

uint32_t vsdag_transition(float lo, float hi, uint32_t z_bits) {
  if (!(lo <= hi)) throw Error("vsdag: interval [" + std::to_string(lo) + ", " + std::to_string(hi) + "] is empty or NaN");
  const uint32_t d = 1u << z_bits;
  const double l = std::clamp(double(lo), 0.0, 1.0), h = std::clamp(double(hi), 0.0, 1.0);
  const uint32_t tmin = std::min<uint32_t>(uint32_t(std::floor(l * d)), d);
  const uint32_t tmax = std::min<uint32_t>(uint32_t(std::floor(h * d)) + 1, d);
  for (uint32_t b = z_bits + 1; b-- > 0;) {
    const uint64_t step = uint64_t(1) << b, c = (uint64_t(tmin) + step - 1) / step * step;
    if (c <= tmax) return uint32_t(c);
  }
  return tmin;  // unreachable: b = 0 always fits
}

namespace {

class Builder {
 public:
  Builder(const Hierarchy& h, uint32_t z_bits) : s_(Shape::of(h.depth, z_bits)) {
    const uint32_t n = h.depth, side = 1u << n, p = s_.padded_xy_bits, ps = 1u << p;
    // Each valued node paints its transition over its square; finer levels overwrite
    // (hierarchy.hpp "Meaning": the deepest valued ancestor answers).
    std::vector<uint32_t> t(size_t(side) * side, 0);
    for (uint32_t l = 0; l <= n; ++l)
      for (const HNode& nd : h.levels[l]) {
        if (!nd.has_value) continue;
        const uint32_t tv = vsdag_transition(nd.lo, nd.hi, z_bits), sz = 1u << (n - l);
        const uint32_t x0 = morton_compact(nd.morton) * sz, y0 = morton_compact(nd.morton >> 1) * sz;
        for (uint32_t y = y0; y < y0 + sz; ++y) std::fill_n(t.begin() + size_t(y) * side + x0, sz, tv);
      }
    // Padded to at least 8x8 by repeating the edge (never looked up).
    t_.resize(size_t(ps) * ps);
    for (uint32_t y = 0; y < ps; ++y)
      for (uint32_t x = 0; x < ps; ++x) t_[size_t(y) * ps + x] = t[size_t(std::min(y, side - 1)) * side + std::min(x, side - 1)];
    // Min-max pyramid of the transitions (§6.1: "a min-max hierarchy of this shadow map").
    mn_.assign(p + 1, {}), mx_.assign(p + 1, {});
    mn_[0] = t_, mx_[0] = t_;
    for (uint32_t g = 1; g <= p; ++g) {
      const uint32_t w = ps >> g, pw = w * 2;
      mn_[g].resize(size_t(w) * w), mx_[g].resize(size_t(w) * w);
      for (uint32_t y = 0; y < w; ++y)
        for (uint32_t x = 0; x < w; ++x) {
          const size_t a = size_t(2 * y) * pw + 2 * x, b = a + pw;
          mn_[g][size_t(y) * w + x] = std::min({mn_[g - 1][a], mn_[g - 1][a + 1], mn_[g - 1][b], mn_[g - 1][b + 1]});
          mx_[g][size_t(y) * w + x] = std::max({mx_[g - 1][a], mx_[g - 1][a + 1], mx_[g - 1][b], mx_[g - 1][b + 1]});
        }
    }
  }

  std::vector<uint8_t> run() {
    const uint32_t xlog = s_.padded_xy_bits - s_.grid_xy_bits, zlog = s_.z_bits - s_.grid_z_bits;
    const uint32_t gx = 1u << s_.grid_xy_bits, gz = 1u << s_.grid_z_bits;
    std::vector<uint32_t> grid(s_.grid_cells());
    for (uint32_t cz = 0; cz < gz; ++cz)
      for (uint32_t cy = 0; cy < gx; ++cy)
        for (uint32_t cx = 0; cx < gx; ++cx) {
          const uint32_t x0 = cx << xlog, y0 = cy << xlog, z0 = cz << zlog;
          const uint32_t st = classify(x0, y0, xlog, z0, zlog);
          grid[s_.grid_cell(x0, y0, z0)] = st == kMixed ? (kMixed << kStateShift) | build(0, x0, y0, xlog, z0, zlog) : st << kStateShift;
        }
    if (nodes_.size() >= kMaxCount || leaves_.size() >= kMaxCount)
      throw Error("vsdag: tile too large for the format (" + std::to_string(nodes_.size()) + " node words)");
    Header h{};
    h.magic = kMagic, h.version = kVersion, h.header_bytes = sizeof(Header);
    h.xy_bits = s_.xy_bits, h.z_bits = s_.z_bits;
    h.grid_xy_bits = s_.grid_xy_bits, h.grid_z_bits = s_.grid_z_bits, h.inner_levels = s_.levels;
    h.leaf_count = uint32_t(leaves_.size()), h.node_words = uint32_t(nodes_.size());
    const uint64_t total = sizeof(Header) + 8 * leaves_.size() + 4 * grid.size() + 4 * nodes_.size();
    if (total > UINT32_MAX) throw Error("vsdag: tile of " + std::to_string(total) + " bytes exceeds 4 GiB");
    h.leaf_offset = sizeof(Header);
    h.grid_offset = h.leaf_offset + 8 * h.leaf_count;
    h.node_offset = h.grid_offset + 4 * uint32_t(grid.size());
    h.total_bytes = uint32_t(total);
    std::vector<uint8_t> out(total);
    uint8_t* o = out.data();
    std::memcpy(o, &h, sizeof h);
    if (!leaves_.empty()) std::memcpy(o + h.leaf_offset, leaves_.data(), 8 * leaves_.size());
    std::memcpy(o + h.grid_offset, grid.data(), 4 * grid.size());
    if (!nodes_.empty()) std::memcpy(o + h.node_offset, nodes_.data(), 4 * nodes_.size());
    return out;
  }

  // Every column of the buffer must turn from lit to shadowed at the transition intended
  // for it: slab t - 1 lit and slab t shadowed, read back through the validating opener
  // and the readers' own walk. (Two walks per column, where the readers' bisection
  // first_shadow_slab takes z_bits + 1; on the columns this builder writes, lit above one
  // transition and shadowed below, the two checks are equivalent.)
  void verify(std::span<const uint8_t> bytes) const {
    const VsdagEvaluator ev(bytes);
    const View& v = ev.view();
    const uint32_t side = 1u << s_.xy_bits, ps = 1u << s_.padded_xy_bits;
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) {
        const uint32_t t = t_[size_t(y) * ps + x];
        ST_CHECK(t == 0 || v.lit(x, y, t - 1));
        ST_CHECK(t == v.slabs() || !v.lit(x, y, t));
      }
  }

 private:
  uint32_t classify(uint32_t x0, uint32_t y0, uint32_t xlog, uint32_t z0, uint32_t zlog) const {
    const uint32_t w = 1u << (s_.padded_xy_bits - xlog);
    const size_t i = size_t(y0 >> xlog) * w + (x0 >> xlog);
    if (mn_[xlog][i] >= z0 + (1u << zlog)) return kLit;
    if (mx_[xlog][i] <= z0) return kShadow;
    return kMixed;
  }

  // The smallest transition above z0 among the columns of block (x, y) of pyramid level
  // g (kNone if none), by descending the min-max pyramid: a sub-block entirely at or
  // below z0 holds none, one entirely above offers its minimum, and a sub-block whose
  // minimum cannot beat the best found so far is skipped.
  static constexpr uint32_t kNone = UINT32_MAX;
  uint32_t next_above(uint32_t g, uint32_t x, uint32_t y, uint32_t z0, uint32_t best) const {
    const size_t i = size_t(y) * (1u << (s_.padded_xy_bits - g)) + x;
    if (mx_[g][i] <= z0 || mn_[g][i] >= best) return best;
    if (mn_[g][i] > z0) return mn_[g][i];
    for (uint32_t c = 0; c < 4; ++c) best = next_above(g - 1, 2 * x + (c & 1), 2 * y + (c >> 1), z0, best);
    return best;
  }

  // A block whose columns have no transition strictly inside (z0, z0 + 2^zlog) holds the
  // same voxels at every depth of that range: lit exactly in the columns whose
  // transition lies above z0, i.e. those at or above the smallest such transition
  // (`above`). Its subtree at a given level depends only on that set, so (level, block,
  // above) names it; returns false when some transition lies inside.
  bool depth_uniform(uint32_t x0, uint32_t y0, uint32_t xlog, uint32_t z0, uint32_t zlog, uint32_t& above) const {
    above = next_above(xlog, x0 >> xlog, y0 >> xlog, z0, kNone);
    return above == kNone || above >= z0 + (1u << zlog);
  }

  // The node at inner level i (i == levels: the z-node) covering the given mixed block;
  // returns its word offset, shared with an identical earlier node. Depth-uniform blocks
  // (depth_uniform) are memoized by (level, block, lit columns): without that the build
  // visits every node along each column's whole undefined-to-shadow span, although the
  // merge leaves one node per pattern.
  uint32_t build(uint32_t i, uint32_t x0, uint32_t y0, uint32_t xlog, uint32_t z0, uint32_t zlog) {
    uint32_t above = 0;
    const bool uniform = depth_uniform(x0, y0, xlog, z0, zlog, above);
    const UniformKey key{(uint64_t(y0) << 32) | x0, (uint64_t(above) << 8) | i};
    if (uniform) {
      if (const auto it = uniform_.find(key); it != uniform_.end()) return it->second;
    }
    const uint32_t at = build_node(i, x0, y0, xlog, z0, zlog);
    if (uniform) uniform_.emplace(key, at);
    return at;
  }

  uint32_t build_node(uint32_t i, uint32_t x0, uint32_t y0, uint32_t xlog, uint32_t z0, uint32_t zlog) {
    uint32_t words[9];
    uint32_t mask = 0, count = 1;
    if (i == s_.levels) {  // 8 slabs of 8x8 leaves (§5 layout)
      for (uint32_t c = 0; c < 8; ++c) {
        uint64_t bits = 0;
        for (uint32_t yy = 0; yy < 8; ++yy)
          for (uint32_t xx = 0; xx < 8; ++xx)
            bits |= uint64_t(z0 + c < t_[size_t(y0 + yy) * (1u << s_.padded_xy_bits) + x0 + xx]) << leaf_bit(xx, yy);
        const uint32_t st = bits == ~uint64_t(0) ? kLit : bits == 0 ? kShadow : kMixed;
        mask |= st << (2 * c);
        if (st == kMixed) words[count++] = leaf(bits);
      }
    } else {
      const bool sx = s_.split[i] & kSplitXy, sz = s_.split[i] & kSplitZ;
      const uint32_t cx = sx ? xlog - 1 : xlog, cz = sz ? zlog - 1 : zlog;
      for (uint32_t c = 0; c < 8; ++c) {
        if ((!sx && (c & 3)) || (!sz && c >= 4)) continue;
        const uint32_t x = x0 + ((c & 1) << cx), y = y0 + (((c >> 1) & 1) << cx), z = z0 + ((c >> 2) << cz);
        const uint32_t st = classify(x, y, cx, z, cz);
        mask |= st << (2 * c);
        if (st == kMixed) words[count++] = build(i + 1, x, y, cx, z, cz);
      }
    }
    words[0] = mask;
    return intern(i, words, count);
  }

  uint32_t leaf(uint64_t bits) {
    auto [it, fresh] = leaf_index_.try_emplace(bits, uint32_t(leaves_.size()));
    if (fresh) leaves_.push_back(bits);
    return it->second;
  }

  // Nodes are shared within one level only: a node's meaning depends on its level's split.
  uint32_t intern(uint32_t level, const uint32_t* words, uint32_t count) {
    uint64_t hash = mix64(count + (uint64_t(level) << 32));
    for (uint32_t k = 0; k < count; ++k) hash = mix64(hash ^ (uint64_t(words[k]) + 0x9E3779B97F4A7C15ull * (k + 1)));
    auto [lo, hi] = node_index_.equal_range(hash);
    for (auto it = lo; it != hi; ++it) {
      const auto [at, at_level] = it->second;
      if (at_level != level) continue;
      // A hash match is a candidate only: compare the whole node (STYLE.md).
      if (at + count <= nodes_.size() && (1 + uint32_t(std::popcount(mixed_bits(nodes_[at])))) == count &&
          std::equal(words, words + count, nodes_.begin() + at))
        return at;
    }
    const uint32_t at = uint32_t(nodes_.size());
    nodes_.insert(nodes_.end(), words, words + count);
    node_index_.emplace(hash, std::pair<uint32_t, uint32_t>(at, level));
    return at;
  }

  struct UniformKey {
    uint64_t block, above_level;
    bool operator==(const UniformKey&) const = default;
  };
  struct UniformKeyHash {
    size_t operator()(const UniformKey& k) const { return size_t(mix64(k.block ^ mix64(k.above_level))); }
  };

  Shape s_;
  std::vector<uint32_t> t_;
  std::unordered_map<UniformKey, uint32_t, UniformKeyHash> uniform_;
  std::vector<std::vector<uint32_t>> mn_, mx_;
  std::vector<uint32_t> nodes_;
  std::vector<uint64_t> leaves_;
  std::unordered_map<uint64_t, uint32_t> leaf_index_;
  std::unordered_multimap<uint64_t, std::pair<uint32_t, uint32_t>> node_index_;  // hash -> (word, level)
};

}  // namespace

std::vector<uint8_t> encode_vsdag(const Hierarchy& h, const VsdagOptions& options) {
  if (options.z_bits < kMinZBits || options.z_bits > kMaxZBits)
    throw Error("vsdag: depth bits " + std::to_string(options.z_bits) + " outside 3..20");
  if (h.depth > kMaxLevel || h.levels.size() != h.depth + 1 || h.levels[0].size() != 1 || !h.levels[0][0].has_value)
    throw Error("vsdag: malformed hierarchy (levels or root)");
  Builder b(h, options.z_bits);
  std::vector<uint8_t> out = b.run();
  b.verify(out);
  return out;
}

}  // namespace st
