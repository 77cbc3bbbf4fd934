// The client's lookup paths agree bit for bit: batched visibility with single visibility,
// the shared-walk PCF (a kernel inside one tile goes to the tile's own pcf) with the
// average of single lookups (Evaluator's base pcf) on every texel, across tile borders,
// map edges and missing tiles, for every encoding; lookups used between arrivals keep
// their tiles (LRU from stamps); lookups on two threads while tiles arrive answer, once
// everything is resident, exactly like the pack. Tiles are delivered straight to the
// RemoteMap (tile_arrived), no socket.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <string>
#include <thread>

#include "client/map_access.hpp"
#include "client/remote_map.hpp"
#include "tests/client/loopback.hpp"
#include "common/hash.hpp"

namespace st::client {
namespace batched_lookups_test {

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

struct Fixture {
  looptest::TestPack pack;
  uint32_t level = 0;
  std::shared_ptr<RemoteMap> map;
  uint32_t request_id = 1;

  // Delivers every queued tile once (one request id per round); returns how many.
  size_t deliver_round(size_t max = 1u << 20) {
    std::vector<proto::TileRequest> want;
    map->take_wanted(max, request_id, want);
    for (const auto& t : want) deliver(t.tile_id);
    ++request_id;
    return want.size();
  }
  void deliver(uint64_t tile) const {
    const TileIndexEntry e = *pack.reader->find(tile);
    proto::TileMeta m;
    m.tile_id = tile;
    m.flags = proto::kTileFlagZlib;
    m.uncompressed_size = e.raw_size;
    m.payload_crc32 = e.crc;
    map->tile_arrived(m, request_id, pack.reader->read_stored(tile));
  }
  // The finest level's 8 x 8 cells resident in a checkerboard (cell (0, 0) resident), the
  // others missing.
  void make_checkerboard_resident() {
    const uint64_t cell = (uint64_t(1) << level) / 8;
    for (int round = 0; round < 8; ++round) {
      for (uint64_t cy = 0; cy < 8; ++cy)
        for (uint64_t cx = (cy & 1); cx < 8; cx += 2) map->request_region(level, cx * cell, cy * cell, cell, cell, 1);
      if (deliver_round() == 0) break;
    }
  }
  // A new map over the same pack, with `slots` cache slots.
  void new_map(const std::string& name, uint32_t slots) {
    ClientOptions o = looptest::quick_options();
    o.cache_slots = slots;
    const auto h = pack.reader->header_bytes();
    const auto g = pack.reader->grid_bytes();
    map = std::make_shared<RemoteMap>(name, std::vector<uint8_t>(h.begin(), h.end()),
                                      std::vector<uint8_t>(g.begin(), g.end()), o, std::make_shared<Notifier>());
  }
  // The first texel of tile t at the fixture's level.
  std::array<uint64_t, 2> texel_of_tile(uint64_t t) const {
    const TileAddress a = tile_address(t);
    const uint32_t s = level - a.level;
    return {uint64_t(a.x) << s, uint64_t(a.y) << s};
  }
  void make_all_resident() {
    const uint64_t side = uint64_t(1) << level;
    do map->request_region(level, 0, 0, side, side, 1);
    while (deliver_round() > 0);
  }
};

Fixture make_fixture(const std::string& name, Encoding e, uint32_t tile_bytes, uint32_t extra_slots = 8) {
  Fixture f;
  // Level 7 at every scale: with K = 3 the map preview answers levels up to 6 exactly
  // (no tile needed there), and these tests need tiles below it.
  f.level = 7;
  f.pack = looptest::build_pack(name, f.level, 77, e, 3, tile_bytes);
  ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(f.pack.reader->tiles().size()) + extra_slots;
  o.want_capacity = o.cache_slots;
  const auto h = f.pack.reader->header_bytes();
  const auto g = f.pack.reader->grid_bytes();
  f.map = std::make_shared<RemoteMap>(name, std::vector<uint8_t>(h.begin(), h.end()),
                                      std::vector<uint8_t>(g.begin(), g.end()), o, std::make_shared<Notifier>());
  return f;
}

// Every texel of the finest and one coarser level, every kernel size: the client's pcf
// (shared walk where the kernel fits a tile) equals the per-tap base implementation, and
// so does one batch of them all in scan order (where the last answer's region carries
// from query to query and across tiles).
std::string pcf_difference(const RemoteMap& m, uint32_t level) {
  for (uint32_t l : {level, level - 2}) {
    std::vector<PcfQuery> queries;
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x)
        for (uint32_t r : {1u, 3u, 5u}) queries.push_back({x, y, l, r, m.depth(l, x, (y + x % 3) & ((1u << l) - 1))});
    std::vector<float> got(queries.size());
    m.pcf_batch(queries, got);
    for (size_t i = 0; i < queries.size(); ++i) {
      const PcfQuery& q = queries[i];
      if (bits(got[i]) != bits(m.Evaluator::pcf(q.level, q.x, q.y, q.r, q.receiver)))
        return "batch: level " + std::to_string(l) + " (" + std::to_string(q.x) + ", " + std::to_string(q.y) +
               ") r " + std::to_string(q.r);
    }
  }
  // One kernel size per batch, rows in scan order: each kernel shares all columns but one
  // with the last (the client's tap window), across tile borders, missing tiles and the
  // map's clamped edges; the widest on every fifth row. Single taps in scan order go to
  // each tile's own batch in runs (tiles/core/tap_batch.hpp).
  for (uint32_t l : {level, level - 2})
    for (uint32_t r : {1u, 2u, 5u, 9u}) {
      std::vector<PcfQuery> queries;
      for (uint64_t y = 0; y < (uint64_t(1) << l); y += r == 9 ? 5 : 1)
        for (uint64_t x = 0; x < (uint64_t(1) << l); ++x)
          queries.push_back({x, y, l, r, m.depth(l, x, (y + x % 3) & ((1u << l) - 1))});
      std::vector<float> got(queries.size());
      m.pcf_batch(queries, got);
      for (size_t i = 0; i < queries.size(); ++i) {
        const PcfQuery& q = queries[i];
        if (bits(got[i]) != bits(m.Evaluator::pcf(q.level, q.x, q.y, q.r, q.receiver)))
          return "row batch: level " + std::to_string(l) + " (" + std::to_string(q.x) + ", " + std::to_string(q.y) +
                 ") r " + std::to_string(q.r);
      }
    }
  for (uint32_t l : {level, level - 2})
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x)
        for (uint32_t r : {2u, 5u, 9u}) {
          if (r == 9 && (x + y) % 3 != 0) continue;  // the widest kernel on a third of the texels
          const float receiver = m.depth(l, x, y);
          const float got = m.pcf(l, x, y, r, receiver), want = m.Evaluator::pcf(l, x, y, r, receiver);
          if (bits(got) != bits(want))
            return "level " + std::to_string(l) + " (" + std::to_string(x) + ", " + std::to_string(y) + ") r " +
                   std::to_string(r) + ": " + std::to_string(got) + " vs " + std::to_string(want);
        }
  return "";
}

