// Deep shadow tiles (DEEP.md): pinned offsets, a round trip within the error contract
// at every mip, filtered lookups between their texels, and hostile input refused
// (truncation at every length, trailing bytes, corrupted fields).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tiles/encode/deep_encode.hpp"
#include "tiles/core/deep_tile.hpp"

namespace st {
namespace {

VisibilityFunction step(float z, float t0, float t1, float t2) {
  VisibilityFunction f;
  f.monochrome = t0 == t1 && t1 == t2;
  f.vertices = {{z, {1, 1, 1}}, {z, {t0, t1, t2}}};
  return f;
}

// Random functions like a sampler's: steps and linear runs, some coloured, some empty.
std::vector<VisibilityFunction> random_tile(uint32_t side_bits, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  const uint32_t n = 1u << side_bits;
  std::vector<VisibilityFunction> out(size_t(n) * n);
  for (auto& f : out) {
    const int k = int(rng() % 6);
    const bool mono = rng() % 2;
    f.monochrome = mono;
    std::array<float, 3> t{1, 1, 1};
    float z = 0.1f * u(rng);
    for (int i = 0; i < k; ++i) {
      z += 0.15f * u(rng);
      f.vertices.push_back({z, t});
      for (int c = 0; c < 3; ++c) t[c] *= mono ? (c == 0 ? u(rng) : 1.0f) : u(rng);
      if (mono) t[1] = t[2] = t[0];
      if (rng() % 3 == 0) z += 0.05f;  // a linear run instead of a step
      f.vertices.push_back({z, t});
    }
  }
  return out;
}

TEST(DeepFormat, OffsetsArePinned) {
  EXPECT_EQ(offsetof(deep::Header, magic), 0u);
  EXPECT_EQ(offsetof(deep::Header, version), 4u);
  EXPECT_EQ(offsetof(deep::Header, header_bytes), 8u);
  EXPECT_EQ(offsetof(deep::Header, side_bits), 12u);
  EXPECT_EQ(offsetof(deep::Header, mip_count), 16u);
  EXPECT_EQ(offsetof(deep::Header, texel_count), 20u);
  EXPECT_EQ(offsetof(deep::Header, directory_offset), 24u);
  EXPECT_EQ(offsetof(deep::Header, data_offset), 28u);
  EXPECT_EQ(offsetof(deep::Header, data_bytes), 32u);
  EXPECT_EQ(offsetof(deep::Header, total_bytes), 36u);
  EXPECT_EQ(offsetof(deep::Header, epsilon), 40u);
  EXPECT_EQ(offsetof(deep::Header, reserved), 44u);
  EXPECT_EQ(offsetof(deep::DirEntry, offset), 0u);
  EXPECT_EQ(offsetof(deep::DirEntry, vertex_count), 4u);
  EXPECT_EQ(offsetof(deep::DirEntry, flags), 6u);
  EXPECT_EQ(deep::block_bytes(2, true), 12u);   // 8 depth + 4 value
  EXPECT_EQ(deep::block_bytes(1, true), 8u);    // 4 + 2, padded
  EXPECT_EQ(deep::block_bytes(2, false), 20u);  // 8 + 12
  // A 2 x 2 tile, bytes written out: one grey step, one coloured step, two lit texels.
  const std::vector<VisibilityFunction> in = {step(0.5f, 0.5f, 0.5f, 0.5f),
                                              step(0.25f, 1, 0.5f, 0), {}, {}};
  const std::vector<uint8_t> b = encode_deep_tile(in, 1, 0.0);
  ASSERT_EQ(b.size(), 48u + 5 * 8 + 12 + 20 + 0 + 0 + deep::block_bytes(4, false));
  EXPECT_EQ(load_le<uint32_t>(b, 0), 0x544D5344u);  // "DSMT"
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "DSMT");
  EXPECT_EQ(load_le<uint32_t>(b, 12), 1u);
  EXPECT_EQ(load_le<uint32_t>(b, 20), 5u);
  EXPECT_EQ(load_le<uint32_t>(b, 28), 88u);
  // Texel 0: offset 0, 2 vertices, monochrome; texel 1: offset 12, 2 vertices, rgb.
  EXPECT_EQ(load_le<uint32_t>(b, 48), 0u);
  EXPECT_EQ(load_le<uint16_t>(b, 52), 2u);
  EXPECT_EQ(b[54], deep::kFlagMonochrome);
  EXPECT_EQ(load_le<uint32_t>(b, 56), 12u);
  EXPECT_EQ(b[62], 0);
  EXPECT_EQ(load_le<float>(b, 88), 0.5f);
  EXPECT_EQ(load_le<uint16_t>(b, 88 + 8), 65535u);
  EXPECT_EQ(load_le<uint16_t>(b, 88 + 10), 32768u);  // 0.5 rounds up
  EXPECT_EQ(load_le<float>(b, 100), 0.25f);
  EXPECT_EQ(load_le<uint16_t>(b, 100 + 8 + 6), 65535u);  // vertex 1, red
  EXPECT_EQ(load_le<uint16_t>(b, 100 + 8 + 10), 0u);     // vertex 1, blue
  // Mip 1: the average of the four (exact with epsilon 0).
  const DeepTileView v = DeepTileView::open(b);
  EXPECT_EQ(v.mip_count(), 2u);
  const auto coarse = v.transmittance(0, 0, 0.75f, 1);
  EXPECT_NEAR(coarse[0], (0.5 + 1 + 1 + 1) / 4, 1e-4);
  EXPECT_NEAR(coarse[2], (0.5 + 0 + 1 + 1) / 4, 1e-4);
}

TEST(DeepTile, RoundTripWithinTheBoundAtEveryMip) {
  const uint32_t bits = 3;
  const double eps = 0.01;
  const auto in = random_tile(bits, 5);
  DeepEncodeStats stats;
  const std::vector<uint8_t> b = encode_deep_tile(in, bits, eps, &stats);
  const DeepTileView v = DeepTileView::open(b);
  EXPECT_EQ(v.side(0), 8u);
  EXPECT_FLOAT_EQ(v.epsilon(), float(eps));
  // Mip m against the exact box average of the inputs.
  for (uint32_t m = 0; m <= bits; ++m) {
    const uint32_t s = v.side(m), block = 1u << m;
    for (uint32_t y = 0; y < s; ++y)
      for (uint32_t x = 0; x < s; ++x) {
        std::vector<const VisibilityFunction*> kids;
        for (uint32_t j = 0; j < block; ++j)
          for (uint32_t i = 0; i < block; ++i) kids.push_back(&in[(y * block + j) * 8 + x * block + i]);
        const std::vector<double> w(kids.size(), 1.0);
        const VisibilityFunction truth = average(kids, w);
        const VisibilityFunction got = v.function(x, y, m);
        ASSERT_EQ(got.check(), "");
        EXPECT_LE(max_difference(truth, got), eps * (2 - std::ldexp(1.0, -int(m))) +
                                                  deep::kQuantisation + 1e-6)
            << "mip " << m << " texel " << x << "," << y;
        // Lookups agree with the decoded function.
        for (float z : {0.0f, 0.2f, 0.45f, 0.9f}) {
          const auto a = v.transmittance(x, y, z, m);
          const auto e = got.eval(z);
          for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], e[c], 1e-6);
        }
      }
  }
  // Filters stay within the range of the texels they blend and are monotone in depth.
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(0, 1);
  for (int k = 0; k < 200; ++k) {
    const double x = u(rng), y = u(rng), lod = 3.5 * u(rng);
    const float z0 = float(u(rng)), z1 = z0 + 0.1f;
    const auto a = v.trilinear(x, y, z0, lod), b1 = v.trilinear(x, y, z1, lod);
    for (int c = 0; c < 3; ++c) {
      EXPECT_GE(a[c], 0.0f);
      EXPECT_LE(a[c], 1.0f);
      EXPECT_LE(b1[c], a[c] + 1e-6f);
    }
  }
  // At a texel centre bilinear is the texel; the widest footprint is the last mip.
  const auto centre = v.bilinear((2 + 0.5) / 8, (5 + 0.5) / 8, 0.4f, 0);
  const auto texel = v.transmittance(2, 5, 0.4f, 0);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(centre[c], texel[c], 1e-6);
  const auto wide = v.filtered(0.3, 0.6, 0.4f, 4.0);
  const auto top = v.transmittance(0, 0, 0.4f, 3);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(wide[c], top[c], 1e-6);
}

