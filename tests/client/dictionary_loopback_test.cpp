// The pack-wide DAG-MH dictionary over the wire (loopback, in-process server): MapInfo
// carries it with the skip grid, the client keeps it resident (beside cache_slots' tile
// slots, or out of a cache_bytes budget, its share reported exactly) and decodes the tiles flagged for it with it, answering every
// texel exactly as the same build without a dictionary answers locally.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/map_build.hpp"
#include "scene/scene.hpp"
#include "tiles/core/dagmh_validate.hpp"

namespace st::client {
namespace dictionary_loopback_test {

using looptest::quick_options;
using looptest::start_server;
using looptest::wait_until;

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

struct CityPacks {
  std::string on, off;
  uint32_t level = 0;
  LightSpace light;
  Aabb bounds;
};

const CityPacks& city_packs() {
  static const CityPacks p = [] {
    CityPacks c;
    const Scene s = make_procedural("procedural:city");
    c.light = LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), s.bounds());
    c.bounds = s.bounds();
    c.level = looptest::small_scale() ? 8 : 9;
    for (bool dict : {true, false}) {
      const std::string path = std::string(SHADOWTILE_TEST_TMP) + (dict ? "/dict_city_on.pack" : "/dict_city_off.pack");
      MapBuildOptions o;
      o.map_level = c.level;
      o.skip_level = 4;
      o.encoding = Encoding::dagmh;
      o.tile_bytes = 2048;  // small tiles: many of them, sharing footprints and roofs
      o.dagmh_dictionary = dict;
      const MapBuildReport r = build_map(s, c.light, o, path);
      EXPECT_EQ(r.dictionary_bytes > 0, dict) << r.dictionary_skipped;
      (dict ? c.on : c.off) = path;
    }
    return c;
  }();
  return p;
}

TEST(DictionaryLoopback, SameAnswersLocallyAndOverTheWire) {
  const CityPacks& p = city_packs();
  const auto on = PackReader::open(p.on);
  const std::shared_ptr<const PackReader> off = PackReader::open(p.off);
  ASSERT_NE(on->dictionary(), nullptr);
  looptest::TestServer srv = start_server({p.on});
  ClientOptions co = quick_options();
  co.cache_slots = uint32_t(on->tiles().size()) + 64;  // every tile fits beside the dictionary
  Client c({"127.0.0.1", srv.port}, co);
  Map m = c.open("dict_city_on");
  const uint32_t L = p.level;
  const uint64_t side = uint64_t(1) << L;
  m.request_region(L, 0, 0, side, side, 10);
  ASSERT_TRUE(wait_until([&] { return m.region_resident(L, 0, 0, side, side); }))
      << m.stats().tiles_received << " of " << on->tiles().size() << " tiles";
  const MapStats st = m.stats();
  EXPECT_EQ(st.dictionary_bytes, on->dictionary()->memory_bytes());
  EXPECT_EQ(st.tiles_failed, 0u);
  EXPECT_EQ(st.decode_errors, 0u);
  // cache_slots are all for tiles: the dictionary lies beside them, nothing shrinks.
  const uint64_t slots = uint64_t(st.cache.resident) + st.cache.pinned + st.cache.free;
  EXPECT_EQ(slots, co.cache_slots);
  EXPECT_EQ(st.tile_slots, co.cache_slots);
  EXPECT_EQ(st.dictionary_slots, 0u);

  // Every texel of every level equals the pack built without a dictionary, read locally.
  PackEvaluator local(off, 256);
  const Evaluator& wire = evaluator(m);
  for (uint32_t l = 0; l <= L; ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x)
        ASSERT_EQ(bits(wire.depth(l, x, y)), bits(local.depth(l, x, y))) << "level " << l << " (" << x << ", " << y << ")";
  for (uint64_t i = 0; i < 300; ++i) {
    const uint64_t x = (i * 131) % side, y = (i * 71) % side;
    const float r = float(i % 19) / 18.0f;
    EXPECT_EQ(bits(m.pcf(L, x, y, 3, r)), bits(local.pcf(L, x, y, 3, r)));
  }
}

TEST(DictionaryLoopback, CacheSlotsAreAllForTiles) {
  const CityPacks& p = city_packs();
  looptest::TestServer srv = start_server({p.on});
  for (uint32_t slots : {1u, 2u, 64u}) {
    ClientOptions co = quick_options();
    co.cache_slots = slots;
    Client c({"127.0.0.1", srv.port}, co);
    Map m = c.open("dict_city_on");  // a probe with one slot opens it too
    const MapStats st = m.stats();
    ASSERT_GT(st.dictionary_bytes, 0u);  // it used to take (rounded up) slots of these
    EXPECT_EQ(uint64_t(st.cache.free) + st.cache.resident + st.cache.pinned, slots);
    EXPECT_EQ(st.tile_slots, slots);
    EXPECT_EQ(st.dictionary_slots, 0u);
    EXPECT_GE(st.accounted_bytes, st.dictionary_bytes + slots * (m.slot_bytes() + kSlotOverheadBytes));
  }
}

