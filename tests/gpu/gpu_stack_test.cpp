// GpuMap on a stack map (shadow-map stacks, MH 2016 §4) over a loopback server: every texel
// of every level of every slice answers bit for bit like the Map's CPU lookup
// (Map::slice_depth), with every tile resident and with cells absent (the level-K value,
// and feedback naming exactly the absent cells); PCF and the footprint's level per slice;
// the shadow pass at sample times and between equals its CPU twin; its feedback queues the
// cells the pass needed, and once they arrive the pass has no holes; the soft pass (every
// slice averaged) equals its twin too, and the twin the client's soft lookup; an area
// light's stack (perspective samples, both frames) passes at times and soft equal their
// twins. The validation layer is on throughout and must stay silent.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <random>
#include <set>
#include <thread>

#include "client/map_access.hpp"
#include "tests/client/loopback.hpp"
#include "tests/gpu/engine_harness.hpp"
#include "tests/gpu/gpu_test_util.hpp"
#include "tests/gpu/shadow_twins.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/mh_octree.hpp"
#include "tiles/core/plane_format.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st::gpu {
namespace {

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

// Boxes' shadows sliding with w over a ground at 0.8 (coherent slices), as the stack
// loopback test builds them.
IntervalStack sliding_stack(uint32_t level, uint32_t slices) {
  const uint64_t side = uint64_t(1) << level;
  IntervalStack s{level, slices, std::vector<Interval>(side * side * slices, Interval{0.8f, 0.8f})};
  for (uint32_t w = 0; w < slices; ++w)
    for (int b = 0; b < 3; ++b) {
      const uint64_t x0 = (7 + 17 * b + w) % (side - 12), y0 = (5 + 23 * b) % (side - 12);
      for (uint64_t y = y0; y < y0 + 10; ++y)
        for (uint64_t x = x0; x < x0 + 10; ++x) s.at(x, y, w) = {0.2f + 0.1f * float(b), 0.35f + 0.1f * float(b)};
    }
  return s;
}

// sliding_stack over a slanted ground: each ground texel the decoded depth of one plane
// (plane_format.hpp, exact), so per-slice cells store plane slices there.
IntervalStack planar_stack(uint32_t level, uint32_t slices) {
  IntervalStack s = sliding_stack(level, slices);
  for (uint32_t w = 0; w < slices; ++w)
    for (uint64_t y = 0; y < s.side(); ++y)
      for (uint64_t x = 0; x < s.side(); ++x)
        if (s.at(x, y, w).lo == 0.8f) {
          const float v = planes::plane_fixed_to_float(planes::kOne / 2 + planes::kOne / 512 * int64_t(x) +
                                                       planes::kOne / 1024 * int64_t(y));
          s.at(x, y, w) = {v, v};
        }
  return s;
}

struct ServedStack {
  std::string path;
  size_t tiles = 0;
  looptest::TestServer server;
  std::unique_ptr<client::Client> client;
  client::Map map;
  std::vector<std::vector<uint8_t>> tile_bytes;  // the cut's tiles, by cell
};

constexpr uint32_t kSlices = 10;
// A tile bound that splits cells of this file's small stacks below K (split cells).
constexpr uint32_t kSplitTileBytes = 256;

// An area light over the G-buffer's box (light_set.hpp "area"): 10 Hilbert-ordered points
// of a 6 x 4 rectangle, frame window (spot_window samples) or translate (spots).
std::string area_spec(const std::string& frame) {
  return "area:pos=4,28,6,target=0,0,0,size=6,4,samples=" + std::to_string(kSlices) + ",fov=50,frame=" + frame;
}

// The stack of kSlices slices, its skip level and tile bytes a served stack is cut with
// (default: sliding_stack, the default level, 512-byte tiles).
struct StackSource {
  const IntervalStack* stack = nullptr;
  std::optional<uint32_t> skip_level;
  uint32_t tile_bytes = 512;
  StackCells cells = StackCells::octree;  // else the blocked cut's per-slice or smaller cells
  bool split = false;  // the blocked cut splitting cells over tile_bytes below K (grid version 2)
  bool planes = false;  // per-slice cells' slices may be plane tiles (tiles/core/PLANES.md)
};

// The blocked cut of `is` (the builder's; cut_stack's bytes for octree cells) with `cells`.
StackCut blocked_cut(const IntervalStack& is, const std::string& name, const StackSource& src) {
  const std::string base = std::string(SHADOWTILE_TEST_TMP) + "/" + name;
  StackSpill spill(base + ".spill", is.level, is.slices, 0);
  const size_t area = size_t(is.side() * is.side());
  for (uint32_t w = 0; w < is.slices; ++w)
    spill.write_rows(w, 0, is.side(), std::span<const Interval>(is.data.data() + w * area, area));
  BlockedStackCut blocked(spill, src.skip_level, src.tile_bytes, base + ".tiles", nullptr, src.cells, src.split,
                          src.planes ? std::optional<PlaneFitOptions>(PlaneFitOptions{}) : std::nullopt);
  if (src.split && blocked.split_cells == 0) ADD_FAILURE() << name << ": no cell split";
  if (src.split) std::printf("%s: K = %u, %llu cells split, %zu entries, %zu tiles\n", name.c_str(), blocked.grid.skip_level,
                             (unsigned long long)blocked.split_cells, blocked.grid.entries.size(), blocked.tile_count());
  StackCut cut;
  cut.grid = blocked.grid;
  for (size_t i = 0; i < blocked.tile_count(); ++i) cut.tiles.push_back(blocked.tile(i));
  cut.max_tile_bytes = blocked.max_tile_bytes;
  return cut;
}

// frame: the sun path's frame (light_set.hpp "Frames"; ground is the default); or a whole
// light set spec (area_spec).
ServedStack serve_stack(const std::string& name, const std::string& frame = "ground", const StackSource& src = {}) {
  ServedStack s;
  const IntervalStack is = src.stack ? *src.stack : sliding_stack(looptest::small_scale() ? 5 : 6, kSlices);
  StackCut cut = src.cells == StackCells::octree && !src.split
                     ? cut_stack(build_octree(is), src.skip_level, src.tile_bytes)
                     : blocked_cut(is, name, src);
  Aabb box;
  box.extend({-10, 0, -10});
  box.extend({10, 5, 10});
  const LightSet set = LightSet::fit(
      LightSetSpec::parse(frame.find(':') != std::string::npos
                              ? frame
                              : "sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(kSlices) +
                                    ",frame=" + frame),
      box);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  s.path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  StackPackParams p;
  p.tile_bytes = src.tile_bytes;
  write_stack_pack(s.path, cut, p);
  s.tiles = cut.tiles.size();
  for (auto& t : cut.tiles) s.tile_bytes.push_back(std::move(t.second));
  s.server = looptest::start_server({s.path});
  client::ClientOptions o = looptest::quick_options();
  o.cache_slots = uint32_t(s.tiles) + 4;
  s.client = std::make_unique<client::Client>(client::Endpoint{"127.0.0.1", s.server.port}, o);
  s.map = s.client->open(name);
  return s;
}

// serve_stack with slices 0..last resident and the server stopped: the cache then stays
// as it is, so a GPU pass and its CPU twin read the same tiles.
ServedStack serve_frozen(const std::string& name, const std::string& frame, uint32_t last, const StackSource& src = {}) {
  ServedStack s = serve_stack(name, frame, src);
  if (s.map.request_slices(0, last, 10) == 0) ADD_FAILURE() << "nothing to prefetch";
  if (!looptest::wait_until([&] { return s.map.slices_resident(0, last); })) ADD_FAILURE() << "prefetch timed out";
  s.server.stop();
  return s;
}

std::string describe(const GpuStackQuery& q) {
  return "slice " + std::to_string(q.slice) + " level " + std::to_string(q.level) + " x " + std::to_string(q.x) +
         " y " + std::to_string(q.y) + " r " + std::to_string(q.r);
}

// Every texel (and one past the edge) of every level up to n + 1, of every slice and one
// past the last: GPU depths against Map::slice_depth. Returns "" or the first difference.
std::string compare_every_texel(GpuMap& g, const client::Map& map, uint32_t n) {
  size_t bad = 0;
  std::string first;
  for (uint32_t w = 0; w <= kSlices; ++w) {
    std::vector<GpuStackQuery> q;
    for (uint32_t l = 0; l <= n + 1; ++l)
      for (uint32_t y = 0; y <= (1u << l); ++y)
        for (uint32_t x = 0; x <= (1u << l); ++x) q.push_back({x, y, w, l, 0, 1, 0});
    std::vector<float> out(q.size());
    g.evaluate(q, out);
    for (size_t i = 0; i < q.size(); ++i) {
      const float want = map.slice_depth(q[i].slice, q[i].level, q[i].x, q[i].y);
      if (bits(out[i]) == bits(want)) continue;
      if (bad++ == 0) first = describe(q[i]) + ": gpu " + std::to_string(out[i]) + ", cpu " + std::to_string(want);
    }
  }
  return bad ? std::to_string(bad) + " differ; first: " + first : "";
}

TEST(GpuStack, EveryTexelOfEverySliceAnswersBitExactlyLikeTheCpu) {
  ServedStack s = serve_stack("gpu_stack_all");
  ASSERT_GT(s.tiles, 4u);
  ASSERT_EQ(s.map.slices(), kSlices);
  ASSERT_GT(s.map.request_slices(0, kSlices - 1, 10), 0u);
  ASSERT_TRUE(looptest::wait_until([&] { return s.map.slices_resident(0, kSlices - 1); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  EXPECT_TRUE(g.is_stack());
  EXPECT_EQ(g.sync(), s.tiles);
  const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
  const uint32_t n = grid.geo.n;
  EXPECT_EQ(compare_every_texel(g, s.map, n), "");

  // r x r PCF at a level and through the footprint's level, per slice, with random
  // receivers: against the same kernel over Map::slice_depth (StackMap::filtered's).
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<float> depth01(0.1f, 0.9f), fp(-1.0f, 7.0f);
  std::vector<GpuStackQuery> q;
  for (int i = 0; i < 6000; ++i) {
    GpuStackQuery a;
    a.slice = uint32_t(rng() % kSlices);
    a.x = uint32_t(rng() % (1u << n));
    a.y = uint32_t(rng() % (1u << n));
    a.receiver = depth01(rng);
    a.r = uint32_t(1 + 2 * (rng() % 5));
    if (i % 2) a.level = kLevelFromFootprint, a.footprint = std::exp2(fp(rng));
    else a.level = n - uint32_t(rng() % 3), a.x >>= n - a.level, a.y >>= n - a.level;
    q.push_back(a);
  }
  std::vector<float> out(q.size());
  g.evaluate(q, out);
  auto pcf = [&](const GpuStackQuery& a, uint32_t level, uint32_t x, uint32_t y) {
    const uint64_t side = uint64_t(1) << level;
    uint32_t lit = 0;
    for (uint32_t j = 0; j < a.r; ++j)
      for (uint32_t i = 0; i < a.r; ++i)
        lit += a.receiver <= s.map.slice_depth(a.slice, level, pcf_tap(x, i, a.r, side), pcf_tap(y, j, a.r, side));
    return float(lit) / float(a.r * a.r);
  };
  size_t bad = 0, fractional = 0;
  for (size_t i = 0; i < q.size(); ++i) {
    const GpuStackQuery& a = q[i];
    float want;
    if (a.level != kLevelFromFootprint) {
      want = pcf(a, a.level, a.x, a.y);
    } else {
      const FilterLevels f = filter_levels(n, a.footprint);
      want = pcf(a, f.fine, a.x >> (n - f.fine), a.y >> (n - f.fine));
      if (f.t != 0.0f) want = filter_blend(want, pcf(a, f.coarse, a.x >> (n - f.coarse), a.y >> (n - f.coarse)), f.t);
    }
    fractional += want > 0.0f && want < 1.0f;
    if (bits(out[i]) != bits(want) && bad++ == 0)
      ADD_FAILURE() << describe(a) << ": gpu " << out[i] << ", cpu " << want;
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_GT(fractional, 100u);  // the kernels straddle shadow edges
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// One tile holding a stack whose equal blocks lie beyond a 16-bit offset's reach, so its
// octree reaches them through far words (MHOCT.md "Far words"): random slices whose bottom
// half repeats the top half shifted by two texels (the finest 2x2x2 blocks are equal,
// two root quadrants apart). Every finest texel of every slice and the level above it,
// by the GPU's st_oct_step, against the CPU's MhOctree::depth, bit for bit.
TEST(GpuStack, FarSharedBlocksAnswerBitExactlyLikeTheCpu) {
  const uint32_t level = 7;
  const uint64_t side = uint64_t(1) << level;
  IntervalStack is{level, kSlices, std::vector<Interval>(side * side * kSlices)};
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> u(0.05f, 0.95f);
  for (Interval& v : is.data) {
    const float a = u(rng), b = u(rng);
    v = rng() % 4 == 0 ? Interval{a, a} : Interval{std::min(a, b), std::max(a, b)};
  }
  for (uint32_t w = 0; w < kSlices; ++w)
    for (uint64_t y = side / 2 + 2; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) is.at(x, y, w) = is.at(x, y - side / 2 - 2, w);
  OctEncodeStats st;
  const std::vector<uint8_t> whole = encode_octree(build_octree(is), &st);
  ASSERT_GT(st.far_blocks, 100u) << "the stack must use far words; words " << st.words;
  // Skip level 0: the one tile is that buffer (checked through the CPU's answers below).
  ServedStack s = serve_stack("gpu_stack_far", "ground", {&is, 0, uint32_t(2 * whole.size())});
  ASSERT_EQ(s.tiles, 1u);
  ASSERT_GT(s.map.request_slices(0, kSlices - 1, 10), 0u);
  ASSERT_TRUE(looptest::wait_until([&] { return s.map.slices_resident(0, kSlices - 1); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  EXPECT_EQ(g.sync(), 1u);
  const MhOctree t = MhOctree::open(whole);
  std::vector<GpuStackQuery> q;
  for (uint32_t w = 0; w < kSlices; ++w)
    for (uint32_t l : {level - 1, level})
      for (uint32_t y = 0; y < (1u << l); ++y)
        for (uint32_t x = 0; x < (1u << l); ++x) q.push_back({x, y, w, l, 0, 1, 0});
  size_t bad = 0, checked = 0;
  for (size_t at = 0; at < q.size(); at += gputest::options().max_queries) {
    const std::vector<GpuStackQuery> part(q.begin() + ptrdiff_t(at),
                                          q.begin() + ptrdiff_t(std::min(q.size(), at + gputest::options().max_queries)));
    std::vector<float> out(part.size());
    g.evaluate(part, out);
    for (size_t i = 0; i < part.size(); ++i, ++checked) {
      const GpuStackQuery& a = part[i];
      const float want = t.depth(a.x, a.y, a.slice, a.level);
      if (bits(want) != bits(s.map.slice_depth(a.slice, a.level, a.x, a.y)) && bad++ == 0)
        ADD_FAILURE() << describe(a) << ": the tile and the whole stack's buffer differ";
      if (bits(out[i]) != bits(want) && bad++ == 0)
        ADD_FAILURE() << describe(a) << ": gpu " << out[i] << ", cpu " << want;
    }
  }
  EXPECT_EQ(bad, 0u);
  EXPECT_EQ(checked, q.size());
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

bool cell_resident(const client::Map& map, uint64_t tile) {
  bool r = false;
  client::MapAccess::remote(map).inspect_cache(
      [&](const TileCache& c) { r = c.lookup(tile).state == PageState::resident; });
  return r;
}

TEST(GpuStack, AbsentCellsAnswerTheirLevelKValueAndFeedbackNamesExactlyThem) {
  ServedStack s = serve_stack("gpu_stack_absent");
  ASSERT_GT(s.map.request_slices(0, kSlices / 2 - 1, 10), 0u);
  ASSERT_TRUE(looptest::wait_until([&] { return s.map.slices_resident(0, kSlices / 2 - 1); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  g.sync();
  const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
  const uint32_t n = grid.geo.n;
  EXPECT_EQ(compare_every_texel(g, s.map, n), "");
  // Every finest texel of the later slices: the cells they fall in that are tiles and not
  // resident are exactly the feedback, each with the number of queries in it.
  const StackMap cells(grid);  // no tile: the cells' level-K values
  std::vector<GpuStackQuery> q;
  std::map<uint64_t, uint32_t> want;
  for (uint32_t w = kSlices / 2 - 1; w < kSlices; ++w)
    for (uint32_t y = 0; y < (1u << n); ++y)
      for (uint32_t x = 0; x < (1u << n); ++x) {
        q.push_back({x, y, w, n, 0, 1, 0});
        const uint64_t cell = cells.cell_of(x, y, w);
        if (grid.entries[cell].kind == 1 && !cell_resident(s.map, grid.tile_id(cell))) ++want[grid.tile_id(cell)];
      }
  ASSERT_FALSE(want.empty());
  std::vector<float> out(q.size());
  const FrameStats fs = g.evaluate(q, out);
  std::map<uint64_t, uint32_t> got;
  for (const GpuMap::FeedbackTile& t : g.last_feedback()) got[t.tile] = t.pixels;
  EXPECT_EQ(got, want);
  uint32_t holes = 0;
  for (const auto& [tile, count] : want) holes += count;
  EXPECT_EQ(fs.holes, holes);
  EXPECT_EQ(fs.feedback_tiles, want.size());
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// A G-buffer over the light sets' box: a wavy surface, a margin outside the box, a few
// background pixels, normals up.
struct GBuffer {
  uint32_t width = 64, height = 48;
  std::vector<float> pos, nrm;
  GBuffer() : pos(size_t(width) * height * 4), nrm(pos.size()) {
    for (uint32_t y = 0; y < height; ++y)
      for (uint32_t x = 0; x < width; ++x) {
        const size_t p = size_t(y) * width + x;
        const double wx = -11 + 22.0 * (x + 0.5) / width, wz = -11 + 22.0 * (y + 0.5) / height;
        pos[4 * p] = float(wx);
        pos[4 * p + 1] = float(2.5 + 2.4 * std::sin(0.7 * wx) * std::cos(0.5 * wz));
        pos[4 * p + 2] = float(wz);
        pos[4 * p + 3] = (x * 7 + y * 3) % 31 == 0 ? 0.0f : 1.0f;
        nrm[4 * p + 1] = 1.0f;
      }
  }
  // Moves 8 x 8 blocks in a checkerboard onto the plane y = `ground`.
  void ground_checkers(float ground) {
    for (uint32_t y = 0; y < height; ++y)
      for (uint32_t x = 0; x < width; ++x)
        if (((x >> 3) + (y >> 3)) % 2 == 0) pos[4 * (size_t(y) * width + x) + 1] = ground;
  }
  ShadowPassInput input(double time, uint32_t kernel, bool soft = false) const {
    ShadowPassInput in;
    in.positions = pos;
    in.normals = nrm;
    in.width = width;
    in.height = height;
    in.kernel = kernel;
    in.normal_offset = 0.01f;
    in.neighbour_footprint = kernel != 5;
    in.footprint = 2.5f;
    in.time = time;
    in.soft = soft;
    return in;
  }
};

// Every pixel of the pass against its CPU twin, bit for bit. Returns the mismatches and
// adds the answers' classes (lit, shadowed, in between) to `tally`.
size_t pass_against_twin(GpuMap& g, const client::Map& map, const ShadowPassInput& in, FrameStats& fs,
                         std::array<size_t, 3>& tally) {
  std::vector<float> got(size_t(in.width) * in.height), want(got.size());
  fs = g.wait(g.submit_shadow_pass(in), got);
  stack_shadow_pass_reference(map, in, want);
  size_t bad = 0;
  for (size_t i = 0; i < got.size(); ++i) {
    if (bits(got[i]) != bits(want[i]) && bad++ == 0)
      ADD_FAILURE() << "pixel " << i << ": gpu " << got[i] << " (" << bits(got[i]) << "), cpu " << want[i] << " ("
                    << bits(want[i]) << ")";
    ++tally[want[i] == 1.0f ? 0 : want[i] == 0.0f ? 1 : 2];
  }
  return bad;
}

// Both frames: the orthographic sun's and the ground frame's sheared light transform.
TEST(GpuStack, ShadowPassAtSampleTimesAndBetweenEqualsItsCpuTwin) {
  for (const std::string frame : {"ortho", "ground"}) {
  SCOPED_TRACE("frame=" + frame);
  ServedStack s = serve_stack("gpu_stack_pass_" + frame, frame);
  ASSERT_EQ(client::MapAccess::remote(s.map).stack_grid()->light_kind,
            frame == "ground" ? LightKind::sun_ground : LightKind::sun);
  ASSERT_GT(s.map.request_slices(0, kSlices / 2 - 1, 10), 0u);  // the later slices stay absent
  ASSERT_TRUE(looptest::wait_until([&] { return s.map.slices_resident(0, kSlices / 2 - 1); }));
  s.server.stop();
  GpuMap g(s.map, gputest::options());
  const GBuffer gb;
  size_t lit = 0, shadow = 0, between = 0, plane_moved = 0;
  for (double time : {0.0, 2.0 / 9.0, 0.2, 0.43, 0.5, 0.61, 1.0})
    for (uint32_t kernel : {1u, 3u, 5u}) {
      SCOPED_TRACE("time " + std::to_string(time) + " kernel " + std::to_string(kernel));
      const ShadowPassInput in = gb.input(time, kernel);  // with the receiver plane (the default)
      std::vector<float> got(size_t(gb.width) * gb.height), want(got.size());
      const FrameStats fs = g.wait(g.submit_shadow_pass(in), got);
      stack_shadow_pass_reference(s.map, in, want);
      size_t bad = 0;
      for (size_t i = 0; i < got.size(); ++i) {
        if (bits(got[i]) != bits(want[i]) && bad++ == 0)
          ADD_FAILURE() << "pixel " << i << ": gpu " << got[i] << ", cpu " << want[i];
        lit += want[i] == 1.0f, shadow += want[i] == 0.0f, between += want[i] > 0.0f && want[i] < 1.0f;
      }
      EXPECT_EQ(bad, 0u);
      std::vector<float> flat_want(got.size());
      if (kernel <= 3) {  // one receiver depth for every tap: its own twin; the plane moves answers
        ShadowPassInput flat_in = in;
        flat_in.receiver_plane = false;
        std::vector<float> flat(got.size());
        g.wait(g.submit_shadow_pass(flat_in), flat);
        stack_shadow_pass_reference(s.map, flat_in, flat_want);
        size_t bad_flat = 0;
        for (size_t i = 0; i < got.size(); ++i) {
          bad_flat += bits(flat[i]) != bits(flat_want[i]);
          plane_moved += bits(flat[i]) != bits(got[i]);
        }
        EXPECT_EQ(bad_flat, 0u);
      }
      // The last slices are absent: a pass that reads them answers coarsely and says so.
      const StackTime t = stack_time(kSlices, time);
      if (s.map.slices_resident(t.a, t.b)) {
        EXPECT_EQ(fs.holes, 0u);
      }
      if (t.b == kSlices - 1) {
        EXPECT_GT(fs.holes, 0u);
      }
      // A sample's time, one tap: that slice alone, 0 or 1, where the footprint stays within
      // a texel. The ground frame's oblique map stretches this sloped G-buffer's pixels
      // over more texels (u, v shear with height), so its footprint blends two levels.
      // A receiver on a surface lies in its texel's own interval, where the lossless
      // contract allows either answer, and the two levels a footprint near a level
      // boundary blends may answer it differently (a few pixels: at most 1 in 1000).
      // (One receiver depth: the receiver plane's least depth over a coarse texel lies
      // further in front than over a fine one, so its two levels differ more often.)
      if (kernel == 1 && t.a == t.b && frame == "ortho") {
        size_t blended = 0;
        for (float v : flat_want) blended += v != 0.0f && v != 1.0f;
        EXPECT_LE(blended, want.size() / 1000) << blended << " of " << want.size();
      }
    }
  EXPECT_GT(lit, 1000u);
  EXPECT_GT(shadow, 1000u);
  EXPECT_GT(between, 100u);
  // The ground frame's depth is the height above the ground plane: these receivers' normals
  // (up) give it zero slopes, so the plane moves nothing there; the ortho sun's it must.
  if (frame == "ortho") {
    EXPECT_GT(plane_moved, 0u) << "the receiver plane changed no answer: its path tests nothing";
  }
  std::printf("%s: %zu answers moved by the receiver plane\n", frame.c_str(), plane_moved);
  EXPECT_EQ(g.stats().validation_messages, 0u);
  }
}

TEST(GpuStack, ShadowPassFeedbackStreamsTheCellsItNeedsUntilNoHoleIsLeft) {
  // The orthographic frame: its square is wide enough that this G-buffer leaves some of
  // slices 0-1's cells untouched (the ground frame's tighter square puts it over every cell).
  ServedStack s = serve_stack("gpu_stack_feedback", "ortho");
  GpuMap g(s.map, gputest::options());
  const GBuffer gb;
  std::vector<float> vis(size_t(gb.width) * gb.height);
  const ShadowPassInput in = gb.input(0.5, 3);  // slices 4 and 5
  const FrameStats first = g.wait(g.submit_shadow_pass(in), vis);
  EXPECT_GT(first.holes, 0u);
  EXPECT_GT(first.feedback_tiles, 0u);
  EXPECT_EQ(first.requested, first.feedback_tiles);
  const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
  const uint32_t sw = grid.geo.k - grid.geo.w_bits(grid.skip_level);  // slices per cell: 2^sw
  for (const GpuMap::FeedbackTile& t : g.last_feedback()) {
    uint64_t cell = 0;
    ASSERT_TRUE(grid.cell_of(t.tile, cell));
    const uint64_t cw = cell >> (2 * grid.geo.xy_bits(grid.skip_level));
    EXPECT_TRUE((cw << sw) <= 5 && 4 <= ((cw + 1) << sw) - 1) << "cell " << cell << " holds no slice 4 or 5";
  }
  FrameStats fs = first;
  for (int frame = 0; frame < 2000 && fs.holes > 0; ++frame) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    fs = g.wait(g.submit_shadow_pass(in), vis);
  }
  EXPECT_EQ(fs.holes, 0u);
  EXPECT_GT(g.stats().slots_uploaded, 0u);
  EXPECT_FALSE(s.map.slices_resident(0, 1));  // nothing asked for slices 0 and 1
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// One tap at the finest level (no neighbour footprint, footprint half a texel): the CPU
// twin's soft value against the client's own soft lookup (Map::soft_visibility, double
// light transform) at the same receivers (moved along the normal as the pass moves them),
// inside the box every slice's light covers (the pass's one-depth rule, as
// soft_visibility's single tap). They can differ only where the float32
// transform and the double one pick different texels or round the receiver's depth
// apart (none of the 1515 receivers here did, for the sun path and the area light).
void expect_twin_agrees_with_client_soft(const client::Map& map, const GBuffer& gb) {
  ShadowPassInput in = gb.input(0, 1, true);
  in.neighbour_footprint = false;
  in.footprint = 0.5f;
  in.receiver_plane = false;  // the client's soft_visibility: one receiver depth
  std::vector<float> twin(size_t(gb.width) * gb.height);
  stack_shadow_pass_reference(map, in, twin);
  size_t compared = 0, same = 0, fractional = 0;
  for (size_t p = 0; p < twin.size(); ++p) {
    const float* q = gb.pos.data() + 4 * p;
    if (q[3] == 0.0f || std::fabs(q[0]) > 8.0f || std::fabs(q[2]) > 8.0f) continue;
    const client::WorldPoint w{double(q[0]), double(q[1] + gb.nrm[4 * p + 1] * in.normal_offset), double(q[2])};
    ++compared;
    same += twin[p] == map.soft_visibility(w);
    fractional += twin[p] > 0.0f && twin[p] < 1.0f;
  }
  EXPECT_GT(compared, 1000u);
  EXPECT_GT(fractional, 100u);
  EXPECT_GE(double(same), 0.99 * double(compared)) << same << " of " << compared;
}

// The soft pass (ShadowPassInput::soft: the average over all N = 10 slices, each in its
// own light space, sum in slice order then / N) equals its CPU twin on every pixel, with
// the later slices' cells absent (their level-K values, fed back) and once all are
// resident; the twin agrees with the client's own soft lookup (Map::soft_visibility) on
// nearly every pixel (they differ only where the float light transform and the double
// one pick different texels, or outside the light box, which the pass calls lit).
TEST(GpuStack, SoftPassEqualsItsCpuTwinAndTheClientsSoftLookup) {
  std::array<size_t, 3> tally{};
  FrameStats fs;
  const GBuffer gb;
  {
    ServedStack s = serve_frozen("gpu_stack_soft_half", "ortho", kSlices / 2 - 1);
    GpuMap g(s.map, gputest::options());
    for (uint32_t kernel : {1u, 3u, 5u}) {
      SCOPED_TRACE("kernel " + std::to_string(kernel));
      EXPECT_EQ(pass_against_twin(g, s.map, gb.input(0, kernel, true), fs, tally), 0u);
      EXPECT_GT(fs.holes, 0u);  // slices 5..9 absent: their level-K values, fed back
      EXPECT_GT(fs.feedback_tiles, 0u);
      if (kernel == 1) {
        EXPECT_EQ(fs.requested, fs.feedback_tiles);  // queued on the Map
      }
      // Every cell fed back holds absent slices (5..9) and is not resident.
      const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
      const uint32_t sw = grid.geo.k - grid.geo.w_bits(grid.skip_level);
      for (const GpuMap::FeedbackTile& t : g.last_feedback()) {
        uint64_t cell = 0;
        ASSERT_TRUE(grid.cell_of(t.tile, cell));
        const uint64_t cw = cell >> (2 * grid.geo.xy_bits(grid.skip_level));
        EXPECT_GE(((cw + 1) << sw) - 1, kSlices / 2) << "cell " << cell;
        EXPECT_FALSE(cell_resident(s.map, t.tile));
      }
    }
    EXPECT_EQ(g.stats().validation_messages, 0u);
  }
  EXPECT_GT(tally[0], 500u);
  EXPECT_GT(tally[2], 500u);  // a soft shadow: most shadowed pixels see some samples
  ServedStack s = serve_frozen("gpu_stack_soft_all", "ortho", kSlices - 1);
  GpuMap g(s.map, gputest::options());
  EXPECT_EQ(pass_against_twin(g, s.map, gb.input(0, 3, true), fs, tally), 0u);
  EXPECT_EQ(fs.holes, 0u);
  EXPECT_EQ(g.stats().validation_messages, 0u);
  expect_twin_agrees_with_client_soft(s.map, gb);
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// The passes resume each tile walk from the previous walk's path (st_oct_depth_resumed,
// MH §3.3's last-sample cache carried over w). A ground-frame sun path gives a receiver on
// the ground plane the same texel in every slice, so its soft pass walks differ in w only
// (the resumed level is set by w's bits); above the ground the texel moves with the slice
// (set by x, y's bits too). Slices 7..9 absent: walks in resident tiles interleave with
// absent cells. With one tap and 3 x 3 PCF the pass equals its CPU twin on every pixel,
// and so it does with resume_walks off (every walk from the tile's root).
// The reference plane is at y = 1.5, where the plane's depth (about 0.7) lies between the
// sliding boxes' (0.2-0.55) and the stack's ground (0.8), so the boxes' shadows slide over
// it.
TEST(GpuStack, SoftPassResumedWalksOnAndAboveTheGroundEqualTheCpuTwin) {
  GBuffer gb;
  gb.ground_checkers(1.5f);
  ServedStack s = serve_frozen("gpu_stack_soft_ground",
                               "sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(kSlices) +
                                   ",frame=ground,ground=1.5",
                               kSlices - 4);
  GpuMap g(s.map, gputest::options());
  std::array<size_t, 3> tally{}, ground{};  // classes of all pixels, of the ground's
  FrameStats fs;
  for (const auto& [kernel, resume] : {std::pair{1u, true}, std::pair{3u, true}, std::pair{3u, false}}) {
    SCOPED_TRACE("kernel " + std::to_string(kernel) + (resume ? "" : ", walks from the root"));
    ShadowPassInput in = gb.input(0, kernel, true);
    in.resume_walks = resume;
    in.normal_offset = 0.0f;  // the ground pixels stay on the plane
    EXPECT_EQ(pass_against_twin(g, s.map, in, fs, tally), 0u);
    EXPECT_GT(fs.holes, 0u);
    std::vector<float> twin(size_t(gb.width) * gb.height);
    stack_shadow_pass_reference(s.map, in, twin);
    for (size_t p = 0; p < twin.size(); ++p)
      if (gb.pos[4 * p + 3] != 0.0f && gb.pos[4 * p + 1] == 1.5f)
        ++ground[twin[p] == 1.0f ? 0 : twin[p] == 0.0f ? 1 : 2];
  }
  EXPECT_GT(tally[0], 500u);
  EXPECT_GT(tally[2], 1000u);
  EXPECT_GT(ground[2], 500u);  // on the ground, shadows slide over a fixed texel with w
  EXPECT_EQ(g.stats().validation_messages, 0u);
}

// An area light's stack (perspective samples: frame=window, LightKind::spot_window, and
// frame=translate, LightKind::spot): the time pass at samples and between, and the soft
// pass, equal their CPU twins on every pixel, with absent cells (window) and without
// (translate).
TEST(GpuStack, AreaLightStackPassesEqualTheirCpuTwins) {
  for (const std::string frame : {"window", "translate"}) {
    SCOPED_TRACE("frame=" + frame);
    std::array<size_t, 3> tally{};
    FrameStats fs;
    const GBuffer gb;
    {
      // The window frame with the later slices absent, the translate frame all resident.
      const uint32_t last = frame == "window" ? kSlices / 2 - 1 : kSlices - 1;
      ServedStack s = serve_frozen("gpu_stack_area_" + frame + std::to_string(last), area_spec(frame), last);
      ASSERT_EQ(client::MapAccess::remote(s.map).stack_grid()->light_kind,
                frame == "window" ? LightKind::spot_window : LightKind::spot);
      GpuMap g(s.map, gputest::options());
      for (double time : {0.0, 0.37, 0.8}) {
        SCOPED_TRACE("time " + std::to_string(time) + " last " + std::to_string(last));
        EXPECT_EQ(pass_against_twin(g, s.map, gb.input(time, 3), fs, tally), 0u);
        if (stack_time(kSlices, time).b > last) {
          EXPECT_GT(fs.holes, 0u);
        } else {
          EXPECT_EQ(fs.holes, 0u);
        }
      }
      {
        SCOPED_TRACE("soft, last " + std::to_string(last));
        EXPECT_EQ(pass_against_twin(g, s.map, gb.input(0, 3, true), fs, tally), 0u);
        EXPECT_EQ(fs.holes > 0, last < kSlices - 1);
      }
      if (last == kSlices - 1) expect_twin_agrees_with_client_soft(s.map, gb);
      EXPECT_EQ(g.stats().validation_messages, 0u);
    }
    EXPECT_GT(tally[0], 1000u);
    EXPECT_GT(tally[1], 100u);
    EXPECT_GT(tally[2], 300u);
  }
}


// Engine mode on stack maps (a sun path's ground frame, its cells split below K, and an
// area light's perspective samples): the pass over the engine's images, at sample times,
// between them and soft, equals the CPU twin bit for bit; the light spaces come from the
// GPU-resident stack block.
TEST(GpuStack, EngineModePassesOverTheEnginesImagesEqualTheCpuTwin) {
  for (const std::string& spec : {std::string("ground"), area_spec("window")}) {
    SCOPED_TRACE(spec);
    const bool split = spec == "ground";
    ServedStack s = serve_frozen(split ? "gpu_stack_engine_sun" : "gpu_stack_engine_area", spec, kSlices / 2,
                                 StackSource{nullptr, std::nullopt, split ? 96u : 512u, StackCells::octree, split});
    ASSERT_EQ(client::MapAccess::remote(s.map).stack_grid()->split(), split);
    const GBuffer gb;
    enginetest::TestEngine e(2);
    enginetest::Targets t(e, gb.width, gb.height, gb.pos, gb.nrm, 2);
    GpuMap g(s.map, e.engine_device());
    uint64_t frame = 0;
    size_t between = 0;
    for (const double time : {0.0, 0.43, 1.0, -1.0}) {  // -1: soft
      SCOPED_TRACE(time);
      const ShadowPassInput in = gb.input(std::max(time, 0.0), 3, time < 0);
      ShadowPassSettings set;
      set.kernel = in.kernel;
      set.normal_offset = in.normal_offset;
      set.neighbour_footprint = in.neighbour_footprint;
      set.footprint = in.footprint;
      set.time = in.time;
      set.soft = in.soft;
      enginetest::run_frame(e, g, t, ++frame, set);
      g.retire(e.finish());
      const std::vector<float> got = t.read(frame);
      std::vector<float> want(got.size());
      stack_shadow_pass_reference(s.map, in, want);
      size_t bad = 0;
      for (size_t i = 0; i < got.size(); ++i) {
        if (bits(got[i]) != bits(want[i]) && bad++ == 0)
          ADD_FAILURE() << "pixel " << i << ": engine pass " << got[i] << ", cpu twin " << want[i];
        between += want[i] > 0.0f && want[i] < 1.0f;
      }
      EXPECT_EQ(bad, 0u);
    }
    EXPECT_GT(between, 100u);
    EXPECT_EQ(e.messages(), 0u) << e.first_message();
  }
}

// The forms of a served stack's tiles: [octree tiles, per-slice tiles, their slices that are
// DAG-MH tiles, MMH tiles, constants] (stack_slices.hpp's layout, read here by hand).
std::array<size_t, 6> tile_forms(const ServedStack& s) {
  std::array<size_t, 6> f{};
  auto u32 = [](const std::vector<uint8_t>& b, size_t at) {
    uint32_t v;
    std::memcpy(&v, b.data() + at, 4);
    return v;
  };
  for (const std::vector<uint8_t>& t : s.tile_bytes) {
    if (!is_slice_tiles(t)) {
      ++f[0];
      continue;
    }
    ++f[1];
    for (uint32_t w = 0; w < (1u << t[7]); ++w) {
      const uint32_t off = u32(t, kSliceTilesHeaderBytes + kSliceTilesEntryBytes * w);
      ++f[off == 0 ? 4 : u32(t, off) == 0x4D4D5453u ? 3 : u32(t, off) == 0x4E505453u ? 5 : 2];  // "STMM": MMH, "STPN": planes
    }
  }
  return f;
}

// sliding_stack with its lower half incoherent across w: on the right a slope whose height
// changes with every slice, on the left a pattern that shifts with w; the builder's default
// then stores cells of both forms (the octree for the coherent top, per-slice tiles below).
IntervalStack mixed_stack(uint32_t level, uint32_t slices) {
  IntervalStack s = sliding_stack(level, slices);
  const uint64_t side = s.side();
  for (uint32_t w = 0; w < slices; ++w)
    for (uint64_t y = side / 2; y < side; ++y)
      for (uint64_t x = 0; x < side; ++x) {
        const float slope = 0.3f + 0.004f * float(x) + 0.003f * float(y) + 0.011f * float(w);
        const float pattern = 0.3f + 0.1f * float(((x * 7 + w * 13) ^ (y * 3)) % 5);
        s.at(x, y, w) = x >= side / 2 ? Interval{slope, slope} : Interval{pattern, pattern + 0.01f};
      }
  return s;
}

// Per-slice cells (tiles/core/stack_slices.hpp): each cell its slices' own DAG-MH or MMH
// tiles or constants (every cell, under a sun path's ground frame), and the smaller form's
// mix of those and octree cells (mixed_stack, under an area light's windowed spots) with a
// tile bound that splits cells below K (split cells, grid version 2: st_stack_depth walks
// down them as StackGrid::cell_at). With the later slices absent: every texel of every level
// of every slice equals the CPU's (Map::slice_depth), the time pass at samples and between
// and the soft pass equal their CPU twins on every pixel, with and without resumed walks
// (st_stack.glsl resumes octree walks only).
TEST(GpuStack, PerSliceCellsAnswerBitExactlyLikeTheCpu) {
  const uint32_t level = looptest::small_scale() ? 5 : 6;
  const IntervalStack sliding = sliding_stack(level, kSlices), mixed = mixed_stack(level, kSlices);
  // Level 6 for the plane slices at every scale: at level 5 the stack build keeps every
  // slice's plain form (slices that small deflate to a few bytes; no plane fit pays).
  const IntervalStack planar = planar_stack(6, kSlices);
  // Per-slice cells only; both forms (split); per-slice cells with plane slices.
  for (const int form : {0, 1, 2}) {
    const StackCells cells = form == 1 ? StackCells::smaller : StackCells::slices;
    const bool all = cells == StackCells::slices, planes = form == 2;
    const IntervalStack& is = planes ? planar : all ? sliding : mixed;
    SCOPED_TRACE(planes ? "slices with planes" : all ? "slices" : "smaller");
    const std::string name = planes ? "gpu_stack_slices_planes" : all ? "gpu_stack_slices_all" : "gpu_stack_slices_smaller";
    ServedStack s = serve_frozen(name, all ? "ground" : area_spec("window"), kSlices / 2 - 1,
                                 StackSource{&is, std::nullopt, all ? 4096u : kSplitTileBytes, cells, !all, planes});
    const std::array<size_t, 6> f = tile_forms(s);
    EXPECT_EQ(f[5] > 0, planes) << "plane slices";
    EXPECT_EQ(bool(client::MapAccess::remote(s.map).header().flags & kFeaturePlaneTiles), planes);
    if (planes) {
      EXPECT_EQ(f[0], 0u);
    } else if (all) {
      EXPECT_EQ(f[0], 0u);
      EXPECT_GT(f[2], 0u);  // DAG-MH slices
      EXPECT_GT(f[3], 0u);  // MMH slices
      EXPECT_GT(f[4], 0u);  // constant slices
    } else {
      EXPECT_GT(f[0], 0u);  // both forms in one pack
      EXPECT_GT(f[1], 0u);
    }
    EXPECT_GT(f[2] + f[3] + f[5], 0u);
    ASSERT_TRUE(client::MapAccess::remote(s.map).header().flags & kFeatureStackSliceTiles);
    const StackGrid& grid = *client::MapAccess::remote(s.map).stack_grid();
    EXPECT_EQ(grid.split(), !all);
    if (!all) {
      // Splits two levels down or more (the walk's loop, not one step); the small scale's
      // 32^2 slices split one level.
      uint32_t deepest = 0;
      for (const StackEntry& e : grid.entries) deepest = std::max<uint32_t>(deepest, e.level);
      EXPECT_GE(deepest, grid.skip_level + (looptest::small_scale() ? 1 : 2)) << grid.entries.size() << " entries";
    }
    GpuMap g(s.map, gputest::options());
    const uint32_t n = client::MapAccess::remote(s.map).stack_grid()->geo.n;
    EXPECT_EQ(compare_every_texel(g, s.map, n), "");
    const GBuffer gb;
    std::array<size_t, 3> tally{};
    FrameStats fs;
    for (const bool resume : {true, false})
      for (const double time : {0.0, 0.43, 1.0, -1.0}) {  // -1: soft
        if (planes && (!resume || time == 1.0)) continue;  // the plane slices' reads: every texel and three passes
        SCOPED_TRACE("time " + std::to_string(time) + (resume ? "" : ", walks from the root"));
        ShadowPassInput in = gb.input(std::max(time, 0.0), 3, time < 0);
        in.resume_walks = resume;
        EXPECT_EQ(pass_against_twin(g, s.map, in, fs, tally), 0u);
        if (time == 0.0) {
          EXPECT_EQ(fs.holes, 0u);
        } else if (time == 1.0 || time < 0) {
          EXPECT_GT(fs.holes, 0u);
        }
      }
    EXPECT_GT(tally[0], 1000u);
    EXPECT_GT(tally[1], 100u);
    EXPECT_GT(tally[2], 100u);
    EXPECT_EQ(g.stats().validation_messages, 0u);
  }
}

}  // namespace
}  // namespace st::gpu
