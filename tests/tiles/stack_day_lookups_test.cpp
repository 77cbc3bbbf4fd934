// The time-interpolated and soft lookups of a stack pack (StackMap::visibility,
// soft_visibility single and batched) against their per-sample definition, bit for bit:
// each sample's texel from its own light (to_light, texel_of), the stack's depth of that
// texel (StackMap::depth, one slice's 2D lookup), the lit test, then the blend of the two
// nearest samples or the average over all of them. Receivers just in front of and just
// behind every texel's surface of slice 0, for every cell form (octree, per-slice, the
// smaller per cell), a sun path and an area light, and with absent tiles (the cells'
// level-K values answer; `exact` cleared as the definition's lookups clear it). The
// lookups share transforms, tile fetches and walks between samples; none of that may
// change an answer.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>

#include "common/hash.hpp"
#include "tests/test_tmp.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/encode/stack_slices_encode.hpp"

namespace st {
namespace stack_day_lookups_test {

std::string tmp(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/day_" + name; }

// The pack of `s` with cells in form `cells` and the lights of `light_set` (fitted to a
// 20 x 5 x 20 box), written and opened as a client would.
std::unique_ptr<PackReader> build(const IntervalStack& s, StackCells cells, const std::string& light_set,
                                  const std::string& name, std::optional<uint32_t> skip_level) {
  StackSpill spill(tmp(name + ".spill"), s.level, s.slices, 0);
  const size_t area = size_t(s.side() * s.side());
  for (uint32_t w = 0; w < s.slices; ++w)
    spill.write_rows(w, 0, s.side(), std::span<const Interval>(s.data.data() + w * area, area));
  BlockedStackCut cut(spill, skip_level, 64 * 1024, tmp(name + ".tiles"), nullptr, cells);
  const LightSet set = LightSet::fit(LightSetSpec::parse(light_set), Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  write_stack_pack(tmp(name + ".pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, {});
  return PackReader::open(tmp(name + ".pack"));
}

// Slice w's lit test of p by the definition: its own transform, one 2D lookup.
bool lit_by_definition(const StackMap& m, const Vec3d& p, uint32_t w, bool* exact) {
  const LightPoint lp = m.grid().light(w).to_light(p);
  const auto t = LightSpace::texel_of(m.xy_level(), lp.u, lp.v);
  return float(lp.d) <= m.depth(t[0], t[1], w, m.xy_level(), exact);
}

float time_by_definition(const StackMap& m, const Vec3d& p, double time, bool* exact) {
  const uint32_t n = m.slices();
  const double s = std::clamp(time, 0.0, 1.0) * double(n - 1), near = std::nearbyint(s);
  if (std::fabs(s - near) <= 1e-9) return lit_by_definition(m, p, uint32_t(near), exact) ? 1.0f : 0.0f;
  const uint32_t a = uint32_t(std::floor(s));
  const float f = float(s - double(a));
  const float la = lit_by_definition(m, p, a, exact) ? 1.0f : 0.0f;
  const float lb = lit_by_definition(m, p, a + 1, exact) ? 1.0f : 0.0f;
  return la + f * (lb - la);
}

// Receivers 1e-4 in front of and behind the stored surface of every texel of slice 0.
std::vector<Vec3d> receivers(const StackMap& m) {
  const LightSpace ls = m.grid().light(0);
  const uint32_t n = m.xy_level();
  std::vector<Vec3d> pts;
  for (uint64_t y = 0; y < (uint64_t(1) << n); ++y)
    for (uint64_t x = 0; x < (uint64_t(1) << n); ++x) {
      const float v = m.depth(x, y, 0, n);
      if (v >= kLitDepth) continue;
      const LightRay ray = ls.texel_ray(n, x, y);
      // Every fifth texel also far in front and far behind: receivers the slices' bounds
      // decide without a walk (SliceTiles::bounds).
      const bool far = (x + y) % 5 == 0;
      for (double dd : {-1e-4, 1e-4, far ? -1.0 : 0.0, far ? 1.0 : 0.0}) {
        if (dd == 0.0) continue;
        const double d = std::clamp(double(v) + dd, 0.0, 1.0);
        const double t = ls.parallel() ? d : ls.near_plane() + d * (ls.far_plane() - ls.near_plane());
        pts.push_back(ray.origin + ray.dir * t);
      }
    }
  return pts;
}

void expect_like_definition(const StackMap& m, const std::vector<Vec3d>& pts, const std::string& what) {
  SCOPED_TRACE(what);
  const uint32_t n = m.slices();
  std::vector<float> batch(pts.size());
  bool batch_exact = true;
  m.soft_visibility(pts, batch, &batch_exact);
  bool all_exact = true;
  Rng rng(3);
  size_t shadowed = 0, partial = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    bool want_exact = true, got_exact = true;
    uint32_t lit = 0;
    for (uint32_t w = 0; w < n; ++w) lit += lit_by_definition(m, pts[i], w, &want_exact);
    const float soft = float(lit) / float(n);
    shadowed += lit == 0, partial += lit > 0 && lit < n;
    ASSERT_EQ(m.soft_visibility(pts[i], &got_exact), soft) << "point " << i;
    ASSERT_EQ(batch[i], soft) << "point " << i;
    ASSERT_EQ(got_exact, want_exact) << "point " << i;
    all_exact = all_exact && want_exact;
    // Between every pair of neighbouring samples, at each sample, and a random time.
    for (uint32_t k = 0; k + 1 < 2 * n; ++k) {
      const double time = k + 1 == 2 * n - 1 ? rng.uniform() : double(k) / double(2 * (n - 1));
      bool we = true, ge = true;
      ASSERT_EQ(m.visibility(pts[i], time, &ge), time_by_definition(m, pts[i], time, &we)) << "point " << i << " t " << time;
      ASSERT_EQ(ge, we) << "point " << i << " t " << time;
    }
  }
  EXPECT_EQ(batch_exact, all_exact);
  // The receivers reach both answers and the penumbra between them.
  EXPECT_GT(shadowed, 0u);
  EXPECT_GT(partial, 0u);
}

// `mmh_slices` (if given) gains the per-slice tiles' MMH slices (walked by the lookups'
// own MMH steps, stack_map.cpp), so that a caller can check the packs had some.
void expect_every_form_like_definition(const IntervalStack& s, const std::string& light_set, const std::string& what,
                                       std::optional<uint32_t> skip_level = std::nullopt, size_t* mmh_slices = nullptr) {
  for (StackCells form : {StackCells::octree, StackCells::slices, StackCells::smaller}) {
    const std::string name = form == StackCells::octree ? "octree" : form == StackCells::slices ? "slices" : "smaller";
    const auto pack = build(s, form, light_set, name, skip_level);
    const ResidentStack rs(*pack);
    const std::vector<Vec3d> pts = receivers(rs.map());
    // Per-slice tiles' bounds hold every answer of their slice, at every level.
    size_t bounded = 0;
    for (const TileIndexEntry& e : pack->tiles()) {
      const std::vector<uint8_t> raw = pack->read_raw(e.id);
      if (!is_slice_tiles(raw)) continue;
      const SliceTiles t = SliceTiles::open(raw);
      for (uint32_t w = 0; w < t.slices(); ++w) {
        if (mmh_slices) *mmh_slices += t.record(w).kind == SliceTiles::RecordKind::mmh;
        const SliceTiles::Bounds b = t.bounds(w);
        if (std::isnan(b.lo)) continue;
        ++bounded;
        for (uint32_t l = 0; l <= t.xy_level(); ++l)
          for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
            for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) {
              const float v = t.depth(x, y, w, l);
              ASSERT_TRUE(b.lo <= v && v <= b.hi) << what << " slice " << w << " level " << l;
            }
      }
    }
    if (form == StackCells::slices) {
      EXPECT_GT(bounded, 0u) << what;
    }
    expect_like_definition(rs.map(), pts, what + ", " + name + " cells");
    // Every third stored cell absent (streaming): its level-K value answers, exact cleared.
    const StackGrid& g = *pack->stack();
    std::vector<std::vector<uint8_t>> bufs;
    std::vector<uint64_t> cells;
    for (const TileIndexEntry& e : pack->tiles()) {
      uint64_t cell = 0;
      ASSERT_TRUE(g.cell_of(e.id, cell));
      cells.push_back(cell);
      bufs.push_back(pack->read_raw(e.id));
    }
    std::vector<StackTile> tiles;
    for (const auto& b : bufs) tiles.push_back(StackTile::open(b));
    const StackMap holes(g, [&](const uint64_t* want, uint32_t n, StackTileRef* out) {
      for (uint32_t k = 0; k < n; ++k) {
        const size_t i = size_t(std::lower_bound(cells.begin(), cells.end(), want[k]) - cells.begin());
        out[k] = i < cells.size() && cells[i] == want[k] && i % 3 != 1 ? tiles[i].ref() : StackTileRef();
      }
    });
    expect_like_definition(holes, pts, what + ", " + name + " cells, a third absent");
  }
}

TEST(StackDayLookups, TimeAndSoftEqualTheirPerSampleDefinitionOnEveryTexel) {
  size_t mmh = 0;
  const IntervalStack sun = stacks::coherent_stack(6, 9, 11);
  expect_every_form_like_definition(sun, "sun-path:azimuth=150..200,elevation=40..60,samples=9", "sun path, 64^2 x 9",
                                    std::nullopt, &mmh);
  // Slices of 128^2 in one cell (skip level 0): per-slice tiles finer than the DAG-MH
  // skip table's level 6, so their walks descend inner nodes below it (the lockstep rounds).
  expect_every_form_like_definition(stacks::coherent_stack(7, 3, 13),
                                    "sun-path:azimuth=120..220,elevation=30..70,samples=3", "sun path, 128^2 x 3", 0u,
                                    &mmh);
  const IntervalStack rnd = stacks::random_stack(4, 6, 12);
  expect_every_form_like_definition(rnd, "area:pos=0,20,0,target=0,0,0,size=4,4,samples=6,jitter=0.5",
                                    "area light, random 16^2 x 6", std::nullopt, &mmh);
  // Some slices were MMH tiles (the lookups' MMH walks were compared too).
  EXPECT_GT(mmh, 0u);
}

}  // namespace stack_day_lookups_test
}  // namespace st