TEST(ClientLookups, SharedWalkPcfEqualsSingleLookupsAcrossBordersEdgesAndMissingTiles) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    Fixture f = make_fixture("pcf_walk_" + to_string(e), e, 512);  // small tiles: many borders, index tiles
    const uint64_t side = uint64_t(1) << f.level;
    // Half the map resident: kernels straddle resident and missing tiles.
    f.map->request_region(f.level, 0, 0, side / 2, side, 1);
    while (f.deliver_round() > 0) f.map->request_region(f.level, 0, 0, side / 2, side, 1);
    ASSERT_TRUE(f.map->region_resident(f.level, 0, 0, side / 2, side));
    ASSERT_FALSE(f.map->region_resident(f.level, 0, 0, side, side));
    EXPECT_EQ(pcf_difference(*f.map, f.level), "");
    f.make_all_resident();
    EXPECT_EQ(pcf_difference(*f.map, f.level), "");
    // And the whole map answers like the pack.
    PackEvaluator local(f.pack.reader);
    for (uint64_t y = 0; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x)
        ASSERT_EQ(bits(f.map->pcf(f.level, x, y, 5, 0.5f)), bits(local.pcf(f.level, x, y, 5, 0.5f)));
  }
}

// Kernels with no tap clamped that leave their centre's tile are counted one window per
// tile or kept region (RemoteMap::count_window_shared, WindowDepths::count_window): with
// a checkerboard of resident and missing tiles, every texel's kernel of every side 2..9
// (straddling borders and corners, missing neighbours answered coarsely) equals the
// per-tap reference bit for bit, with receivers at a tap's exact depth and one ulp either
// side; single calls (fresh scratch) and one batch in a scattered order alike.
TEST(ClientLookups, CountedKernelsEqualPerTapKernelsAcrossBordersAndMissingTiles) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    Fixture f = make_fixture("pcf_count_" + to_string(e), e, 512);
    const uint64_t side = uint64_t(1) << f.level, cell = side / 8;
    f.make_checkerboard_resident();
    ASSERT_TRUE(f.map->region_resident(f.level, 0, 0, cell, cell));
    ASSERT_FALSE(f.map->region_resident(f.level, 0, 0, side, side));
    st::Rng rng(17);
    for (uint32_t l : {f.level, f.level - 1, f.level - 3}) {
      const uint64_t n = uint64_t(1) << l;
      std::vector<PcfQuery> queries;
      for (uint64_t y = 0; y < n; ++y)
        for (uint64_t x = 0; x < n; ++x) {
          const uint32_t r = 2 + uint32_t((x + 3 * y) % 8);
          const uint64_t tx = pcf_tap(x, uint32_t(rng.next() % r), r, n), ty = pcf_tap(y, uint32_t(rng.next() % r), r, n);
          const float d = f.map->depth(l, tx, ty);
          const float receiver = (x + y) % 3 == 0 ? d : std::nextafter(d, (x + y) % 3 == 1 ? -1.0f : 2.0f);
          const PcfQuery q{x, y, l, r, receiver};
          queries.push_back(q);
          const float want = f.map->Evaluator::pcf(l, x, y, r, receiver);
          ASSERT_EQ(bits(f.map->pcf(l, x, y, r, receiver)), bits(want))
              << "level " << l << " (" << x << ", " << y << ") r " << r << " receiver " << receiver;
        }
      for (size_t i = queries.size(); i > 1; --i) std::swap(queries[i - 1], queries[rng.next() % i]);
      std::vector<float> got(queries.size());
      f.map->pcf_batch(queries, got);
      for (size_t i = 0; i < queries.size(); ++i) {
        const PcfQuery& q = queries[i];
        ASSERT_EQ(bits(got[i]), bits(f.map->Evaluator::pcf(q.level, q.x, q.y, q.r, q.receiver)))
            << "batch level " << l << " (" << q.x << ", " << q.y << ") r " << q.r;
      }
    }
    EXPECT_GT(f.map->stats().coarse_answers, 0u);
  }
}

