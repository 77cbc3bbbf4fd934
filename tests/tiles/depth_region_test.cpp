// Evaluator::depth_region: the region each encoding reports around a texel really shares
// its answer (every texel in it gives the same depth() bits), the value is depth()'s, and
// the regions are not vacuous (a field with constant areas reports regions wider than one
// texel). The client's last-sample cache trusts exactly this (client/remote_map_lookups.cpp).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <vector>

#include "interval_fields.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/tap_batch.hpp"

namespace st {
namespace {

uint32_t bits(float f) { return std::bit_cast<uint32_t>(f); }

TEST(DepthRegion, EveryTexelOfTheRegionSharesTheAnswer) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7, side = 1u << L;
  for (const fields::NamedField& f : fields::all_fields(side, 20261203)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);
      const auto eval = open_encoded(e, bytes);
      fields::Rng rng(uint64_t(e) + 1);
      uint64_t wide = 0;
      for (uint32_t level = 0; level <= L; ++level)
        for (uint32_t k = 0; k < 64; ++k) {
          const uint64_t n = uint64_t(1) << level;
          const uint64_t x = rng.next() & (n - 1), y = rng.next() & (n - 1);
          const DepthRegion r = eval->depth_region(level, x, y);
          ASSERT_LE(r.shift, level);
          ASSERT_EQ(bits(r.value), bits(eval->depth(level, x, y))) << "level " << level << " at " << x << "," << y;
          wide += r.shift > 0;
          const uint64_t s = uint64_t(1) << r.shift, x0 = x & ~(s - 1), y0 = y & ~(s - 1);
          // Up to 16 x 16 texels of the region, its far edges included.
          std::vector<uint64_t> offsets;
          for (uint64_t o = 0; o < s; o += std::max<uint64_t>(1, s / 16)) offsets.push_back(o);
          offsets.push_back(s - 1);
          for (uint64_t j : offsets)
            for (uint64_t i : offsets)
              ASSERT_EQ(bits(eval->depth(level, x0 + i, y0 + j)), bits(r.value))
                  << "level " << level << " region " << x0 << "," << y0 << " shift " << r.shift << " texel " << x0 + i
                  << "," << y0 + j;
        }
      if (f.name == "constant" || f.name == "city") {
        EXPECT_GT(wide, 0u) << "no region wider than a texel";
      }
    }
  }
}

// pcf_batch's single taps (tiles/core/tap_batch.hpp: kept regions, walks resumed from the
// last walk's path) answer like pcf(), bit for bit: rows in scan order, a zigzag, random
// texels and levels, coordinates past the edge (clamped), a level finer than the tree and
// wider kernels in between.
TEST(DepthRegion, BatchedSingleTapsAnswerLikePcf) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7, side = 1u << L;
  for (const fields::NamedField& f : fields::all_fields(side, 20261204)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);  // the evaluator reads them in place
      const auto eval = open_encoded(e, bytes);
      fields::Rng rng(uint64_t(e) + 7);
      std::vector<PcfQuery> q;
      auto receiver = [&](uint32_t level, uint64_t x, uint64_t y) {
        const uint64_t top = (uint64_t(1) << std::min(level, L)) - 1;
        const float d = eval->depth(std::min(level, L), std::min(x, top), std::min(y, top));
        return rng.next() & 1 ? d : std::nextafter(d, 2.0f);
      };
      for (uint32_t level : {L, L - 1, L - 3})
        for (uint64_t y = 0; y < (uint64_t(1) << level); y += 3)
          for (uint64_t k = 0; k < (uint64_t(1) << level); ++k) {
            const uint64_t x = (y / 3) & 1 ? (uint64_t(1) << level) - 1 - k : k;  // zigzag
            q.push_back({x, y, level, 1, receiver(level, x, y)});
          }
      for (uint32_t k = 0; k < 2000; ++k) {
        const uint32_t level = uint32_t(rng.next() % (L + 2));  // L + 1: finer than the tree
        const uint64_t x = rng.next() % ((uint64_t(1) << level) + 3), y = rng.next() % ((uint64_t(1) << level) + 3);
        q.push_back({x, y, level, k % 7 == 0 ? 3u : k % 11 == 0 ? 0u : 1u, receiver(level, x, y)});
      }
      std::vector<float> got(q.size());
      eval->pcf_batch(q, got);
      for (size_t i = 0; i < q.size(); ++i)
        ASSERT_EQ(bits(got[i]), bits(eval->pcf(q[i].level, q[i].x, q[i].y, q[i].r, q[i].receiver)))
            << "query " << i << ": level " << q[i].level << " at " << q[i].x << "," << q[i].y << " r " << q[i].r;
    }
  }
}

