// GpuMap against the CPU over a loopback server: every texel of every encoding answers
// bit for bit like the Map's CPU evaluator (depth, r x r PCF, the footprint's level, the
// coarse answer where a tile is absent); feedback names exactly the absent tiles a pass
// touched, with the pixels that needed each; a pool of a few slots churning while frames
// are in flight never yields a torn answer; the shadow pass equals its CPU twin; no
// device of the name asked for fails with one clear error and leaves the CPU path alone.
// The validation layer is on throughout and must stay silent.
#include <gtest/gtest.h>

#include <bit>
#include <map>
#include <random>
#include <set>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/gpu_test_util.hpp"
#include "tests/gpu/shadow_twins.hpp"
#include "gpu/tile_slot_table.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/encode/plane_fit.hpp"
#include "tiles/core/dagmh_format.hpp"
#include "tiles/core/dagmh_validate.hpp"
#include "tiles/core/light.hpp"
#include "tiles/core/page_table.hpp"
#include "tiles/core/plane_tile.hpp"

namespace st::gpu {
namespace gpu_map_test {

using looptest::build_pack;
using looptest::start_server;
using looptest::wait_until;

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }
uint32_t test_level() { return looptest::small_scale() ? 5 : 6; }

struct Served {
  looptest::TestPack pack;
  looptest::TestServer server;
  std::unique_ptr<client::Client> client;
  client::Map map;
};

Served serve(const std::string& name, Encoding e, uint32_t slots_extra, uint32_t fixed_slots = 0,
             uint32_t tile_bytes = 512) {
  Served s;
  s.pack = build_pack(name, test_level(), 7, e, 2, tile_bytes);
  s.server = start_server({s.pack.path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = fixed_slots ? fixed_slots : uint32_t(s.pack.reader->tiles().size()) + slots_extra;
  s.client = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s.server.port}, o);
  s.map = s.client->open(name);
  return s;
}

bool fetch_all(client::Map& map) {
  const uint32_t l = map.finest_level();
  const uint64_t side = uint64_t(1) << l;
  map.request_region(l, 0, 0, side, side, 10);
  return wait_until([&] { return map.region_resident(l, 0, 0, side, side); });
}

// Compares GPU answers with `cpu(i)` for every query; "" or the first difference.
template <class Cpu>
std::string compare(const std::vector<GpuQuery>& q, const std::vector<float>& got, Cpu&& cpu) {
  size_t bad = 0;
  std::string first;
  for (size_t i = 0; i < q.size(); ++i) {
    const float want = cpu(i);
    if (bits(got[i]) == bits(want)) continue;
    if (bad++ == 0)
      first = "query " + std::to_string(i) + " (level " + std::to_string(q[i].level) + ", x " + std::to_string(q[i].x) +
              ", y " + std::to_string(q[i].y) + ", r " + std::to_string(q[i].r) + "): gpu " + std::to_string(got[i]) +
              ", cpu " + std::to_string(want);
  }
  return bad ? std::to_string(bad) + " differ; first: " + first : "";
}

// Every texel of every level (depth), every finest texel under r x r PCF with random
// receivers, random footprints through the level choice, and texels outside the map.
void expect_bit_exact(GpuMap& g, const client::Map& map, uint64_t seed) {
  const Evaluator& cpu = client::evaluator(map);
  const uint32_t finest = map.finest_level();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> depth01(-0.05f, 1.05f);
  std::vector<GpuQuery> q;
  for (uint32_t l = 0; l <= finest + 1; ++l)
    for (uint32_t y = 0; y < (1u << l) + (l == finest ? 1 : 0); ++y)
      for (uint32_t x = 0; x < (1u << l) + (l == finest ? 1 : 0); ++x) q.push_back({x, y, 0, 1, 0, l});
  std::vector<float> out(q.size());
  g.evaluate(q, out);
  EXPECT_EQ(compare(q, out, [&](size_t i) { return map.depth(q[i].level, q[i].x, q[i].y); }), "");

  q.clear();
  for (uint32_t y = 0; y < (1u << finest); ++y)
    for (uint32_t x = 0; x < (1u << finest); ++x)
      q.push_back({x, y, depth01(rng), 1, uint32_t(1 + 2 * (rng() % 5)), uint32_t(rng() % 4 == 0 ? finest - 1 : finest)});
  out.resize(q.size());
  g.evaluate(q, out);
  EXPECT_EQ(compare(q, out, [&](size_t i) { return map.pcf(q[i].level, q[i].x, q[i].y, q[i].r, q[i].receiver); }), "");

  q.clear();
  std::vector<std::array<double, 2>> uv;
  std::uniform_real_distribution<double> u01(0, 1);
  std::uniform_real_distribution<float> fp(-1.0f, 9.0f);
  for (int i = 0; i < 4000; ++i) {
    const double u = u01(rng), v = u01(rng);
    float f = std::exp2(fp(rng));
    if (i % 7 == 0) f = std::exp2(float(int(fp(rng))));  // exact powers of two
    const auto t = LightSpace::texel_of(finest, u, v);
    uv.push_back({u, v});
    q.push_back({uint32_t(t[0]), uint32_t(t[1]), depth01(rng), f, uint32_t(1 + 2 * (rng() % 5)), kLevelFromFootprint});
  }
  out.resize(q.size());
  g.evaluate(q, out);
  EXPECT_EQ(compare(q, out,
                    [&](size_t i) {
                      return cpu.pcf_footprint(uv[i][0], uv[i][1], q[i].receiver, q[i].footprint, q[i].r);
                    }),
            "");
}

TEST(GpuMap, EveryTexelOfEveryEncodingAnswersBitExactlyLikeTheCpu) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    Served s = serve("gpu_exact_" + to_string(e), e, 4);
    ASSERT_TRUE(fetch_all(s.map));
    GpuMap g(s.map, gputest::options());
    EXPECT_EQ(g.sync(), s.map.stats().cache.resident);
    expect_bit_exact(g, s.map, 11);
    const GpuStats st = g.stats();
    EXPECT_EQ(st.resident_slots, s.map.stats().cache.resident);
    EXPECT_EQ(st.feedback_tiles, 0u);  // everything resident: nothing asked for
    EXPECT_EQ(st.holes, 0u);
    EXPECT_EQ(st.validation_messages, 0u);
  }
}

