// The client's batched single taps on packs of real open-mesh assets (Debian's
// assimp-testmodels, installed by scripts/deps), where almost every texel has its own
// value and every tap walks its tile: batches answered in Morton order, one run per tile
// (tap_order.hpp, TapWalks::tap_run), equal bit for bit the lit test on each texel's
// single lookup through the client and through the pack, in screen-like, shuffled and
// scan orders, with batches of every size around the ordering's bounds, PCF kernels and
// coarser levels mixed in. A missing package skips with the command to run.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <filesystem>
#include <random>

#include "client/remote_map.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/tap_order.hpp"

namespace st::client {
namespace real_asset_taps_test {

namespace fs = std::filesystem;

struct RealTapCase {
  const char* file;  // under /usr/share/assimp/models/
  Encoding encoding;
};

class RealAssetTaps : public ::testing::TestWithParam<RealTapCase> {};

TEST_P(RealAssetTaps, BatchedTapsEqualSingleLookupsOnEveryTexel) {
  const RealTapCase& c = GetParam();
  const std::string file = std::string("/usr/share/assimp/models/") + c.file;
  if (!fs::exists(file)) GTEST_SKIP() << file << " missing: run scripts/deps (Debian package assimp-testmodels)";
  const Scene scene = load_scene(file);
  const LightSpace light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), scene.bounds());
  const uint32_t L = looptest::small_scale() ? 8 : 9;
  MapBuildOptions o;
  o.map_level = L;
  o.encoding = c.encoding;
  o.skip_level = 3;
  o.tile_bytes = 2048;  // many tiles: runs end at tile borders often
  o.dagmh_dictionary = o.dagmh_mixed_tiles = c.encoding == Encoding::dagmh;  // the CLI's default build
  fs::create_directories(SHADOWTILE_TEST_TMP);
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/taps_" + fs::path(c.file).stem().string() + "_" +
                           to_string(c.encoding) + ".pack";
  build_map(scene, light, o, path);
  const std::shared_ptr<const PackReader> reader = PackReader::open(path);
  ASSERT_GT(reader->tiles().size(), 16u);
  ClientOptions co = looptest::quick_options();
  co.cache_slots = uint32_t(reader->tiles().size()) + 8;
  co.want_capacity = co.cache_slots;
  const auto h = reader->header_bytes();
  const auto g = reader->grid_bytes();
  RemoteMap map("taps", std::vector<uint8_t>(h.begin(), h.end()), std::vector<uint8_t>(g.begin(), g.end()), co,
                std::make_shared<Notifier>());
  const uint64_t side = uint64_t(1) << L;
  for (uint32_t id = 1;; ++id) {  // every tile, as the fetcher delivers them
    map.request_region(L, 0, 0, side, side, 1);
    std::vector<proto::TileRequest> want;
    map.take_wanted(1u << 20, id, want);
    if (want.empty()) break;
    for (const auto& t : want) {
      const TileIndexEntry e = *reader->find(t.tile_id);
      proto::TileMeta m;
      m.tile_id = t.tile_id, m.flags = proto::kTileFlagZlib, m.uncompressed_size = e.raw_size, m.payload_crc32 = e.crc;
      ASSERT_TRUE(map.tile_arrived(m, id, reader->read_stored(t.tile_id)));
    }
  }
  ASSERT_TRUE(map.region_resident(L, 0, 0, side, side));
  const PackEvaluator pack(reader);

  // Every texel once, the receiver a hair in front of or behind its value (open surfaces:
  // the lit test turns on the last bit).
  std::vector<PcfQuery> all;
  std::vector<float> truth;
  std::mt19937_64 rng(36);
  size_t distinct = 0;
  float last = -1;
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x) {
      const float v = map.depth(L, x, y);
      ASSERT_EQ(std::bit_cast<uint32_t>(v), std::bit_cast<uint32_t>(pack.depth(L, x, y))) << x << "," << y;
      distinct += v != last, last = v;
      const float recv = (rng() & 1) ? std::nextafter(v, 2.0f) : v;
      all.push_back(PcfQuery{x, y, L, 1, recv});
      truth.push_back(recv <= v ? 1.0f : 0.0f);
    }
  EXPECT_GT(distinct, all.size() / 32) << "an open-mesh map: many texels with their own value";

  auto check = [&](const std::vector<size_t>& idx, size_t batch, const char* what) {
    std::vector<PcfQuery> q(idx.size());
    for (size_t k = 0; k < idx.size(); ++k) q[k] = all[idx[k]];
    std::vector<float> got(q.size(), -1.0f);
    for (size_t i = 0; i < q.size(); i += batch) {
      const size_t n = std::min(batch, q.size() - i);
      map.pcf_batch(std::span(q).subspan(i, n), std::span(got).subspan(i, n));
    }
    size_t wrong = 0;
    for (size_t k = 0; k < q.size(); ++k) wrong += std::bit_cast<uint32_t>(got[k]) != std::bit_cast<uint32_t>(truth[idx[k]]);
    EXPECT_EQ(wrong, 0u) << what << ", batches of " << batch;
  };
  std::vector<size_t> scan(all.size());
  for (size_t i = 0; i < scan.size(); ++i) scan[i] = i;
  // A camera's order: 8x8 screen tiles whose pixels lie 3 texels apart in the map.
  std::vector<size_t> view;
  for (uint64_t ty = 0; ty < side; ty += 24)
    for (uint64_t tx = 0; tx < side; tx += 24)
      for (uint64_t y = ty; y < std::min(side, ty + 24); y += 3)
        for (uint64_t x = tx; x < std::min(side, tx + 24); x += 3) view.push_back(y * side + x);
  std::vector<size_t> shuffled = scan;
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  for (size_t batch : {size_t(1), kTapOrderMin - 1, kTapOrderMin, size_t(777), kTapOrderMax, kTapOrderMax + 333}) {
    check(view, batch, "view order");
    check(shuffled, batch, "shuffled");
  }
  check(scan, kTapOrderMax, "scan order");

  // Kernels and a coarser level in the same batches (a block with a kernel keeps its own
  // order): each answer the base implementation's (r * r single lookups).
  std::vector<PcfQuery> mixed;
  for (size_t k = 0; k < 4096; ++k) {
    PcfQuery q = all[shuffled[k]];
    if (k % 7 == 3) q.r = 3;
    if (k % 11 == 5) q.level = L - 2, q.x >>= 2, q.y >>= 2;
    mixed.push_back(q);
  }
  std::vector<float> got(mixed.size());
  map.pcf_batch(mixed, got);
  for (size_t k = 0; k < mixed.size(); ++k) {
    const PcfQuery& q = mixed[k];
    ASSERT_EQ(std::bit_cast<uint32_t>(got[k]), std::bit_cast<uint32_t>(map.Evaluator::pcf(q.level, q.x, q.y, q.r, q.receiver)))
        << "query " << k;
  }
  fs::remove(path);
}

INSTANTIATE_TEST_SUITE_P(Assimp, RealAssetTaps,
                         ::testing::Values(RealTapCase{"Collada/teapots.DAE", Encoding::mmh},
                                           RealTapCase{"Collada/teapots.DAE", Encoding::dagmh},
                                           RealTapCase{"FBX/spider.fbx", Encoding::mh}),
                         [](const auto& info) {
                           return fs::path(info.param.file).stem().string() + "_" + to_string(info.param.encoding);
                         });

}  // namespace real_asset_taps_test
}  // namespace st::client
