// A stack pack (tiles/PACK.md "Stack packs") served by the unchanged server: the client's
// Map opens it, streams its octree tiles by id, and once they are resident answers
// time_visibility / soft_visibility / slice_depth exactly as the local pack does; before
// that it answers the coarser level-K values, and its 2D lookups answer lit.
#include <gtest/gtest.h>

#include <cmath>

#include "tests/client/loopback.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/light_set.hpp"
#include "tiles/core/stack_map.hpp"

namespace st {
namespace {

using client::Client;
using client::Map;

// Boxes' shadows sliding slowly with w over a ground at 0.8: coherent slices.
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

// The out-of-core cut of `s` as a StackCut: every cell per slice (tiles/core/stack_slices.hpp),
// or with `split` each cell's smaller form and the overflowing cells split below K.
StackCut blocked_cut(const IntervalStack& s, const std::string& name, uint32_t tile_bytes, bool split) {
  const std::string base = std::string(SHADOWTILE_TEST_TMP) + "/" + name;
  StackSpill spill(base + ".spill", s.level, s.slices, 0);
  const size_t area = size_t(s.side() * s.side());
  for (uint32_t w = 0; w < s.slices; ++w)
    spill.write_rows(w, 0, s.side(), std::span<const Interval>(s.data.data() + w * area, area));
  BlockedStackCut blocked(spill, std::nullopt, tile_bytes, base + ".tiles", nullptr,
                          split ? StackCells::smaller : StackCells::slices, split);
  StackCut cut;
  cut.grid = blocked.grid;
  for (size_t i = 0; i < blocked.tile_count(); ++i) cut.tiles.push_back(blocked.tile(i));
  cut.max_tile_bytes = blocked.max_tile_bytes;
  return cut;
}

// `light_set` gives the slices' transforms (the stack itself is synthetic); `name` the
// pack's file and map name; `per_slice`: every cell as per-slice tiles instead of octrees;
// `split`: cells over a small tile bound split below K (feature stack_split_cells).
void served_stack_answers_like_local(const std::string& light_set, const std::string& name, bool per_slice = false,
                                     bool split = false) {
  const uint32_t slices = 10;
  const IntervalStack s = sliding_stack(looptest::small_scale() ? 5 : 6, slices);
  const uint32_t tile_bytes = per_slice ? 4096 : split ? 96 : 512;
  StackCut cut = per_slice || split ? blocked_cut(s, name, tile_bytes, split)
                                    : cut_stack(build_octree(s), std::nullopt, tile_bytes);
  Aabb box;
  box.extend({-10, 0, -10});
  box.extend({10, 5, 10});
  const LightSet set = LightSet::fit(LightSetSpec::parse(light_set + ",samples=" + std::to_string(slices)), box);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name + ".pack";
  StackPackParams p;
  p.tile_bytes = std::max(tile_bytes, kMinTileBytes);
  write_stack_pack(path, cut, p);
  ASSERT_GT(cut.tiles.size(), 4u);

  const auto reader = PackReader::open(path);
  if (!split) {
    EXPECT_EQ(bool(reader->header().flags & kFeatureStackSliceTiles), per_slice);
  }
  EXPECT_EQ(bool(reader->header().flags & kFeatureStackSplitCells), split);
  const ResidentStack local(*reader);
  auto srv = looptest::start_server({path});
  Client c({"127.0.0.1", srv.port}, looptest::quick_options());
  Map m = c.open(name);
  ASSERT_EQ(m.slices(), slices);

  uint64_t rng = 99;
  auto next = [&] {
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return double(rng >> 11) / double(1ull << 53);
  };
  std::vector<Vec3d> points;
  for (int i = 0; i < 300; ++i) points.push_back({-10 + 20 * next(), 5 * next(), -10 + 20 * next()});
  // While tiles stream (each miss queues its tile), a slice depth is either the coarser
  // level-K value or already the exact one: never missing, never anything else.
  const StackMap coarse(*reader->stack());  // no tile: the cells' level-K values
  const uint32_t n = reader->stack()->geo.n;
  int coarse_answers = 0;
  for (uint64_t y = 0; y < (uint64_t(1) << n); ++y) {
    const float v = m.slice_depth(3, n, y, y), c = coarse.depth(y, y, 3, n), e = local.map().depth(y, y, 3, n);
    EXPECT_TRUE(v == c || v == e) << "texel " << y;
    coarse_answers += v == c && c != e;
  }
  EXPECT_GT(coarse_answers, 0);  // the first lookup of a cell found no tile

  EXPECT_GT(m.request_slices(0, slices - 1, 10), 0u);
  ASSERT_TRUE(looptest::wait_until([&] { return m.slices_resident(0, slices - 1); }));
  for (const Vec3d& q : points) {
    const client::WorldPoint wp{q.x, q.y, q.z};
    const double t = next();
    EXPECT_EQ(m.time_visibility(wp, t), local.map().visibility(q, t));
    EXPECT_EQ(m.soft_visibility(wp), local.map().soft_visibility(q));
    EXPECT_EQ(m.visibility(wp), 1.0f);  // the 2D lookup of a stack map: lit
    // PCF and the footprint level: the local pack's answers; no footprint, no kernel: the
    // single tap.
    const float fp = float(3 * next());
    EXPECT_EQ(m.time_visibility_filtered(wp, t, fp, 3), local.map().visibility_filtered(q, t, 1, fp));
    EXPECT_EQ(m.soft_visibility_filtered(wp, fp, 5), local.map().soft_visibility_filtered(q, 2, fp));
    EXPECT_EQ(m.time_visibility(wp, t, 3), local.map().visibility_filtered(q, t, 1, 0));
    EXPECT_EQ(m.time_visibility_filtered(wp, t, 0), m.time_visibility(wp, t));
    // With the receiver's normal: the local pack's plane lookups.
    const Vec3d nrm = normalize(Vec3d{next() - 0.5, 0.5 + next(), next() - 0.5});
    const client::WorldPoint wn{nrm.x, nrm.y, nrm.z};
    EXPECT_EQ(m.time_visibility_filtered(wp, wn, t, fp, 3), local.map().visibility_filtered_on_plane(q, nrm, t, 1, fp));
    EXPECT_EQ(m.soft_visibility_filtered(wp, wn, fp, 5, true),
              local.map().soft_visibility_filtered_on_plane(q, nrm, 2, fp, true));
    EXPECT_TRUE(std::isnan(m.time_visibility_filtered(wp, wn, t, fp, 2)));  // an even side: NaN
  }
  {  // the batched soft lookup (interleaved walks; PCF: per point)
    std::vector<client::WorldPoint> wps;
    for (const Vec3d& q : points) wps.push_back({q.x, q.y, q.z});
    std::vector<float> out(wps.size()), out_pcf(wps.size());
    m.soft_visibility(wps, out);
    m.soft_visibility(wps, out_pcf, 3);
    for (size_t i = 0; i < wps.size(); ++i) {
      EXPECT_EQ(out[i], local.map().soft_visibility(points[i]));
      EXPECT_EQ(out_pcf[i], m.soft_visibility(wps[i], 3));
    }
  }
  for (uint32_t w = 0; w < slices; w += 3)
    for (uint32_t level = 0; level <= n; level += 2)
      for (uint64_t y = 0; y < (uint64_t(1) << level); y += 3)
        for (uint64_t x = 0; x < (uint64_t(1) << level); x += 3)
          ASSERT_EQ(m.slice_depth(w, level, x, y), local.map().depth(x, y, w, level));
  srv.stop();
}

TEST(StackLoopback, ServedStackAnswersLikeTheLocalPack) {
  served_stack_answers_like_local("sun-path:azimuth=150..200,elevation=40..60", "stackmap");
}

// An area light's samples in the window frame (windowed spots): the client transforms
// each slice's points as the local pack does.
TEST(StackLoopback, ServedWindowFrameAreaStackAnswersLikeTheLocalPack) {
  served_stack_answers_like_local("area:pos=1,30,2,target=0,0,0,size=4,4,jitter=0.5", "stackarea");
}

// Per-slice cells (every cell its slices' own DAG-MH / MMH tiles) stream and answer the same.
TEST(StackLoopback, ServedPerSliceCellsAnswerLikeTheLocalPack) {
  served_stack_answers_like_local("sun-path:azimuth=150..200,elevation=40..60", "stackslices", true);
}

// Split cells (cells over the tile bound answered by their children, stack grid version 2)
// stream, prefetch by slices and answer the same.
TEST(StackLoopback, ServedSplitCellsAnswerLikeTheLocalPack) {
  served_stack_answers_like_local("sun-path:azimuth=150..200,elevation=40..60", "stacksplit", false, true);
}

}  // namespace
}  // namespace st