// Screen-coherent rows of kernels, the pattern whose columns the client keeps ahead
// (RemoteMap::pcf_shared counts a kernel on their rows from them and reads the columns
// it lacks one window walk per tile or region, fill_columns): runs of kernels stepping
// right along a row, mostly by one texel, sometimes staying, jumping by up to r or
// stepping back (a kernel left of or past the kept columns), some runs alternating two
// levels (a filtered lookup's pattern), every side 2..9, rows and columns crossing tile
// borders and a checkerboard of missing tiles (answered coarsely), receivers at a tap's
// exact depth and one ulp either side. Each answer equals the per-tap reference bit for
// bit, in pcf_batch and in Map::visibility over a span; then again with every tile
// resident.
std::string coherent_rows_difference(Fixture& f, uint64_t seed) {
  const RemoteMap& m = *f.map;
  st::Rng rng(seed);
  std::vector<PcfQuery> queries;
  for (uint32_t l : {f.level, f.level - 1}) {
    const uint64_t n = uint64_t(1) << l;
    for (int run = 0; run < 96; ++run) {
      const uint32_t r = 2 + uint32_t(rng.next() % 8);
      const bool two_levels = run % 5 == 4;
      uint64_t x = rng.next() % n, y = rng.next() % n;
      const int len = 8 + int(rng.next() % (n / 2));
      for (int k = 0; k < len && x < n; ++k) {
        for (uint32_t lv : {l, l - 2}) {
          if (lv != l && !two_levels) continue;
          const uint64_t s = lv == l ? 0 : 2, side = uint64_t(1) << lv;
          const uint64_t qx = x >> s, qy = y >> s;
          const uint64_t tx = pcf_tap(qx, uint32_t(rng.next() % r), r, side);
          const uint64_t ty = pcf_tap(qy, uint32_t(rng.next() % r), r, side);
          const float d = m.depth(lv, tx, ty);
          const uint64_t pick = rng.next() % 3;
          const float receiver = pick == 0 ? d : std::nextafter(d, pick == 1 ? -1.0f : 2.0f);
          queries.push_back({qx, qy, lv, r, receiver});
        }
        const uint64_t step = rng.next() % 16;
        if (step < 12) x += 1;                               // the next kernel along the row
        else if (step == 12) x += 0;                         // the same kernel again
        else if (step == 13) x += 2 + rng.next() % r;        // past the kept columns
        else x -= std::min<uint64_t>(x, 1 + rng.next() % r);  // back, left of them
      }
    }
  }
  std::vector<float> got(queries.size());
  m.pcf_batch(queries, got);
  for (size_t i = 0; i < queries.size(); ++i) {
    const PcfQuery& q = queries[i];
    const float want = m.Evaluator::pcf(q.level, q.x, q.y, q.r, q.receiver);
    if (bits(got[i]) != bits(want))
      return "batch: level " + std::to_string(q.level) + " (" + std::to_string(q.x) + ", " + std::to_string(q.y) +
             ") r " + std::to_string(q.r) + ": " + std::to_string(got[i]) + " vs " + std::to_string(want);
  }
  // Map::visibility over a span: kernels of the finest level at texel centres along rows.
  Map map = MapAccess::wrap(f.map);
  const LightSpace light = f.pack.reader->light();
  const uint64_t side = uint64_t(1) << f.level;
  std::vector<WorldPoint> points;
  for (int run = 0; run < 64; ++run) {
    const uint64_t y = rng.next() % side;
    for (uint64_t x = rng.next() % side, k = 0; x < side && k < 96; ++x, ++k) {
      const LightRay ray = light.texel_ray(f.level, x, y);
      const Vec3d w = ray.origin + ray.dir * (double(m.depth(f.level, x, y)) + (rng.uniform() - 0.5) * 1e-3);
      points.push_back({w.x, w.y, w.z});
    }
  }
  for (uint32_t side : {3u, 5u, 9u}) {
    std::vector<float> batch(points.size());
    map.visibility(points, batch, side);
    for (size_t i = 0; i < points.size(); ++i)
      if (bits(batch[i]) != bits(map.visibility(points[i], side)))
        return "visibility: point " + std::to_string(i) + " side " + std::to_string(side);
  }
  return "";
}

