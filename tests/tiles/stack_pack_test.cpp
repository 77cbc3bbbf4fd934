// Stack packs (tiles/PACK.md "Stack packs"): the cut of a stack's octree at a skip level
// in (x, y, w) answers every level of every slice exactly as the uncut octree, tiles stay
// under the byte bound, the pack opens and verifies, lookups equal StackLookup's, absent
// tiles answer the coarser level-K value, and hostile grids are refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/test_tmp.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "scene/scene.hpp"
#include "tiles/encode/mh_octree_encode.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/core/evaluator.hpp"
#include "tiles/core/filter_level.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/receiver_plane.hpp"
#include "tiles/core/stack_lookup.hpp"
#include "tiles/core/stack_map.hpp"

namespace st {
namespace {

Aabb box() {
  Aabb b;
  b.extend({-10, 0, -10});
  b.extend({10, 5, 10});
  return b;
}

LightSet lights(uint32_t n) {
  return LightSet::fit(LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(n)),
                       box());
}

std::string write(const OctHierarchy& h, const LightSet& set, std::optional<uint32_t> k, uint32_t tile_bytes,
                  const std::string& name, StackCut* out = nullptr, bool finished = true) {
  StackCut cut = cut_stack(h, k, tile_bytes);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  StackPackParams p;
  p.tile_bytes = tile_bytes;
  p.build_params = {{"light", cut.grid.spec}};
  p.payloads_only = p.compress_grid = finished;
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/" + name;
  write_stack_pack(path, cut, p);
  if (out) *out = std::move(cut);
  return path;
}

TEST(StackPack, CutAnswersEveryLevelOfEverySliceLikeTheOctree) {
  struct Case {
    IntervalStack s;
    std::optional<uint32_t> k;
    uint32_t tile_bytes;
  };
  const Case cases[] = {
      {stacks::coherent_stack(5, 12, 3), std::nullopt, 64 * 1024},  // n > k, default K
      {stacks::coherent_stack(5, 12, 4), 1, 256},                   // bound forces a deeper K
      {stacks::random_stack(2, 40, 5), std::nullopt, 1024},         // k > n
      {stacks::random_stack(3, 1, 6), 0, 64 * 1024},                // one slice, one cell
  };
  int i = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(i);
    const OctHierarchy h = build_octree(c.s);
    const LightSet set = lights(c.s.slices);
    StackCut cut;
    const std::string path = write(h, set, c.k, c.tile_bytes, "stack" + std::to_string(i++) + ".pack", &cut);
    EXPECT_LE(cut.max_tile_bytes, c.tile_bytes);
    if (c.k) {
      EXPECT_GE(cut.grid.skip_level, *c.k);
    }
    auto reader = PackReader::open(path);
    ASSERT_NE(reader->stack(), nullptr);
    EXPECT_TRUE(reader->header().flags & kFeatureStack);
    EXPECT_EQ(reader->stack()->slices, c.s.slices);
    EXPECT_EQ(reader->stack()->spec, set.spec.to_string());
    EXPECT_NO_THROW(reader->verify());
    EXPECT_NO_THROW(reader->check_depth_range());
    const ResidentStack rs(*reader);
    EXPECT_EQ(stacks::first_octree_difference(h, rs.map()), "");
    EXPECT_EQ(stacks::first_violation(c.s, [&](uint64_t x, uint64_t y, uint32_t w) {
                return rs.map().depth(x, y, w, c.s.level);
              }),
              "");
    // A 2D reader refuses it in one line rather than walking a grid it does not have.
    EXPECT_THROW(PackEvaluator(std::shared_ptr<const PackReader>(std::move(reader)), 4), Error);
  }
}

