// The public light transform (MapInfo::light: the pack's own LightSpace, bit for bit) and
// cameras (Map::request_view): levels from pixel footprints, nearest first, what leaves
// every view cancelled, views' tiles kept resident while other tiles come and go, the
// working set's overflow counted, refusals. Driven without a network (like
// remote_map_requests_test): the test takes the fetcher's requests and delivers the
// pack's tiles itself.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "tests/client/loopback.hpp"
#include "common/hash.hpp"
#include "tiles/core/camera.hpp"

namespace st::client {
namespace camera_view_test {

struct Fixture {
  looptest::TestPack pack;
  uint32_t level = 7, k = 3;
  std::shared_ptr<RemoteMap> remote;
  Map map;
  uint32_t next_request = 1;

  std::vector<proto::TileRequest> take(size_t max = 100000) {
    std::vector<proto::TileRequest> out;
    remote->take_wanted(max, next_request, out);
    return out;
  }
  void deliver(const std::vector<proto::TileRequest>& sent) {
    for (const auto& t : sent) {
      const TileIndexEntry e = *pack.reader->find(t.tile_id);
      proto::TileMeta m;
      m.tile_id = t.tile_id;
      m.map_id = 1;
      m.flags = proto::kTileFlagZlib;
      m.uncompressed_size = e.raw_size;
      m.payload_crc32 = e.crc;
      remote->tile_arrived(m, next_request, pack.reader->read_stored(t.tile_id));
    }
    ++next_request;
  }
  void fetch_all() {
    for (int i = 0; i < 8; ++i) deliver(take());
  }
};

Fixture make_fixture(const std::string& name, uint32_t cache_slots, uint32_t k = 3) {
  Fixture f;
  f.k = k;
  // Level 7 at every scale: with K = 3 the map preview answers levels up to 6 exactly
  // (no tile needed there), and these tests need tiles below it.
  f.level = 7;
  f.pack = looptest::build_pack(name, f.level, 31, looptest::first_encoding(), f.k, 1 << 20);  // no index tiles
  ClientOptions o = looptest::quick_options();
  o.cache_slots = cache_slots;
  const auto h = f.pack.reader->header_bytes();
  const auto g = f.pack.reader->grid_bytes();
  f.remote = std::make_shared<RemoteMap>(name, std::vector<uint8_t>(h.begin(), h.end()),
                                         std::vector<uint8_t>(g.begin(), g.end()), o, std::make_shared<Notifier>());
  f.map = MapAccess::wrap(f.remote);
  return f;
}

// A camera `height` above the scene's ground, looking down at 45 degrees along +x.
std::array<double, 16> camera_at(const MapInfo& info, double x, double z, double height) {
  Camera c;
  c.pos = {x, info.scene.ground + height, z};
  c.target = {x + height, info.scene.ground, z};
  c.fov_deg = 60;
  c.aspect = 16.0 / 9.0;
  return view_projection(c, 0.01, 1000);
}

TEST(LightTransform, IsThePacksLightBitForBit) {
  Fixture f = make_fixture("view_light", 64);
  const MapInfo info = f.map.info();
  ASSERT_TRUE(info.light.valid());
  EXPECT_TRUE(info.light.orthographic());
  EXPECT_STREQ(info.light.kind_name(), "sun");
  const PackHeader& h = pack_header(f.map);
  const LightSpace ls = LightSpace::from_array(h.light_kind, h.light);
  EXPECT_EQ(info.light.extent(), ls.extent_uv());
  EXPECT_EQ(info.light.far_plane(), ls.far_plane());
  uint64_t s = 7;
  for (int i = 0; i < 2000; ++i) {
    const WorldPoint p{unit_random(s) * 30 - 15, unit_random(s) * 10 - 2, unit_random(s) * 30 - 15};
    const LightCoord c = info.light.to_light(p);
    const LightPoint want = ls.to_light({p.x, p.y, p.z});
    ASSERT_EQ(c.u, want.u);
    ASSERT_EQ(c.v, want.v);
    ASSERT_EQ(c.d, want.d);
    for (uint32_t l : {0u, 3u, f.level, 20u}) {
      const Texel t = info.light.texel(l, p);
      const auto wt = LightSpace::texel_of(l, want.u, want.v);
      ASSERT_EQ(t.x, wt[0]);
      ASSERT_EQ(t.y, wt[1]);
      ASSERT_EQ(info.light.texel_size(p, l), ls.extent_uv() / std::ldexp(1.0, int(l)));
    }
    const WorldPoint back = info.light.to_world(c);
    ASSERT_NEAR(back.x, p.x, 1e-9);
    ASSERT_NEAR(back.y, p.y, 1e-9);
    ASSERT_NEAR(back.z, p.z, 1e-9);
  }
  // The scene's surfaces lie inside the light's volume; the ground is within them.
  const WorldBox vol = info.light.volume_bounds();
  ASSERT_GE(info.scene.points, 4u);
  EXPECT_GE(info.scene.bounds.lo.x, vol.lo.x - 1e-9);
  EXPECT_LE(info.scene.bounds.hi.y, vol.hi.y + 1e-9);
  EXPECT_GE(info.scene.ground, info.scene.bounds.lo.y);
  EXPECT_LE(info.scene.ground, info.scene.bounds.hi.y);
}

TEST(LightTransform, SpotTexelSizeGrowsWithDistance) {
  // The one home of the texel-size formula, on a perspective light.
  const LightSpace spot =
      LightSpace::fit(LightSpec::parse("spot:pos=0,20,0,target=0,0,0,fov=60"), Aabb{{-10, 0, -10}, {10, 5, 10}});
  const double near = spot.texel_size({0, 10, 0}, 8), far = spot.texel_size({0, 0, 0}, 8);
  EXPECT_EQ(near, 10 * spot.extent_uv() / 256);
  EXPECT_EQ(far, 2 * near);
}

TEST(RequestView, NearestFirstAtThePixelsLevelAndNothingForCoarsePixels) {
  Fixture f = make_fixture("view_levels", 200);
  const MapInfo info = f.map.info();
  const double cx = (info.scene.x0 + info.scene.x1) / 2 - 4, cz = (info.scene.z0 + info.scene.z1) / 2;
  // Far above: every pixel covers more than a level-K texel; the skip grid answers all.
  const auto high = camera_at(info, cx, cz, 1e5);
  const ViewStats far = f.map.request_view(1, high.data(), 1920, 1080);
  ASSERT_TRUE(far.ok);
  EXPECT_EQ(far.wanted, 0u);
  EXPECT_TRUE(f.take().empty());

  const auto low = camera_at(info, cx, cz, 3);
  const ViewStats v = f.map.request_view(1, low.data(), 1920, 1080);
  ASSERT_TRUE(v.ok);
  ASSERT_GT(v.wanted, 2u);
  EXPECT_EQ(v.kept, v.wanted);
  EXPECT_EQ(v.queued, v.kept);
  EXPECT_EQ(v.resident, 0u);
  const auto sent = f.take();
  ASSERT_EQ(sent.size(), v.kept);
  for (size_t i = 1; i < sent.size(); ++i) EXPECT_LT(sent[i].priority, sent[i - 1].priority) << "nearest first";
  EXPECT_EQ(sent[0].priority, ViewOptions{}.priority);
  // The first tile holds the ground under the nearest sample (the bottom of the screen).
  for (const auto& t : sent) EXPECT_GE(tile_address(t.tile_id).level, f.k);
  f.deliver(sent);
  EXPECT_EQ(f.map.view_stats(1).resident, v.kept);
  EXPECT_FALSE(f.map.view_stats(2).ok);
  const MapStats s = f.map.stats();
  EXPECT_EQ(s.views, 1u);
  EXPECT_EQ(s.view_tiles_wanted, v.wanted);
  EXPECT_EQ(s.view_tiles_over, 0u);
}

TEST(RequestView, ViewTilesStayResidentWhileOtherTilesComeAndGo) {
  Fixture f = make_fixture("view_protect", 24);
  const MapInfo info = f.map.info();
  const double cx = (info.scene.x0 + info.scene.x1) / 2 - 4, cz = (info.scene.z0 + info.scene.z1) / 2;
  const auto cam = camera_at(info, cx, cz, 3);
  const ViewStats v = f.map.request_view(7, cam.data(), 1920, 1080);
  ASSERT_TRUE(v.ok);
  ASSERT_GT(v.kept, 0u);
  ASSERT_LT(v.kept, 16u) << "the test wants room for other tiles";
  f.fetch_all();
  ASSERT_EQ(f.map.view_stats(7).resident, v.kept);
  // Every tile of the map through the rest of the cache, several times over.
  const uint32_t L = f.level;
  for (int round = 0; round < 3; ++round) {
    for (uint64_t y = 0; y < 8; ++y)
      for (uint64_t x = 0; x < 8; ++x) {
        const uint64_t side = uint64_t(1) << (L - f.k);
        f.map.request_region(L, x * side, y * side, side, side, 5);
        f.fetch_all();
        ASSERT_EQ(f.map.view_stats(7).resident, v.kept) << "a view's tile was evicted";
        // A frame: the camera asks again (what keeps its tiles the most recently used).
        ASSERT_EQ(f.map.request_view(7, cam.data(), 1920, 1080).queued, 0u) << "nothing fetched twice while in view";
      }
  }
  const MapStats s = f.map.stats();
  EXPECT_GT(s.cache.evictions, 50u);
  EXPECT_EQ(s.view_refetches, 0u);
}

TEST(RequestView, WhatLeavesEveryViewIsCancelled) {
  Fixture f = make_fixture("view_cancel", 200);
  const MapInfo info = f.map.info();
  const double cz = (info.scene.z0 + info.scene.z1) / 2;
  const auto a = camera_at(info, info.scene.x0 - 2, cz, 3);
  const auto b = camera_at(info, info.scene.x1 - 6, cz, 3);
  const ViewStats va = f.map.request_view(1, a.data(), 1920, 1080);
  ASSERT_GT(va.queued, 0u);
  // A second view over the same ground (a minimap's shadow) holds them too: moving the
  // first away cancels nothing the second still sees.
  const ViewStats vb = f.map.request_view(2, a.data(), 1920, 1080, ViewOptions{64, 36, NAN, 0, 20000});
  ASSERT_EQ(vb.kept, va.kept);
  const ViewStats moved = f.map.request_view(1, b.data(), 1920, 1080);
  ASSERT_TRUE(moved.ok);
  EXPECT_EQ(moved.cancelled, 0u);
  // The second one goes: its tiles (no longer in view 1) are dropped from the queue.
  EXPECT_TRUE(f.map.remove_view(2));
  EXPECT_FALSE(f.map.remove_view(2));
  const auto sent = f.take();
  std::set<uint64_t> now;
  for (const auto& t : sent) now.insert(t.tile_id);
  EXPECT_EQ(sent.size(), moved.kept) << "only view 1's tiles are still queued";
  EXPECT_EQ(f.map.stats().views, 1u);
  // In flight, then out of view: a Cancel goes out for each.
  const auto c = camera_at(info, info.scene.x0 - 2, cz, 3);
  const ViewStats back = f.map.request_view(1, c.data(), 1920, 1080);
  std::vector<uint64_t> cancels;
  f.remote->take_cancels(cancels);
  EXPECT_EQ(back.cancelled, cancels.size());
  for (uint64_t t : cancels) EXPECT_TRUE(now.count(t));
}

TEST(RequestView, AWorkingSetOverTheCacheIsCountedNotThrashed) {
  Fixture f = make_fixture("view_over", 12);
  const MapInfo info = f.map.info();
  const double cx = (info.scene.x0 + info.scene.x1) / 2 - 6, cz = (info.scene.z0 + info.scene.z1) / 2;
  const auto cam = camera_at(info, cx, cz, 6);
  const ViewStats v = f.map.request_view(3, cam.data(), 3840, 2160, ViewOptions{128, 72, NAN, 0, 60000});
  ASSERT_TRUE(v.ok);
  const MapStats s = f.map.stats();
  ASSERT_GT(v.wanted, s.view_slots) << "the test wants a view larger than the cache";
  EXPECT_EQ(v.kept, s.view_slots);
  EXPECT_EQ(s.view_tiles_over, v.wanted - s.view_slots);
  EXPECT_EQ(s.view_overflows, 1u);
  for (int i = 0; i < 4; ++i) {
    f.fetch_all();
    const ViewStats again = f.map.request_view(3, cam.data(), 3840, 2160, ViewOptions{128, 72, NAN, 0, 60000});
    EXPECT_EQ(again.resident, again.kept);
    EXPECT_EQ(again.queued, 0u);
  }
  EXPECT_EQ(f.map.stats().view_refetches, 0u);
  EXPECT_EQ(f.map.stats().cache.evictions, 0u);
}

TEST(RequestView, RefusesWhatItCannotUse) {
  Fixture f = make_fixture("view_refuse", 32);
  const MapInfo info = f.map.info();
  const auto cam = camera_at(info, 0, 0, 3);
  EXPECT_FALSE(f.map.request_view(1, cam.data(), 0, 1080).ok);
  EXPECT_FALSE(f.map.request_view(1, cam.data(), 1920, 1080, ViewOptions{0, 36, NAN, 0, 60000}).ok);
  EXPECT_FALSE(f.map.request_view(1, cam.data(), 1920, 1080, ViewOptions{1000, 1000, NAN, 0, 60000}).ok);
  const double zero[16] = {};
  EXPECT_FALSE(f.map.request_view(1, zero, 1920, 1080).ok);
  auto nan = cam;
  nan[5] = NAN;
  EXPECT_FALSE(f.map.request_view(1, nan.data(), 1920, 1080).ok);
  EXPECT_EQ(f.map.stats().views, 0u);
  for (uint32_t i = 0; i < kMaxViews; ++i) EXPECT_TRUE(f.map.request_view(100 + i, cam.data(), 64, 64).ok);
  EXPECT_FALSE(f.map.request_view(99, cam.data(), 64, 64).ok);
  EXPECT_TRUE(f.map.remove_view(100));
  EXPECT_TRUE(f.map.request_view(99, cam.data(), 64, 64).ok);
  EXPECT_FALSE(Map().request_view(1, cam.data(), 64, 64).ok);
}

// A camera `height` above the ground at (x, z), heading `yaw` radians from +x, 45 degrees down.
std::array<double, 16> camera_heading(const MapInfo& info, double x, double z, double height, double yaw) {
  Camera c;
  c.pos = {x, info.scene.ground + height, z};
  c.target = {x + height * std::cos(yaw), info.scene.ground, z + height * std::sin(yaw)};
  c.fov_deg = 60;
  c.aspect = 16.0 / 9.0;
  return view_projection(c, 0.01, 1000);
}

// A camera flying straight at constant speed, 60 frames a second, over a map whose tiles
// arrive at once: with its frame time (ViewOptions::time) the view asks for the tiles of
// its poses ahead, so that from the third frame on (the motion is known after two) every
// tile a frame's pixels need was asked for before that frame and is resident when the
// frame asks: no tile enters the view unrequested. The same flight without times does
// meet tiles it never asked for (what the look-ahead removes), and neither fetches a tile
// twice while it stays in view, though tiles leave the cache all along the way.
struct Flight {
  uint32_t frames_short = 0;  // frames whose tiles were not all resident before delivery
  uint32_t max_held = 0;      // most tiles the view held at once (its own and ahead)
  uint64_t distinct = 0, refetches = 0, evictions = 0;
};
// The same pack opened again: an empty cache of `cache_slots`.
Fixture reopen(const Fixture& base, uint32_t cache_slots) {
  Fixture f;
  f.level = base.level, f.k = base.k;
  ClientOptions co = looptest::quick_options();
  co.cache_slots = cache_slots;
  const auto h = base.pack.reader->header_bytes();
  const auto g = base.pack.reader->grid_bytes();
  f.remote = std::make_shared<RemoteMap>("again", std::vector<uint8_t>(h.begin(), h.end()),
                                         std::vector<uint8_t>(g.begin(), g.end()), co, std::make_shared<Notifier>());
  f.map = MapAccess::wrap(f.remote);
  f.pack.reader = base.pack.reader;
  return f;
}

Flight fly(const Fixture& base, bool with_time, uint32_t cache_slots) {
  Fixture f = reopen(base, cache_slots);
  const MapInfo info = f.map.info();
  const double w = info.scene.x1 - info.scene.x0, d = info.scene.z1 - info.scene.z0;
  Flight out;
  std::set<uint64_t> seen;
  for (uint32_t k = 0; k < 90; ++k) {
    const double t = k / 60.0;  // corner to corner in 1.5 s, heading along the diagonal
    const double x = info.scene.x0 + w * (0.02 + 0.64 * t), z = info.scene.z0 + d * (0.02 + 0.64 * t);
    const auto cam = camera_heading(info, x, z, 2.5, std::atan2(d, w));
    ViewOptions o;
    o.samples_x = 48, o.samples_y = 27;
    o.max_distance = 3;  // the lower half of the screen: the flight crosses many views' worth of tiles
    o.lookahead = 0.05;  // three frames
    if (with_time) o.time = t;
    const ViewStats v = f.map.request_view(1, cam.data(), 1920, 1080, o);
    EXPECT_TRUE(v.ok);
    EXPECT_EQ(v.kept, v.wanted) << "the test wants views that fit";
    if (k >= 2 && v.resident < v.kept) ++out.frames_short;
    out.max_held = std::max(out.max_held, v.kept + v.ahead);
    const auto sent = f.take();
    for (const auto& r : sent) seen.insert(r.tile_id);
    f.deliver(sent);
    EXPECT_EQ(f.map.view_stats(1).resident, v.kept) << "frame " << k;
  }
  const MapStats s = f.map.stats();
  out.distinct = seen.size();
  out.refetches = s.view_refetches;
  out.evictions = s.cache.evictions;
  return out;
}

TEST(RequestView, AMovingCameraAsksForTilesBeforeTheyEnterTheView) {
  const Fixture base = make_fixture("view_fly", 8);
  // A cache just larger than what the view holds at once, smaller than the flight's ground.
  const Flight roomy = fly(base, true, 1000);
  EXPECT_EQ(roomy.frames_short, 0u);
  const uint32_t slots = roomy.max_held + 4;  // view_slots: slots - 4
  ASSERT_GT(roomy.distinct, slots) << "the test wants a flight over more tiles than the cache holds";
  const Flight known = fly(base, true, slots), unknown = fly(base, false, slots);
  EXPECT_EQ(known.frames_short, 0u) << "a tile entered the view before it was asked for";
  EXPECT_GT(unknown.frames_short, 0u) << "without its times the camera meets tiles it never asked for";
  EXPECT_EQ(known.refetches, 0u);
  EXPECT_EQ(unknown.refetches, 0u);
  EXPECT_GT(known.evictions, 0u) << "the test wants tiles leaving the cache on the way";
}

// The receivers view_samples returns are the ones request_view's tiles answer: once the
// view is resident, filtered lookups there read no missing tile, and answer exactly what
// they answer with the whole map resident (levels the map preview answers included).
TEST(RequestView, ViewSamplesReadOnlyTheViewsTiles) {
  const Fixture base = make_fixture("view_samples", 8);
  for (double height : {3.0, 12.0}) {
    Fixture f = reopen(base, 1000);
    const MapInfo info = f.map.info();
    const double cx = (info.scene.x0 + info.scene.x1) / 2 - 4, cz = (info.scene.z0 + info.scene.z1) / 2;
    const auto cam = camera_at(info, cx, cz, height);
    std::vector<ViewSample> samples(64 * 36);
    samples.resize(f.map.view_samples(cam.data(), 1920, 1080, {}, samples));
    ASSERT_GT(samples.size(), 100u);
    for (size_t i = 1; i < samples.size(); ++i) {  // footprints grow with the distance
      ASSERT_GT(samples[i].footprint, 0.0f);
      if (samples[i].distance > 1.01f * samples[i - 1].distance) {
        ASSERT_GT(samples[i].footprint, samples[i - 1].footprint);
      }
    }
    ASSERT_TRUE(f.map.request_view(1, cam.data(), 1920, 1080).ok);
    f.fetch_all();
    ASSERT_EQ(f.map.view_stats(1).resident, f.map.view_stats(1).kept);
    std::vector<WorldPoint> points;
    std::vector<float> footprints;
    for (const ViewSample& s : samples) points.push_back(s.point), footprints.push_back(s.footprint);
    std::vector<float> view(points.size()), full(points.size());
    const uint64_t coarse = f.map.stats().coarse_answers, queued = f.map.stats().tiles_requested;
    f.map.visibility_filtered(points, footprints, view, 1);
    EXPECT_EQ(f.map.stats().coarse_answers, coarse) << "height " << height;
    f.fetch_all();
    EXPECT_EQ(f.map.stats().tiles_requested, queued) << "the lookups queued tiles the view did not hold";
    const uint32_t side = 1u << f.level;
    f.map.request_region(f.level, 0, 0, side, side, 10);
    f.fetch_all();
    ASSERT_TRUE(f.map.region_resident(f.level, 0, 0, side, side));
    f.map.visibility_filtered(points, footprints, full, 1);
    for (size_t i = 0; i < points.size(); ++i) ASSERT_EQ(view[i], full[i]) << i;
  }
}
}  // namespace camera_view_test
}  // namespace st::client