// The voxel shadow DAG (not among the hierarchy encodings available_encodings names):
// its depths are the columns' transitions (VSDAG.md "Depth values"), so the GPU's walk to
// each voxel and bisection must give the CPU's bits, and PCF the CPU's popcount. Tiles of
// 16 KiB: under a 512-byte bound the cut's index tiles answer every texel from their
// coarse values and no vsdag tile would be decoded (a shader answering 0.5 passed then).
TEST(GpuMap, EveryTexelOfAVsdagMapAnswersBitExactlyLikeTheCpu) {
  Served s = serve("gpu_exact_vsdag", Encoding::vsdag, 4, 0, 1u << 14);
  ASSERT_TRUE(fetch_all(s.map));
  GpuMap g(s.map, gputest::options());
  EXPECT_EQ(g.sync(), s.map.stats().cache.resident);
  expect_bit_exact(g, s.map, 13);
  const GpuStats st = g.stats();
  EXPECT_EQ(st.feedback_tiles, 0u);
  EXPECT_EQ(st.holes, 0u);
  EXPECT_EQ(st.validation_messages, 0u);
}

// A pack with the DAG-MH dictionary (tiles/PACK.md "DAG-MH dictionary"): the dictionary
// rides in the page table, tiles flagged for it resolve references below its size there, and
// every answer stays the CPU's bits.
TEST(GpuMap, EveryTexelOfADictionaryPackAnswersBitExactlyLikeTheCpu) {
  // The loopback tests' random field in small DAG-MH tiles (serve()'s pack), written with
  // the dictionary: many tiles share treelets and small subtrees.
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/gpu_dict.pack";
  const Hierarchy h = build_hierarchy(looptest::random_field(test_level(), 7));
  CutParams cut;
  cut.map_level = test_level();
  cut.skip_level = 2;
  cut.tile_bytes = 512;
  cut.codec = TileCodec::of(Encoding::dagmh);
  PackParams pp = PackParams::from(
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}}), cut);
  pp.dagmh_dictionary = true;
  write_pack(path, h, cut, pp);
  const auto pack = PackReader::open(path);
  ASSERT_NE(pack->dictionary(), nullptr);
  size_t v2 = 0;
  for (const TileIndexEntry& t : pack->tiles())
    if (t.kind == TileKind::encoded) v2 += (pack->read_raw(t.id)[10] & dagmh::kFlagDictionary) != 0;
  ASSERT_GT(v2, 0u);
  looptest::TestServer srv = start_server({path});
  client::ClientOptions co = looptest::quick_options();
  co.cache_slots = uint32_t(pack->tiles().size()) + 32;
  client::Client c({"127.0.0.1", srv.port}, co);
  client::Map map = c.open("gpu_dict");
  ASSERT_NE(client::MapAccess::remote(map).dictionary(), nullptr);
  ASSERT_TRUE(fetch_all(map));
  GpuMap g(map, gputest::options());
  EXPECT_EQ(g.sync(), map.stats().cache.resident);
  expect_bit_exact(g, map, 17);
  const GpuStats st = g.stats();
  EXPECT_EQ(st.holes, 0u);
  EXPECT_EQ(st.validation_messages, 0u);
}