TEST(StackPack, LookupsMatchTheWholeOctreeAndAbsentTilesAnswerCoarser) {
  const IntervalStack s = stacks::coherent_stack(5, 9, 7);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(9);
  const std::vector<uint8_t> whole = encode_octree(h);
  const MhOctree tree = MhOctree::open(whole);
  const StackLookup ref(tree, set);
  auto reader = PackReader::open(write(h, set, 2, 512, "lookups.pack"));
  const ResidentStack rs(*reader);
  const StackMap none(*reader->stack());  // no tile: the cells' level-K values
  uint64_t rng = 12345;
  auto next = [&] {
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return double(rng >> 11) / double(1ull << 53);
  };
  const uint32_t K = reader->stack()->skip_level;
  bool any_inexact = false;
  for (int i = 0; i < 500; ++i) {
    const Vec3d p{-10 + 20 * next(), 5 * next(), -10 + 20 * next()};
    const double t = next();
    bool exact = true;
    EXPECT_EQ(rs.map().visibility(p, t, &exact), ref.visibility(p, t));
    EXPECT_EQ(rs.map().soft_visibility(p, &exact), ref.soft_visibility(p));
    EXPECT_TRUE(exact);
    bool none_exact = true;
    (void)none.soft_visibility(p, &none_exact);
    any_inexact |= !none_exact;
    for (uint32_t w = 0; w < 9; w += 4) {
      EXPECT_EQ(rs.map().lit(p, w), ref.lit(p, w));
      uint64_t x, y;
      float d;
      none.texel(p, w, x, y, d);
      const moct::Geometry& g = h.geo;
      const uint32_t sx = g.n - g.xy_bits(K);
      EXPECT_EQ(none.depth(x, y, w, g.n), h.depth_at(K, x >> sx, y >> sx, w >> (g.k - g.w_bits(K))));
    }
  }
  EXPECT_TRUE(any_inexact);
}

TEST(StackPack, GridLayoutIsPinned) {
  // Two 2x2 slices (n = 1, k = 1), cut at K = 1: one coarse value, 8 entries.
  IntervalStack s{1, 2, std::vector<Interval>(8, Interval{0.5f, 0.5f})};
  s.at(0, 0, 0) = {0.25f, 0.25f};
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(2);
  StackCut cut = cut_stack(h, 1, 1024);
  cut.grid.light_kind = set.samples[0].kind();  // a sun path's ground frame
  cut.grid.lights = {set.samples[0].to_array(), set.samples[1].to_array()};
  cut.grid.spec = "abcde";
  const std::vector<uint8_t> b = cut.grid.serialize();
  ASSERT_EQ(b.size(), StackGrid::serialized_size(h.geo, 2, 1, 5));
  ASSERT_EQ(b.size(), 24u + 288 + 8 + 4 + 64);
  EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "STSG");
  EXPECT_EQ(b[4], 1);
  EXPECT_EQ(b[8], 1);   // xy_level
  EXPECT_EQ(b[9], 1);   // w_level
  EXPECT_EQ(b[10], 1);  // skip level
  EXPECT_EQ(b[11], 2);  // sun_ground
  EXPECT_EQ(b[12], 2);  // slices
  EXPECT_EQ(b[16], 5);  // spec size
  double d;
  std::memcpy(&d, b.data() + 24 + 144, 8);
  EXPECT_EQ(d, set.samples[1].to_array()[0]);
  EXPECT_EQ(std::string(b.begin() + 312, b.begin() + 317), "abcde");
  EXPECT_EQ(b[317] | b[318] | b[319], 0);
  float v;
  std::memcpy(&v, b.data() + 320, 4);
  EXPECT_EQ(v, 0.5f);  // level 0
  std::memcpy(&v, b.data() + 324, 4);  // entry (0, 0, 0): the leaf 0.25
  EXPECT_EQ(v, 0.25f);
  std::memcpy(&v, b.data() + 324 + 8 * 7, 4);  // entry (1, 1, 1)
  EXPECT_EQ(v, 0.5f);
  EXPECT_EQ(b[324 + 4], 0);  // constant: K is the finest level
  EXPECT_EQ(StackGrid::parse(b, "t").entries, cut.grid.entries);
}

