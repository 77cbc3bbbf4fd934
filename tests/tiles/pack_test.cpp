// Packs end to end (pack_writer, pack_reader, pack_evaluator): built from random
// interval fields, every texel of every level answers exactly as the hierarchy that was
// cut, for every encoding linked; the lossless invariant holds on every texel.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <thread>

#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "common/error.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"
#include "tiles/encode/pack_writer.hpp"

namespace st {
namespace pack_test {

using packtest::bits;

LightSpace test_light() {
  return LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}});
}

struct Built {
  std::shared_ptr<PackReader> reader;
  std::string path;
};

Built build_pack(const std::string& name, const Hierarchy& h, Encoding e, uint32_t skip, uint32_t tile_bytes) {
  CutParams cut;
  cut.map_level = h.depth;
  cut.skip_level = skip;
  cut.tile_bytes = tile_bytes;
  cut.codec = TileCodec::of(e);
  PackParams pp = PackParams::from(test_light(), cut);
  pp.scene_hash = 0x1234567890abcdefull;
  pp.features = kFeatureExitDepths;
  pp.build_params = {{"scene", name}, {"light", "sun:azimuth=30,elevation=50"}};
  std::string path = packtest::temp_path(name + ".pack");
  write_pack(path, h, cut, pp);
  return {std::shared_ptr<PackReader>(PackReader::open(path)), path};
}

std::string lossless(const Evaluator& ev, const IntervalTile& t) {
  return fields::first_violation(t, [&](uint32_t i, uint32_t j) { return ev.depth(t.level, i, j); });
}

// What a pack of whole-cell tiles must answer: levels <= K from `h`; below, each cell's
// subtree encoded on its own and opened in memory (so MMH/DAG-MH values compare exactly).
std::string differs_from_cell_encodings(const Evaluator& ev, const Hierarchy& h, uint32_t k, const TileCodec& codec) {
  SplitResult s = split_hierarchy(h, k);
  std::vector<std::vector<uint8_t>> bytes(s.subtrees.size());
  std::vector<std::unique_ptr<Evaluator>> evals(s.subtrees.size());
  for (size_t i = 0; i < s.subtrees.size(); ++i)
    if (s.subtrees[i]) {
      bytes[i] = codec.encode(*s.subtrees[i]);
      evals[i] = codec.open(bytes[i]);
    }
  return packtest::first_difference(ev, h.depth, [&](uint32_t l, uint64_t x, uint64_t y) {
    if (l <= k) return h.depth_at(l, x, y);
    uint32_t r = l - k;
    size_t i = size_t(y >> r) * (size_t(1) << k) + (x >> r);
    if (!evals[i]) return s.grid.entries[i].value;
    return evals[i]->depth(r, x & ((uint64_t(1) << r) - 1), y & ((uint64_t(1) << r) - 1));
  });
}

TEST(Pack, EveryFieldAnswersLikeTheHierarchyForEveryEncoding) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty()) << "no encoding linked";
  const uint32_t side = fields::small_test_scale() ? 32 : 64;
  for (Encoding e : encodings)
    for (auto& f : fields::all_fields(side, 11)) {
      const std::string what = to_string(e) + " " + f.name;
      Hierarchy h = build_hierarchy(f.tile);
      const uint32_t k = default_skip_level(h.depth);
      for (uint32_t tile_bytes : {kDefaultTileBytes, 512u}) {
        Built b = build_pack(f.name + "_" + to_string(e), h, e, k, tile_bytes);
        ASSERT_NO_THROW(b.reader->verify(TileCodec::of(e).open)) << what;
        PackEvaluator ev(b.reader);
        ASSERT_EQ(ev.finest_level(), h.depth);
        ASSERT_EQ(packtest::first_difference(ev, h, k), "") << what << " tile_bytes " << tile_bytes;
        if (packtest::exact_values(e)) {
          ASSERT_EQ(packtest::first_difference(ev, h), "") << what << " tile_bytes " << tile_bytes;
        } else if (tile_bytes == kDefaultTileBytes) {
          ASSERT_FALSE(b.reader->header().flags & kFeatureIndexTiles);
          ASSERT_EQ(differs_from_cell_encodings(ev, h, k, TileCodec::of(e)), "") << what;
        }
        ASSERT_EQ(lossless(ev, f.tile), "") << what;
        for (const TileIndexEntry& t : b.reader->tiles()) EXPECT_LE(t.raw_size, tile_bytes) << what;
      }
    }
}

