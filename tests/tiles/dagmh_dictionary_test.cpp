// The DAG-MH pack dictionary (tiles/core/DAGMH.md "Dictionary", tiles/encode/dagmh_dictionary.hpp):
// tiles rewritten to share their common subtrees answer every lookup bit-identically, the
// bytes shrink, the dictionary's layout is the drawn one, and hostile dictionaries and
// tiles are refused with a FormatError or answer without reading out of bounds (ASan).
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "common/error.hpp"
#include "tests/tiles/dagmh_fixtures.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tiles/encode/dagmh_dictionary.hpp"
#include "tiles/core/dagmh_validate.hpp"

namespace st {
namespace dagmh_dictionary_test {

// The same topology with fresh intervals: what neighbouring tiles of a city look like to
// the per-tile DAG (the same building footprints, other depths).
Hierarchy with_fresh_values(Hierarchy h, uint64_t seed) {
  fields::Rng rng(seed);
  for (auto& level : h.levels)
    for (HNode& n : level)
      if (n.has_value) {
        const Interval iv = dagmh_test::mixed_interval(rng);
        n.lo = iv.lo, n.hi = iv.hi, n.value = iv.lo;
      }
  return h;
}

// Tiles 0-2 share one topology, 3-4 another, 5 is alone.
std::vector<std::vector<uint8_t>> tile_set(uint64_t seed) {
  const Hierarchy a = dagmh_test::random_hierarchy(7, seed, 0.5, 0.5, dagmh_test::mixed_interval);
  const Hierarchy b = dagmh_test::random_hierarchy(6, seed + 1, 0.6, 0.3, dagmh_test::mixed_interval);
  const Hierarchy c = dagmh_test::random_hierarchy(7, seed + 2, 0.55, 0.4, dagmh_test::mixed_interval);
  std::vector<std::vector<uint8_t>> tiles;
  for (uint64_t k = 0; k < 3; ++k) tiles.push_back(encode_dagmh(with_fresh_values(a, seed * 10 + k)));
  for (uint64_t k = 0; k < 2; ++k) tiles.push_back(encode_dagmh(with_fresh_values(b, seed * 20 + k)));
  tiles.push_back(encode_dagmh(c));
  return tiles;
}

std::string open_error(std::span<const uint8_t> tile, std::shared_ptr<const dagmh::Dictionary> dict) {
  try {
    open_dagmh(tile, std::move(dict));
  } catch (const FormatError& e) {
    return e.what();
  }
  return "";
}

double exercise(const Evaluator& e) {
  double sum = 0;
  for (uint32_t l = 0; l <= e.finest_level(); ++l)
    for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) sum += double(e.depth_region(l, x, y).shift);
  for (uint32_t r = 1; r <= 9; r += 4) sum += e.pcf(e.finest_level(), 3, 5, r, 0.5f);
  return sum;
}

TEST(DagmhDictionary, SharedTilesAnswerBitEqual) {
  const auto tiles = tile_set(5);
  const auto shared = dagmh::share_across_tiles(tiles);
  ASSERT_FALSE(shared.dictionary.empty());
  EXPECT_GE(shared.tiles_rewritten, 5u);
  // Tiles 1, 2 and 4 lose their whole structure: the dictionary holds one copy.
  EXPECT_LT(shared.bytes_after + shared.dictionary.size(), shared.bytes_before);
  const auto dict = dagmh::Dictionary::open(shared.dictionary);
  for (size_t t = 0; t < tiles.size(); ++t) {
    const auto before = open_dagmh(tiles[t]);
    const auto after = open_dagmh(shared.tiles[t], dict);
    ASSERT_EQ(before->finest_level(), after->finest_level());
    for (uint32_t l = 0; l <= before->finest_level(); ++l)
      for (uint64_t y = 0; y < (uint64_t(1) << l); ++y)
        for (uint64_t x = 0; x < (uint64_t(1) << l); ++x) {
          const DepthRegion a = before->depth_region(l, x, y), b = after->depth_region(l, x, y);
          ASSERT_EQ(std::bit_cast<uint32_t>(a.value), std::bit_cast<uint32_t>(b.value)) << t << " " << l;
          ASSERT_EQ(a.shift, b.shift);
        }
    const uint32_t L = before->finest_level();
    for (uint32_t r : {1u, 3u, 5u, 9u})
      for (uint64_t p = 0; p < 40; ++p) {
        const uint64_t x = (p * 37) % (uint64_t(1) << L), y = (p * 53) % (uint64_t(1) << L);
        const float receiver = float(p % 8) / 8.0f;
        EXPECT_EQ(before->pcf(L, x, y, r, receiver), after->pcf(L, x, y, r, receiver));
      }
  }
}

TEST(DagmhDictionary, LayoutIsTheDrawnOne) {
  const auto shared = dagmh::share_across_tiles(tile_set(7));
  const auto& d = shared.dictionary;
  ASSERT_GE(d.size(), 32u);
  EXPECT_EQ(std::string(d.begin(), d.begin() + 4), "DGMD");
  const uint32_t words = st::load_le<uint32_t>(d.data() + 12), treelets = st::load_le<uint32_t>(d.data() + 16);
  EXPECT_EQ(st::load_le<uint32_t>(d.data() + 4), 1u);
  EXPECT_EQ(st::load_le<uint32_t>(d.data() + 8), 32u);
  EXPECT_EQ(st::load_le<uint32_t>(d.data() + 20), d.size());
  EXPECT_EQ(st::load_le<uint32_t>(d.data() + 24), 32u);
  EXPECT_EQ(st::load_le<uint32_t>(d.data() + 28), 32u + 4 * words);
  EXPECT_EQ(d.size(), 32u + 4 * words + 12 * treelets);
  const auto dict = dagmh::Dictionary::open(d);
  for (const auto& t : shared.tiles) {
    EXPECT_EQ(st::load_le<uint32_t>(t.data() + 4), dagmh::kVersion);
    const bool flagged = t[10] & dagmh::kFlagDictionary;
    EXPECT_EQ(st::load_le<uint32_t>(t.data() + 28), flagged ? dict->crc() : 0u);
  }
}

TEST(DagmhDictionary, TilesNeedTheirOwnDictionary) {
  const auto shared = dagmh::share_across_tiles(tile_set(5));
  const auto other = dagmh::share_across_tiles(tile_set(9));
  const auto dict = dagmh::Dictionary::open(other.dictionary);
  for (const auto& t : shared.tiles) {
    if (!(t[10] & dagmh::kFlagDictionary)) continue;
    EXPECT_NE(open_error(t, nullptr).find("flags at byte 10: the tile references a pack dictionary"),
              std::string::npos)
        << open_error(t, nullptr);
    EXPECT_NE(open_error(t, dict).find("dictionary_crc"), std::string::npos);
  }
  // A tile without the flag opens with or without one.
  EXPECT_EQ(open_error(tile_set(5)[0], dict), "");
  // Versions the reader does not know name themselves.
  auto t = shared.tiles[0];
  st::store_le<uint32_t>(t.data() + 4, 4);
  EXPECT_NE(open_error(t, dict).find("version at byte 4: is 4"), std::string::npos) << open_error(t, dict);
}

TEST(DagmhDictionary, HostileDictionariesAndTiles) {
  const auto shared = dagmh::share_across_tiles(tile_set(5));
  const auto& d = shared.dictionary;
  for (size_t n = 0; n < d.size(); n += 1 + n / 64) {
    EXPECT_THROW(dagmh::Dictionary::open(std::vector<uint8_t>(d.begin(), d.begin() + long(n))), FormatError) << n;
  }
  auto longer = d;
  longer.push_back(0);
  EXPECT_THROW(dagmh::Dictionary::open(longer), FormatError);
  // Bit flips: in the dictionary (its CRC then differs from the tiles', so re-stamp the
  // tile's to reach the structural checks) and in a rewritten tile.
  fields::Rng rng(11);
  double sink = 0;
  const int flips = fields::small_test_scale() ? 80 : 300;  // the asan preset: fewer
  for (int i = 0; i < flips; ++i) {
    auto bad = d;
    bad[rng.below(bad.size())] ^= uint8_t(1u << rng.below(8));
    std::shared_ptr<const dagmh::Dictionary> dict;
    try {
      dict = dagmh::Dictionary::open(bad);
    } catch (const FormatError&) {
      continue;
    }
    for (auto t : shared.tiles) {
      if (t[10] & dagmh::kFlagDictionary) st::store_le<uint32_t>(t.data() + 28, dict->crc());
      try {
        sink += exercise(*open_dagmh(t, dict));
      } catch (const FormatError&) {
      }
    }
  }
  const auto dict = dagmh::Dictionary::open(d);
  for (int i = 0; i < flips; ++i) {
    auto t = shared.tiles[rng.below(shared.tiles.size())];
    t[rng.below(t.size())] ^= uint8_t(1u << rng.below(8));
    try {
      sink += exercise(*open_dagmh(t, dict));
    } catch (const FormatError&) {
    }
  }
  EXPECT_GE(sink, 0.0);
}

}  // namespace dagmh_dictionary_test
}  // namespace st