// A pack served over loopback and fetched whole: the client's CPU answers equal the pack's
// own on every texel of every level, and the GPU's equal the client's (no hole, the
// validation layer silent).
void expect_served_pack_bit_exact(const std::string& path, const std::string& name, size_t tiles, uint32_t seed) {
  looptest::TestServer srv = start_server({path});
  client::ClientOptions co = looptest::quick_options();
  co.cache_slots = uint32_t(tiles) + 32;
  client::Client c({"127.0.0.1", srv.port}, co);
  client::Map map = c.open(name);
  ASSERT_TRUE(fetch_all(map));
  PackEvaluator local(PackReader::open(path));
  for (uint32_t l = 0; l <= map.finest_level(); ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x)
        ASSERT_EQ(bits(map.depth(l, x, y)), bits(local.depth(l, x, y))) << l << " " << x << " " << y;
  GpuMap g(map, gputest::options());
  EXPECT_EQ(g.sync(), map.stats().cache.resident);
  expect_bit_exact(g, map, seed);
  const GpuStats st = g.stats();
  EXPECT_EQ(st.holes, 0u);
  EXPECT_EQ(st.validation_messages, 0u);
}

// A DAG-MH pack with mixed tiles (tiles/PACK.md "Mixed tiles"): every other tile an MMH
// buffer (the builder picks by size; here the order decides, so both kinds are sure to be
// there), told apart by its magic on the GPU as on the CPU, every answer the CPU's bits.
TEST(GpuMap, EveryTexelOfAMixedTilesPackAnswersBitExactlyLikeTheCpu) {
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/gpu_mixed.pack";
  const Hierarchy h = build_hierarchy(looptest::random_field(test_level(), 5));
  CutParams cut;
  cut.map_level = test_level();
  cut.skip_level = 2;
  cut.tile_bytes = 4096;
  cut.codec = TileCodec::of(Encoding::dagmh);
  auto count = std::make_shared<uint32_t>(0);
  cut.codec.encode = [count](const Hierarchy& t) { return ++*count % 2 ? encode_mmh(t) : encode_dagmh(t); };
  PackParams pp = PackParams::from(
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}}), cut);
  pp.dagmh_dictionary = true;
  write_pack(path, h, cut, pp);
  const auto pack = PackReader::open(path);
  ASSERT_TRUE(pack->header().flags & kFeatureMixedTiles);
  size_t mmh = 0, dag = 0;
  for (const TileIndexEntry& t : pack->tiles())
    if (t.kind == TileKind::encoded) ++(is_mmh_buffer(pack->read_raw(t.id)) ? mmh : dag);
  ASSERT_GT(mmh, 0u);
  ASSERT_GT(dag, 0u);
  expect_served_pack_bit_exact(path, "gpu_mixed", pack->tiles().size(), 19);
}

