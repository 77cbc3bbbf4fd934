// Per-slice stack cells (tiles/core/stack_slices.hpp, MHOCT.md "Per-slice cells"): the
// "STSL" layout pinned, hostile buffers refused in one line, and stack packs built with
// per-slice cells (every cell, or the smaller form per cell) lossless on every texel of
// every slice, equal to the octree pack above the cells, and whose soft lookups (single and
// batched) equal the slices' lit tests.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "common/error.hpp"
#include "common/hash.hpp"
#include "tests/test_tmp.hpp"
#include "tests/tiles/stack_fixtures.hpp"
#include "scene/scene.hpp"
#include "tiles/bake/stack_build.hpp"
#include "tiles/encode/stack_blocked.hpp"
#include "tiles/encode/stack_pack.hpp"
#include "tiles/encode/stack_slices_encode.hpp"
#include "tiles/encode/encode.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/pack_format.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/core/plane_format.hpp"
#include "tiles/core/plane_pack.hpp"
#include "tiles/core/stack_map.hpp"
#include "tiles/core/stack_slices.hpp"

namespace st {
namespace stack_slices_test {

std::string tmp(const std::string& name) { return std::string(SHADOWTILE_TEST_TMP) + "/" + name; }

uint32_t u32(const std::vector<uint8_t>& b, size_t at) {
  uint32_t v;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

IntervalTile square(uint32_t m, float lo, float hi) {
  IntervalTile t;
  t.level = m;
  t.width = t.height = 1u << m;
  t.data.assign(size_t(t.width) * t.height, Interval{lo, hi});
  return t;
}

// Three 2x2 slices in 2^2 entries: slice 0 one value (constant), slices 1 and 2 equal
// (one buffer both name), entry 3 the padding (kLitDepth).
std::vector<uint8_t> example() {
  IntervalTile a = square(1, 0.5f, 0.5f), b = square(1, 0.5f, 0.5f);
  b.data[0] = {0.25f, 0.25f};
  return encode_slice_tiles(std::vector<IntervalTile>{a, b, b}, 1, 2);
}

TEST(StackSlicesFormat, LayoutIsPinned) {
  const std::vector<uint8_t> b = example();
  ASSERT_GE(b.size(), 48u);
  EXPECT_EQ(std::vector<uint8_t>(b.begin(), b.begin() + 8), (std::vector<uint8_t>{'S', 'T', 'S', 'L', 1, 0, 1, 2}));
  EXPECT_EQ(u32(b, 8), b.size());  // byte_size
  EXPECT_EQ(u32(b, 12), 0u);
  // entries at 16 + 8 w: (0, the value's bits) constant, else (offset, size)
  EXPECT_EQ(u32(b, 16), 0u);
  EXPECT_EQ(u32(b, 20), std::bit_cast<uint32_t>(0.5f));
  EXPECT_EQ(u32(b, 24), 48u);  // the first buffer right after the 4 entries
  const uint32_t size = u32(b, 28);
  EXPECT_EQ(u32(b, 32), 48u);  // slice 2 names the same buffer
  EXPECT_EQ(u32(b, 36), size);
  EXPECT_EQ(u32(b, 40), 0u);  // padding slice: kLitDepth
  EXPECT_EQ(u32(b, 44), std::bit_cast<uint32_t>(kLitDepth));
  EXPECT_EQ(b.size(), 48u + ((size + 3) & ~3u));
  const uint32_t magic = u32(b, 48);
  EXPECT_TRUE(magic == 0x484D4744u || magic == 0x4D4D5453u) << "a DAG-MH or MMH buffer";
  const SliceTiles t = SliceTiles::open(b);
  EXPECT_EQ(t.slices(), 4u);
  EXPECT_EQ(t.buffers(), 1u);
  for (uint64_t y = 0; y < 2; ++y)
    for (uint64_t x = 0; x < 2; ++x) {
      EXPECT_EQ(t.depth(x, y, 0, 1), 0.5f);
      EXPECT_EQ(t.depth(x, y, 1, 1), x == 0 && y == 0 ? 0.25f : 0.5f);
      EXPECT_EQ(t.depth(x, y, 2, 1), t.depth(x, y, 1, 1));
      EXPECT_EQ(t.depth(x, y, 3, 1), kLitDepth);
    }
}

TEST(StackSlicesFormat, RefusesHostileBuffers) {
  const std::vector<uint8_t> good = example();
  auto refused = [](std::vector<uint8_t> b, const char* field) {
    try {
      SliceTiles::open(b);
    } catch (const FormatError& e) {
      return std::string(e.what()).find(field) != std::string::npos ? "" : std::string(e.what());
    }
    return std::string("accepted");
  };
  for (size_t n = 0; n < good.size(); ++n) {  // every truncation
    std::vector<uint8_t> b(good.begin(), good.begin() + ptrdiff_t(n));
    if (b.size() >= 12) std::memcpy(b.data() + 8, &n, 4);  // even with a matching byte_size
    EXPECT_NE(refused(b, ""), "accepted") << n << " bytes";
  }
  std::vector<uint8_t> b = good;
  b.push_back(0), b.push_back(0), b.push_back(0), b.push_back(0);
  const uint32_t longer = uint32_t(b.size());
  std::memcpy(b.data() + 8, &longer, 4);
  EXPECT_EQ(refused(b, "after the last buffer"), "");
  b = good, b[4] = 2;
  EXPECT_EQ(refused(b, "version"), "");
  b = good, b[12] = 1;
  EXPECT_EQ(refused(b, "reserved"), "");
  b = good, b[7] = 13;
  EXPECT_EQ(refused(b, "w_level"), "");
  b = good;
  const uint32_t nan = 0x7FC00000u;
  std::memcpy(b.data() + 20, &nan, 4);
  EXPECT_EQ(refused(b, "not finite"), "");
  b = good;
  const uint32_t off = 52;
  std::memcpy(b.data() + 24, &off, 4);
  EXPECT_EQ(refused(b, "the next buffer starts at"), "");
  b = good;
  const uint32_t size = u32(good, 28) + 4;
  std::memcpy(b.data() + 36, &size, 4);
  EXPECT_EQ(refused(b, "size differs"), "");
  b = good, b[48] ^= 0xFF;
  EXPECT_EQ(refused(b, "slice 1's tile"), "");
}

// A hand-made STSL of two slices: slice 0 a 2x2 DAG-MH buffer, slice 1 a 2x2 MMH buffer
// (texel (0, 0) differs from the rest in both), in 2^1 entries.
std::vector<uint8_t> two_kinds(std::vector<uint8_t>& dag, std::vector<uint8_t>& mmh) {
  IntervalTile a = square(1, 0.5f, 0.5f), b = square(1, 0.75f, 0.75f);
  a.data[0] = {0.25f, 0.25f};
  b.data[0] = {0.125f, 0.125f};
  dag = encode_dagmh(build_hierarchy(a));
  mmh = encode_mmh(build_hierarchy(b));
  std::vector<uint8_t> out(32, 0);
  auto put = [&](size_t at, uint32_t v) { std::memcpy(out.data() + at, &v, 4); };
  put(0, kSliceTilesMagic);
  out[4] = 1, out[6] = 1, out[7] = 1;
  put(16, 32), put(20, uint32_t(dag.size()));
  out.insert(out.end(), dag.begin(), dag.end());
  out.resize((out.size() + 3) & ~size_t(3), 0);
  put(24, uint32_t(out.size())), put(28, uint32_t(mmh.size()));
  out.insert(out.end(), mmh.begin(), mmh.end());
  out.resize((out.size() + 3) & ~size_t(3), 0);
  put(8, uint32_t(out.size()));
  return out;
}

TEST(StackSlicesFormat, GroupedLayoutIsPinned) {
  std::vector<uint8_t> dag, mmh;
  const std::vector<uint8_t> stsl = two_kinds(dag, mmh);
  ASSERT_NO_THROW(SliceTiles::open(stsl));
  ASSERT_EQ(u32(dag, 0), 0x484D4744u);  // "DGMH"
  ASSERT_EQ(u32(mmh, 0), 0x4D4D5453u);  // "STMM"
  // The MMH: a root node (word 0) with its value (word 1) and one leaf (word 2).
  const size_t mt = 16 + ((size_t(mmh[6]) + 3) & ~size_t(3));
  ASSERT_EQ(mmh.size(), mt + 12);
  // The DAG-MH: header, no skip table (S = 0), nodes, treelets, chunk infos, multipliers.
  ASSERT_EQ(dag[9], 0);
  const size_t structure = 4 * size_t(u32(dag, 16)) + 12 * size_t(u32(dag, 20)) + 20 * ((size_t(u32(dag, 24)) + 31) / 32);
  std::vector<uint8_t> want(stsl.begin(), stsl.begin() + 32);
  const std::vector<uint8_t> magic{'S', 'T', 'S', 'P'};
  std::copy(magic.begin(), magic.end(), want.begin());
  auto add = [&](const std::vector<uint8_t>& from, size_t at, size_t n) { want.insert(want.end(), from.begin() + ptrdiff_t(at), from.begin() + ptrdiff_t(at + n)); };
  add(dag, 0, 32);                                   // heads: the DAG-MH's header,
  add(mmh, 0, mt);                                   // the MMH's header and shifts
  add(dag, 32, structure);                           // DAG-MH structure
  add(mmh, mt, 4);                                   // MMH node words
  add(dag, 32 + structure, dag.size() - 32 - structure);  // DAG-MH multipliers
  add(mmh, mt + 4, 8);                               // MMH values
  want.resize(stsl.size(), 0);                       // the padding, last
  const std::vector<uint8_t> grouped = group_slice_tiles(stsl);
  EXPECT_EQ(grouped, want);
  std::vector<uint8_t> back = grouped;
  ungroup_slice_tiles(back);
  EXPECT_EQ(back, stsl);
  // What does not group comes back as it was: an octree tile, an STSL of constants only.
  const std::vector<uint8_t> constants = encode_slice_tiles(std::vector<IntervalTile>{square(1, 0.5f, 0.5f)}, 1, 0);
  EXPECT_EQ(group_slice_tiles(constants), constants);
}

TEST(StackSlicesFormat, GroupedCellsRoundTripAndHostileOnesAreRefused) {
  // Random cells (DAG-MH, MMH, constants, shared buffers) come back byte for byte.
  for (uint32_t seed = 1; seed <= 6; ++seed) {
    const IntervalStack s = seed % 2 ? stacks::random_stack(4, 5, seed) : stacks::coherent_stack(4, 5, seed);
    std::vector<IntervalTile> squares(s.slices);
    for (uint32_t w = 0; w < s.slices; ++w) {
      squares[w] = square(s.level, 0, 0);
      for (size_t i = 0; i < squares[w].data.size(); ++i) squares[w].data[i] = s.data[w * squares[w].data.size() + i];
    }
    const std::vector<uint8_t> stsl = encode_slice_tiles(squares, s.level, 3);
    const std::vector<uint8_t> grouped = group_slice_tiles(stsl);
    ASSERT_EQ(grouped.size(), stsl.size());
    std::vector<uint8_t> back = grouped;
    if (is_grouped_slice_tiles(grouped)) ungroup_slice_tiles(back);
    EXPECT_EQ(back, stsl) << seed;
  }
  std::vector<uint8_t> dag, mmh;
  const std::vector<uint8_t> good = group_slice_tiles(two_kinds(dag, mmh));
  ASSERT_TRUE(is_grouped_slice_tiles(good));
  auto refused = [](std::vector<uint8_t> b, const char* field) -> std::string {
    try {
      ungroup_slice_tiles(b);
      SliceTiles::open(b);
    } catch (const FormatError& e) {
      return std::string(e.what()).find(field) != std::string::npos ? "" : std::string(e.what());
    }
    return "accepted";
  };
  for (size_t n = 0; n < good.size(); ++n) {  // every truncation, even with a matching byte_size
    std::vector<uint8_t> b(good.begin(), good.begin() + ptrdiff_t(n));
    if (b.size() >= 12) std::memcpy(b.data() + 8, &n, 4);
    EXPECT_NE(refused(b, ""), "accepted") << n << " bytes";
  }
  std::vector<uint8_t> b = good;
  // Entry 0 one byte shorter (the same padded end): the parts end a byte early and the
  // MMH's last value byte (non-zero) is left over.
  const uint32_t shorter = uint32_t(dag.size() - 1);
  std::memcpy(b.data() + 20, &shorter, 4);
  EXPECT_EQ(refused(b, "tail"), "");
  b = good, b[0] = 'X';
  EXPECT_EQ(refused(b, "magic"), "");
  b = good, b[32] = 'X';  // the first head: neither kind
  EXPECT_EQ(refused(b, "neither"), "");
  b = good, b[32 + 9] = 7;  // a skip level past 6
  EXPECT_EQ(refused(b, "skip level"), "");
  b = good;
  const uint32_t off = 36;
  std::memcpy(b.data() + 16, &off, 4);
  EXPECT_EQ(refused(b, "the next buffer starts at"), "");
  for (size_t i = 0; i < good.size(); ++i)  // any one byte changed: refused or read, never a crash
    for (uint8_t x : {uint8_t(1), uint8_t(0x80), uint8_t(0xFF)}) {
      b = good, b[i] ^= x;
      (void)refused(b, "");
    }
}

// A 16x16 square on a slanted plane (each texel the plane's own decoded depth, exact:
// plane_format.hpp) with a box of wide intervals in one corner: plane blocks over the rest.
IntervalTile planar_square(int64_t slope) {
  IntervalTile t = square(4, 0, 0);
  for (uint32_t y = 0; y < 16; ++y)
    for (uint32_t x = 0; x < 16; ++x) {
      const float v = planes::plane_fixed_to_float(planes::kOne / 2 + slope * x + planes::kOne / 1024 * y);
      t.data[y * 16 + x] = x < 3 && y < 3 ? Interval{0.1f, 0.2f} : Interval{v, v};
    }
  return t;
}

// Plane slices (tiles/core/PLANES.md) in a per-slice cell: the entry names an "STPN" buffer,
// the grouped form holds it whole and packed ("STPL") among the heads and says which
// features that needs, every slice reads back each texel's value, and hostile buffers
// (every truncation, every byte flipped) are refused in one line or read, never a crash.
TEST(StackSlicesFormat, PlaneSlicesArePinnedAndHostileOnesAreRefused) {
  const std::vector<IntervalTile> squares{planar_square(planes::kOne / 512), planar_square(planes::kOne / 256)};
  const PlaneFitOptions fit;
  const std::vector<uint8_t> stsl = encode_slice_tiles(squares, 4, 1, &fit);
  EXPECT_EQ(encode_slice_tiles(squares, 4, 1), encode_slice_tiles(squares, 4, 1, nullptr));
  const SliceTiles t = SliceTiles::open(stsl);
  ASSERT_TRUE(t.has_planes());
  EXPECT_FALSE(SliceTiles::open(encode_slice_tiles(squares, 4, 1)).has_planes());
  // The stack cut's second pass: the cell's plain buffer given, a slice whose plain tile
  // deflates above 80 bytes is fitted as without it, a smaller one kept as it was; the
  // plain buffer of another shape is refused.
  const std::vector<uint8_t> plain = encode_slice_tiles(squares, 4, 1);
  const std::vector<uint8_t> reused = encode_slice_tiles(squares, 4, 1, &fit, plain);
  for (uint32_t w = 0; w < 2; ++w) {
    const std::span<const uint8_t> p(plain.data() + u32(plain, 16 + 8 * w), u32(plain, 20 + 8 * w));
    const std::span<const uint8_t> r(reused.data() + u32(reused, 16 + 8 * w), u32(reused, 20 + 8 * w));
    const std::span<const uint8_t> f(stsl.data() + u32(stsl, 16 + 8 * w), u32(stsl, 20 + 8 * w));
    const bool fitted = zlib_compress(p, 6).size() > 80;
    EXPECT_TRUE(std::ranges::equal(r, fitted ? f : p)) << "slice " << w << (fitted ? " fitted" : " kept");
  }
  EXPECT_THROW(encode_slice_tiles(squares, 4, 2, &fit, plain), Error);
  ASSERT_EQ(u32(stsl, 16), 32u);  // slice 0's buffer right after the 2 entries
  const uint32_t size0 = u32(stsl, 20);
  EXPECT_EQ(u32(stsl, 32), 0x4E505453u);  // "STPN"
  for (uint32_t w = 0; w < 2; ++w)
    for (uint32_t y = 0; y < 16; ++y)
      for (uint32_t x = 0; x < 16; ++x) {
        const Interval iv = squares[w].data[y * 16 + x];
        const float v = t.depth(x, y, w, 4);
        ASSERT_TRUE(iv.lo <= v && v <= iv.hi) << x << " " << y << " " << w;
      }
  // Grouped: the plane buffer whole, in its packed form, where its head would be.
  const std::vector<uint8_t> grouped = group_slice_tiles(stsl);
  ASSERT_TRUE(is_grouped_slice_tiles(grouped));
  const std::vector<uint8_t> packed = pack_plane_tile(std::span<const uint8_t>(stsl).subspan(32, size0));
  ASSERT_EQ(packed.size(), size0);
  EXPECT_EQ(u32(packed, 0), 0x4C505453u);  // "STPL"
  EXPECT_TRUE(std::equal(packed.begin(), packed.end(), grouped.begin() + 32));
  std::vector<uint8_t> back = grouped;
  uint32_t need = 0;
  ungroup_slice_tiles(back, &need);
  EXPECT_EQ(back, stsl);
  EXPECT_EQ(need, uint32_t(kFeaturePlaneTiles | kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels));
  auto refused = [](std::vector<uint8_t> b, bool group) -> std::string {
    try {
      if (group) ungroup_slice_tiles(b);
      SliceTiles::open(b);
    } catch (const FormatError& e) {
      const std::string m = e.what();
      const bool named = m.rfind("slice tiles: ", 0) == 0 || m.rfind("grouped slice tiles: ", 0) == 0;
      return named && m.find('\n') == std::string::npos ? "" : "not one named line: " + m;
    }
    return "accepted";
  };
  for (const bool group : {false, true}) {
    const std::vector<uint8_t>& good = group ? grouped : stsl;
    for (size_t n = 0; n < good.size(); ++n) {  // every truncation, even with a matching byte_size
      std::vector<uint8_t> b(good.begin(), good.begin() + ptrdiff_t(n));
      if (b.size() >= 12) std::memcpy(b.data() + 8, &n, 4);
      EXPECT_EQ(refused(b, group), "") << n << " bytes";
    }
    for (size_t i = 0; i < good.size(); ++i)  // any one byte changed: refused in one line or read
      for (uint8_t x : {uint8_t(1), uint8_t(0x80)}) {
        std::vector<uint8_t> b = good;
        b[i] ^= x;
        const std::string r = refused(b, group);
        EXPECT_TRUE(r.empty() || r == "accepted") << i << ": " << r;
      }
  }
  std::vector<uint8_t> b = stsl;
  b[32 + 4] ^= 0xFF;  // the plane tile's version
  EXPECT_NE(refused(b, false), "accepted");
}

TEST(StackSlicesPack, PerSliceCellsAreStoredGroupedAndReadAsStsl) {
  const IntervalStack s = stacks::random_stack(5, 3, 4);
  auto spill = spill_of(s, 0, "grouped.spill");
  BlockedStackCut cut(*spill, std::nullopt, 64 * 1024, tmp("grouped.tiles"), nullptr, StackCells::slices);
  const LightSet set = LightSet::fit(LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=3"),
                                     Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  StackPackParams plain;
  plain.group_slice_tiles = false;
  const uint64_t grouped_size = write_stack_pack(tmp("grouped.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, {});
  const uint64_t plain_size = write_stack_pack(tmp("plain.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, plain);
  EXPECT_NE(grouped_size, plain_size);
  auto r = PackReader::open(tmp("grouped.pack"));
  r->verify();
  size_t grouped = 0;
  for (size_t i = 0; i < cut.tile_count(); ++i) {
    const auto [cell, raw] = cut.tile(i);
    const uint64_t id = r->stack()->tile_id(cell);
    const auto t = r->find(id);
    ASSERT_TRUE(t);
    const std::vector<uint8_t> stored = zlib_decompress(r->read_stored(id), t->raw_size, "test");
    grouped += is_grouped_slice_tiles(stored);
    EXPECT_EQ(r->read_raw(id), raw);  // the reader hands out the STSL bytes
    std::vector<uint8_t> slot(t->raw_size + 8, 0);
    ASSERT_EQ(r->read_raw_into(id, slot), raw.size());
    EXPECT_TRUE(std::equal(raw.begin(), raw.end(), slot.begin()));
  }
  EXPECT_GT(grouped, 0u);
}

std::unique_ptr<StackSpill> spill_of(const IntervalStack& s, uint32_t block_level, const std::string& name) {
  auto spill = std::make_unique<StackSpill>(tmp(name), s.level, s.slices, block_level);
  const size_t area = size_t(s.side() * s.side());
  for (uint32_t w = 0; w < s.slices; ++w)
    spill->write_rows(w, 0, s.side(), std::span<const Interval>(s.data.data() + w * area, area));
  return spill;
}

// The pack of `s` with cells in form `cells`, written and opened as a client would.
// `planes`: per-slice cells' slices may be plane tiles.
std::unique_ptr<PackReader> build(const IntervalStack& s, StackCells cells, const std::string& name,
                                  uint64_t* slice_cells = nullptr, bool planes = false,
                                  std::optional<uint32_t> skip_level = std::nullopt) {
  auto spill = spill_of(s, 0, name + ".spill");
  BlockedStackCut cut(*spill, skip_level, 64 * 1024, tmp(name + ".tiles"), nullptr, cells, false,
                      planes ? std::optional<PlaneFitOptions>(PlaneFitOptions{}) : std::nullopt);
  if (slice_cells) *slice_cells = cut.slice_cells;
  const LightSet set = LightSet::fit(
      LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=" + std::to_string(s.slices)),
      Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  write_stack_pack(tmp(name + ".pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, {});
  auto r = PackReader::open(tmp(name + ".pack"));
  r->verify();
  return r;
}

// A stack of zero-width intervals on planes (each texel one plane's exact decoded depth,
// plane_format.hpp), two planes meeting along a crease that moves with w, and a box of
// wide intervals sliding with w: the plane slices' blocks, labelled blocks and inner tree.
IntervalStack planar_stack(uint32_t level, uint32_t slices) {
  IntervalStack s{level, slices, std::vector<Interval>((size_t(1) << (2 * level)) * slices)};
  for (uint32_t w = 0; w < slices; ++w)
    for (uint64_t y = 0; y < s.side(); ++y)
      for (uint64_t x = 0; x < s.side(); ++x) {
        const bool right = x + y / 3 > 20 + 3 * w;
        const int64_t v = right ? planes::kOne / 2 + planes::kOne / 512 * int64_t(x) + planes::kOne / 1024 * int64_t(y)
                                : planes::kOne / 3 + planes::kOne / 300 * int64_t(y) + planes::kOne / 4096 * int64_t(x);
        const float d = planes::plane_fixed_to_float(v);
        const bool box = x >= 5 + 2 * w && x < 14 + 2 * w && y >= 40 && y < 49;
        s.at(x, y, w) = box ? Interval{0.1f, 0.25f} : Interval{d, d};
      }
  return s;
}

// `planes`: the per-slice cells' slices may be plane tiles, and in the all-slices pack some are.
// `skip_level`: the cut's (default: the stack's default).
void expect_lossless_and_like_octree(const IntervalStack& s, const std::string& what, bool planes = false,
                                     std::optional<uint32_t> skip_level = std::nullopt) {
  SCOPED_TRACE(what);
  const auto oct = build(s, StackCells::octree, "oct", nullptr, false, skip_level);
  EXPECT_FALSE(oct->header().flags & kFeatureStackSliceTiles);
  const ResidentStack ro(*oct);
  for (StackCells form : {StackCells::slices, StackCells::smaller}) {
    uint64_t slice_cells = 0;
    const auto pack = build(s, form, form == StackCells::slices ? "slices" : "smaller", &slice_cells, planes, skip_level);
    EXPECT_EQ(bool(pack->header().flags & kFeatureStackSliceTiles), slice_cells > 0);
    if (form == StackCells::slices) {
      EXPECT_EQ(slice_cells, pack->tiles().size());
      EXPECT_EQ(bool(pack->header().flags & kFeaturePlaneTiles), planes) << "plane slices";
    }
    const ResidentStack rs(*pack);
    const StackMap& m = rs.map();
    EXPECT_EQ(stacks::first_violation(s, [&](uint64_t x, uint64_t y, uint32_t w) { return m.depth(x, y, w, s.level); }), "");
    // Above the cells the grid answers as the octree pack's (the same grid).
    const uint32_t a = m.grid().geo.xy_bits(m.grid().skip_level);
    for (uint32_t w = 0; w < s.slices; ++w)
      for (uint32_t level = 0; level <= std::min(a, s.level); ++level)
        for (uint64_t y = 0; y < (uint64_t(1) << level); ++y)
          for (uint64_t x = 0; x < (uint64_t(1) << level); ++x)
            ASSERT_EQ(m.depth(x, y, w, level), ro.map().depth(x, y, w, level)) << level << " " << x << " " << y << " " << w;
    // Soft lookups: single, batched, and the slices' lit tests agree bit for bit.
    Rng rng(5);
    std::vector<Vec3d> pts(40);
    for (Vec3d& p : pts) p = {rng.uniform(-10, 10), rng.uniform(0, 5), rng.uniform(-10, 10)};
    std::vector<float> batch(pts.size());
    m.soft_visibility(pts, batch);
    for (size_t i = 0; i < pts.size(); ++i) {
      uint32_t lit = 0;
      for (uint32_t w = 0; w < s.slices; ++w) lit += m.lit(pts[i], w);
      const float want = float(lit) / float(s.slices);
      EXPECT_EQ(m.soft_visibility(pts[i]), want);
      EXPECT_EQ(batch[i], want);
    }
  }
}

TEST(StackSlicesPack, EveryTexelOfEverySliceIsLossless) {
  expect_lossless_and_like_octree(stacks::coherent_stack(6, 5, 3), "coherent 64^2 x 5");
  expect_lossless_and_like_octree(stacks::random_stack(5, 3, 4), "random 32^2 x 3");
  expect_lossless_and_like_octree(stacks::coherent_stack(3, 20, 6), "coherent 8^2 x 20 (deeper than wide)");
  // Zero-width intervals on planes, as an open mesh's: per-slice cells with plane slices
  // (tiles/core/PLANES.md), read back exactly by the pack reader and the lookups. (The
  // demo's real day, 2CylinderEngine.glb at 1024^2 x 16, is re-traced on every texel by
  // `shadowtile verify --all`: tiles/core/MHOCT.md "Plane slices".)
  expect_lossless_and_like_octree(planar_stack(6, 4), "planes 64^2 x 4 with plane slices", true, 1);
}

TEST(StackSlicesPack, SmallerFormIsNeverLargerThanTheOctree) {
  const IntervalStack s = stacks::random_stack(6, 4, 9);  // incoherent: per-slice wins
  const auto oct = build(s, StackCells::octree, "oct2");
  uint64_t slice_cells = 0;
  const auto pick = build(s, StackCells::smaller, "pick2", &slice_cells);
  EXPECT_GT(slice_cells, 0u);
  uint64_t a = 0, b = 0;
  for (const TileIndexEntry& e : oct->tiles()) a += e.stored_size;
  for (const TileIndexEntry& e : pick->tiles()) b += e.stored_size;
  EXPECT_LE(b, a);
}

// The cut moves a level deeper only when a cell's kept form does not fit the tile bound:
// with the bound between the octree cells' largest and the largest of each cell's smaller
// form, the octree form's cut moves deeper while the smaller form's stays at its skip level
// (the per-slice tiles of the cells whose octree outgrows the bound fit), every tile fitting;
// past it, the probe for the next level weighs both forms too.
TEST(StackSlicesPack, TheSmallerFormsCutMovesDeeperOnlyWhenACellFitsNeitherWay) {
  // A pattern of five depths that shifts with w: each slice's quadtree stays small (the
  // pattern repeats), the octree over (x, y, w) shares nothing between slices.
  IntervalStack s{6, 8, std::vector<Interval>(64 * 64 * 8)};
  for (uint32_t w = 0; w < s.slices; ++w)
    for (uint64_t y = 0; y < s.side(); ++y)
      for (uint64_t x = 0; x < s.side(); ++x) {
        const float v = 0.3f + 0.1f * float(((x * 7 + w * 13) ^ (y * 3)) % 5);
        s.at(x, y, w) = {v, v + 0.01f};
      }
  auto spill = spill_of(s, 0, "depth.spill");
  // At skip level `level` without a bound: the octree cells' largest, and the largest of
  // each cell's smaller form (raw bytes, what the bound limits).
  auto largest = [&](std::optional<uint32_t> level, uint32_t& K, uint64_t& octree_largest, uint64_t& bound) {
    const uint32_t unbounded = 1u << 26;
    BlockedStackCut oct(*spill, level, unbounded, tmp("depth_oct.tiles"), nullptr, StackCells::octree);
    BlockedStackCut per(*spill, level, unbounded, tmp("depth_per.tiles"), nullptr, StackCells::slices);
    K = oct.grid.skip_level;
    ASSERT_EQ(per.grid.skip_level, K);
    ASSERT_EQ(oct.tile_count(), per.tile_count());
    octree_largest = bound = 0;
    for (size_t i = 0; i < oct.tile_count(); ++i) {
      const auto [cell, o] = oct.tile(i);
      const auto [cell2, p] = per.tile(i);
      ASSERT_EQ(cell, cell2);
      octree_largest = std::max<uint64_t>(octree_largest, o.size());
      bound = std::max<uint64_t>(bound, std::min(o.size(), p.size()));
    }
  };
  uint32_t K = 0, K1 = 0;
  uint64_t octree_largest = 0, bound = 0, octree_largest1 = 0, bound1 = 0;
  largest(1, K, octree_largest, bound);  // cells of 32^2 texels x 8 slices
  largest(2, K1, octree_largest1, bound1);
  ASSERT_LT(bound, octree_largest) << "the fixture's per-slice cells are no smaller";
  // A bound below both the first level's smaller-form largest and the next level's octree
  // cells' largest, that the next level's smaller forms fit.
  const uint64_t tight = std::min(bound, octree_largest1) - 1;
  ASSERT_LE(bound1, tight) << "the fixture's next level has no bound between the forms";
  BlockedStackCut oct_bounded(*spill, K, uint32_t(bound), tmp("depth_ob.tiles"), nullptr, StackCells::octree);
  EXPECT_GT(oct_bounded.grid.skip_level, K);
  BlockedStackCut pick(*spill, K, uint32_t(bound), tmp("depth_pick.tiles"), nullptr, StackCells::smaller);
  EXPECT_EQ(pick.grid.skip_level, K);
  EXPECT_GT(pick.slice_cells, 0u);
  EXPECT_LE(pick.max_tile_bytes, bound);
  // Tighter: some cell fits neither way, so the smaller form's cut moves deeper too, one
  // level (where each cell's smaller form fits), not to where the octree cells would fit.
  BlockedStackCut tighter(*spill, K, uint32_t(tight), tmp("depth_t.tiles"), nullptr, StackCells::smaller);
  EXPECT_EQ(tighter.grid.skip_level, K + 1);
  EXPECT_LE(tighter.max_tile_bytes, tight);
}

TEST(StackSlicesPack, ATileWithoutTheFeatureBitIsRefused) {
  // The per-slice tiles written with the octree pack's header flags: verify names the tile.
  const IntervalStack s = stacks::coherent_stack(5, 3, 2);
  auto spill = spill_of(s, 0, "nobit.spill");
  BlockedStackCut cut(*spill, std::nullopt, 64 * 1024, tmp("nobit.tiles"), nullptr, StackCells::slices);
  const LightSet set = LightSet::fit(LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=3"),
                                     Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  // Clear a bit and fix the header's CRC: without stack_slice_tiles (and so without
  // stack_grouped_tiles, which needs it) and, with plain cells, without stack_grouped_tiles alone.
  StackPackParams plain;
  plain.group_slice_tiles = false;
  const std::pair<uint32_t, const char*> cases[] = {
      {uint32_t(kFeatureStackSliceTiles | kFeatureStackGroupedTiles), "stack_slice_tiles"},
      {uint32_t(kFeatureStackGroupedTiles), "stack_grouped_tiles"}};
  for (const auto& [clear, name] : cases) {
    const bool grouped_case = clear == uint32_t(kFeatureStackGroupedTiles);
    write_stack_pack(tmp("nobit.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); },
                     grouped_case ? StackPackParams{} : plain);
    std::vector<uint8_t> file;
    {
      std::ifstream f(tmp("nobit.pack"), std::ios::binary);
      file.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    }
    PackHeader h = PackHeader::parse(std::span<const uint8_t>(file.data(), kPackHeaderBytes), "nobit");
    ASSERT_TRUE(h.flags & kFeatureStackSliceTiles);
    if (grouped_case) {
      ASSERT_TRUE(h.flags & kFeatureStackGroupedTiles) << "no grouped cell to refuse";
    }
    h.flags &= ~clear;
    const auto head = h.serialize();
    std::memcpy(file.data(), head.data(), head.size());
    {
      std::ofstream f(tmp("nobit.pack"), std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(file.data()), std::streamsize(file.size()));
    }
    auto r = PackReader::open(tmp("nobit.pack"));
    try {
      r->verify();
      ADD_FAILURE() << "verify accepted a per-slice cell without the feature bit " << name;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
}

// Plane slices in a pack without the plane features: verify names what is missing, for
// grouped cells (their packed plane slices) and for plain STSL cells (their STPN slices).
TEST(StackSlicesPack, PlaneSlicesWithoutTheFeatureBitsAreRefused) {
  const IntervalStack s = planar_stack(5, 2);
  auto spill = spill_of(s, 0, "noplane.spill");
  BlockedStackCut cut(*spill, 1u, 64 * 1024, tmp("noplane.tiles"), nullptr, StackCells::slices, false, PlaneFitOptions{});
  const LightSet set = LightSet::fit(LightSetSpec::parse("sun-path:azimuth=150..200,elevation=40..60,samples=2"),
                                     Aabb{{-10, 0, -10}, {10, 5, 10}});
  cut.grid.light_kind = set.samples[0].kind();
  for (const LightSpace& l : set.samples) cut.grid.lights.push_back(l.to_array());
  cut.grid.spec = set.spec.to_string();
  const uint32_t planes = kFeaturePlaneTiles | kFeaturePackedPlaneTiles | kFeaturePredictedPlaneLabels;
  for (const bool grouped : {true, false}) {
    StackPackParams p;
    p.group_slice_tiles = grouped;
    write_stack_pack(tmp("noplane.pack"), cut.grid, cut.tile_count(), [&](size_t i) { return cut.tile(i); }, p);
    PackReader::open(tmp("noplane.pack"))->verify();
    std::vector<uint8_t> file;
    {
      std::ifstream f(tmp("noplane.pack"), std::ios::binary);
      file.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    }
    PackHeader h = PackHeader::parse(std::span<const uint8_t>(file.data(), kPackHeaderBytes), "noplane");
    EXPECT_EQ(h.flags & planes, grouped ? planes : uint32_t(kFeaturePlaneTiles));
    h.flags &= ~planes;
    const auto head = h.serialize();
    std::memcpy(file.data(), head.data(), head.size());
    {
      std::ofstream f(tmp("noplane.pack"), std::ios::binary | std::ios::trunc);
      f.write(reinterpret_cast<const char*>(file.data()), std::streamsize(file.size()));
    }
    try {
      PackReader::open(tmp("noplane.pack"))->verify();
      ADD_FAILURE() << "verify accepted plane slices without plane_tiles" << (grouped ? " (grouped)" : "");
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("without feature plane_tiles"), std::string::npos) << e.what();
    }
  }
}

}  // namespace stack_slices_test
}  // namespace st