TEST(ClientLookups, CoherentKernelRowsEqualPerTapKernelsAcrossBordersAndMissingTiles) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    Fixture f = make_fixture("pcf_rows_" + to_string(e), e, 512);  // small tiles: many borders
    const uint64_t side = uint64_t(1) << f.level, cell = side / 8;
    f.make_checkerboard_resident();
    ASSERT_TRUE(f.map->region_resident(f.level, 0, 0, cell, cell));
    ASSERT_FALSE(f.map->region_resident(f.level, 0, 0, side, side));
    EXPECT_EQ(coherent_rows_difference(f, 23), "");
    EXPECT_GT(f.map->stats().coarse_answers, 0u);
    f.make_all_resident();
    EXPECT_EQ(coherent_rows_difference(f, 31), "");
  }
}

TEST(ClientLookups, BatchesAnswerLikeSingleLookupsBitForBit) {
  Fixture f = make_fixture("batch_eq", looptest::first_encoding(), 2048);
  const uint64_t side = uint64_t(1) << f.level;
  f.map->request_region(f.level, 0, 0, side, side / 2, 1);
  f.deliver_round();  // some of the map: misses are answered coarsely in both paths
  Map map = MapAccess::wrap(f.map);
  const LightSpace light = f.pack.reader->light();
  std::vector<WorldPoint> points;
  std::vector<float> footprints;
  st::Rng rng(5);
  for (uint64_t y = 0; y < side; y += 3)
    for (uint64_t x = 0; x < side; ++x) {
      const LightRay ray = light.texel_ray(f.level, x, y);
      const Vec3d w = ray.origin + ray.dir * rng.uniform();
      points.push_back({w.x, w.y, w.z});
      footprints.push_back(float(light.extent_uv() / double(side)) * 8.0f * float(rng.uniform()));
    }
  points.push_back({1e9, 0, 0});  // outside the light's box: lit
  footprints.push_back(1.0f);
  for (uint32_t side : {1u, 3u, 5u}) {
    std::vector<float> batch(points.size()), filtered(points.size());
    map.visibility(points, batch, side);
    map.visibility_filtered(points, footprints, filtered, side);
    for (size_t i = 0; i < points.size(); ++i) {
      ASSERT_EQ(bits(batch[i]), bits(map.visibility(points[i], side))) << i << " side " << side;
      ASSERT_EQ(bits(filtered[i]), bits(map.visibility_filtered(points[i], footprints[i], side))) << i;
      ASSERT_GE(filtered[i], 0.0f);
      ASSERT_LE(filtered[i], 1.0f);
    }
    EXPECT_EQ(batch.back(), 1.0f);
  }
  // The smallest span bounds the answers; nothing past it is written.
  std::vector<float> out(4, -1.0f);
  map.visibility(std::span(points).first(2), out, 1);
  EXPECT_EQ(out[2], -1.0f);
  std::fill(out.begin(), out.end(), -1.0f);
  map.visibility_filtered(points, std::span<const float>(), out, 1);
  for (float v : out) EXPECT_EQ(v, -1.0f);
  EXPECT_GT(f.map->stats().cache.hits, 0u);
  EXPECT_GT(f.map->stats().coarse_answers, 0u);
}