// Every skip level from 0 (one cell: the whole map) to L (cells are texels: no tiles), on
// maps from 1 texel up.
TEST(Pack, EverySkipLevelOnTinyMaps) {
  for (Encoding e : packtest::available_encodings())
    for (uint32_t side : {1u, 2u, 16u}) {
      IntervalTile t = fields::city_field(side, 3);
      Hierarchy h = build_hierarchy(t);
      for (uint32_t k = 0; k <= h.depth; ++k)
        for (uint32_t tile_bytes : {kMinTileBytes, kDefaultTileBytes}) {
          const std::string what = to_string(e) + " side " + std::to_string(side) + " K " + std::to_string(k) +
                                   " tile_bytes " + std::to_string(tile_bytes);
          Built b = build_pack("tiny", h, e, k, tile_bytes);
          ASSERT_NO_THROW(b.reader->verify(TileCodec::of(e).open)) << what;
          PackEvaluator ev(b.reader);
          EXPECT_EQ(packtest::first_difference(ev, h, packtest::exact_values(e) ? h.depth : k), "") << what;
          EXPECT_EQ(lossless(ev, t), "") << what;
          if (k == h.depth) {
            EXPECT_TRUE(b.reader->tiles().empty()) << what;
          }
        }
    }
}

TEST(Pack, HeaderRecordsTheBuild) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  IntervalTile t = fields::city_field(32, 2);
  Hierarchy h = build_hierarchy(t);
  Built b = build_pack("header", h, encodings[0], 2, kDefaultTileBytes);
  const PackHeader& hd = b.reader->header();
  EXPECT_EQ(hd.state, PackState::complete);
  EXPECT_EQ(hd.map_level, 5u);
  EXPECT_EQ(hd.skip_level, 2u);
  EXPECT_EQ(hd.encoding, encodings[0]);
  EXPECT_EQ(hd.scene_hash, 0x1234567890abcdefull);
  EXPECT_TRUE(hd.flags & kFeatureExitDepths);
  EXPECT_EQ(bool(hd.flags & kFeatureHasTiles), !b.reader->tiles().empty());
  EXPECT_EQ(b.reader->light().to_array(), test_light().to_array());
  PackParamList want = {{"light", "sun:azimuth=30,elevation=50"}, {"scene", "header"}};
  EXPECT_EQ(b.reader->params(), want);
  EXPECT_EQ(b.reader->header_bytes().size(), kPackHeaderBytes);
  // The grid section: the skip grid, then the map preview (tiles/PACK.md "Map preview").
  EXPECT_EQ(b.reader->grid_bytes().size(), CutGrid::serialized_size(2) + b.reader->preview().serialized_size());
  EXPECT_FALSE(std::filesystem::exists(b.path + ".tmp"));
  const std::string summary = b.reader->summary();
  EXPECT_NE(summary.find("map level 5 (32 texels a side), skip level 2"), std::string::npos) << summary;
  EXPECT_NE(summary.find("exit_depths"), std::string::npos) << summary;
  EXPECT_NE(summary.find("scene = header"), std::string::npos) << summary;
  // A finished pack holds the payloads alone, back to back in id order (tiles/PACK.md
  // "Payloads only"): no journal record is left.
  EXPECT_TRUE(hd.flags & kFeaturePayloadsOnly);
  uint64_t next = hd.journal_offset;
  for (const TileIndexEntry& e : b.reader->tiles()) {
    EXPECT_EQ(e.offset, next);
    next = e.offset + e.stored_size;
  }
  EXPECT_LT(hd.grid_offset - next, 8u);
  b.reader->verify(b.reader->tile_opener());
  // Stored bytes are the zlib stream as it lies in the file.
  for (const TileIndexEntry& e : b.reader->tiles()) {
    std::vector<uint8_t> stored = b.reader->read_stored(e.id);
    EXPECT_EQ(stored.size(), e.stored_size);
    EXPECT_EQ(stored[0] & 0x0F, 8) << "zlib CM = deflate";
    EXPECT_EQ(((stored[0] << 8) | stored[1]) % 31, 0) << "zlib FCHECK";
  }
}

TEST(Pack, ConstantRegionsProduceNoTiles) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  IntervalTile t = fields::constant_field(64, Interval{0.25f, 0.5f});
  // Plus one lit quadrant that differs: still constant per cell.
  for (uint32_t y = 0; y < 32; ++y)
    for (uint32_t x = 0; x < 32; ++x) t.at(x, y) = Interval{kLitDepth, kLitDepth};
  Hierarchy h = build_hierarchy(t);
  for (Encoding e : encodings) {
    Built b = build_pack("constant", h, e, 3, kDefaultTileBytes);
    EXPECT_TRUE(b.reader->tiles().empty());
    EXPECT_FALSE(b.reader->header().flags & kFeatureHasTiles);
    PackEvaluator ev(b.reader);
    EXPECT_EQ(packtest::first_difference(ev, h), "");
    EXPECT_EQ(lossless(ev, t), "");
    EXPECT_EQ(ev.tiles_opened(), 0u);
  }
}