TEST(StackPack, HostileGridsAndTilesAreRefused) {
  const IntervalStack s = stacks::random_stack(2, 3, 9);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(3);
  StackCut cut;
  const std::string path = write(h, set, 1, 1024, "hostile.pack", &cut);
  const std::vector<uint8_t> grid = cut.grid.serialize();
  for (size_t n = 0; n < grid.size(); ++n)
    EXPECT_THROW(StackGrid::parse(std::span(grid).first(n), "t"), FormatError) << n;
  for (size_t i = 0; i < grid.size(); i += 3) {
    std::vector<uint8_t> bad = grid;
    bad[i] ^= 0x5A;
    try {
      const StackGrid g = StackGrid::parse(bad, "t");
      EXPECT_EQ(g.entries.size(), g.cells(g.skip_level));  // what parses is consistent
    } catch (const FormatError&) {
    }
  }
  // Any flipped byte of the file, in both layouts (payloads only with a compact index and
  // a compressed grid, the default; journal records, plain index, raw grid): open or
  // verify refuses it (CRCs, then the octree check).
  for (const bool finished : {true, false}) {
    SCOPED_TRACE(finished ? "payloads only" : "journal");
    std::ifstream f(finished ? path : write(h, set, 1, 1024, "hostile_journal.pack", nullptr, false), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(f)), {});
    for (size_t i = 0; i < bytes.size(); i += 7) {
      std::vector<uint8_t> bad = bytes;
      bad[i] ^= 0x10;
      EXPECT_THROW(
          {
            auto r = PackReader::open_memory(bad, "bad");
            r->verify();
          },
          FormatError)
          << "byte " << i;
    }
  }
}