// Plane tiles (tiles/core/PLANES.md): random plane blocks of every size and labelled 8x8
// blocks of 1-4 planes over DAG-MH and MMH
// inner buffers (a, b, c drawn across their whole ranges, so the integer evaluation crosses
// word carries, binades, the clamps at 0 and 1 and exact rounding ties), every answer the
// CPU's bits: shadowtile.glsl's st_plane_lookup against plane_tile.cpp.
TEST(GpuMap, EveryTexelOfAPlaneTilesPackAnswersBitExactlyLikeTheCpu) {
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/gpu_planes.pack";
  const Hierarchy h = build_hierarchy(looptest::random_field(test_level(), 6));
  CutParams cut;
  cut.map_level = test_level();
  cut.skip_level = 1;
  cut.tile_bytes = 1u << 16;
  cut.codec = TileCodec::of(Encoding::dagmh);
  auto rng = std::make_shared<std::mt19937_64>(11);
  cut.codec.encode = [rng](const Hierarchy& t) {
    std::mt19937_64& r = *rng;
    const std::vector<uint8_t> inner = r() % 3 == 0 ? encode_mmh(t) : encode_dagmh(t);
    std::vector<planes::Plane> ps;
    const uint32_t side = 1u << t.depth;
    for (uint32_t shift = std::min<uint32_t>(t.depth - 1, planes::kMaxShift); shift >= planes::kMinShift; --shift) {
      // A few blocks of this size in squares no plane holds yet; the first, at the corner,
      // holds an exact tie between two floats on its first row.
      for (int k : {1, 0, 2}) {
        const bool corner = k == 1 && shift == std::min<uint32_t>(t.depth - 1, planes::kMaxShift);
        const uint32_t bx = corner ? 0 : uint32_t(r() % (side >> shift)) << shift;
        const uint32_t by = corner ? 0 : uint32_t(r() % (side >> shift)) << shift;
        planes::Plane p;
        p.shift = shift;
        p.start = uint32_t(morton_encode(bx, by));
        const uint64_t size = uint64_t(1) << (2 * shift);
        bool free = true;
        for (const planes::Plane& q : ps)
          free &= p.start + size <= q.start || q.start + (uint64_t(1) << (2 * q.shift)) <= p.start;
        if (!free) continue;
        const int64_t mag = int64_t(1) << (r() % 53);
        p.a = int64_t(r() % uint64_t(planes::kOne + planes::kOne / 4)) - planes::kOne / 8;
        if (k == 1) p.a = (int64_t(1) << 59) + (int64_t(1) << 35);  // 0.5 + half an ulp: a tie
        p.b = k == 1 ? 0 : int64_t(r() % uint64_t(2 * mag + 1)) - mag;
        p.c = k == 1 ? int64_t(1) << 36 : int64_t(r() % uint64_t(2 * mag + 1)) - mag;
        ps.push_back(p);
      }
    }
    // Labelled 8x8 blocks in free squares: 1-8 random planes (past 4 a wide block), a random label per texel.
    std::vector<LabelBlock> lbs;
    for (int k = 0; k < 3 && t.depth > planes::kLabelShift; ++k) {
      LabelBlock lb;
      lb.start = uint32_t(morton_encode(uint32_t(r() % (side >> 3)) << 3, uint32_t(r() % (side >> 3)) << 3));
      bool free = true;
      for (const planes::Plane& q : ps)
        free &= lb.start + 64 <= q.start || q.start + (uint64_t(1) << (2 * q.shift)) <= lb.start;
      for (const LabelBlock& q : lbs) free &= lb.start != q.start;
      if (!free) continue;
      const size_t n = 1 + r() % planes::kWidePalette;
      for (size_t j = 0; j < n; ++j) {
        const int64_t mag = int64_t(1) << (r() % 53);
        planes::Plane q;
        q.shift = planes::kLabelShift;
        q.start = lb.start;
        q.a = int64_t(r() % uint64_t(planes::kOne + planes::kOne / 4)) - planes::kOne / 8;
        q.b = int64_t(r() % uint64_t(2 * mag + 1)) - mag;
        q.c = int64_t(r() % uint64_t(2 * mag + 1)) - mag;
        lb.palette.push_back(q);
      }
      for (uint8_t& l : lb.label) l = uint8_t(r() % n);
      lbs.push_back(lb);
    }
    if (ps.empty() && lbs.empty()) return inner;
    std::sort(ps.begin(), ps.end(), [](const planes::Plane& a, const planes::Plane& b) { return a.start < b.start; });
    std::sort(lbs.begin(), lbs.end(), [](const LabelBlock& a, const LabelBlock& b) { return a.start < b.start; });
    return wrap_planes(ps, t.depth, inner, lbs);
  };
  PackParams pp = PackParams::from(
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}}), cut);
  write_pack(path, h, cut, pp);
  const auto pack = PackReader::open(path);
  ASSERT_TRUE(pack->header().flags & kFeaturePlaneTiles);
  expect_served_pack_bit_exact(path, "gpu_planes", pack->tiles().size(), 23);
}