TEST(DeepTile, HostileInputIsRefused) {
  const auto in = random_tile(2, 11);
  const std::vector<uint8_t> b = encode_deep_tile(in, 2, 0.02);
  DeepTileView::open(b);
  for (size_t n = 0; n < b.size(); ++n)
    EXPECT_THROW(DeepTileView::open(std::span(b.data(), n)), FormatError) << n;
  std::vector<uint8_t> longer = b;
  longer.push_back(0);
  EXPECT_THROW(DeepTileView::open(longer), FormatError);
  // Any single header field changed is refused (epsilon: to NaN).
  for (size_t at = 0; at < 48; at += 4) {
    std::vector<uint8_t> c = b;
    if (at == 40) store_le<float>(c.data() + 40, NAN);
    else store_le<uint32_t>(c.data() + at, load_le<uint32_t>(c, at) + 1);
    EXPECT_THROW(DeepTileView::open(c), FormatError) << at;
  }
  // Directory: an offset, a count, unknown flags.
  for (size_t at : {size_t(48 + 8), size_t(48 + 4), size_t(48 + 7)}) {
    std::vector<uint8_t> c = b;
    c[at] ^= 0x40;
    EXPECT_THROW(DeepTileView::open(c), FormatError) << at;
  }
  // A depth that decreases or is NaN, and a value that increases.
  const uint32_t data = load_le<uint32_t>(b, 28);
  uint32_t first = 0;  // the first texel with two or more vertices
  while (load_le<uint16_t>(b, 48 + 8 * first + 4) < 2) ++first;
  const uint32_t off = data + load_le<uint32_t>(b, 48 + 8 * first);
  std::vector<uint8_t> c = b;
  store_le<float>(c.data() + off, 2.0f);
  EXPECT_THROW(DeepTileView::open(c), FormatError);
  c = b;
  store_le<float>(c.data() + off + 4, NAN);
  EXPECT_THROW(DeepTileView::open(c), FormatError);
  c = b;
  const uint32_t n = load_le<uint16_t>(b, 48 + 8 * first + 4);
  const uint32_t ch = (b[48 + 8 * first + 6] & deep::kFlagMonochrome) ? 1 : 3;
  store_le<uint16_t>(c.data() + off + 4 * n + 2 * ch, 65535);  // vertex 1 back to 1
  store_le<uint16_t>(c.data() + off + 4 * n, 100);             // vertex 0 down to ~0
  EXPECT_THROW(DeepTileView::open(c), FormatError);
  // The encoder refuses what it cannot store.
  EXPECT_THROW(encode_deep_tile(in, 3, 0.1), Error);  // wrong count
  EXPECT_THROW(encode_deep_tile(in, 2, -1), Error);
  EXPECT_THROW(encode_deep_tile(in, 2, 0.0, nullptr, 64), Error);
}

}  // namespace
}  // namespace st