// TapWalks::walk_tap (tiles/core/tap_batch.hpp: one resumed walk, the path kept by the
// caller) gives depth_region's answer and region bit for bit, with one path switched
// between two trees (a new owner starts afresh) and walks in scan order, zigzag and at
// random texels and levels (resumed, restarted).
TEST(DepthRegion, ResumedSingleWalksAnswerLikeDepthRegion) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7, side = 1u << L;
  for (const fields::NamedField& f : fields::all_fields(side, 20261205)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);
      const auto a = open_encoded(e, bytes), b = open_encoded(e, bytes);
      const TapWalks* wa = dynamic_cast<const TapWalks*>(a.get());
      const TapWalks* wb = dynamic_cast<const TapWalks*>(b.get());
      ASSERT_TRUE(wa && wb);
      fields::Rng rng(uint64_t(e) + 11);
      TapPath path;
      auto check = [&](uint32_t level, uint64_t x, uint64_t y) {
        const bool first = rng.next() % 5 != 0;  // now and then the other tree, same path
        const DepthRegion got = (first ? wa : wb)->walk_tap(level, x, y, path);
        const DepthRegion want = a->depth_region(level, x, y);
        ASSERT_EQ(bits(got.value), bits(want.value)) << "level " << level << " at " << x << "," << y;
        ASSERT_EQ(got.shift, want.shift) << "level " << level << " at " << x << "," << y;
      };
      for (uint32_t level : {L, L - 2})
        for (uint64_t y = 0; y < (uint64_t(1) << level); y += 2)
          for (uint64_t k = 0; k < (uint64_t(1) << level); ++k)
            ASSERT_NO_FATAL_FAILURE(check(level, (y / 2) & 1 ? (uint64_t(1) << level) - 1 - k : k, y));
      for (uint32_t k = 0; k < 2000; ++k) {
        const uint32_t level = uint32_t(rng.next() % (L + 1));
        ASSERT_NO_FATAL_FAILURE(check(level, rng.next() & ((uint64_t(1) << level) - 1),
                                      rng.next() & ((uint64_t(1) << level) - 1)));
      }
    }
  }
}

// WindowDepths (tiles/core/tap_batch.hpp): every texel of a window walk's rectangle gets
// depth()'s bits, for rectangles of 1..9 texels a side anywhere (corners, straddling the
// quadrants of every level), at every level; the region it reports holds out[0] for the
// whole rectangle; and pcf (which counts its taps from a window walk) equals the count of
// depth() taps, at the map's clamped edges too.
TEST(DepthRegion, WindowWalkAnswersLikeDepth) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7;
  for (const fields::NamedField& f : fields::all_fields(1u << L, 20261205)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);
      const auto eval = open_encoded(e, bytes);
      const auto* win = dynamic_cast<const WindowDepths*>(eval.get());
      ASSERT_NE(win, nullptr);
      fields::Rng rng(uint64_t(e) + 11);
      for (uint32_t k = 0; k < 600; ++k) {
        const uint32_t level = uint32_t(rng.next() % (L + 1));
        const uint64_t n = uint64_t(1) << level;
        const uint32_t w = uint32_t(std::min<uint64_t>(n, 1 + rng.next() % Evaluator::kMaxPcf));
        const uint32_t hh = uint32_t(std::min<uint64_t>(n, 1 + rng.next() % Evaluator::kMaxPcf));
        const uint64_t x0 = rng.next() % (n - w + 1), y0 = rng.next() % (n - hh + 1);
        float out[Evaluator::kMaxPcf * Evaluator::kMaxPcf];
        const uint32_t shift = win->depth_window(level, x0, y0, w, hh, out);
        ASSERT_LE(shift, level);
        for (uint32_t i = 0; i < w; ++i)
          for (uint32_t j = 0; j < hh; ++j)
            ASSERT_EQ(bits(out[i * hh + j]), bits(eval->depth(level, x0 + i, y0 + j)))
                << "level " << level << " window " << x0 << "," << y0 << " " << w << "x" << hh << " texel +" << i << ",+"
                << j;
        const uint64_t s = uint64_t(1) << shift, rx = x0 & ~(s - 1), ry = y0 & ~(s - 1);
        if (((x0 ^ (x0 + w - 1)) | (y0 ^ (y0 + hh - 1))) >> shift == 0) {
          for (uint64_t t : {uint64_t(0), s / 2, s - 1})
            ASSERT_EQ(bits(eval->depth(level, rx + t, ry + (s - 1 - t))), bits(out[0])) << "region shift " << shift;
        }
        const uint32_t r = 1 + 2 * uint32_t(rng.next() % 5);
        const uint64_t cx = rng.next() % n, cy = rng.next() % n;
        const float recv = eval->depth(level, cx, cy);
        uint32_t lit = 0;
        for (uint32_t j = 0; j < r; ++j)
          for (uint32_t i = 0; i < r; ++i)
            lit += recv <= eval->depth(level, pcf_tap(cx, i, r, n), pcf_tap(cy, j, r, n)) ? 1u : 0u;
        ASSERT_EQ(bits(eval->pcf(level, cx, cy, r, recv)), bits(float(lit) / float(r * r)))
            << "pcf r " << r << " level " << level << " at " << cx << "," << cy;
      }
    }
  }
}