// The tiles the CPU's page-table walk over the same cache finds absent for each texel.
std::map<uint64_t, uint32_t> absent_tiles(const client::Map& map, const std::vector<GpuQuery>& q) {
  const client::RemoteMap& rm = client::MapAccess::remote(map);
  std::map<uint64_t, uint32_t> want;
  rm.inspect_cache([&](const TileCache& c) {
    std::map<uint32_t, CutGrid> grids;
    for (const GpuQuery& x : q) {
      PageEntry page;
      auto index = [&](uint64_t id, const GridEntry&) -> const CutGrid* {
        page = c.lookup(id);
        if (page.state != PageState::resident) return nullptr;
        auto it = grids.find(page.slot);
        if (it == grids.end()) it = grids.emplace(page.slot, CutGrid::parse(c.tile_bytes(page.slot), "slot", kMaxIndexLevels)).first;
        return &it->second;
      };
      const PageHit hit = walk_page_table(rm.grid(), x.level, x.x, x.y, index);
      if (hit.kind == PageHit::Kind::absent ||
          (hit.kind == PageHit::Kind::tile && c.lookup(hit.tile).state != PageState::resident))
        ++want[hit.tile];
    }
  });
  return want;
}

TEST(GpuMap, AbsentTilesAnswerCoarselyLikeTheCpuAndFeedbackNamesExactlyThem) {
  for (Encoding e : looptest::available_encodings()) {
    SCOPED_TRACE(to_string(e));
    Served s = serve("gpu_absent_" + to_string(e), e, 0, 12);
    const uint32_t l = s.map.finest_level();
    const uint64_t part = (uint64_t(1) << l) / 4;
    s.map.request_region(l, 0, 0, part, part, 10);
    ASSERT_TRUE(wait_until([&] { return s.map.region_resident(l, 0, 0, part, part); }));
    s.server.stop();  // nothing arrives from here on: the cache holds still
    GpuMap g(s.map, gputest::options());
    g.sync();
    std::vector<GpuQuery> q;
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) q.push_back({x, y, 0, 1, 0, l});
    std::vector<float> out(q.size());
    const FrameStats fs = g.evaluate(q, out);
    std::map<uint64_t, uint32_t> got;
    for (const auto& t : g.last_feedback()) got[t.tile] = t.pixels;
    const std::map<uint64_t, uint32_t> want = absent_tiles(s.map, q);
    EXPECT_FALSE(want.empty());
    EXPECT_EQ(got, want);  // the same tiles, each with the number of texels that needed it
    EXPECT_EQ(fs.feedback_tiles, want.size());
    EXPECT_EQ(fs.requested, want.size());  // all newly queued on the Map
    EXPECT_EQ(fs.feedback_dropped, 0u);
    uint32_t holes = 0;
    for (const auto& [tile, n] : want) holes += n;
    EXPECT_EQ(fs.holes, holes);
    EXPECT_EQ(compare(q, out, [&](size_t i) { return s.map.depth(l, q[i].x, q[i].y); }), "");
    expect_bit_exact(g, s.map, 12);
    EXPECT_EQ(g.stats().validation_messages, 0u);
  }
}

// GpuMap's tile -> slot hash (gpu/tile_slot_table.hpp) churned against a reference map, no
// device: slots take tiles and lose them in random order, a tile sometimes moving to a second
// slot before its first one empties (as link runs before the old slot's unlink). Tiles drawn
// from a small set at load 1/2 share homes, so runs form, wrap past the last bucket and are
// shifted back over every hole; each tile must stay findable in its latest slot after every
// step. (The GpuMap churn test below links too few slots to reach a broken shift.)
TEST(GpuMap, TheTileSlotTableFindsEveryTileThroughChurnAndBackShifts) {
  for (const uint32_t slots : {8u, 64u}) {
    SCOPED_TRACE(slots);
    TileSlotTable table;
    table.init(slots);
    std::vector<TileId> rec(slots, kInvalidTile);  // a slot's record: the key the table reads
    auto key_of = [&](uint32_t s) { return rec[s]; };
    std::map<TileId, uint32_t> owner;  // the reference: tile -> the slot find must answer
    std::vector<TileId> pool;
    for (uint32_t i = 0; i < 3 * slots; ++i) pool.push_back(make_tile_id(6, i % 64, i / 64));
    std::mt19937_64 rng(slots);
    uint64_t busy_steps = 0;
    for (int step = 0; step < 4000; ++step) {
      const uint32_t s = uint32_t(rng() % slots);
      if (rec[s] != kInvalidTile) {  // unlink: the slot loses its tile (its bucket, if it has one)
        const TileId t = rec[s];
        table.erase(t, s);
        if (auto it = owner.find(t); it != owner.end() && it->second == s) owner.erase(it);
        rec[s] = kInvalidTile;
      } else {  // link: a tile not held anywhere, or now and then one held in another slot
        TileId t = pool[rng() % pool.size()];
        if (owner.count(t) && rng() % 4 != 0) continue;
        table.set(t, s, key_of);
        rec[s] = t;
        owner[t] = s;
      }
      for (const auto& [t, slot] : owner) ASSERT_EQ(table.find(t, key_of), slot) << "step " << step << " tile " << t;
      for (int i = 0; i < 4; ++i) {
        const TileId t = pool[rng() % pool.size()];
        if (!owner.count(t)) {
          ASSERT_EQ(table.find(t, key_of), layout::kNoSlot) << "step " << step << " tile " << t;
        }
      }
      busy_steps += owner.size() > slots / 2;
    }
    EXPECT_GT(busy_steps, 100u);  // more than half the slots held tiles for a while
  }
}