// The finished layout (StackPackParams payloads_only, compress_grid; the 2D packs' own, tiles/
// PACK.md): each on or off, the pack opens, verifies and reads the same grid, tiles and
// answers; on, it is smaller (no 32-byte journal record and 32-byte index entry per tile, the
// grid deflated). A compressed stack grid that claims more than a stack grid can hold is
// refused in one line before anything is inflated.
TEST(StackPack, FinishedLayoutReadsTheSameInFewerBytes) {
  const IntervalStack s = stacks::coherent_stack(5, 12, 3);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(s.slices);
  StackCut cut = cut_stack(h, std::nullopt, 2048);
  ASSERT_GT(cut.tiles.size(), 8u);
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  uint64_t sizes[2][2] = {};
  for (const bool payloads_only : {false, true})
    for (const bool compress_grid : {false, true}) {
      SCOPED_TRACE(std::to_string(payloads_only) + std::to_string(compress_grid));
      StackPackParams p;
      p.tile_bytes = 2048;
      p.payloads_only = payloads_only;
      p.compress_grid = compress_grid;
      const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/finished.pack";
      sizes[payloads_only][compress_grid] = write_stack_pack(path, cut, p);
      EXPECT_EQ(sizes[payloads_only][compress_grid], std::filesystem::file_size(path));
      auto reader = PackReader::open(path);
      ASSERT_NE(reader->stack(), nullptr);
      EXPECT_EQ(bool(reader->header().flags & kFeaturePayloadsOnly), payloads_only);
      EXPECT_EQ(bool(reader->header().flags & kFeatureCompressedGrid), compress_grid);
      EXPECT_EQ(reader->stack()->serialize(), cut.grid.serialize());
      ASSERT_EQ(reader->tiles().size(), cut.tiles.size());
      for (const auto& [cell, raw] : cut.tiles) EXPECT_EQ(reader->read_raw(cut.grid.tile_id(cell)), raw) << cell;
      EXPECT_NO_THROW(reader->verify());
      EXPECT_NO_THROW(reader->check_depth_range());
      const ResidentStack rs(*reader);
      EXPECT_EQ(stacks::first_octree_difference(h, rs.map()), "");
    }
  EXPECT_LT(sizes[1][0], sizes[0][0]);
  EXPECT_LT(sizes[0][1], sizes[0][0]);
  EXPECT_LT(sizes[1][1], sizes[1][0]);
  EXPECT_LE(sizes[1][1] + 56 * cut.tiles.size(), sizes[0][0]);  // 64 bytes a tile less the compact index's

  // The compressed grid's inflated size past kStackMaxGridBytes, CRCs made good: refused.
  const std::string path = std::string(SHADOWTILE_TEST_TMP) + "/finished.pack";
  std::vector<uint8_t> file;
  {
    std::ifstream f(path, std::ios::binary);
    file.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  PackHeader head = PackHeader::parse(std::span<const uint8_t>(file.data(), kPackHeaderBytes), "finished");
  const uint32_t claim = uint32_t(kStackMaxGridBytes + 1);
  std::memcpy(file.data() + head.grid_offset + 4, &claim, 4);
  head.grid_crc = crc32_of(std::span<const uint8_t>(file.data() + head.grid_offset, head.grid_size));
  const auto hb = head.serialize();
  std::memcpy(file.data(), hb.data(), hb.size());
  try {
    PackReader::open_memory(file, "claims");
    ADD_FAILURE() << "a stack grid claiming " << claim << " inflated bytes opened";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("inflated size"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace st

namespace st {
namespace {

// PCF and the footprint level on stacks (StackMap::filtered and the _filtered forms): the
// single tap equals lit bit for bit; a kernel equals its taps counted through depth(); a
// footprint picks filter_levels' two levels and blends them; the time blend and the soft
// average are taken of those answers.
TEST(StackPack, PcfAndFootprintLevelAsIn2D) {
  const IntervalStack s = stacks::coherent_stack(5, 6, 9);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(s.slices);
  auto reader = PackReader::open(write(h, set, std::nullopt, 1024, "filtered.pack"));
  const ResidentStack rs(*reader);
  const StackMap& m = rs.map();
  const uint32_t n = m.xy_level();
  uint64_t rng = 777;
  auto next = [&] {
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return double(rng >> 11) / double(1ull << 53);
  };
  uint32_t partial = 0;
  for (int i = 0; i < 300; ++i) {
    const Vec3d p{-10 + 20 * next(), 5 * next(), -10 + 20 * next()};
    const uint32_t w = uint32_t(next() * s.slices);
    const double t = next();
    ASSERT_EQ(m.filtered(p, w, 0, 0), m.lit(p, w) ? 1.0f : 0.0f);
    ASSERT_EQ(m.visibility_filtered(p, t, 0, 0), m.visibility(p, t));
    ASSERT_EQ(m.soft_visibility_filtered(p, 0, 0), m.soft_visibility(p));
    // A 3x3 kernel: its taps, clamped to the slice, counted through depth().
    uint64_t x, y;
    float d;
    m.texel(p, w, x, y, d);
    uint32_t lit = 0;
    for (uint32_t j = 0; j < 3; ++j)
      for (uint32_t k = 0; k < 3; ++k)
        lit += d <= m.depth(pcf_tap(x, k, 3, uint64_t(1) << n), pcf_tap(y, j, 3, uint64_t(1) << n), w, n);
    const float pcf = m.filtered(p, w, 1, 0);
    ASSERT_EQ(pcf, float(lit) / 9.0f);
    partial += pcf > 0 && pcf < 1;
    // A footprint of about 2.5 finest texels (a sun's texel is extent_uv / 2^n world
    // units): levels n - 1 and n - 2, blended by about 0.25.
    const LightSpace& ls = m.grid().light(w);
    const double texel = ls.extent_uv() / double(uint64_t(1) << n);
    const LightPoint lp = ls.to_light(p);
    auto tap = [&](uint32_t level) {
      const auto tt = LightSpace::texel_of(level, lp.u, lp.v);
      return float(lp.d) <= m.depth(tt[0], tt[1], w, level) ? 1.0f : 0.0f;
    };
    const float fp = float(2.5 * texel);
    const FilterLevels f = filter_levels(n, float(double(fp) / texel));
    ASSERT_EQ(f.fine, n - 1);
    ASSERT_NEAR(f.t, 0.25f, 1e-5f);
    ASSERT_EQ(m.filtered(p, w, 0, fp), filter_blend(tap(n - 1), tap(n - 2), f.t));
    // The whole slice or more: level 0, one tap.
    ASSERT_EQ(m.filtered(p, w, 0, float(1e6 * texel)), tap(0));
    const float v = m.visibility_filtered(p, t, 1, fp);
    ASSERT_TRUE(v >= 0 && v <= 1);
  }
  EXPECT_GT(partial, 0u);  // some kernels straddle a shadow edge
}

// The filtered lookups with the receiver's normal (StackMap::*_on_plane): in each slice the
// 2D rule, the kernel counted by the 2D library's pcf_footprint_plane over that slice
// (receiver_plane_at in the slice's light, the lookup point moved along the normal); the
// time blend and the soft average of those answers; and the plane moves some answers.
TEST(StackPack, ReceiverPlaneLookupsCountEachSliceLikeThe2DPlaneFilter) {
  const IntervalStack s = stacks::coherent_stack(5, 6, 9);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(s.slices);
  auto reader = PackReader::open(write(h, set, std::nullopt, 1024, "filtered_plane.pack"));
  const ResidentStack rs(*reader);
  const StackMap& m = rs.map();
  const uint32_t n = m.xy_level();
  struct SliceEval final : Evaluator {  // slice w of the stack as a 2D map
    const StackMap& map;
    uint32_t w;
    SliceEval(const StackMap& sm, uint32_t slice) : map(sm), w(slice) {}
    uint32_t finest_level() const override { return map.xy_level(); }
    float depth(uint32_t level, uint64_t x, uint64_t y) const override { return map.depth(x, y, w, level); }
  };
  uint64_t rng = 4242;
  auto next = [&] {
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return double(rng >> 11) / double(1ull << 53);
  };
  uint32_t moved = 0, partial = 0;
  for (int i = 0; i < 200; ++i) {
    const Vec3d p{-10 + 20 * next(), 5 * next(), -10 + 20 * next()};
    const Vec3d nrm = normalize(Vec3d{next() - 0.5, 0.3 + next(), next() - 0.5});  // up-ish, tilted any way
    const uint32_t w = uint32_t(next() * s.slices);
    const bool closed = i % 3 == 0;
    const LightSpace& ls = m.grid().light(w);
    const float fp = i % 2 ? float(3 * next() * ls.texel_size(p, n)) : 0.0f;
    const uint32_t side = 1 + 2 * (uint32_t(i) % 3);
    LightPoint lp;
    ReceiverPlane pl;
    float want = 1.0f;
    if (receiver_plane_at(ls, n, p, nrm, closed, lp, pl))
      want = pcf_footprint_plane(SliceEval(m, w), lp.u, lp.v, pl,
                                 fp > 0 ? float(double(fp) / ls.texel_size(p, n)) : 0.0f, side);
    const float got = m.filtered_on_plane(p, nrm, w, side / 2, fp, closed);
    ASSERT_EQ(got, want) << "point " << i;
    partial += got > 0 && got < 1;
    // The same receiver point with one depth for every tap.
    moved += got != m.filtered(ls.to_world(lp.u, lp.v, lp.d), w, side / 2, fp);
    const double t = next();
    const double st = t * double(s.slices - 1);
    const uint32_t a = uint32_t(std::floor(st));
    const float va = m.filtered_on_plane(p, nrm, a, side / 2, fp, closed);
    const float vt = m.visibility_filtered_on_plane(p, nrm, t, side / 2, fp, closed);
    if (a + 1 < s.slices && std::fabs(st - std::nearbyint(st)) > 1e-9) {
      const float f = float(st - double(a));
      ASSERT_EQ(vt, va + f * (m.filtered_on_plane(p, nrm, a + 1, side / 2, fp, closed) - va));
    }
    float sum = 0;
    for (uint32_t k = 0; k < s.slices; ++k) sum += m.filtered_on_plane(p, nrm, k, side / 2, fp, closed);
    ASSERT_EQ(m.soft_visibility_filtered_on_plane(p, nrm, side / 2, fp, closed), sum / float(s.slices));
  }
  EXPECT_GT(partial, 0u);
  EXPECT_GT(moved, 0u) << "the receiver plane changed no answer";
}

}  // namespace
}  // namespace st

namespace st {
namespace {

// The soft lookup's shared walk within a cell equals N separate lit() calls, with every
// tile resident or every other cell's tile absent, at a coarse and at a fine cut.
TEST(StackPack, SoftVisibilitySharedWalkEqualsSeparateLookups) {
  const IntervalStack s = stacks::coherent_stack(5, 13, 3);
  const OctHierarchy h = build_octree(s);
  const LightSet set = lights(13);
  for (uint32_t K : {1u, 3u}) {
    auto reader = PackReader::open(write(h, set, K, 1 << 20, "soft" + std::to_string(K) + ".pack"));
    const StackGrid& grid = *reader->stack();
    std::vector<uint64_t> cells;
    std::vector<std::vector<uint8_t>> bufs;
    for (const TileIndexEntry& e : reader->tiles()) {
      uint64_t cell = 0;
      ASSERT_TRUE(grid.cell_of(e.id, cell));
      cells.push_back(cell);
      bufs.push_back(reader->read_raw(e.id));
    }
    std::vector<MhOctree> trees;
    for (const auto& b : bufs) trees.push_back(MhOctree::open(b));
    auto source = [&](bool every_other) -> StackMap::TileSource {
      return [&, every_other](const uint64_t* want, uint32_t n, StackTileRef* out) {
        for (uint32_t i = 0; i < n; ++i) {
          const auto it = std::lower_bound(cells.begin(), cells.end(), want[i]);
          const bool absent = it == cells.end() || *it != want[i] || (every_other && (it - cells.begin()) % 2);
          out[i] = absent ? nullptr : &trees[size_t(it - cells.begin())];
        }
      };
    };
    const StackMap full(grid, source(false)), half(grid, source(true));
    uint64_t rng = 99 + K;
    auto next = [&] {
      rng = rng * 6364136223846793005ull + 1442695040888963407ull;
      return double(rng >> 11) / double(1ull << 53);
    };
    std::vector<Vec3d> pts;
    for (int i = 0; i < 300; ++i) {
      const Vec3d p{-10 + 20 * next(), 5 * next(), -10 + 20 * next()};
      pts.push_back(p);
      for (const StackMap* m : {&full, &half}) {
        uint32_t lit = 0;
        bool exact_lit = true, exact_soft = true;
        for (uint32_t w = 0; w < 13; ++w) lit += m->lit(p, w, &exact_lit);
        ASSERT_EQ(m->soft_visibility(p, &exact_soft), float(lit) / 13.0f) << "K " << K << " point " << i;
        ASSERT_EQ(exact_soft, exact_lit);
      }
    }
    // The batched lookup (interleaved walks): the same answers, and inexact where a tile
    // was absent.
    for (const StackMap* m : {&full, &half}) {
      std::vector<float> out(pts.size());
      bool exact = true, exact_single = true;
      m->soft_visibility(pts, out, &exact);
      for (size_t i = 0; i < pts.size(); ++i) ASSERT_EQ(out[i], m->soft_visibility(pts[i], &exact_single)) << "K " << K << " " << i;
      EXPECT_EQ(exact, exact_single);
    }
  }
}

// An area light (window frame, jittered) over the hairball, traced: the soft lookups
// through the pack (PackReader, ResidentStack's StackMap: what a local client map reads)
// answer as StackLookup on the in-memory octree, single and batched, with 37 samples (a
// full run of the batched transforms and a short one).
TEST(StackPack, SoftLookupsUnderAnAreaLightMatchTheInMemoryOctree) {
  const char* scene = "procedural:hairball,count=12";
  const LightSet set = stacks::fitted_set(scene, "area:pos=2,14,1,target=0,0,0,size=3,3,samples=37,jitter=0.5");
  const IntervalStack s = stacks::traced_stack(scene, set, stacks::small_scale() ? 5 : 6);
  const OctHierarchy h = build_octree(s);
  const std::vector<uint8_t> bytes = encode_octree(h);
  const MhOctree tree = MhOctree::open(bytes);
  const StackLookup look(tree, set);
  auto reader = PackReader::open(write(h, set, std::nullopt, 1024, "soft_area.pack"));
  ASSERT_GT(reader->tiles().size(), 4u);
  const ResidentStack local(*reader);
  const StackMap& m = local.map();
  const Aabb b = load_scene(scene).bounds();
  Rng rng(23);
  std::vector<Vec3d> pts;
  uint32_t penumbra = 0;
  for (int i = 0; i < 400; ++i) {
    const Vec3d p{rng.uniform(b.lo.x, b.hi.x), rng.uniform(b.lo.y, b.hi.y), rng.uniform(b.lo.z, b.hi.z)};
    pts.push_back(p);
    bool exact = true;
    const float v = m.soft_visibility(p, &exact);
    ASSERT_EQ(v, look.soft_visibility(p)) << "point " << i;
    ASSERT_EQ(v, look.soft_visibility_independent(p)) << "point " << i;
    ASSERT_TRUE(exact);
    penumbra += v > 0 && v < 1;
  }
  EXPECT_GT(penumbra, 20u);  // the test sees soft shadows, not only lit and umbra
  std::vector<float> out(pts.size()), out_tree(pts.size());
  m.soft_visibility(pts, out);
  look.soft_visibility(pts, out_tree);
  for (size_t i = 0; i < pts.size(); ++i) {
    ASSERT_EQ(out[i], look.soft_visibility(pts[i])) << i;
    ASSERT_EQ(out_tree[i], out[i]) << i;
  }
}

}  // namespace
}  // namespace st