// WindowDepths::count_window counts exactly the lit texels the per-texel tests on
// depth() find: every window size 1..7 (squares and rectangles), random positions, and
// receivers at the window's own depths, one ulp either side and past every depth (the
// exact endpoints where the test flips). The tile's pcf through it equals the per-tap
// fraction bit for bit (pcf_fraction's table included).
TEST(DepthRegion, CountingWindowEqualsPerTapCount) {
  const uint32_t L = fields::small_test_scale() ? 6 : 7;
  for (const fields::NamedField& f : fields::all_fields(1u << L, 20261207)) {
    const Hierarchy h = build_hierarchy(f.tile);
    for (Encoding e : {Encoding::mh, Encoding::mmh, Encoding::dagmh}) {
      SCOPED_TRACE(f.name + " " + to_string(e));
      const std::vector<uint8_t> bytes = encode(h, e);
      const auto eval = open_encoded(e, bytes);
      const auto* win = dynamic_cast<const WindowDepths*>(eval.get());
      ASSERT_NE(win, nullptr);
      fields::Rng rng(uint64_t(e) + 23);
      for (uint32_t size = 1; size <= 7; ++size)
        for (uint32_t k = 0; k < 120; ++k) {
          const uint32_t level = uint32_t(rng.next() % (L + 1));
          const uint64_t n = uint64_t(1) << level;
          const uint32_t w = uint32_t(std::min<uint64_t>(n, size));
          const uint32_t hh = uint32_t(std::min<uint64_t>(n, k % 3 == 0 ? 1 + rng.next() % 7 : size));
          const uint64_t x0 = rng.next() % (n - w + 1), y0 = rng.next() % (n - hh + 1);
          std::vector<float> depths;
          for (uint32_t i = 0; i < w; ++i)
            for (uint32_t j = 0; j < hh; ++j) depths.push_back(eval->depth(level, x0 + i, y0 + j));
          const float d = depths[rng.next() % depths.size()];
          for (float recv : {d, std::nextafter(d, -1.0f), std::nextafter(d, 2.0f), 0.0f, 2.0f,
                             depths.front(), depths.back(), float(rng.uniform())}) {
            uint32_t lit = 0;
            for (float v : depths) lit += recv <= v ? 1u : 0u;
            ASSERT_EQ(win->count_window(level, x0, y0, w, hh, recv), lit)
                << "level " << level << " window " << x0 << "," << y0 << " " << w << "x" << hh << " receiver " << recv;
          }
          // The kernel of side `size` around a random texel (odd and even sides, clamped at
          // the edges or not) against its per-tap fraction.
          const uint64_t cx = rng.next() % n, cy = rng.next() % n;
          const float recv = eval->depth(level, cx, cy);
          uint32_t lit = 0;
          for (uint32_t j = 0; j < size; ++j)
            for (uint32_t i = 0; i < size; ++i)
              lit += recv <= eval->depth(level, pcf_tap(cx, i, size, n), pcf_tap(cy, j, size, n)) ? 1u : 0u;
          ASSERT_EQ(bits(eval->pcf(level, cx, cy, size, recv)), bits(float(lit) / float(size * size)))
              << "pcf r " << size << " level " << level << " at " << cx << "," << cy;
        }
    }
  }
}

TEST(DepthRegion, PcfFractionIsTheDivision) {
  for (uint32_t r = 1; r <= Evaluator::kMaxPcf; ++r)
    for (uint32_t lit = 0; lit <= r * r; ++lit) {
      volatile float num = float(lit), den = float(r * r);  // the division at run time
      ASSERT_EQ(bits(pcf_fraction(lit, r)), bits(num / den)) << lit << " / " << r << "^2";
    }
}

}  // namespace
}  // namespace st
