// EXR and PNG I/O of depth-interval maps: bit-exact round trips, metadata, hostile files.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "image/exr_io.hpp"
#include "image/png_io.hpp"
#include "common/error.hpp"

namespace st {
namespace exr_io_test {

std::string tmp_path(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/" + name; }

IntervalTile random_tile(uint32_t level, uint64_t x0, uint64_t y0, uint32_t w, uint32_t h,
                         uint32_t seed) {
  IntervalTile t;
  t.level = level, t.x0 = x0, t.y0 = y0, t.width = w, t.height = h;
  t.data.resize(size_t(w) * h);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> d(0, 1);
  for (size_t k = 0; k < t.data.size(); ++k) {
    switch (rng() % 5) {
      case 0: t.data[k] = {kLitDepth, kLitDepth}; break;
      case 1: t.data[k] = {-0.0f, 1e-40f}; break;  // negative zero and a denormal survive
      default: {
        float a = d(rng), b = d(rng);
        t.data[k] = {std::min(a, b), std::max(a, b)};
      }
    }
  }
  return t;
}

void expect_bit_exact(const IntervalTile& a, const IntervalTile& b) {
  ASSERT_EQ(a.level, b.level);
  ASSERT_EQ(a.x0, b.x0);
  ASSERT_EQ(a.y0, b.y0);
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  ASSERT_EQ(a.data.size(), b.data.size());
  EXPECT_EQ(std::memcmp(a.data.data(), b.data.data(), a.data.size() * sizeof(Interval)), 0);
}

TEST(ExrIo, ScanlineRoundTripIsBitExactWithMetadata) {
  auto t = random_tile(10, 200, 900, 37, 23, 1);
  LightSpec spec = LightSpec::parse("sun:azimuth=31.5,elevation=47.25,margin=0.02");
  Aabb box;
  box.extend({-3, 0.5, -2}), box.extend({4e6, 7, 1e-3});
  LightSpace ls = LightSpace::fit(spec, box);
  const std::string p = tmp_path("scan.exr");
  write_interval_exr(p, t, {spec.to_string(), ls});
  EXPECT_FALSE(exr_is_tiled(p));
  ExrLightInfo info;
  auto back = read_interval_exr(p, &info);
  expect_bit_exact(t, back);
  EXPECT_EQ(info.spec, spec.to_string());
  ASSERT_TRUE(info.space.has_value());
  EXPECT_EQ(info.space->to_array(), ls.to_array());
  EXPECT_EQ(info.space->kind(), LightKind::sun);
  EXPECT_FALSE(std::filesystem::exists(p + ".tmp"));
}

TEST(ExrIo, LargeMapsAreTiledAndRoundTripBitExact) {
  auto t = random_tile(13, 8192 - 4100, 5, 4100, 3, 2);
  const std::string p = tmp_path("tiled.exr");
  write_interval_exr(p, t);
  EXPECT_TRUE(exr_is_tiled(p));
  ExrLightInfo info;
  auto back = read_interval_exr(p, &info);
  expect_bit_exact(t, back);
  EXPECT_TRUE(info.spec.empty());
  EXPECT_FALSE(info.space.has_value());
}

TEST(ExrIo, Level20RegionKeepsItsAddress) {
  auto t = random_tile(20, (1u << 20) - 5, 123456, 5, 2, 3);
  const std::string p = tmp_path("l20.exr");
  write_interval_exr(p, t);
  expect_bit_exact(t, read_interval_exr(p));
}

TEST(ExrIo, RejectsInconsistentTilesOnWrite) {
  auto t = random_tile(4, 10, 0, 7, 2, 4);  // 10 + 7 > 16
  EXPECT_THROW(write_interval_exr(tmp_path("bad.exr"), t), Error);
  IntervalTile empty;
  EXPECT_THROW(write_interval_exr(tmp_path("bad.exr"), empty), Error);
}

TEST(ExrIo, MissingTruncatedAndCorruptFilesGiveFormatErrors) {
  EXPECT_THROW(read_interval_exr(tmp_path("does-not-exist.exr")), FormatError);
  auto t = random_tile(8, 0, 0, 64, 40, 5);
  const std::string p = tmp_path("whole.exr");
  write_interval_exr(p, t);
  std::ifstream in(p, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
  ASSERT_GT(bytes.size(), 100u);
  const std::string q = tmp_path("cut.exr");
  const size_t step = std::max<size_t>(1, bytes.size() / 40);
  for (size_t len = 0; len < bytes.size(); len += step) {
    std::ofstream(q, std::ios::binary).write(bytes.data(), std::streamsize(len));
    EXPECT_THROW(read_interval_exr(q), FormatError) << "truncated at " << len;
  }
  std::vector<char> junk(512, 'x');
  std::ofstream(q, std::ios::binary).write(junk.data(), std::streamsize(junk.size()));
  EXPECT_THROW(read_interval_exr(q), FormatError);
}

TEST(PngIo, PreviewShowsLitTexelsInBlueAndNearHitsBright) {
  IntervalTile t;
  t.level = 2, t.width = 4, t.height = 4;
  t.data.assign(16, Interval{kLitDepth, kLitDepth});
  t.at(1, 1) = {0.25f, 0.5f};  // nearest
  t.at(2, 3) = {0.75f, 0.75f};  // farthest
  uint32_t w = 0, h = 0;
  auto px = depth_preview(t, 4096, w, h);
  ASSERT_EQ(w, 4u);
  ASSERT_EQ(h, 4u);
  EXPECT_EQ(px[0], kPreviewLitColour);
  EXPECT_EQ(px[5], (Rgb8{250, 250, 250}));
  EXPECT_EQ(px[14], (Rgb8{40, 40, 40}));
  const std::string p = tmp_path("preview.png");
  write_depth_preview_png(p, t);
  uint32_t rw = 0, rh = 0;
  EXPECT_EQ(read_png(p, rw, rh), px);
  EXPECT_EQ(rw, 4u);
  // Point-sampled down when larger than max_side.
  auto small = depth_preview(t, 2, w, h);
  EXPECT_EQ(w, 2u);
  EXPECT_EQ(small.size(), 4u);
  EXPECT_THROW(write_png(tmp_path("x.png"), 3, 3, std::vector<Rgb8>(8)), Error);
  const std::string junk = tmp_path("junk.png");
  std::ofstream(junk, std::ios::binary) << "\x89PNG not really";
  EXPECT_THROW(read_png(junk, rw, rh), FormatError);
}

}  // namespace exr_io_test
}  // namespace st