TEST(Pack, SmallTileBytesForcesIndexTilesAndStaysExact) {
  for (Encoding e : packtest::available_encodings()) {
    IntervalTile t = fields::uniform_field(64, 4);
    Hierarchy h = build_hierarchy(t);
    Built b = build_pack("index", h, e, 2, 128);
    EXPECT_TRUE(b.reader->header().flags & kFeatureIndexTiles);
    size_t index_tiles = std::count_if(b.reader->tiles().begin(), b.reader->tiles().end(),
                                       [](auto& x) { return x.kind == TileKind::index; });
    EXPECT_GT(index_tiles, 16u);
    ASSERT_NO_THROW(b.reader->verify(TileCodec::of(e).open));
    PackEvaluator ev(b.reader, 8);  // a small cache: tiles are evicted and reopened
    EXPECT_EQ(packtest::first_difference(ev, h, packtest::exact_values(e) ? h.depth : 2), "") << to_string(e);
    EXPECT_EQ(lossless(ev, t), "");
  }
}

// Out of core: cells cut one at a time (shuffled, two threads), the coarse levels built
// over the cells' root intervals at the end (MH §3.1 tiled construction).
TEST(Pack, CellByCellBuildAnswersLikeTheCellsAndTheCoarseHierarchy) {
  for (Encoding e : packtest::available_encodings()) {
    const uint32_t side = 128, k = 3, cell = side >> k;
    IntervalTile t = fields::scene_field(side, 5);
    CutParams cut;
    cut.map_level = 7;
    cut.skip_level = k;
    cut.tile_bytes = kDefaultTileBytes;
    cut.codec = TileCodec::of(e);
    TileCutter cutter(cut);
    std::string path = packtest::temp_path("cells_" + to_string(e) + ".pack");
    auto w = PackWriter::create(path, PackParams::from(test_light(), cut));
    std::vector<uint32_t> order(1u << (2 * k));
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    fields::Rng rng(3);
    for (size_t i = order.size(); i > 1; --i) std::swap(order[i - 1], order[rng.below(uint32_t(i))]);
    std::vector<Hierarchy> cells(order.size());
    auto worker = [&](size_t begin) {
      for (size_t n = begin; n < order.size(); n += 2) {
        uint32_t cx = order[n] & ((1u << k) - 1), cy = order[n] >> k;
        Hierarchy ch = build_hierarchy(packtest::sub_tile(t, cx * cell, cy * cell, cell));
        cells[order[n]] = ch;
        w->append_cell(cutter.cut_cell(cx, cy, std::move(ch)));
      }
    };
    std::thread other(worker, 1);
    worker(0);
    other.join();
    w->finish(cutter.coarse_grid(w->cells()));

    auto reader = std::shared_ptr<PackReader>(PackReader::open(path));
    ASSERT_NO_THROW(reader->verify(cut.codec.open));
    PackEvaluator ev(reader);
    IntervalTile roots;
    roots.level = k;
    roots.width = roots.height = 1u << k;
    for (auto& c : cells) roots.data.push_back(Interval{c.levels[0][0].lo, c.levels[0][0].hi});
    Hierarchy coarse = build_hierarchy(roots);
    std::vector<std::vector<uint8_t>> bytes(cells.size());
    std::vector<std::unique_ptr<Evaluator>> evals(cells.size());
    for (size_t i = 0; i < cells.size(); ++i) {
      bytes[i] = cut.codec.encode(cells[i]);
      evals[i] = cut.codec.open(bytes[i]);
    }
    std::string diff = packtest::first_difference(ev, 7, [&](uint32_t l, uint64_t x, uint64_t y) {
      if (l < k) return coarse.depth_at(l, x, y);
      uint32_t r = l - k;
      size_t i = (y >> r) * (1u << k) + (x >> r);
      const HNode& root = cells[i].levels[0][0];
      if (r == 0 || !root.child_mask) return root.value;
      return evals[i]->depth(r, x & ((1u << r) - 1), y & ((1u << r) - 1));
    });
    if (packtest::exact_values(e)) {
      // MH keeps values: the cells' hierarchies answer too.
      EXPECT_EQ(packtest::first_difference(ev, 7, [&](uint32_t l, uint64_t x, uint64_t y) {
                  if (l < k) return coarse.depth_at(l, x, y);
                  uint32_t r = l - k;
                  const Hierarchy& c = cells[(y >> r) * (1u << k) + (x >> r)];
                  return c.depth_at(r, x & ((1u << r) - 1), y & ((1u << r) - 1));
                }),
                "");
    }
    EXPECT_EQ(diff, "") << to_string(e);
    EXPECT_EQ(lossless(ev, t), "") << to_string(e);
  }
}