TEST(GpuMap, AFewSlotsChurningUnderFramesInFlightNeverTearAndEndExact) {
  const Encoding e = looptest::first_encoding();
  Served s = serve("gpu_churn", e, 0, 6);
  PackEvaluator local(s.pack.reader);
  GpuOptions o = gputest::options();
  o.upload_budget_bytes = 600;  // about one slot a frame: uploads trail the cache
  o.frames_in_flight = 2;
  GpuMap g(s.map, o);
  const uint32_t l = s.map.finest_level();
  const uint32_t side = 1u << l;
  std::mt19937_64 rng(5);
  struct InFlight {
    uint64_t frame;
    std::vector<GpuQuery> q;
  };
  std::vector<InFlight> flight;
  uint64_t checked = 0, torn = 0;
  auto check = [&](InFlight& f) {
    std::vector<float> out(f.q.size());
    g.wait(f.frame, out);
    for (size_t i = 0; i < f.q.size(); ++i) {
      // Any answer is the value of a node on the texel's path (this level or coarser):
      // a torn slot or a stale pointer would give something else.
      const GpuQuery& x = f.q[i];
      bool ok = false;
      for (uint32_t c = 0; c <= x.level && !ok; ++c)
        ok = bits(out[i]) == bits(local.depth(c, x.x >> (x.level - c), x.y >> (x.level - c)));
      torn += !ok;
      ++checked;
    }
  };
  for (int frame = 0; frame < 40; ++frame) {
    const uint32_t w = side / 4;
    s.map.request_region(l, rng() % (side - w), rng() % (side - w), w, w, uint16_t(1 + frame));
    InFlight f;
    for (int i = 0; i < 512; ++i) {
      const uint32_t lv = l - uint32_t(rng() % 3);
      f.q.push_back({uint32_t(rng() % (1u << lv)), uint32_t(rng() % (1u << lv)), 0, 1, 0, lv});
    }
    f.frame = g.submit_evaluate(f.q);
    flight.push_back(std::move(f));
    if (flight.size() == 2) {
      check(flight.front());
      flight.erase(flight.begin());
    }
  }
  for (InFlight& f : flight) check(f);
  EXPECT_EQ(torn, 0u) << "of " << checked;
  const GpuStats st = g.stats();
  EXPECT_GT(st.slots_uploaded, 6u);  // slots were reused
  EXPECT_GT(st.feedback_requested, 0u);
  s.server.stop();
  // Tiles already on the wire may still land after stop(): the comparison below needs a
  // cache that no longer changes, which it is once the client has seen the disconnect.
  ASSERT_TRUE(wait_until([&] { return !s.client->stats().connected; }));
  g.sync();
  std::vector<GpuQuery> q;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) q.push_back({x, y, 0, 1, 0, l});
  std::vector<float> out(q.size());
  g.evaluate(q, out);
  EXPECT_EQ(compare(q, out, [&](size_t i) { return s.map.depth(l, q[i].x, q[i].y); }), "");
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

