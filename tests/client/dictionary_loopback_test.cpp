// The pack-wide DAG-MH dictionary over the wire (loopback, in-process server): MapInfo
// carries it with the skip grid, the client keeps it resident (its bytes taken from the
// cache's slots, always leaving one) and decodes the tiles flagged for it with it, answering every
// texel exactly as the same build without a dictionary answers locally.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"
#include "tiles/bake/map_build.hpp"
#include "tiles/bake/scene.hpp"
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
  // The dictionary's bytes came out of the slots: fewer than cache_slots exist.
  const uint64_t slots = uint64_t(st.cache.resident) + st.cache.pinned + st.cache.free;
  EXPECT_LT(slots, co.cache_slots);
  const uint64_t slot = MapAccess::remote(m).slot_bytes();
  EXPECT_EQ(slots, co.cache_slots - (st.dictionary_bytes + slot - 1) / slot);

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

TEST(DictionaryLoopback, TheDictionaryTakesSlotsButLeavesOne) {
  const CityPacks& p = city_packs();
  looptest::TestServer srv = start_server({p.on});
  for (uint32_t slots : {1u, 2u, 64u}) {
    ClientOptions co = quick_options();
    co.cache_slots = slots;
    Client c({"127.0.0.1", srv.port}, co);
    Map m = c.open("dict_city_on");  // a probe with one slot opens it too
    const MapStats st = m.stats();
    const uint64_t slot = MapAccess::remote(m).slot_bytes(), taken = (st.dictionary_bytes + slot - 1) / slot;
    ASSERT_GT(taken, 0u);
    EXPECT_EQ(uint64_t(st.cache.free) + st.cache.resident + st.cache.pinned, std::max<uint64_t>(1, slots > taken ? slots - taken : 1))
        << slots << " slots";
  }
}

}  // namespace dictionary_loopback_test
}  // namespace st::client
