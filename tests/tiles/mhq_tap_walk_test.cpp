// The MH / MMH single-tap walk of batches (tiles/core/mhq_tap_walk.hpp: branch-free steps,
// resumed from the last walk's path), behind TapWalks::walk_tap, TapWalks::tap_run and
// Evaluator::pcf_batch: every texel of every level answers depth_region's value and region
// bit for bit, in scan, Morton, reversed, strided (a real level's view: taps a dozen
// texels apart) and shuffled orders, with the path kept across runs of every length and
// shared between two trees (a new owner starts afresh).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <numeric>
#include <vector>

#include "interval_fields.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/morton.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {
namespace mhq_tap_walk_test {
namespace {

uint32_t bits(float f) { return std::bit_cast<uint32_t>(f); }

// The orders a batch's texels (indices y * side + x) come in.
std::vector<std::vector<uint32_t>> orders(uint32_t level, fields::Rng& rng) {
  const uint32_t side = 1u << level, n = side * side;
  std::vector<std::vector<uint32_t>> out;
  std::vector<uint32_t> scan(n);
  std::iota(scan.begin(), scan.end(), 0u);
  out.push_back(scan);
  std::vector<uint32_t> morton = scan;
  std::sort(morton.begin(), morton.end(), [&](uint32_t a, uint32_t b) {
    return morton_encode(a % side, a / side) < morton_encode(b % side, b / side);
  });
  out.push_back(morton);
  out.push_back(std::vector<uint32_t>(morton.rbegin(), morton.rend()));
  // Every 13th texel of each row in turn, then the next offset: neighbours a dozen apart.
  std::vector<uint32_t> strided;
  for (uint32_t o = 0; o < 13; ++o)
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = o; x < side; x += 13) strided.push_back(y * side + x);
  out.push_back(strided);
  std::vector<uint32_t> shuffled = scan;
  for (uint32_t i = n; i > 1; --i) std::swap(shuffled[i - 1], shuffled[rng.next() % i]);
  out.push_back(shuffled);
  return out;
}

std::vector<std::pair<std::string, std::vector<uint8_t>>> trees(uint32_t side, uint64_t seed) {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
  for (const fields::NamedField& f : fields::all_fields(side, seed)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh}) out.emplace_back(f.name + " " + to_string(e), encode(h, e));
  }
  return out;
}

Encoding encoding_of(const std::string& name) { return name.ends_with(" mh") ? Encoding::mh : Encoding::mmh; }

// tap_run over every texel of the finest level, in runs of random lengths (one path kept
// across them, as the client keeps one per tile), receivers at, just below and just above
// each texel's value: out equals the lit test on depth_region, and each run's end region
// is depth_region's at its last walked texel.
TEST(MhqTapWalk, RunsAnswerEveryTexelLikeDepthRegion) {
  const uint32_t L = fields::small_test_scale() ? 5 : 6, side = 1u << L;
  fields::Rng rng(20261206);
  for (const auto& [name, bytes] : trees(side, 20261206)) {
    SCOPED_TRACE(name);
    const auto eval = open_encoded(encoding_of(name), bytes);
    const TapWalks* walks = dynamic_cast<const TapWalks*>(eval.get());
    ASSERT_TRUE(walks);
    std::vector<float> want(size_t(side) * side);
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) want[y * side + x] = eval->depth_region(L, x, y).value;
    for (const std::vector<uint32_t>& order : orders(L, rng)) {
      std::vector<PcfQuery> q(order.size());
      for (size_t i = 0; i < q.size(); ++i) {
        const float v = want[i];
        const float receiver = i % 3 == 0 ? v : std::nextafter(v, i % 3 == 1 ? 0.0f : 2.0f);
        q[i] = PcfQuery{i % side, i / side, L, 1, receiver};
      }
      std::vector<uint16_t> ord(order.begin(), order.end());
      std::vector<float> out(q.size(), -1.0f);
      TapPath path;
      for (size_t k = 0; k < ord.size();) {
        const size_t len = std::min<size_t>(ord.size() - k, 1 + rng.next() % 300);
        const TapRunEnd end = walks->tap_run(TapRun{q.data(), ord.data() + k, len, L, L, 0, 0, out.data()}, path);
        const DepthRegion at = eval->depth_region(L, end.x, end.y);
        ASSERT_EQ(bits(end.region.value), bits(at.value));
        ASSERT_EQ(end.region.shift, at.shift);
        ASSERT_GE(end.walks, 1u);
        k += len;
      }
      for (size_t i = 0; i < q.size(); ++i)
        ASSERT_EQ(bits(out[i]), bits(q[i].receiver <= want[i] ? 1.0f : 0.0f)) << "texel " << i % side << "," << i / side;
    }
  }
}

// walk_tap at every level, every texel, in each order, the path now and then handed to a
// second tree over the same bytes: value and region of depth_region, bit for bit.
TEST(MhqTapWalk, WalksAtEveryLevelAnswerLikeDepthRegion) {
  const uint32_t L = fields::small_test_scale() ? 5 : 6;
  fields::Rng rng(20261207);
  for (const auto& [name, bytes] : trees(1u << L, 20261207)) {
    SCOPED_TRACE(name);
    const auto a = open_encoded(encoding_of(name), bytes), b = open_encoded(encoding_of(name), bytes);
    const TapWalks* wa = dynamic_cast<const TapWalks*>(a.get());
    const TapWalks* wb = dynamic_cast<const TapWalks*>(b.get());
    ASSERT_TRUE(wa && wb);
    TapPath path;
    for (uint32_t level = 0; level <= L; ++level) {
      const uint32_t side = 1u << level;
      for (const std::vector<uint32_t>& order : orders(level, rng))
        for (uint32_t t : order) {
          const uint32_t x = t % side, y = t / side;
          const DepthRegion got = (rng.next() % 7 ? wa : wb)->walk_tap(level, x, y, path);
          const DepthRegion want = a->depth_region(level, x, y);
          ASSERT_EQ(bits(got.value), bits(want.value)) << "level " << level << " at " << x << "," << y;
          ASSERT_EQ(got.shift, want.shift) << "level " << level << " at " << x << "," << y;
        }
    }
  }
}

// pcf_batch's single taps (the same walk inside single_tap_batch) over every texel in each
// order, levels mixed: pcf() bit for bit.
TEST(MhqTapWalk, BatchedSingleTapsAnswerLikePcf) {
  const uint32_t L = fields::small_test_scale() ? 5 : 6, side = 1u << L;
  fields::Rng rng(20261208);
  for (const auto& [name, bytes] : trees(side, 20261208)) {
    SCOPED_TRACE(name);
    const auto eval = open_encoded(encoding_of(name), bytes);
    for (const std::vector<uint32_t>& order : orders(L, rng)) {
      std::vector<PcfQuery> q;
      for (uint32_t t : order) {
        const uint32_t level = rng.next() % 4 == 0 ? L - 1 - uint32_t(rng.next() % 2) : L;
        const uint32_t shift = L - level;
        const float v = eval->depth(level, (t % side) >> shift, (t / side) >> shift);
        q.push_back(PcfQuery{(t % side) >> shift, (t / side) >> shift, level, 1, t % 2 ? v : std::nextafter(v, 0.0f)});
      }
      std::vector<float> out(q.size());
      eval->pcf_batch(q, out);
      for (size_t i = 0; i < q.size(); ++i)
        ASSERT_EQ(bits(out[i]), bits(eval->pcf(q[i].level, q[i].x, q[i].y, 1, q[i].receiver))) << "query " << i;
    }
  }
}

}  // namespace
}  // namespace mhq_tap_walk_test
}  // namespace st