TEST(ClientLookups, TilesUsedSinceTheLastArrivalAreNotTheNextVictims) {
  Fixture f = make_fixture("lru_stamps", looptest::first_encoding(), 1 << 20);  // no index tiles
  std::vector<uint64_t> tiles;
  for (const TileIndexEntry& e : f.pack.reader->tiles())
    if (tile_address(e.id).level == 3) tiles.push_back(e.id);
  ASSERT_GE(tiles.size(), 3u);
  f.new_map("lru", 2);  // exactly two slots
  auto texel_of_tile = [&](uint64_t t) { return f.texel_of_tile(t); };
  auto want = [&](uint64_t t) {
    const auto p = texel_of_tile(t);
    f.map->request_region(f.level, p[0], p[1], 1, 1, 1);
    f.deliver_round();
  };
  auto resident = [&](uint64_t t) {
    const auto p = texel_of_tile(t);
    return f.map->region_resident(f.level, p[0], p[1], 1, 1);
  };
  want(tiles[0]);
  want(tiles[1]);  // tiles[0] is now the least recently used
  const auto p0 = texel_of_tile(tiles[0]);
  f.map->depth(f.level, p0[0], p0[1]);  // a lookup uses it: tiles[1] becomes the victim
  want(tiles[2]);
  EXPECT_TRUE(resident(tiles[0]));
  EXPECT_FALSE(resident(tiles[1]));
  EXPECT_TRUE(resident(tiles[2]));
  // Batches remember the tiles this thread entered across calls (RemoteMap::TileMemo):
  // after tiles came and went they still answer like single lookups, each texel against
  // its own depth and the next float up (a tile's stale evaluator would flip one).
  auto batch_differs = [&](std::initializer_list<uint64_t> ts) -> std::string {
    std::vector<PcfQuery> q;
    for (uint64_t t : ts) {
      const auto p = texel_of_tile(t);
      for (uint64_t i = 0; i < 64; ++i) {
        const uint64_t x = p[0] + i % 8, y = p[1] + i / 8;
        const float d = f.map->depth(f.level, x, y);
        q.push_back({x, y, f.level, 1, d});
        q.push_back({x, y, f.level, 1, std::nextafter(d, 2.0f)});
      }
    }
    std::vector<float> got(q.size());
    f.map->pcf_batch(q, got);
    for (size_t i = 0; i < q.size(); ++i)
      if (bits(got[i]) != bits(f.map->pcf(q[i].level, q[i].x, q[i].y, 1, q[i].receiver)))
        return "query " + std::to_string(i) + " texel (" + std::to_string(q[i].x) + ", " + std::to_string(q[i].y) + ")";
    return "";
  };
  EXPECT_EQ(batch_differs({tiles[2]}), "");
  EXPECT_EQ(batch_differs({tiles[0]}), "");
  want(tiles[1]);  // evicts one of the two the last batches entered
  EXPECT_TRUE(resident(tiles[1]));
  EXPECT_EQ(batch_differs({tiles[0]}), "");
  EXPECT_EQ(batch_differs({tiles[2]}), "");
  EXPECT_EQ(batch_differs({tiles[1]}), "");
  want(tiles[0]);
  want(tiles[2]);
  EXPECT_EQ(batch_differs({tiles[1]}), "");
  EXPECT_EQ(batch_differs({tiles[2], tiles[1], tiles[0]}), "");
}