TEST(Pack, ConcurrentLookupsWithATinyCacheAgree) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  IntervalTile t = fields::city_field(64, 8);
  Hierarchy h = build_hierarchy(t);
  Built b = build_pack("threads", h, encodings[0], 2, 256);
  const std::vector<float> want = packtest::all_answers(PackEvaluator(b.reader));
  PackEvaluator ev(b.reader, 2);
  std::atomic<int> bad{0};
  auto work = [&](uint64_t seed) {
    fields::Rng rng(seed);
    for (int i = 0; i < 20000; ++i) {
      uint32_t l = rng.below(7), x = rng.below(1u << l), y = rng.below(1u << l);
      size_t at = CutGrid::coarse_count(l) + (size_t(y) << l) + x;
      if (bits(ev.depth(l, x, y)) != bits(want[at])) ++bad;
    }
  };
  std::thread a(work, 1), c(work, 2);
  a.join();
  c.join();
  EXPECT_EQ(bad.load(), 0);
  // Outside the map: lit, the page table's one out-of-range rule (page_table.hpp).
  EXPECT_EQ(ev.depth(7, 0, 0), kLitDepth);
  EXPECT_EQ(ev.depth(6, 64, 0), kLitDepth);
  EXPECT_EQ(ev.depth(6, 0, 64), kLitDepth);
}

// Level-20 addressing: a map of level 20 whose only detail is a small patch near the far
// corner, cut with K = 8; integer texels up to 2^20 - 1 answer exactly.
TEST(Pack, Level20MapIsAddressedExactly) {
  const auto encodings = packtest::available_encodings();
  ASSERT_FALSE(encodings.empty());
  const uint32_t L = 20, patch = 16;
  IntervalTile p = fields::uniform_field(patch, 6);
  Hierarchy ph = build_hierarchy(p);
  // Embed the patch's hierarchy below node (L - 4, 2^16 - 1, 2^16 - 2) of a lit map.
  Hierarchy h;
  h.depth = L;
  h.levels.resize(L + 1);
  h.levels[0].push_back(HNode{0, kLitDepth, kLitDepth, kLitDepth, 0, 1});
  const uint32_t px = (1u << 16) - 1, py = (1u << 16) - 2;
  for (uint32_t l = 1; l <= L - 4; ++l) {
    uint32_t s = (L - 4) - l;
    uint64_t m = morton_encode(px >> s, py >> s);
    h.levels[l - 1].back().child_mask = uint8_t(1u << (m & 3));
    h.levels[l].push_back(HNode{m, 0, 0, 0, 0, 0});
  }
  HNode& anchor = h.levels[L - 4].back();
  anchor = ph.levels[0][0];
  anchor.morton = morton_encode(px, py);
  for (uint32_t r = 1; r <= 4; ++r)
    for (HNode n : ph.levels[r]) {
      n.morton |= anchor.morton << (2 * r);
      h.levels[L - 4 + r].push_back(n);
    }
  for (Encoding e : encodings) {
    Built b = build_pack("level20", h, e, default_skip_level(L), kDefaultTileBytes);
    PackEvaluator ev(b.reader);
    ASSERT_EQ(b.reader->tiles().size(), 1u);
    EXPECT_EQ(tile_address(b.reader->tiles()[0].id), (TileAddress{8, px >> 8, py >> 8}));
    for (uint32_t j = 0; j < patch; ++j)
      for (uint32_t i = 0; i < patch; ++i) {
        uint64_t x = (uint64_t(px) << 4) + i, y = (uint64_t(py) << 4) + j;
        if (packtest::exact_values(e)) {
          ASSERT_EQ(bits(ev.depth(L, x, y)), bits(h.depth_at(L, x, y)));
        }
        ASSERT_TRUE(p.at(i, j).contains(ev.depth(L, x, y)));
      }
    fields::Rng rng(1);
    for (int n = 0; n < 4000; ++n) {
      uint32_t l = rng.below(L + 1);
      uint64_t x = rng.below(1u << l), y = rng.below(1u << l);
      bool in_tile = l > 8 && (x >> (l - 8)) == (px >> 8) && (y >> (l - 8)) == (py >> 8);
      if (in_tile && !packtest::exact_values(e)) continue;
      ASSERT_EQ(bits(ev.depth(l, x, y)), bits(h.depth_at(l, x, y))) << l << " " << x << " " << y;
    }
    EXPECT_EQ(bits(ev.depth(L, (1u << L) - 1, (1u << L) - 1)), bits(kLitDepth));
  }
}

}  // namespace pack_test
}  // namespace st