// With a byte budget the dictionary comes out of it, and its share is exact: the same
// budget gives the pack built without a dictionary (same skip grid, preview and tile
// bound) exactly tile_slots + dictionary_slots slots, at budgets on either side of a
// slot boundary of the pack without it.
TEST(DictionaryLoopback, ByteBudgetReportsTheDictionarysShareExactly) {
  const CityPacks& p = city_packs();
  looptest::TestServer srv = start_server({p.on, p.off});
  ClientOptions big = quick_options();
  big.cache_bytes = uint64_t(16) << 20;
  Client probe({"127.0.0.1", srv.port}, big);
  const Map off_map = probe.open("dict_city_off");
  const MapStats off_big = off_map.stats();
  const uint64_t per_slot = off_map.slot_bytes() + kSlotOverheadBytes;
  const uint64_t meta_off = off_big.accounted_bytes - uint64_t(off_big.tile_slots) * per_slot;
  uint32_t displaced = 0;
  for (uint64_t k : {uint64_t(kMinTileSlots) + 40, uint64_t(300)})
    for (uint64_t extra : {uint64_t(0), uint64_t(1), per_slot - 1}) {
      const uint64_t budget = meta_off + k * per_slot + extra;
      ClientOptions co = quick_options();
      co.cache_bytes = budget;
      Client c({"127.0.0.1", srv.port}, co);
      const MapStats on = c.open("dict_city_on").stats(), off = c.open("dict_city_off").stats();
      EXPECT_EQ(off.tile_slots, k) << budget;
      EXPECT_EQ(off.dictionary_slots, 0u);
      EXPECT_EQ(on.tile_slots + on.dictionary_slots, off.tile_slots) << budget;
      EXPECT_LE(on.accounted_bytes, budget);
      EXPECT_LE(off.accounted_bytes, budget);
      displaced += on.dictionary_slots;
    }
  EXPECT_GT(displaced, 0u);  // just above a boundary, the dictionary's bytes cost a slot
}

// A budget that cannot hold the metadata (the dictionary included) and kMinTileSlots tile
// slots is refused at open, naming the sizes and the budget to set; one byte more opens
// with exactly kMinTileSlots slots.
TEST(DictionaryLoopback, ByteBudgetTooSmallForTheDictionaryAndAViewIsAnError) {
  const CityPacks& p = city_packs();
  looptest::TestServer srv = start_server({p.on});
  ClientOptions big = quick_options();
  big.cache_bytes = uint64_t(16) << 20;
  Client probe({"127.0.0.1", srv.port}, big);
  const Map m = probe.open("dict_city_on");
  const MapStats st = m.stats();
  const uint64_t per_slot = m.slot_bytes() + kSlotOverheadBytes;
  const uint64_t meta = st.accounted_bytes - uint64_t(st.tile_slots) * per_slot;
  ASSERT_GT(meta, st.dictionary_bytes);
  const uint64_t need = meta + kMinTileSlots * per_slot;
  {
    ClientOptions co = quick_options();
    co.cache_bytes = need - 1;
    Client c({"127.0.0.1", srv.port}, co);
    try {
      (void)c.open("dict_city_on");
      ADD_FAILURE() << "a budget of " << need - 1 << " bytes opened";
    } catch (const std::exception& e) {
      const std::string why = e.what();
      EXPECT_EQ(why.find('\n'), std::string::npos) << why;
      for (const std::string& part :
           {"a cache of " + std::to_string(need - 1) + " bytes", "metadata (" + std::to_string(meta) + " bytes",
            std::to_string(st.dictionary_bytes) + " are the DAG-MH dictionary",
            std::to_string(kMinTileSlots) + " tile slots", std::to_string(per_slot) + " bytes each",
            "set cache_bytes (--cache-mb) to at least " + std::to_string(need) + " bytes"})
        EXPECT_NE(why.find(part), std::string::npos) << "'" << part << "' not in: " << why;
    }
  }
  ClientOptions co = quick_options();
  co.cache_bytes = need;
  Client c({"127.0.0.1", srv.port}, co);
  const MapStats least = c.open("dict_city_on").stats();
  EXPECT_EQ(least.tile_slots, kMinTileSlots);
  EXPECT_EQ(least.accounted_bytes, need);
}

}  // namespace dictionary_loopback_test
}  // namespace st::client