// A lookup marks the index tiles its walk passed used too, single or batched: after it the
// next arrival evicts a tile nobody looked at, not the index tile the looked-at tile hangs
// from (which would cut that tile off).
TEST(ClientLookups, IndexTilesOnALookupsWayAreUsedToo) {
  Fixture f = make_fixture("lru_index", looptest::first_encoding(), 512);  // index tiles
  // Three encoded tiles below one index tile.
  std::vector<uint64_t> kids;
  for (const TileIndexEntry& i : f.pack.reader->tiles()) {
    if (i.kind != TileKind::index) continue;
    const TileAddress b = tile_address(i.id);
    kids.clear();
    for (const TileIndexEntry& e : f.pack.reader->tiles()) {
      const TileAddress a = tile_address(e.id);
      if (e.kind == TileKind::encoded && a.level == b.level + 1 && a.x / 2 == b.x && a.y / 2 == b.y) kids.push_back(e.id);
    }
    if (kids.size() >= 3) break;
  }
  ASSERT_GE(kids.size(), 3u);
  auto texel_of_tile = [&](uint64_t t) { return f.texel_of_tile(t); };
  for (int batched = 0; batched < 2; ++batched) {
    const char* how = batched ? "batched" : "single";
    f.new_map("lru_index", 3);  // the index tile and two of its children
    auto want = [&](uint64_t t) {
      const auto p = texel_of_tile(t);
      for (int round = 0; round < 4; ++round) {
        f.map->request_region(f.level, p[0], p[1], 1, 1, 1);
        if (f.deliver_round() == 0) break;
      }
    };
    auto resident = [&](uint64_t t) {
      const auto p = texel_of_tile(t);
      return f.map->region_resident(f.level, p[0], p[1], 1, 1);
    };
    want(kids[0]);  // the index tile, then its child: the index tile is the least recently used
    want(kids[1]);
    ASSERT_TRUE(resident(kids[0])) << how;
    ASSERT_TRUE(resident(kids[1])) << how;
    const auto p = texel_of_tile(kids[0]);
    if (batched) {
      const PcfQuery q{p[0], p[1], f.level, 1, 0.5f};
      float got = -1.0f;
      f.map->pcf_batch(std::span(&q, 1), std::span(&got, 1));
    } else {
      f.map->depth(f.level, p[0], p[1]);
    }
    want(kids[2]);  // kids[1], used by nobody since it arrived, is the victim
    EXPECT_TRUE(resident(kids[0])) << how;
    EXPECT_FALSE(resident(kids[1])) << how;
    EXPECT_TRUE(resident(kids[2])) << how;
  }
}

TEST(ClientLookups, TwoThreadsLookUpWhileTilesArriveAndEndExact) {
  Fixture f = make_fixture("threads", looptest::first_encoding(), 1024);
  const uint64_t side = uint64_t(1) << f.level;
  std::atomic<bool> done{false};
  std::atomic<uint64_t> batches{0};
  auto reader = [&](uint64_t seed) {
    st::Rng rng(seed);
    std::vector<PcfQuery> q(256);
    std::vector<float> out(q.size());
    while (!done.load()) {
      for (auto& x : q)
        x = {rng.next() % side, rng.next() % side, f.level, uint32_t(1 + rng.next() % 5), float(rng.uniform())};
      f.map->pcf_batch(q, out);
      for (float v : out) ASSERT_TRUE(v >= 0.0f && v <= 1.0f);
      batches.fetch_add(1);
    }
  };
  std::thread a(reader, 1), b(reader, 2);
  while (batches.load() < 2) std::this_thread::yield();  // lookups are under way
  f.make_all_resident();  // meanwhile, the lookups' own misses are queued too
  while (f.deliver_round() > 0) {
  }
  done = true;
  a.join();
  b.join();
  EXPECT_GT(batches.load(), 0u);
  PackEvaluator local(f.pack.reader);
  for (uint64_t y = 0; y < side; ++y)
    for (uint64_t x = 0; x < side; ++x)
      ASSERT_EQ(bits(f.map->depth(f.level, x, y)), bits(local.depth(f.level, x, y))) << x << ", " << y;
}

}  // namespace batched_lookups_test
}  // namespace st::client