TEST(GpuMap, ShadowPassEqualsItsCpuTwinBitForBit) {
  const Encoding e = looptest::first_encoding();
  Served s = serve("gpu_pass", e, 0, 10);
  const uint32_t l = s.map.finest_level();
  s.map.request_region(l, 0, 0, (1u << l) / 2, (1u << l) / 2, 10);
  ASSERT_TRUE(wait_until([&] { return s.map.region_resident(l, 0, 0, (1u << l) / 2, (1u << l) / 2); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  const PackHeader& h = client::pack_header(s.map);
  const LightSpace ls = LightSpace::from_array(h.light_kind, h.light);
  const uint32_t w = 64, ht = 48;
  std::vector<float> pos(size_t(w) * ht * 4), nrm(pos.size());
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> jitter(-0.002, 0.002);
  for (uint32_t y = 0; y < ht; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      const size_t p = size_t(y) * w + x;
      // a tilted plane across light space, a little outside the box at the edges
      const double u = -0.05 + 1.1 * (x + 0.5) / w + jitter(rng), v = -0.05 + 1.1 * (y + 0.5) / ht;
      const double d = 0.3 + 0.4 * u + jitter(rng) * 50;
      const double e2 = ls.extent_uv(), z = ls.near_plane() + d * (ls.far_plane() - ls.near_plane());
      const Vec3d wp = ls.origin() + ls.axis_u() * (u * e2) + ls.axis_v() * (v * e2) + ls.forward() * z;
      pos[4 * p] = float(wp.x), pos[4 * p + 1] = float(wp.y), pos[4 * p + 2] = float(wp.z);
      pos[4 * p + 3] = (x * 7 + y * 3) % 29 == 0 ? 0.0f : 1.0f;  // a few background pixels
      const Vec3d n = ls.forward() * -1.0;
      nrm[4 * p] = float(n.x), nrm[4 * p + 1] = float(n.y), nrm[4 * p + 2] = float(n.z);
    }
  for (uint32_t kernel : {1u, 3u, 5u}) {
    SCOPED_TRACE(kernel);
    ShadowPassInput in;
    in.positions = pos;
    in.normals = nrm;
    in.width = w;
    in.height = ht;
    in.kernel = kernel;
    in.normal_offset = 0.001f;
    in.neighbour_footprint = kernel != 5;
    in.footprint = 2.5f;
    std::vector<float> got(size_t(w) * ht), want(got.size());
    const uint64_t f = g.submit_shadow_pass(in);
    const FrameStats fs = g.wait(f, got);
    shadow_pass_reference(client::evaluator(s.map), h, in, want);
    size_t bad = 0, lit = 0, shadow = 0;
    for (size_t i = 0; i < got.size(); ++i) {
      bad += bits(got[i]) != bits(want[i]);
      lit += want[i] == 1.0f;
      shadow += want[i] == 0.0f;
    }
    EXPECT_EQ(bad, 0u);
    EXPECT_GT(shadow + lit, 0u);
    EXPECT_GT(fs.holes, 0u);  // half the map is absent
  }
  // Stack queries on a 2D map: one clear error, and the map is no stack.
  EXPECT_FALSE(g.is_stack());
  std::vector<float> one(1);
  EXPECT_THROW(g.evaluate(std::vector<GpuStackQuery>(1), one), GpuError);
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

TEST(GpuMap, NoDeviceOfTheNameAskedForFailsClearlyAndTheCpuPathStillAnswers) {
  const Encoding e = looptest::first_encoding();
  Served s = serve("gpu_nodev", e, 4);
  ASSERT_TRUE(fetch_all(s.map));
  GpuOptions o = gputest::options();
  o.device = "no-such-vulkan-device";
  try {
    GpuMap g(s.map, o);
    ADD_FAILURE() << "a GpuMap on a device that does not exist";
  } catch (const GpuError& err) {
    const std::string m = err.what();
    EXPECT_NE(m.find("no device named like 'no-such-vulkan-device'"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  PackEvaluator local(s.pack.reader);
  const uint32_t l = s.map.finest_level();
  for (uint64_t i = 0; i < 64; ++i)
    EXPECT_EQ(bits(s.map.depth(l, i % (1u << l), (i * 5) % (1u << l))), bits(local.depth(l, i % (1u << l), (i * 5) % (1u << l))));
  EXPECT_THROW(GpuMap(client::Map{}, gputest::options()), std::runtime_error);
}

}  // namespace gpu_map_test
}  // namespace st::gpu

// Debian 12's current Mesa (lavapipe) leaks from a module it unloads before exit, so
// LeakSanitizer reports "<unknown module>" frames that no suppression can name (and
// gtest_discover_tests passes only the first ENVIRONMENT entry, so lsan_mesa.supp does
// not reach these tests). Leak checking is off for this binary only; ASan and UBSan stay on.
extern "C" int __lsan_is_turned_off() { return 1; }
