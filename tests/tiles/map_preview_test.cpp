// The map preview (tiles/core/map_preview.hpp, tiles/PACK.md "Map preview"): with no tile
// at hand, every texel answers exactly what the fully resident pack answers at level
// min(level, K + p); its bytes are pinned; hostile bytes are refused; packs of version 1
// are refused naming the version.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>

#include "common/bytes.hpp"
#include "common/error.hpp"
#include "tests/tiles/interval_fields.hpp"
#include "tests/tiles/pack_test_support.hpp"
#include "tiles/encode/mh_build.hpp"
#include "tiles/encode/pack_writer.hpp"
#include "tiles/core/map_preview.hpp"
#include "tiles/core/pack_evaluator.hpp"
#include "tiles/core/pack_reader.hpp"

namespace st {
namespace map_preview_test {

using packtest::bits;

std::shared_ptr<PackReader> build(const std::string& name, const Hierarchy& h, Encoding e, uint32_t skip,
                                  uint32_t tile_bytes, uint32_t preview_levels) {
  CutParams cut;
  cut.map_level = h.depth;
  cut.skip_level = skip;
  cut.tile_bytes = tile_bytes;
  cut.codec = TileCodec::of(e);
  const LightSpace light =
      LightSpace::fit(LightSpec::parse("sun:azimuth=30,elevation=50"), Aabb{{-10, 0, -10}, {10, 5, 10}});
  PackParams pp = PackParams::from(light, cut);
  pp.features = kFeatureExitDepths;
  pp.preview_levels = preview_levels;
  pp.compress_grid = false;  // VerifyRefusesAPreviewThatDiffersFromTheTiles patches the section in place
  const std::string path = packtest::temp_path(name + ".pack");
  write_pack(path, h, cut, pp);
  return std::shared_ptr<PackReader>(PackReader::open(path));
}

// Every texel of every level >= K, answered as a client does with no tile at hand (the
// walk stops at the first tile; the preview answers), against the full pack at level
// min(level, K + p).
std::string first_difference(const PackReader& r) {
  PackEvaluator full(std::shared_ptr<const PackReader>(&r, [](const PackReader*) {}));
  const uint32_t k = r.skip_level(), p = r.preview().levels();
  for (uint32_t level = k; level <= r.map_level(); ++level) {
    const uint32_t at = std::min(level, k + p);
    for (uint64_t y = 0; y < (uint64_t(1) << level); ++y)
      for (uint64_t x = 0; x < (uint64_t(1) << level); ++x) {
        const PageHit hit = walk_page_table(r.grid(), level, x, y, [](uint64_t, const GridEntry&) -> const CutGrid* {
          return nullptr;
        });
        const float got = r.preview().coarse_answer(k, hit, level, x, y);
        if (hit.kind != PageHit::Kind::value) {  // the whole region shares the answer: check its first texel
          const uint32_t sh = r.preview().coarse_region_shift(k, hit, level);
          const uint64_t x0 = (x >> sh) << sh, y0 = (y >> sh) << sh;
          const PageHit h0 = walk_page_table(r.grid(), level, x0, y0, [](uint64_t, const GridEntry&) -> const CutGrid* {
            return nullptr;
          });
          if (bits(r.preview().coarse_answer(k, h0, level, x0, y0)) != bits(got))
            return "region of level " + std::to_string(level) + " (" + std::to_string(x) + ", " + std::to_string(y) +
                   ") shift " + std::to_string(sh) + " does not share its answer";
        }
        const float want = full.depth(at, x >> (level - at), y >> (level - at));
        if (bits(got) != bits(want))
          return "level " + std::to_string(level) + " (" + std::to_string(x) + ", " + std::to_string(y) + "): " +
                 std::to_string(got) + " != " + std::to_string(want);
      }
  }
  return "";
}

TEST(MapPreview, WithNoTileEveryTexelAnswersTheFullPackAtLevelKPlusP) {
  const uint32_t side = fields::small_test_scale() ? 32 : 64;
  const IntervalTile t = fields::city_field(side, 7);
  const Hierarchy h = build_hierarchy(t);
  for (Encoding e : packtest::available_encodings())
    for (uint32_t p : {0u, 2u, 3u}) {
      SCOPED_TRACE(to_string(e) + " p=" + std::to_string(p));
      // Small tiles: index tiles too, whose children the walk reaches below K.
      const auto r = build("preview_" + to_string(e) + std::to_string(p), h, e, 2, 256, p);
      EXPECT_EQ(r->preview().levels(), std::min(p, h.depth - 2));
      EXPECT_EQ(first_difference(*r), "");
    }
}

TEST(MapPreview, BytesArePinnedAndHostileOnesRefused) {
  const IntervalTile t = fields::city_field(16, 3);
  const Hierarchy h = build_hierarchy(t);
  const auto r = build("preview_bytes", h, Encoding::mh, 1, 1 << 16, 2);
  const MapPreview& m = r->preview();
  const std::vector<uint8_t> b = m.serialize();
  ASSERT_EQ(b.size(), m.serialized_size());
  ASSERT_GT(m.cells(), 0u);
  EXPECT_EQ(load_le<uint32_t>(b.data() + 0), kPreviewMagic);
  EXPECT_EQ(load_le<uint32_t>(b.data() + 4), 2u);
  EXPECT_EQ(load_le<uint32_t>(b.data() + 8), m.cells());
  const uint32_t r_bytes = load_le<uint32_t>(b.data() + 12);
  EXPECT_EQ(MapPreview::nodes(2), 20u);
  EXPECT_EQ(MapPreview::words(2), 1u);
  EXPECT_EQ(MapPreview::words(4), 6u);
  EXPECT_EQ(b.size(), 16u + 8u * m.cells() + r_bytes);
  // Every byte: the masks as stored, then each stored node's residual against its
  // prediction (map_preview.hpp), decoded here independently of the reader.
  {
    size_t at = 16 + 8 * m.cells(), value = 0;
    uint64_t stored = 0;
    for (size_t o = 0; o < m.cells(); ++o) {
      const uint64_t mask = load_le<uint64_t>(b.data() + 16 + 8 * o);
      EXPECT_EQ(mask, m.masks()[o]);
      EXPECT_EQ(mask >> 20, 0u);
      stored += uint64_t(std::popcount(mask));
      uint32_t level[2][16] = {};  // bit patterns of levels 1 (2 x 2) and 2 (4 x 4), row-major
      const uint32_t entry = bits(m.entry_values()[o]);
      for (uint32_t j = 1; j <= 2; ++j) {
        const uint32_t s = 1u << j;
        uint32_t* g = level[j - 1];
        for (uint32_t y = 0; y < s; ++y)
          for (uint32_t x = 0; x < s; ++x) {
            const uint32_t parent = j == 1 ? entry : level[0][(y / 2) * 2 + x / 2];
            const uint32_t bit = ((1u << (2 * j)) - 4) / 3 + (y << j) + x;
            if (!(mask >> bit & 1)) {
              g[y * s + x] = parent;
              continue;
            }
            auto at_ = [&](uint32_t xx, uint32_t yy) { return g[yy * s + xx]; };
            uint32_t pred = parent;
            if (x >= 1 && y >= 1) pred = at_(x - 1, y) + at_(x, y - 1) - at_(x - 1, y - 1);
            else if (x >= 2) pred = 2 * at_(x - 1, y) - at_(x - 2, y);
            else if (y >= 2) pred = 2 * at_(x, y - 1) - at_(x, y - 2);
            else if (x == 1) pred = at_(0, y);
            else if (y == 1) pred = at_(x, 0);
            uint32_t z = 0;
            for (uint32_t sh = 0;; sh += 7) {
              ASSERT_LT(at, b.size());
              z |= uint32_t(b[at] & 0x7f) << sh;
              if (!(b[at++] & 0x80)) break;
            }
            g[y * s + x] = pred + ((z >> 1) ^ (0u - (z & 1)));
            ASSERT_LT(value, m.values().size());
            EXPECT_EQ(g[y * s + x], bits(m.values()[value++]));
          }
      }
    }
    EXPECT_EQ(stored, m.stored_values());
    EXPECT_EQ(value, m.stored_values());
    EXPECT_EQ(at, b.size());
  }
  // The pack holds it right after the skip grid, in the grid section.
  const auto section = r->grid_bytes();
  ASSERT_EQ(section.size(), CutGrid::serialized_size(1) + b.size());
  EXPECT_TRUE(std::equal(b.begin(), b.end(), section.begin() + long(CutGrid::serialized_size(1))));
  EXPECT_NO_THROW(MapPreview::parse(b, r->grid(), r->map_level(), "ok"));

  auto refused = [&](std::vector<uint8_t> x, const char* why) {
    try {
      MapPreview::parse(x, r->grid(), r->map_level(), "p");
      ADD_FAILURE() << "accepted: " << why;
    } catch (const FormatError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  refused({b.begin(), b.begin() + 12}, "truncated header");
  refused({b.begin(), b.end() - 1}, "needs");
  auto with = [&](size_t off, uint32_t v) {
    std::vector<uint8_t> x = b;
    store_le<uint32_t>(x.data() + off, v);
    return x;
  };
  refused(with(0, 0), "bad magic");
  refused(with(0, 0x56505453), "before residual values");  // "STPV": raw f32 values
  refused(with(4, 5), "levels 5");
  refused(with(4, 4), "levels 4");  // K + p beyond the map's level 4
  refused(with(8, uint32_t(m.cells() + 1)), "non-constant entries");
  refused(with(12, r_bytes + 1), "needs");
  refused({b.begin(), b.end() - 1}, "needs");
  if (m.stored_values() > 0) {
    std::vector<uint8_t> x(b.begin(), b.end());  // one residual byte short: the last value is cut
    x.pop_back();
    store_le<uint32_t>(x.data() + 12, r_bytes - 1);
    refused(x, r_bytes - 1 < m.stored_values() ? "residual bytes for" : "residuals end inside a value");
    std::vector<uint8_t> y(b.begin(), b.end());  // one byte too many
    y.push_back(0);
    store_le<uint32_t>(y.data() + 12, r_bytes + 1);
    refused(y, "after the last value");
    {
      std::vector<uint8_t> o(b.begin(), b.end());  // the first residual written overlong (a 0 byte last)
      const size_t at = 16 + 8 * m.cells();
      if (o[at] < 0x80) {
        o[at] |= 0x80;
        o.insert(o.begin() + long(at + 1), uint8_t(0));
        store_le<uint32_t>(o.data() + 12, r_bytes + 1);
        refused(o, "overlong residual");
      }
    }
    std::vector<uint8_t> big(b.begin(), b.begin() + long(16 + 8 * m.cells()));  // a 5-byte varint above 2^32
    for (uint8_t v : {0xff, 0xff, 0xff, 0xff, 0x1f}) big.push_back(v);
    store_le<uint32_t>(big.data() + 12, 5);
    refused(big, m.stored_values() > 5 ? "residual bytes for" : "above 2^32");
  }
  {
    std::vector<uint8_t> x = with(16 + 4, 1u << 31);  // bit 63 of the first mask: beyond node 19
    refused(x, "mask bits beyond the last node");
  }
  {
    // A first residual that makes the first stored value a NaN (masks first; residual 1 byte
    // replaced by the 5-byte varint of NaN - prediction, here found by re-predicting).
    const size_t values_at = 16 + 8 * m.cells();
    ASSERT_GT(m.stored_values(), 0u);
    uint32_t z = 0;
    size_t len = 0;
    for (uint32_t sh = 0;; sh += 7, ++len) {
      z |= uint32_t(b[values_at + len] & 0x7f) << sh;
      if (!(b[values_at + len] & 0x80)) break;
    }
    ++len;
    const uint32_t pred = bits(m.values()[0]) - ((z >> 1) ^ (0u - (z & 1)));
    const uint32_t e = 0x7fc00000u - pred, nz = (e << 1) ^ uint32_t(int32_t(e) >> 31);
    std::vector<uint8_t> x(b.begin(), b.begin() + long(values_at));
    for (uint32_t u = nz; ; u >>= 7) {
      x.push_back(uint8_t((u & 0x7f) | (u >= 0x80 ? 0x80 : 0)));
      if (u < 0x80) break;
    }
    x.insert(x.end(), b.begin() + long(values_at + len), b.end());
    store_le<uint32_t>(x.data() + 12, uint32_t(x.size() - values_at));
    refused(x, "NaN value");
  }
}

TEST(MapPreview, VerifyRefusesAPreviewThatDiffersFromTheTiles) {
  const IntervalTile t = fields::city_field(16, 3);
  const auto r = build("preview_verify", build_hierarchy(t), Encoding::mh, 1, 1 << 16, 2);
  ASSERT_GT(r->preview().stored_values(), 0u);
  EXPECT_NO_THROW(r->verify(TileCodec::of(Encoding::mh).open));
  std::ifstream in(r->name(), std::ios::binary);  // the pack's path
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(b.size(), r->file_size());
  const uint64_t grid_at = r->header().grid_offset, grid_size = r->header().grid_size;
  const uint64_t value_at = grid_at + CutGrid::serialized_size(1) + 16 + 8 * r->preview().cells();
  b[value_at] ^= 0x02;  // the first residual moves by one unit: still a valid varint and float
  PackHeader h = r->header();
  h.grid_crc = crc32_of(std::span<const uint8_t>(b.data() + grid_at, grid_size));
  const auto head = h.serialize();
  std::copy(head.begin(), head.end(), b.begin());
  const auto bad = PackReader::open_memory(std::move(b), "bad_preview.pack");  // every CRC right
  try {
    bad->verify(TileCodec::of(Encoding::mh).open);
    ADD_FAILURE() << "verify accepted a preview that differs from the tiles";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("map preview differs"), std::string::npos) << e.what();
  }
}

TEST(MapPreview, AVersion1PackIsRefusedNamingTheVersion) {
  const IntervalTile t = fields::city_field(16, 3);
  const auto r = build("preview_v1", build_hierarchy(t), Encoding::mh, 1, 1 << 16, 1);
  std::array<uint8_t, kPackHeaderBytes> head = r->header().serialize();
  store_le<uint32_t>(head.data() + 8, 1);
  store_le<uint32_t>(head.data() + 252, crc32_of(std::span<const uint8_t>(head.data(), 252)));
  try {
    PackHeader::parse(head, "old.pack");
    ADD_FAILURE() << "a version 1 header was accepted";
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("unsupported version 1 (this build reads 2"), std::string::npos) << e.what();
  }
}

}  // namespace map_preview_test
}  // namespace st
